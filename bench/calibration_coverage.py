"""Coverage study of ``femubench calibrate``: does the calibration find the truth it was given?

:func:`run_coverage` makes ``n`` virtual experiments of one Drucker-Prager variant (the truth),
each of a specimen drawn from :attr:`CoverageSettings.specimens` (by default 100 and 150 mm cubes
and 100 x 100 x 300 mm prisms) with parameters drawn uniformly in the middle half of the
variant's box (``lower + [0.25, 0.75] (upper - lower)``: plausible values, never the reference),
its own camera rotation, drift and noise seeds (problems/inverse/virtual_experiment.py). The data
are made on ``data_mesh``, a discretisation finer than the inverse model's ``inverse_mesh``
(never the same, nor the check mesh: the honesty rule, refused up front); the experiment's
images are at fixed strains (the displacement levels scale with the height). Each experiment is
calibrated with :func:`bench.calibration.calibrate` over ``models`` (default: the three surfaces
in the truth's hardening test; the linear surface's three hardening tests are one material and
cannot be told apart), and scored:

* the relative error (%) of every identified parameter of the true variant;
* whether the true variant ranks first by AIC, and by the Laplace evidence; and (with a
  correction) whether it is first or not resolved from the first by the ranking's
  discretisation band (:func:`bench.calibration.ranking_band`);
* whether each 95 % interval (Laplace, Birge-widened) covers the true value.

The summary also states a Gaussian-efficient reference (:func:`noise_limit`): were the estimate
unbiased with Gaussian errors of the Laplace noise sd (the Cramér–Rao bound at the estimate), the
expected number of experiments with a parameter within the 2 % target, and with every parameter
within it (between the Šidák lower bound, the product over the parameters, and the least
parameter's share, an upper bound), that count's sd and its chance of reaching 9 of 10; per
parameter the rms of error / sd over the experiments (about 1 when the errors are the noise's,
well above when a bias dominates); and each experiment's largest |error| / sd. A count of
"within 2 %" near the reference, with errors of about one sd, is read as what it is: a parameter
the test does not determine to 2 %, not a biased calibration. Not stated for a study whose
noise is scaled (``noise_scale`` != 1).

Meshes are stored and keyed as discretisations: a preset of
:data:`problems.fe.presets.SPEC_PRESETS` (``converged``, a role whose mesh can be re-pointed) given
in any mesh option is spelled out when the settings are made
(:func:`problems.fe.presets.spell_out`), and a stored settings block that names one, from a
study made before, is read as what it meant then (:data:`LEGACY_SPEC_PRESETS`,
:func:`settings_from_dict`). A rerun into an ``out`` whose study has another data, inverse or
check mesh is refused (:func:`check_same_meshes`): its records are not overwritten by another
mesh's.

Resumable: each experiment's record is written atomically to ``<out>/experiments/eNNN.json``
keyed by what makes it (settings, index); a rerun reads the records whose key matches and runs
the others (the calibration inside resumes per variant too). The bulky files (virtual
experiments in ``data/``, shared by studies that differ in the calibration alone; the
calibration folders in ``calibration/``) go to ``work`` (default ``<out>/work``), the records
and the summary (``summary.json``, ``summary.md``) to ``out``.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from problems.fe.presets import spell_out
from problems.io.atomic import atomic_write_text

FORMAT = "femubench-calibration-coverage/1"
#: specimens drawn from (width, depth, height), mm
SPECIMENS = ((100.0, 100.0, 100.0), (150.0, 150.0, 150.0), (100.0, 100.0, 300.0))
#: nominal strains (plate displacement / height) of the images: the shipped example's
STRAINS = (4e-4, 8e-4, 1.5e-3, 2.5e-3, 3.5e-3, 4.5e-3, 5.5e-3, 7e-3)
#: the truth is drawn in lower + [DRAW_LOW, DRAW_HIGH] x (upper - lower) of the variant's box
DRAW_LOW, DRAW_HIGH = 0.25, 0.75
#: parameter targets of the issue: relative error (%) of every identified parameter
TARGET_ERROR_PERCENT = 2.0
#: ... in at least this share of the experiments (9 of 10)
TARGET_SHARE = 0.9
#: revision of the scores of a study with a discretisation band, in its records' keys (2: the
#: ranking's band); records scored by another are rescored from the calibrations, no new runs
SCORING = 2
#: the mesh options of a study (:class:`CoverageSettings` fields)
MESH_FIELDS = ("data_mesh", "inverse_mesh", "check_mesh")
#: what a :data:`problems.fe.presets.SPEC_PRESETS` name meant in the settings of the studies that
#: stored it by name, before names were spelled out: ``converged`` was ``12,12,24:g8:hex27`` until
#: it was re-pointed to ``15,15,30:g16:hex27`` at stop 38 (2026-11-27; no coverage study was made
#: between the re-pointing and the spelling out). A stored settings block naming it is read as
#: this mesh (:func:`settings_from_dict`), and the keys spell this mesh by that name, so that the
#: records of those studies (e.g. results/calibration/coverage/linear-compression-hex27) still
#: match: ``--data-mesh 12,12,24:g8:hex27`` resumes or rescores them, today's ``converged`` is
#: another discretisation (new keys; refused into their ``out``, :func:`check_same_meshes`).
#: The :data:`~problems.fe.presets.MESH_PRESETS` names (``coarse``, ``paper``, ...) and ``auto``
#: (the check mesh :data:`problems.inverse.build.DEFAULT_HIFI` names for the inverse mesh) are
#: stored and keyed as typed: they name fixed sizes and a fixed table, not a role whose mesh is
#: chosen anew, and spelling them out would change the keys of every study made with them (the
#: shipped linear-compression ones: data ``fine``, inverse ``coarse``, check ``paper``; the hex27
#: ones: check ``auto``) and rerun them. Re-pointing one of them needs an entry here.
LEGACY_SPEC_PRESETS: dict[str, str] = {"converged": "12,12,24:g8:hex27"}


def read_stored_mesh(spec: str) -> str:
    """A mesh setting as stored by a study: a :data:`LEGACY_SPEC_PRESETS` name (stored before
    names were spelled out) as the spec it meant then (``converged`` -> ``12,12,24:g8:hex27``);
    any other unchanged."""
    base, sep, rest = spec.partition(":")
    legacy = LEGACY_SPEC_PRESETS.get(base.strip())
    return legacy + sep + rest if legacy else spec


def _key_spelling(spec: str) -> str:
    """How a (spelled-out) mesh setting enters the keys: a :data:`LEGACY_SPEC_PRESETS` mesh by
    its old name (the keys of the studies made with it, :func:`read_stored_mesh` reversed),
    any other as it is."""
    for name, legacy in LEGACY_SPEC_PRESETS.items():
        if spec == legacy or spec.startswith(legacy + ":"):
            return name + spec[len(legacy) :]
    return spec


@dataclass(frozen=True)
class CoverageSettings:
    """What makes a coverage study (lengths mm).

    variant      : the Drucker-Prager variant that makes the data (a case name)
    n            : number of virtual experiments
    data_mesh    : mesh of the model that makes the data (finer than ``inverse_mesh``)
    inverse_mesh : mesh of the calibration's inverse model (both, and ``check_mesh``, with a
                   ``converged``-like preset spelled out, :func:`problems.fe.presets.spell_out`)
    models       : variants calibrated and ranked (default: the three surfaces in the
                   variant's hardening test)
    budget       : ``lm`` evaluations per variant and experiment
    seed         : of every draw (experiment i uses the stream (seed, i))
    specimens    : (width, depth, height) mm drawn from, uniformly
    strains      : nominal strains of the images (levels = strain x height)
    spacing_mm   : DIC grid step on the face
    correction, check_mesh, error_band : as :class:`bench.calibration.CalibrationSettings`
                   (check_mesh ``""``: no discretisation check, ``auto``: the inverse mesh's
                   default high-fidelity mesh; never the data mesh)
    plate_margin_mm : the plate margin of every calibration, mm, or ``"auto"`` (10 % of each
                   specimen's smallest dimension,
                   :func:`problems.inverse.build.auto_plate_margin_mm`); part of the calibration
                   key when not 0 (records without one read as margin 0)
    noise_scale  : multiplies the virtual experiments' noise (DIC points, load cell; the declared
                   sigma unchanged): 0 makes the noise-free twins of a study's experiments (the
                   same draws otherwise), whose errors are the inverse model's alone; part of the
                   data and calibration keys when not 1
    """

    variant: str = "linear-compression"
    n: int = 10
    data_mesh: str = "paper"
    inverse_mesh: str = "coarse"
    models: tuple[str, ...] = ()
    budget: int = 40
    seed: int = 0
    specimens: tuple[tuple[float, float, float], ...] = SPECIMENS
    strains: tuple[float, ...] = STRAINS
    spacing_mm: float = 5.0
    correction: str = "none"
    check_mesh: str = ""
    error_band: str = "gci"
    plate_margin_mm: float | str = 0.0
    noise_scale: float = 1.0

    def __post_init__(self):
        from problems.fe.mesh import discretisation_key, parse_mesh_spec
        from problems.inverse.cases import CASES, get_case

        if self.variant not in CASES:
            raise ValueError(f"--variant {self.variant!r} is unknown; allowed: {', '.join(CASES)}")
        if not self.models:
            hardening = get_case(self.variant).hardening
            forms = ("linear", "hyperbolic", "exponent")
            object.__setattr__(self, "models", tuple(f"{f}-{hardening}" for f in forms))
        if self.variant not in self.models:
            raise ValueError(
                f"--models {','.join(self.models)}: must include the variant {self.variant}"
            )
        if self.n < 1:
            raise ValueError(f"--n {self.n}: must be a whole number >= 1")
        data, inverse = parse_mesh_spec(self.data_mesh), parse_mesh_spec(self.inverse_mesh)
        if data.key == inverse.key:
            raise ValueError(
                f"--data-mesh {self.data_mesh}: the same discretisation as --inverse-mesh "
                f"{self.inverse_mesh} ({data.key}); the data are made on a finer mesh, never the "
                "inverse model's"
            )
        if any(d < i for d, i in zip(data.shape, inverse.shape)):
            raise ValueError(
                f"--data-mesh {self.data_mesh} ({data.key}) is not finer than --inverse-mesh "
                f"{self.inverse_mesh} ({inverse.key}) in every direction"
            )
        fine = self.calibration_settings().fine_mesh  # the correction's needs checked too
        if fine and discretisation_key(fine) == data.key:
            raise ValueError(
                f"--check-mesh {self.check_mesh}: the data mesh's discretisation ({data.key}); "
                "never a model of the calibration"
            )
        if not self.specimens or any(len(s) != 3 or min(s) <= 0 for s in self.specimens):
            raise ValueError(
                f"--specimens {self.specimens}: WIDTHxDEPTHxHEIGHT triples of positive mm"
            )
        if not self.strains or any(not 0 < s < 0.05 for s in self.strains):
            raise ValueError(f"--strains {self.strains}: increasing values in (0, 0.05)")
        if list(self.strains) != sorted(set(self.strains)):
            raise ValueError(f"--strains {self.strains}: increasing values in (0, 0.05)")
        if self.plate_margin_mm != "auto":
            if isinstance(self.plate_margin_mm, str):
                raise ValueError(
                    f"--plate-margin-mm {self.plate_margin_mm!r}: a number of mm or auto"
                )
            object.__setattr__(self, "plate_margin_mm", float(self.plate_margin_mm))
        for spec in self.specimens:
            self.margin_mm(spec)  # in range on every specimen drawn from
        if not (math.isfinite(self.noise_scale) and self.noise_scale >= 0):
            raise ValueError(f"--noise-scale {self.noise_scale!r}: a number >= 0 (1: as drawn)")
        object.__setattr__(self, "noise_scale", float(self.noise_scale) + 0.0)  # -0 is 0
        for name in MESH_FIELDS:  # checked as typed above, stored as the discretisation
            object.__setattr__(self, name, spell_out(getattr(self, name)))

    def margin_mm(self, specimen_mm) -> float:
        """The plate margin, mm, of a calibration of a specimen ``specimen_mm`` = (width,
        depth, height) mm; ValueError naming ``--plate-margin-mm`` when out of its range."""
        from problems.inverse.build import resolve_plate_margin

        try:
            return resolve_plate_margin(self.plate_margin_mm, specimen_mm)
        except ValueError as exc:
            raise ValueError(
                f"--plate-margin-mm {self.plate_margin_mm}: {exc} on the "
                f"{'x'.join(f'{v:g}' for v in specimen_mm)} mm specimen"
            ) from None

    def calibration_settings(self):
        """The :class:`bench.calibration.CalibrationSettings` of each experiment's calibration."""
        from bench.calibration import CalibrationSettings

        return CalibrationSettings(
            self.inverse_mesh,
            self.budget,
            self.seed,
            check_mesh=self.check_mesh,
            correction=self.correction,
            error_band=self.error_band,
        )

    def to_dict(self) -> dict:
        d = asdict(self)
        d["models"] = list(self.models)
        d["specimens"] = [list(s) for s in self.specimens]
        d["strains"] = list(self.strains)
        return d

    def _key_dict(self) -> dict:
        """:meth:`to_dict` with the meshes as they enter the keys (:func:`_key_spelling`)."""
        return self.to_dict() | {name: _key_spelling(getattr(self, name)) for name in MESH_FIELDS}

    def data_key(self, i: int) -> str:
        """Hash of what makes experiment ``i``'s data (studies differing in the calibration
        alone share them)."""
        d = self._key_dict()
        body = {k: d[k] for k in ("variant", "data_mesh", "seed", "specimens", "strains")}
        body |= {"spacing_mm": d["spacing_mm"], "index": i}
        if self.noise_scale != 1.0:  # the keys of studies before the option
            body["noise_scale"] = self.noise_scale
        return hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()[:16]

    def calibration_key(self, i: int) -> str:
        """Hash of what makes experiment ``i`` and its calibration (``n`` excluded: a study
        extended to more experiments keeps the ones done): names its calibration folder."""
        body = {k: v for k, v in self._key_dict().items() if k != "n"} | {"index": i}
        if self.correction == "none":  # no band without a correction: studies before it resume
            body.pop("error_band")
        if not self.plate_margin_mm:  # margin 0: the keys of studies before the option
            body.pop("plate_margin_mm")
        if self.noise_scale == 1.0:
            body.pop("noise_scale")
        return hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()[:16]

    def key(self, i: int) -> str:
        """Hash of what makes experiment ``i``'s record: :meth:`calibration_key`, and with a
        discretisation band its orders and safety factor (records scored with other constants
        are rescored from the calibration folder, without new runs)."""
        from problems.analysis.convergence import GCI_ORDERS, GCI_SAFETY

        key = self.calibration_key(i)
        if self.correction == "none" or self.error_band == "none":
            return key
        band = json.dumps(
            {"key": key, "orders": GCI_ORDERS, "safety": GCI_SAFETY, "scoring": SCORING},
            sort_keys=True,
        )
        return hashlib.sha256(band.encode()).hexdigest()[:16]


def settings_from_dict(d: dict) -> CoverageSettings:
    """A study's settings as stored (``summary.json``'s ``settings``), a legacy preset name read
    as what it meant then (:func:`read_stored_mesh`): the keys of its records, not today's
    meaning of the name."""
    d = dict(d)
    for name in MESH_FIELDS:
        if name in d:
            d[name] = read_stored_mesh(d[name])
    d["specimens"] = tuple(tuple(s) for s in d.get("specimens", SPECIMENS))
    for name in ("models", "strains"):
        if name in d:
            d[name] = tuple(d[name])
    return CoverageSettings(**d)


def _fine_mesh(settings: dict) -> str:
    """The check mesh a stored (legacy-read) settings block names ('' for none)."""
    from problems.inverse.build import hifi_mesh_for

    if settings.get("check_mesh", "") != "auto":
        return settings.get("check_mesh", "")
    return hifi_mesh_for(settings["inverse_mesh"])


def check_same_meshes(s: CoverageSettings, out) -> None:
    """ValueError (one line naming the option) when ``out`` holds a study (its ``summary.json``)
    whose data, inverse or check mesh is another discretisation than ``s``'s (a legacy preset
    name read as what it meant then): a rerun would overwrite that study's records with another
    mesh's, e.g. one made on ``converged`` before stop 38 (``12,12,24:g8:hex27``) rerun with
    today's ``converged``."""
    from problems.fe.mesh import discretisation_key

    try:
        stored = json.loads((Path(out) / "summary.json").read_text())["settings"]
        was = {name: read_stored_mesh(stored[name]) for name in MESH_FIELDS}
        was["check_mesh"] = _fine_mesh(was)
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return  # no study there (or not one of these): nothing to overwrite
    now = {name: getattr(s, name) for name in MESH_FIELDS}
    now["check_mesh"] = s.calibration_settings().fine_mesh
    for name in MESH_FIELDS:
        a, b = was[name], now[name]
        if (discretisation_key(a) if a else "") != (discretisation_key(b) if b else ""):
            option = "--" + name.replace("_", "-")
            raise ValueError(
                f"{option} {_named(getattr(s, name), b)}: --out {out} holds a study made with "
                f"{_named(stored[name], a)}, another discretisation; allowed: {option} "
                f"{a or 'none'} (resumes it) or another --out"
            )


def _named(value: str, mesh: str) -> str:
    """A mesh setting ``value`` in words, with the ``mesh`` it stands for when not the same
    (``auto``, a legacy preset name) and the preset that names it today."""
    from problems.fe.presets import SPEC_PRESETS

    if value == "auto":
        return f"auto = {mesh}"
    if value != mesh:
        return f"{value} (= {mesh} until stop 38)"
    today = [name for name, spec in SPEC_PRESETS.items() if spec == value]
    return (value or "none") + (f" ({today[0]} today)" if today else "")


def draw_test(s: CoverageSettings, i: int):
    """The :class:`~problems.inverse.virtual_experiment.VirtualTest` of experiment ``i``."""
    from problems.inverse.cases import get_case
    from problems.inverse.virtual_experiment import VirtualTest

    rng = np.random.default_rng([s.seed, i])
    case = get_case(s.variant)
    lo, hi = np.asarray(case.lower, float), np.asarray(case.upper, float)
    x = lo + rng.uniform(DRAW_LOW, DRAW_HIGH, lo.size) * (hi - lo)
    w, d, h = s.specimens[int(rng.integers(len(s.specimens)))]
    mm_per_px = 0.05
    return VirtualTest(
        s.variant,
        tuple(float(v) for v in x),
        width_mm=w,
        depth_mm=d,
        height_mm=h,
        levels_mm=tuple(float(e * h) for e in s.strains),
        data_mesh=s.data_mesh,
        mm_per_px=mm_per_px,
        rotation_deg=float(rng.uniform(-0.6, 0.6)),
        corner_px=(300.0, 400.0 + h / mm_per_px),
        spacing_mm=s.spacing_mm,
        drift_mm=(float(rng.uniform(-0.03, 0.03)), float(rng.uniform(-0.03, 0.03))),
        drift_rad=float(rng.uniform(-2e-4, 2e-4)),
        seed=int(rng.integers(2**31)),
        noise_scale=s.noise_scale,
    )


def score(truth, variant: str, report: dict) -> dict:
    """The scores of one calibration ``report`` against the true parameters ``truth`` of
    ``variant``: errors (%), interval coverage, ranks by AIC and by the Laplace evidence."""
    v = report["variants"][variant]
    truth = np.asarray(truth, float)
    ranking = report["ranking"]
    by_aic = [r["variant"] for r in ranking]
    by_z = [r["variant"] for r in sorted(ranking, key=lambda r: -r["log_evidence"])]
    prob = {r["variant"]: r["model_probability"] for r in ranking}
    out = {"ok": bool(v.get("ok")), "ranking_aic": by_aic, "ranking_evidence": by_z}
    if not v.get("ok"):
        return out | {
            "true_first_aic": False,
            "true_first_evidence": False,
            "true_first_or_unresolved_aic": False,
        }
    row = next((r for r in ranking if r["variant"] == variant), {})
    first = bool(by_aic and by_aic[0] == variant)
    rank_band = {}
    if (report.get("ranking_band") or {}).get("method") == "gci":
        rank_band = {
            "ranking_band": True,
            "true_delta_aic": row.get("delta_aic"),
            "true_band_delta_aic": row.get("band_delta_aic"),
            "second_resolved": ranking[1]["resolved"] if len(ranking) > 1 else None,
        }
    x = np.asarray(v["x"], float)
    lo, hi = np.asarray(v["ci95_lower"]), np.asarray(v["ci95_upper"])
    covered = (lo <= truth) & (truth <= hi)
    band = {}
    if "band_percent" in v:  # the discretisation band widened the intervals: Laplace's alone too
        lo_l, hi_l = np.asarray(v["ci95_laplace_lower"]), np.asarray(v["ci95_laplace_upper"])
        band = {
            "band_percent": v["band_percent"],
            "covered_laplace": ((lo_l <= truth) & (truth <= hi_l)).tolist(),
            "x_untreated": v["x_untreated"],
            "error_untreated_percent": (
                100.0 * (np.asarray(v["x_untreated"]) / truth - 1.0)
            ).tolist(),
        }
    return (
        out
        | band
        | {
            "names": v["names"],
            "x": x.tolist(),
            "error_percent": (100.0 * (x / truth - 1.0)).tolist(),
            "std_percent": v["std_percent"],
            "ci95_lower": lo.tolist(),
            "ci95_upper": hi.tolist(),
            "covered": covered.tolist(),
            "all_covered": bool(covered.all()),
            "birge_ratio": v["birge_ratio"],
            "rms_sigma": v["rms_sigma"],
            "n_evals": v["n_evals"],
            "true_first_aic": first,
            "true_first_evidence": bool(by_z and by_z[0] == variant),
            # first, or behind it within the ranking's discretisation band (without a band:
            # first alone)
            "true_first_or_unresolved_aic": first or row.get("resolved") is False,
            "model_probability": prob.get(variant, math.nan),
        }
        | rank_band
    )


def run_one(s: CoverageSettings, i: int, out: Path, work: Path, progress=print) -> dict:
    """Experiment ``i``: its record from ``out/experiments`` when the key matches, else made,
    calibrated, scored and written (atomically)."""
    from bench.calibration import calibrate, done_before
    from problems.inverse.virtual_experiment import write_virtual_experiment

    key = s.key(i)
    path = out / "experiments" / f"e{i:03d}.json"
    old = done_before(path, key)
    if old is not None:
        progress(f"experiment {i}: done before ({path})")
        return old
    # a record of the same calibration scored otherwise (other band constants) is rescored from
    # the calibration folder: its wall time carries over (the runs were made then)
    ckey = s.calibration_key(i)
    try:
        prev = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        prev = {}
    t0 = time.perf_counter()
    test = draw_test(s, i)
    folder = work / "calibration" / f"e{i:03d}-{ckey}"
    # records older than the calibration key name their calibration by the experiment itself
    same = prev.get("calibration_key", ckey if _same_test(prev, test) else None) == ckey
    carried = float(prev.get("wall_s", 0.0)) if same and (folder / "report.json").exists() else 0.0
    name = f"coverage-{s.variant}-{i:03d}"
    data_folder = work / "data" / f"e{i:03d}-{s.data_key(i)}"
    exp = data_folder / "experiment.toml"
    if not exp.exists():  # the writer's last file: the data are complete when it exists
        progress(
            f"experiment {i}: {test.width_mm:g}x{test.depth_mm:g}x{test.height_mm:g} mm, data on "
            f"mesh {s.data_mesh} ..."
        )
        write_virtual_experiment(test, data_folder, name)
    margin = s.margin_mm((test.width_mm, test.depth_mm, test.height_mm))
    report = calibrate(
        exp,
        folder,
        models=list(s.models),
        settings=s.calibration_settings(),
        progress=lambda m: progress(f"experiment {i}: {m}"),
        figures=False,
        plate_margin_mm=margin,
    )
    rec = {
        "key": key,
        "index": i,
        "variant": s.variant,
        "truth": list(test.x),
        "specimen_mm": [test.width_mm, test.depth_mm, test.height_mm],
        "levels_mm": list(test.levels_mm),
        "seed": test.seed,
        "data_mesh": s.data_mesh,
        "inverse_mesh": s.inverse_mesh,
        "calibration_key": ckey,
        "plate_margin_mm": margin,
        "points_used": report["import"]["points_used"],
        "wall_s": carried + time.perf_counter() - t0,
        **score(test.x, s.variant, report),
    }
    atomic_write_text(path, json.dumps(rec, indent=1, allow_nan=True) + "\n")
    return rec


def _same_test(prev: dict, test) -> bool:
    """Whether a record was made on the virtual experiment ``test`` (same seed, truth, specimen)."""
    return (
        prev.get("seed") == test.seed
        and prev.get("truth") == list(test.x)
        and prev.get("specimen_mm") == [test.width_mm, test.depth_mm, test.height_mm]
    )


def summarise(s: CoverageSettings, records: list[dict]) -> dict:
    """The study's summary: per parameter the mean and largest |error| (%), the share within
    the 2 % target, the 95 % intervals' coverage; the shares of experiments whose true variant
    ranks first (AIC, evidence) and whose intervals all cover the truth."""
    from problems.inverse.cases import get_case

    names = list(get_case(s.variant).names)
    ok = [r for r in records if r.get("ok")]
    E = np.array([r["error_percent"] for r in ok]).reshape(len(ok), len(names))
    C = np.array([r["covered"] for r in ok], bool).reshape(len(ok), len(names))
    per = {}
    for j, n in enumerate(names):
        e = np.abs(E[:, j])
        per[n] = {
            "mean_abs_error_percent": float(e.mean()) if len(e) else math.nan,
            "max_abs_error_percent": float(e.max()) if len(e) else math.nan,
            "within_target": int(np.sum(e <= TARGET_ERROR_PERCENT)),
            "covered": int(C[:, j].sum()),
        }
        bands = [r["band_percent"][j] for r in ok if "band_percent" in r]
        if bands:  # the discretisation band (% of the value) and the Laplace interval alone
            per[n] |= {
                "mean_band_percent": float(np.mean(bands)),
                "covered_laplace": sum(
                    bool(r["covered_laplace"][j]) for r in ok if "band_percent" in r
                ),
            }
    # the reference is the declared noise's: none for a study whose noise is scaled
    limit = noise_limit(ok, len(names)) if s.noise_scale == 1.0 else None
    if limit is not None:
        for j, n in enumerate(names):
            per[n]["within_target_noise_limit"] = float(limit["per_parameter"][j])
            per[n]["rms_error_over_sd"] = float(limit["rms_error_over_sd"][j])
    n = len(records)
    return {
        "format": FORMAT,
        "settings": s.to_dict(),
        "n_done": n,
        "n_ok": len(ok),
        "parameters": per,
        "true_first_aic": sum(bool(r.get("true_first_aic")) for r in records),
        "true_first_evidence": sum(bool(r.get("true_first_evidence")) for r in records),
        "true_first_or_unresolved_aic": sum(
            bool(r.get("true_first_or_unresolved_aic", r.get("true_first_aic"))) for r in records
        ),
        "n_ranking_band": sum(bool(r.get("ranking_band")) for r in records),
        "all_covered": sum(bool(r.get("all_covered")) for r in records),
        "all_within_target": int(np.sum(np.all(np.abs(E) <= TARGET_ERROR_PERCENT, axis=1))),
        **(
            {
                "all_within_target_noise_limit": [limit["all_lower"], limit["all_upper"]],
                "all_within_target_noise_sd": limit["all_sd"],
                "all_within_target_noise_target_chance": limit["all_target_chance"],
            }
            if limit is not None
            else {}
        ),
        "wall_s": float(sum(r["wall_s"] for r in records)),
        "per_specimen": per_specimen(records),
        "experiments": [
            {"plate_margin_mm": record_margin(r)}
            | {
                k: r.get(k)
                for k in (
                    "index",
                    "specimen_mm",
                    "truth",
                    "error_percent",
                    "covered",
                    "ranking_aic",
                    "ranking_evidence",
                    "model_probability",
                    "true_delta_aic",
                    "true_band_delta_aic",
                    "rms_sigma",
                    "birge_ratio",
                    "wall_s",
                )
            }
            | (
                {"max_error_over_sd": max_error_over_sd(r)}
                if "std_percent" in r and s.noise_scale == 1.0
                else {}
            )
            for r in records
        ],
    }


def noise_sd_percent(record: dict) -> np.ndarray:
    """A record's Laplace noise sd of each parameter, % of the true value (its ``std_percent``,
    % of the estimate, without the Birge widening, which is >= 1 and multiplies it, and rescaled
    to the truth like ``error_percent``)."""
    sd = np.asarray(record["std_percent"], float) / max(1.0, float(record["birge_ratio"]))
    return sd * np.abs(1.0 + np.asarray(record["error_percent"], float) / 100.0)


def max_error_over_sd(record: dict) -> float:
    """A record's largest |error| in units of its parameter's Laplace noise sd."""
    return float(np.max(np.abs(record["error_percent"]) / noise_sd_percent(record)))


def count_at_least(p, k: int) -> float:
    """P(at least ``k`` successes) of independent trials with success chances ``p`` (the
    Poisson-binomial distribution, by convolution)."""
    dist = np.array([1.0])
    for q in p:
        dist = np.convolve(dist, [1.0 - q, q])
    return float(dist[k:].sum())


def noise_limit(records: list[dict], n_par: int) -> dict | None:
    """The Gaussian-efficient reference of ``records`` (those with ``std_percent``; None without
    any): were the estimate unbiased with Gaussian errors of the Laplace noise sd ``sd`` (the
    Cramér–Rao bound at the estimate), a parameter would land within the target t with chance
    ``p = erf(t / (sd sqrt 2))``. Returned: per parameter the expected number of experiments
    within the target (the sum of p); for every parameter at once the expected number between
    the Šidák lower bound (the product of p over the parameters; Gaussian errors of any
    correlation do at least this well) and the upper one (the least p), the count's sd and the
    chance of at least :data:`TARGET_SHARE` of the experiments (both with the least p, the upper
    bound of each experiment's chance); per parameter the rms over the experiments of error/sd.
    A reference, not a bound on every estimator: a biased or non-Gaussian one may do better."""
    from scipy.special import erf

    rs = [r for r in records if "std_percent" in r]
    if not rs:
        return None
    sd = np.array([noise_sd_percent(r) for r in rs]).reshape(len(rs), n_par)
    p = erf(TARGET_ERROR_PERCENT / (np.sqrt(2.0) * sd))
    z = np.array([r["error_percent"] for r in rs], float).reshape(sd.shape) / sd
    least = np.min(p, axis=1)
    return {
        "per_parameter": p.sum(axis=0).tolist(),
        "rms_error_over_sd": np.sqrt(np.mean(z**2, axis=0)).tolist(),
        "all_lower": float(np.prod(p, axis=1).sum()),
        "all_upper": float(least.sum()),
        "all_sd": float(np.sqrt(np.sum(least * (1.0 - least)))),
        "all_target_chance": count_at_least(least, math.ceil(TARGET_SHARE * len(rs) - 1e-9)),
    }


def record_margin(record: dict) -> float:
    """The plate margin, mm, of a record's calibration (records before the option: 0)."""
    return float(record.get("plate_margin_mm", 0.0))


def per_specimen(records: list[dict]) -> list[dict]:
    """Per specimen (width, depth, height mm, in the order first met): experiments, those with
    every parameter within the 2 % target, with the true variant first by AIC, with every 95 %
    interval covering the truth, and the plate margins used (mm)."""
    groups: dict[tuple, list[dict]] = {}
    for r in records:
        groups.setdefault(tuple(r["specimen_mm"]), []).append(r)
    return [
        {
            "specimen_mm": list(spec),
            "n": len(rs),
            "all_within_target": sum(
                bool(r.get("ok"))
                and all(abs(e) <= TARGET_ERROR_PERCENT for e in r["error_percent"])
                for r in rs
            ),
            "true_first_aic": sum(bool(r.get("true_first_aic")) for r in rs),
            "all_covered": sum(bool(r.get("all_covered")) for r in rs),
            "plate_margin_mm": sorted({record_margin(r) for r in rs}),
        }
        for spec, rs in groups.items()
    ]


def _mesh_text(spec: str) -> str:
    """A stored mesh setting in Markdown, a legacy preset name with the mesh it meant then."""
    meant = read_stored_mesh(spec)
    return f"`{spec}`" + (f" (= `{meant}` until stop 38)" if meant != spec else "")


def _check_mesh(s: dict) -> str:
    """The study's check mesh as named, ``auto`` with the mesh it stands for."""
    if s["check_mesh"] != "auto":
        return _mesh_text(s["check_mesh"])
    return f"`auto = {_fine_mesh(s | {'inverse_mesh': read_stored_mesh(s['inverse_mesh'])})}`"


def _margin_text(margin) -> str:
    """The study's plate margin in words."""
    if margin == "auto":
        from problems.inverse.build import AUTO_PLATE_MARGIN_FRACTION

        return (
            f"plate margin auto: {100 * AUTO_PLATE_MARGIN_FRACTION:g} % of each specimen's "
            "smallest dimension"
        )
    return f"plate margin {float(margin):g} mm"


def _noise_text(scale: float) -> str:
    """The study's noise scale in words (nothing when the experiments' noise is as drawn)."""
    if scale == 1.0:
        return ""
    if scale == 0.0:
        return "; noise-free twins (every noise draw times 0, the declared sigma kept)"
    return f"; every noise draw times {scale:g} (the declared sigma kept)"


def _delta_cell(e: dict) -> str:
    """An experiment's true-variant dAIC and the ranking's band U there (``-`` for the first
    or without a band)."""
    d, u = e.get("true_delta_aic"), e.get("true_band_delta_aic")
    if d is None or u is None:
        return "-"
    return f"{d:.3g} ({u:.3g}{', not resolved' if d <= u else ''})"


def _parameter_table(summary: dict) -> list[str]:
    """The per-parameter table of the summary (with the discretisation band's and the noise
    ceiling's columns where the records carry them) and its legend."""
    params, n_ok = summary["parameters"], summary["n_ok"]
    banded = any("mean_band_percent" in p for p in params.values())
    ceiling = any("within_target_noise_limit" in p for p in params.values())
    lines, head = [], ["parameter", "mean abs error %", "max abs error %"]
    head += ["within 2 % (Gaussian-efficient)", "rms error/sd"] if ceiling else ["within 2 %"]
    head += ["95 % interval covers"]
    if ceiling:
        lines += [
            "Gaussian-efficient: the expected count for an unbiased estimate with Gaussian "
            "errors of the Laplace noise sd (the Cramér–Rao bound at the estimate; a reference, "
            "not a bound on every estimator); "
            "'rms error/sd': the parameter's errors in units of its Laplace noise sd, rms over "
            "the experiments (about 1: the noise's; well above: a bias); 'max \\|error\\|/sd' "
            "per experiment.",
            "",
        ]
    if banded:
        lines += [
            "95 % intervals: the Laplace half-width plus the discretisation band (GCI of the "
            "corrected against the untreated estimate, docs/calibrating.md); 'Laplace alone' "
            "without the band.",
            "",
        ]
        head += ["mean band %", "Laplace alone covers"]
    lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, p in params.items():
        cells = [name, f"{p['mean_abs_error_percent']:.3g}", f"{p['max_abs_error_percent']:.3g}"]
        within = f"{p['within_target']} of {n_ok}"
        if ceiling:
            lim, z = p.get("within_target_noise_limit"), p.get("rms_error_over_sd")
            cells += [
                within + (f" ({lim:.1f})" if lim is not None else ""),
                f"{z:.2g}" if z is not None else "-",
            ]
        else:
            cells.append(within)
        cells.append(f"{p['covered']} of {n_ok}")
        if banded:
            cells += (
                [f"{p['mean_band_percent']:.3g}", f"{p['covered_laplace']} of {n_ok}"]
                if "mean_band_percent" in p
                else ["-", "-"]
            )
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def render_summary(summary: dict) -> str:
    """The summary as Markdown."""
    s = summary["settings"]
    n, names = summary["n_done"], list(summary["parameters"])
    lines = [
        f"# Calibration coverage: {s['variant']}, {n} virtual experiments",
        "",
        f"Data made on mesh {_mesh_text(s['data_mesh'])}, calibrated on the inverse mesh "
        f"{_mesh_text(s['inverse_mesh'])} (correction {s['correction']}"
        + (f", check mesh {_check_mesh(s)}" if s["check_mesh"] else "")
        + f"; {_margin_text(s.get('plate_margin_mm', 0.0))}), `lm` with {s['budget']} "
        "evaluations per variant from the test's start; models "
        f"{', '.join(s['models'])}. Specimens (width x depth x height, mm) drawn from "
        + ", ".join("x".join(f"{v:g}" for v in sp) for sp in s["specimens"])
        + f"; the truth drawn in the middle half of the variant's box; seed {s['seed']}"
        + _noise_text(s.get("noise_scale", 1.0))
        + ". "
        f"Total wall time {summary['wall_s'] / 60:.1f} min.",
        "",
        (
            f"- true variant ranked first: {summary['true_first_aic']} of {n} by AIC, "
            f"{summary['true_first_evidence']} of {n} by the Laplace evidence"
            if len(s["models"]) > 1
            else "- model selection not assessed: the true variant alone was calibrated"
        ),
        *(
            [
                f"- true variant first, or not resolved from the first at this discretisation "
                f"(the ranking's discretisation band, docs/calibrating.md): "
                f"{summary['true_first_or_unresolved_aic']} of {n} by AIC"
                + (
                    ""
                    if summary.get("n_ranking_band", 0) == n
                    else f" ({summary.get('n_ranking_band', 0)} of {n} with a band; without "
                    "one, first alone)"
                )
            ]
            if len(s["models"]) > 1 and summary.get("n_ranking_band")
            else []
        ),
        f"- every 95 % interval covers the truth: {summary['all_covered']} of {n}",
        f"- every parameter within {TARGET_ERROR_PERCENT:g} %: {summary['all_within_target']} "
        f"of {summary['n_ok']}"
        + (
            " (a Gaussian-efficient estimate, unbiased at the Laplace noise sd: "
            f"{lim[0]:.1f}–{lim[1]:.1f} expected, sd {summary['all_within_target_noise_sd']:.1f}; "
            f"at least {math.ceil(TARGET_SHARE * summary['n_ok'] - 1e-9)} of {summary['n_ok']} "
            f"with chance {summary['all_within_target_noise_target_chance']:.2g}; "
            "docs/calibrating.md)"
            if (lim := summary.get("all_within_target_noise_limit"))
            else ""
        ),
        "",
    ]
    lines += _parameter_table(summary)
    lines += [
        "",
        "## Per specimen",
        "",
        "| specimen mm | experiments | every parameter within 2 % | true variant first (AIC) "
        "| every 95 % interval covers | plate margin mm |",
        "|---|---|---|---|---|---|",
        *(
            f"| {'x'.join(f'{v:g}' for v in g['specimen_mm'])} | {g['n']} | "
            f"{g['all_within_target']} | {g['true_first_aic']} | {g['all_covered']} | "
            f"{', '.join(f'{m:g}' for m in g['plate_margin_mm'])} |"
            for g in summary.get("per_specimen", [])
        ),
    ]
    lines += [
        "",
        "## Experiments",
        "",
        "| # | specimen mm | error % (" + ", ".join(names) + ") | covered | first (AIC) | "
        "p(true\\|D) | dAIC true (band U) | max \\|error\\|/sd | rms sigma | wall s |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for e in summary["experiments"]:
        err = e.get("error_percent")
        lines.append(
            f"| {e['index']} | {'x'.join(f'{v:g}' for v in e['specimen_mm'])} | "
            + (", ".join(f"{v:+.2g}" for v in err) if err else "failed")
            + f" | {sum(e.get('covered') or [])} of {len(names)} | "
            f"{(e.get('ranking_aic') or ['-'])[0]} | {e.get('model_probability', math.nan):.3g} |"
            f" {_delta_cell(e)} | {e.get('max_error_over_sd', math.nan):.2g} |"
            f" {e.get('rms_sigma') or math.nan:.3g} | {e['wall_s']:.0f} |"
        )
    return "\n".join(lines) + "\n"


def run_coverage(s: CoverageSettings, out, *, work=None, progress=print, indices=None) -> dict:
    """Run (or resume) the study into ``out`` (module docstring); returns the summary.

    indices : the experiments to run (default all ``range(s.n)``): several processes may share
              ``out`` and ``work`` on disjoint ranges (each record is its own file); every
              summary they write covers all the study's records done so far."""
    from bench.calibration import done_before

    out = Path(out)
    check_same_meshes(s, out)
    work = Path(work) if work else out / "work"
    indices = range(s.n) if indices is None else indices
    summary = None
    for i in indices:
        rec = run_one(s, i, out, work, progress)
        done = (
            rec if j == i else done_before(out / "experiments" / f"e{j:03d}.json", s.key(j))
            for j in range(s.n)
        )
        records = [r for r in done if r is not None]
        summary = summarise(s, records)
        atomic_write_text(out / "summary.json", json.dumps(summary, indent=1) + "\n")
        atomic_write_text(out / "summary.md", render_summary(summary))
        progress(
            f"experiment {i}: errors "
            + ", ".join(f"{v:+.2g}" for v in rec.get("error_percent", []))
            + f" %; covered {sum(rec.get('covered', []))}; first {rec['ranking_aic'][:1]}; "
            f"{rec['wall_s']:.0f} s"
        )
    return summary

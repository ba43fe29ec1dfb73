"""Pseudo-experimental data sets: the reference response on a finer mesh, noised and rounded.

One data set is one JSON file (format ``femubench-data/1``) holding the measurements, the
settings that made them and a SHA-256 content hash. The same settings give the same bytes.

Two tiers, labelled in every file, record and report:

* ``model-error``: made on ``15,15,30:g16:hex27`` (the preset ``converged``: 27-node Q2-P1
  hexahedra, 15 x 15 x 30 quarter graded with ratio 16 toward the plate edges and free faces),
  within the reference criterion on all nine cases (against the convergence study's five-mesh
  extrapolation 0.11-0.15 sigma RMS and +0.016 to +0.044 % in force, docs/fe_model.md; until
  stop 38 the tier was made on ``12,12,24:g8:hex27``, 0.25-0.42 sigma and +0.042 to +0.095 %,
  short of it on most cases) and never a model of the inverse loop
  (inverse model, high-fidelity model of a correction, BAE statistics, surrogate training): the
  honest pseudo-experiment, with the inverse model's discretisation error in it, as a real test
  would have it. (Until this tier it was made on the uniform ``xfine``, 24 x 24 x 48 trilinear,
  which is not converged: docs/cases_and_data.md);
* ``consistent``: made with the inverse model's own discretisation plus the same measurement
  model (rounding, optional noise): a known optimum, for judging the optimisers alone.

Where data sets live:

* the default sets of both tiers ship as package data in ``problems/inverse/datasets/<tier>/``
  (the consistent tier for the default inverse mesh, ``coarse``); the environment variable
  ``FEMUBENCH_DATA_DIR`` points the look-up at another directory with the same layout;
* data sets of other settings are computed on first use and cached in ``FEMUBENCH_CACHE_DIR``
  (default ``$XDG_CACHE_HOME/femubench/data``, i.e. ``~/.cache/femubench/data``), never inside
  the installed package; DIC-route images go next to the data file, in ``<stem>__dic_images/``.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import asdict, dataclass, field
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import numpy as np

from problems.fe.front_face import measurement_grid
from problems.fe.mesh import SPEC_PRESETS, SPECIMEN_MM, quarter_size
from problems.fe.newton import Loading, MachineLoading
from problems.inverse.case import Case
from problems.inverse.cases import get_case
from problems.inverse.user_cache import CACHE_DIR_ENV, cache_dir  # noqa: F401 (this module's API)

FORMAT = "femubench-data/1"
#: The shipped default data sets (package data of problems.inverse).
SHIPPED_DIR = Path(__file__).resolve().parent / "datasets"
#: Environment variable: directory of the default data sets, instead of :data:`SHIPPED_DIR`.
DATA_DIR_ENV = "FEMUBENCH_DATA_DIR"
TIERS = ("model-error", "consistent")
#: the tier of data imported from a real (or virtual) test's files (problems/inverse/experiment.py):
#: no model made them, so their ``mesh`` is empty
EXPERIMENT_TIER = "experiment"
#: the discretisation that makes the model-error tier (never used inside the inverse loop): the
#: converged reference, the mesh preset ``converged`` spelled out (so a data file names its mesh
#: whatever the preset may later mean)
MODEL_ERROR_MESH = SPEC_PRESETS["converged"]
#: the inverse model's mesh of the shipped consistent tier (and of the surrogate track): the
#: optimiser benchmark's model, whose own data give a known optimum
DEFAULT_INVERSE_MESH = "coarse"
#: the default inverse model on model-error data (the honest tier): 27-node Q2-P1 hexahedra on a
#: 6 x 6 x 12 quarter mesh graded 8:1 toward the plates and free faces, chosen from the convergence
#: study as the best trade-off of discretisation bias and cost (docs/fe_model.md, "The default
#: inverse model")
MODEL_ERROR_INVERSE_MESH = "6,6,12:g8:hex27"


def default_inverse_mesh(tier: str) -> str:
    """The default inverse mesh on data of ``tier``: :data:`MODEL_ERROR_INVERSE_MESH` on the
    model-error tier (and on a real test's data), :data:`DEFAULT_INVERSE_MESH` on the consistent
    tier."""
    return DEFAULT_INVERSE_MESH if tier == "consistent" else MODEL_ERROR_INVERSE_MESH


def data_dir() -> Path:
    """Directory of the default data sets: ``$FEMUBENCH_DATA_DIR`` if set, else the shipped ones."""
    env = os.environ.get(DATA_DIR_ENV)
    return Path(env).expanduser() if env else SHIPPED_DIR


@dataclass(frozen=True)
class DataSettings:
    """How a data set is made.

    tier                : ``model-error`` or ``consistent`` (see the module docstring)
    mesh                : mesh of the data model: ``15,15,30:g16:hex27`` (``converged``) for the
                          model-error tier, the inverse model's own for the consistent tier
    resolution_um       : displacement rounding step, micrometres (0: no rounding)
    noise_um            : standard deviation of added Gaussian displacement noise, micrometres
    force_resolution_kN : force rounding step, kN (0: no rounding)
    seed                : seed of the noise generator
    displacement_mm, snapshots, plates : the loading
    spacing_mm, margin_mm : the front-face measurement grid
    specimen_mm         : (x, y, z) extents of the whole specimen, mm (default the 150 mm cube;
                          the grid covers the quarter's face y in [0, y/2], z in [0, z])
    levels_mm           : top-plate displacement at each snapshot, mm, when not equally spaced
                          (a machine log; then ``displacement_mm`` and ``snapshots`` are its last
                          value and length); empty: ``snapshots`` equal steps
    ``specimen_mm`` and ``levels_mm`` enter the file and its hash only when they are not the
    default (:meth:`to_dict`), so every data set of the cube keeps its bytes and hash.
    """

    tier: str = "model-error"
    mesh: str = MODEL_ERROR_MESH
    resolution_um: float = 1.0
    noise_um: float = 0.0
    force_resolution_kN: float = 0.1
    seed: int = 0
    displacement_mm: float = 1.5
    snapshots: int = 10
    plates: str = "friction"
    spacing_mm: float = 5.0
    margin_mm: float = 5.0
    route: str = "fe"
    specimen_mm: tuple[float, float, float] = SPECIMEN_MM
    levels_mm: tuple[float, ...] = ()

    def __post_init__(self):
        object.__setattr__(self, "specimen_mm", tuple(float(v) for v in self.specimen_mm))
        object.__setattr__(self, "levels_mm", tuple(float(v) for v in self.levels_mm))
        quarter_size(self.specimen_mm)  # validates the dimensions
        if self.levels_mm and (
            len(self.levels_mm) != self.snapshots or self.levels_mm[-1] != self.displacement_mm
        ):
            raise ValueError(
                f"levels_mm has {len(self.levels_mm)} values ending at {self.levels_mm[-1]!r} mm; "
                f"they must be the snapshots = {self.snapshots} levels ending at displacement_mm = "
                f"{self.displacement_mm!r} mm"
            )
        for name in ("resolution_um", "noise_um", "force_resolution_kN"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} = {v!r} is out of range: must be >= 0")
        if self.route not in ("fe", "dic"):
            raise ValueError(f"route = {self.route!r} is unknown; allowed: fe, dic")
        if (
            isinstance(self.seed, bool)
            or not isinstance(self.seed, (int, np.integer))
            or self.seed < 0
        ):
            raise ValueError(f"seed = {self.seed!r} is out of range: a whole number >= 0")
        if self.tier not in TIERS + (EXPERIMENT_TIER,):
            raise ValueError(
                f"tier = {self.tier!r} is unknown; allowed: {', '.join(TIERS + (EXPERIMENT_TIER,))}"
            )
        if self.tier == EXPERIMENT_TIER:
            if self.mesh:
                raise ValueError(f"mesh = {self.mesh!r}: experiment data have no mesh (empty)")
        else:
            from problems.fe.mesh import parse_mesh_spec

            parse_mesh_spec(self.mesh)  # validates the mesh spec
        _ = self.loading  # validates displacement, snapshots, plates
        from problems.inverse.plausibility import check_displacement

        check_displacement(self.displacement_mm, self.specimen_mm[2])
        if not len(self.points):  # validates spacing_mm and margin_mm
            raise ValueError(
                f"margin_mm = {self.margin_mm!r} leaves no front-face point; allowed: < half the "
                f"{quarter_size(self.specimen_mm)[1]:g} mm face width"
            )

    @property
    def loading(self) -> Loading:
        if self.levels_mm:
            return MachineLoading(self.levels_mm, self.plates)
        return Loading(self.displacement_mm, self.snapshots, self.plates)

    @property
    def points(self) -> np.ndarray:
        _, half_y, height = quarter_size(self.specimen_mm)
        return measurement_grid(self.spacing_mm, self.margin_mm, half_y, height)

    def to_dict(self) -> dict:
        """The fields as a JSON object, ``specimen_mm`` and ``levels_mm`` only when they are not
        the default (the form of the file and of its hash)."""
        d = asdict(self)
        for name in ("specimen_mm", "levels_mm"):
            if d[name] == _DEFAULTS[name]:
                del d[name]
            else:
                d[name] = list(d[name])
        return d


_DEFAULTS = {"specimen_mm": SPECIMEN_MM, "levels_mm": ()}


@dataclass(frozen=True, eq=False)
class Dataset:
    """Measured front-face displacements (mm) and plate force (kN) with their standard
    deviations.

    std_force_kN : (N,) standard deviation of each force, kN, when the data say it (an
                   experiment's load-cell accuracy); None: the objective's ``sigma_force_kN``
    snapshot_rho : correlation of one point's displacement errors between two snapshots (u_h
                   and u_v alike; points and the force independent): each point's covariance
                   across the snapshots is ``D [(1 - rho) I + rho 1 1^T] D``, D its sigmas. 0
                   (every data set but the images route's): the diagonal covariance
    """

    case: str
    settings: DataSettings
    parameters: dict
    points: np.ndarray  # (m, 2) y, z mm
    snapshots_mm: np.ndarray  # (N,)
    u_h: np.ndarray  # (N, m) mm
    u_v: np.ndarray  # (N, m) mm
    reaction_kN: np.ndarray  # (N,)
    std_u_mm: np.ndarray  # (2, N, m) standard deviation of u_h and u_v, mm
    meta: dict = field(default_factory=dict)
    std_force_kN: np.ndarray | None = None
    snapshot_rho: float = 0.0

    @property
    def values(self) -> np.ndarray:
        """Measurement vector ``[u_h, u_v, reaction]`` in the forward model's layout."""
        return np.concatenate([self.u_h.ravel(), self.u_v.ravel(), self.reaction_kN])

    def sigma(self, force_kN: float = 1.0) -> np.ndarray:
        """Standard deviations of the measurement vector (diagonal covariance), mm and kN: the
        force's from :attr:`std_force_kN` when the data have it, else ``force_kN``."""
        if self.std_force_kN is not None:
            return np.concatenate([self.std_u_mm.ravel(), self.std_force_kN])
        if not force_kN > 0:
            raise ValueError(f"sigma_force_kN = {force_kN!r} is out of range: must be > 0 kN")
        return np.concatenate([self.std_u_mm.ravel(), np.full(len(self.reaction_kN), force_kN)])

    def noise(self, force_kN: float = 1.0) -> dict:
        """The noise model as keywords of
        :class:`~problems.inverse.problem.LeastSquaresProblem`: ``sigma`` (:meth:`sigma`) and,
        when :attr:`snapshot_rho` is not 0, the points' groups across the snapshots and rho."""
        out = {"sigma": self.sigma(force_kN)}
        if self.snapshot_rho != 0.0 and len(self.snapshots_mm) > 1:
            from problems.inverse import layout

            out["groups"] = layout.point_groups(len(self.snapshots_mm), len(self.points))
            out["group_rho"] = float(self.snapshot_rho)
        return out

    def to_json(self) -> str:
        doc = self._doc()
        doc["hash"] = _digest(doc)
        return json.dumps(doc, indent=None, separators=(",", ":"), sort_keys=True) + "\n"

    @property
    def hash(self) -> str:
        return _digest(self._doc())

    def _doc(self) -> dict:
        doc = {
            "format": FORMAT,
            "case": self.case,
            "settings": self.settings.to_dict(),
            "parameters": self.parameters,
            "points": self.points.tolist(),
            "snapshots_mm": self.snapshots_mm.tolist(),
            "u_h": self.u_h.tolist(),
            "u_v": self.u_v.tolist(),
            "reaction_kN": self.reaction_kN.tolist(),
            "std_u_mm": self.std_u_mm.tolist(),
            "meta": self.meta,
        }
        if self.std_force_kN is not None:
            doc["std_force_kN"] = np.asarray(self.std_force_kN, float).tolist()
        if self.snapshot_rho != 0.0:  # absent when 0: every other data set keeps its hash
            doc["snapshot_rho"] = float(self.snapshot_rho)
        return doc


def _digest(doc: dict) -> str:
    body = {k: v for k, v in doc.items() if k != "hash"}
    return hashlib.sha256(
        json.dumps(body, sort_keys=True, separators=(",", ":")).encode()
    ).hexdigest()


def package_version() -> str:
    try:
        return version("femubench")
    except PackageNotFoundError:
        return "unknown"


def _round(values: np.ndarray, step: float) -> np.ndarray:
    return np.round(values / step) * step if step > 0 else values


def rounded(values, settings: DataSettings) -> np.ndarray:
    """A measurement vector ``values`` (:mod:`problems.inverse.layout`: ``settings.snapshots`` x
    the points of ``settings``) rounded as :func:`make_data` rounds the FE route's data:
    displacements (mm) to ``resolution_um`` um, forces (kN) to ``force_resolution_kN`` kN (a
    step 0: unchanged). ValueError when the length does not fit the settings' layout."""
    from problems.inverse import layout

    v = np.asarray(values, dtype=float)
    N, m = settings.snapshots, len(settings.points)
    if v.shape != (layout.size(N, m),):
        raise ValueError(
            f"a measurement vector of shape {v.shape} does not fit {N} snapshots x {m} points "
            f"({layout.size(N, m)} values)"
        )
    b = layout.blocks(N, m)
    out = v.copy()
    out[b["displacement"]] = _round(v[b["displacement"]], settings.resolution_um * 1e-3)
    out[b["force"]] = _round(v[b["force"]], settings.force_resolution_kN)
    return out


def displacement_std_mm(settings: DataSettings) -> float:
    """Standard deviation of one displacement value: uniform rounding error (step/sqrt 12) and
    noise.

    Unrounded, noise-free data are weighted as if rounded to 1 um (a weight is needed; the
    cost scale is then that of the default data).
    """
    res_mm = (settings.resolution_um or 1.0) * 1e-3
    return math.hypot(res_mm / math.sqrt(12.0), settings.noise_um * 1e-3)


def make_data(
    case: Case | str,
    settings: DataSettings | None = None,
    *,
    x=None,
    progress: bool = False,
    image_dir: str | Path | None = None,
    reuse: bool = True,
    **overrides,
) -> Dataset:
    """Compute a data set: the FE response at ``x`` (default: the case's reference) on
    ``settings.mesh``.

    Keyword overrides go into :class:`DataSettings`
    (``make_data(case, mesh="coarse", resolution_um=0)``).
    ``image_dir``: where the DIC route writes its images (default: nowhere; see
    :func:`dic_image_dir`).
    On the model-error tier's mesh (:func:`shares_reference_solve`) the FE route takes the run
    from :mod:`problems.inverse.response_cache` (computed and stored there if missing), which the
    convergence study shares: the same numbers as a plain run (the Jacobian's sensitivities
    leave the Newton iterates unchanged); ``reuse=False`` solves afresh (and stores the run).
    Raises RuntimeError when the data model itself does not converge.
    """
    from problems.inverse.forward import FEForwardModel

    case = get_case(case) if isinstance(case, str) else case
    settings = DataSettings(**{**asdict(settings or DataSettings()), **overrides})
    x = case.reference if x is None else np.asarray(x, float)
    model = FEForwardModel(
        case, settings.mesh, settings.loading, settings.points, specimen_mm=settings.specimen_mm
    )
    meta = {"package_version": package_version()}
    if settings.route == "fe" and shares_reference_solve(settings.mesh):
        from problems.inverse import layout, response_cache

        def say(line):
            print(line, flush=True)

        run = response_cache.solve(model, x, reuse=reuse, progress=say if progress else None)
        if not run["ok"]:
            raise RuntimeError(
                f"data model of {case.name} on mesh {settings.mesh} failed: {run['message']}"
            )
        u_h, u_v, reaction = layout.unstack(run["values"], settings.snapshots, len(settings.points))
        snapshots_mm = run["snapshots_mm"]
        meta |= {"mesh": run["mesh"], "symmetry": run["symmetry"]}
    else:
        resp = model.response(x, progress=progress)
        if not resp.converged:
            raise RuntimeError(
                f"data model of {case.name} on mesh {settings.mesh} failed: {resp.message}"
            )
        meta |= {"mesh": resp.mesh.info(), "symmetry": resp.symmetry}
        reaction, snapshots_mm = resp.reaction_kN, resp.snapshots_mm
        if settings.route == "fe":
            u_h, u_v = resp.front_face(settings.points)
    if settings.route == "dic":
        from problems.dic.route import measure_by_dic

        u_h, u_v, std, dic_meta = measure_by_dic(
            resp, settings.points, seed=settings.seed, progress=progress, image_dir=image_dir
        )
        meta |= dic_meta
    else:
        rng = np.random.default_rng(settings.seed)
        noise = settings.noise_um * 1e-3
        if noise > 0:
            u_h = u_h + rng.normal(0.0, noise, u_h.shape)
            u_v = u_v + rng.normal(0.0, noise, u_v.shape)
        res = settings.resolution_um * 1e-3
        u_h, u_v = _round(u_h, res), _round(u_v, res)
        std = np.full((2,) + u_h.shape, displacement_std_mm(settings))
    return Dataset(
        case.name,
        settings,
        case.identified(x),
        settings.points,
        snapshots_mm,
        u_h,
        u_v,
        _round(reaction, settings.force_resolution_kN),
        std,
        meta,
    )


def shares_reference_solve(mesh: str) -> bool:
    """True when ``mesh`` is the model-error tier's data mesh (any spelling of its
    discretisation): its FE-route runs go through :mod:`problems.inverse.response_cache`, shared
    with the convergence study."""
    from problems.fe.mesh import discretisation_key

    return discretisation_key(mesh) == discretisation_key(MODEL_ERROR_MESH)


def tier_settings(tier: str, inverse_mesh: str = DEFAULT_INVERSE_MESH, **overrides) -> DataSettings:
    """The default settings of a tier: ``consistent`` on ``inverse_mesh``, ``model-error`` on
    :data:`MODEL_ERROR_MESH`; ``overrides`` set other fields (rounding, noise, seed, ...)."""
    if tier not in TIERS:
        raise ValueError(f"tier = {tier!r} is unknown; allowed: {', '.join(TIERS)}")
    mesh = inverse_mesh if tier == "consistent" else MODEL_ERROR_MESH
    return DataSettings(**{"tier": tier, "mesh": mesh, **overrides})


def dic_image_dir(path: str | Path) -> Path:
    """Where the DIC images of the data file ``path`` go: ``<parent>/<stem>__dic_images/``."""
    path = Path(path)
    return path.parent / f"{path.stem}__dic_images"


def save(ds: Dataset, path: str | Path) -> Path:
    """Write ``ds`` atomically as JSON."""
    from problems.io.atomic import atomic_write_text

    return atomic_write_text(path, ds.to_json())


def load(path: str | Path) -> Dataset:
    """Read a data set, checking its format, fields, shapes and content hash.

    Raises ValueError (one line, naming the file and the offending field) for a file that is not
    a data set, and FileNotFoundError for a missing one.
    """
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise FileNotFoundError(f"data file {path} does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"data file {path} cannot be read: {exc}") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"data file {path} is not valid JSON: {exc}") from None
    if not isinstance(doc, dict):
        raise ValueError(f"data file {path}: expected a JSON object, got a {type(doc).__name__}")
    if doc.get("format") != FORMAT:
        raise ValueError(f"data file {path}: format {doc.get('format')!r} is not {FORMAT!r}")
    missing = [k for k in _FIELDS if k not in doc]
    if missing:
        raise ValueError(f"data file {path}: field(s) {', '.join(missing)} missing")
    if doc.get("hash") != _digest(doc):
        raise ValueError(
            f"data file {path}: content hash does not match (file modified or truncated)"
        )
    try:
        return _dataset_from_doc(doc)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"data file {path}: {exc}") from None


#: Fields every data file must have (``meta`` is optional).
_FIELDS = (
    "case",
    "settings",
    "parameters",
    "points",
    "snapshots_mm",
    "u_h",
    "u_v",
    "reaction_kN",
    "std_u_mm",
    "hash",
)


def _dataset_from_doc(doc: dict) -> Dataset:
    """The Dataset of a parsed data file; ValueError naming the field whose type or shape is
    wrong."""
    for name, kind in (("case", str), ("settings", dict), ("parameters", dict)):
        if not isinstance(doc[name], kind):
            raise ValueError(f"field {name} must be a JSON {'string' if kind is str else 'object'}")
    try:
        settings = DataSettings(**doc["settings"])
    except (TypeError, ValueError) as exc:
        raise ValueError(f"field settings: {exc}") from None
    arrays = {
        name: _array(doc, name)
        for name in ("points", "snapshots_mm", "u_h", "u_v", "reaction_kN", "std_u_mm")
    }
    n, m = settings.snapshots, len(arrays["points"])
    expected = {
        "points": (m, 2),
        "snapshots_mm": (n,),
        "u_h": (n, m),
        "u_v": (n, m),
        "reaction_kN": (n,),
        "std_u_mm": (2, n, m),
    }
    for name, shape in expected.items():
        if arrays[name].shape != shape:
            raise ValueError(
                f"field {name} has shape {arrays[name].shape}, expected {shape} "
                f"({n} snapshots, {m} points)"
            )
    for name in ("points", "snapshots_mm", "u_h", "u_v", "reaction_kN"):
        if not np.all(np.isfinite(arrays[name])):
            raise ValueError(f"field {name} holds non-finite numbers (NaN or infinite)")
    std = arrays["std_u_mm"]
    if np.any(np.isnan(std)) or np.any(std <= 0):
        raise ValueError(
            "field std_u_mm must hold standard deviations > 0 mm (infinite: a point not measured)"
        )
    if not np.isfinite(std).any():
        raise ValueError(
            f"field std_u_mm: all {std.size} standard deviations are infinite (no displacement "
            "measured); allowed: finite values > 0 mm where a point was measured"
        )
    from problems.inverse.plausibility import check_points

    check_points(arrays["points"], settings.specimen_mm, "field points")
    meta = doc.get("meta", {})
    if not isinstance(meta, dict):
        raise ValueError("field meta must be a JSON object")
    std_force = None
    if "std_force_kN" in doc:
        std_force = _array(doc, "std_force_kN")
        if std_force.shape != (n,) or not np.all(np.isfinite(std_force) & (std_force > 0)):
            raise ValueError(f"field std_force_kN must hold {n} standard deviations > 0 kN")
    rho = doc.get("snapshot_rho", 0.0)
    if isinstance(rho, bool) or not isinstance(rho, (int, float)) or not (
        n < 2 or -1.0 / (n - 1) < rho < 1.0
    ):
        raise ValueError(
            f"field snapshot_rho = {rho!r} is out of range: allowed -1/(N-1) < rho < 1 "
            f"(N = {n} snapshots)"
        )
    return Dataset(
        doc["case"],
        settings,
        doc["parameters"],
        arrays["points"],
        arrays["snapshots_mm"],
        arrays["u_h"],
        arrays["u_v"],
        arrays["reaction_kN"],
        arrays["std_u_mm"],
        meta,
        std_force,
        float(rho),
    )


def _array(doc: dict, name: str) -> np.ndarray:
    """``doc[name]`` as a float array (ValueError naming the field if it is not a numeric array)."""
    try:
        return np.array(doc[name], dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"field {name} is not a rectangular array of numbers") from None


def default_path(case: str, tier: str = "model-error") -> Path:
    """Where the default data set of ``case`` in ``tier`` lives (shipped, or in
    ``$FEMUBENCH_DATA_DIR``)."""
    return data_dir() / tier / f"{case}.json"


def is_default(settings: DataSettings) -> bool:
    """True when ``settings`` are those of a shipped data set (the tier's default)."""
    return settings == tier_settings(settings.tier)


def cached_path(case: str, settings: DataSettings) -> Path:
    """Cache file of a non-default data set, keyed by the settings (in :func:`cache_dir`)."""
    key = hashlib.sha256(json.dumps(settings.to_dict(), sort_keys=True).encode()).hexdigest()[:12]
    return cache_dir() / f"{case}__{key}.json"


def data_path(case: str, settings: DataSettings) -> Path:
    """The file of the data set of ``case`` for ``settings``: the tier's default one
    (:func:`default_path`) or the cache file (:func:`cached_path`)."""
    if is_default(settings):
        return default_path(case, settings.tier)
    return cached_path(case, settings)


def get_data(case: str, settings: DataSettings | None = None, *, progress: bool = False) -> Dataset:
    """The data set of ``case`` for ``settings`` (default: shipped), computed and cached if
    missing."""
    settings = settings or DataSettings()
    path = data_path(case, settings)
    if path.exists():
        try:
            ds = load(path)
        except ValueError as exc:
            if is_default(settings):  # a data set, not a cache: say which file to fix
                raise
            import warnings

            from problems.io.atomic import set_aside_torn

            moved = set_aside_torn(path)  # a torn cache: set aside, computed again
            warnings.warn(f"{exc}; moved to {moved} and computed again", stacklevel=2)
        else:
            if ds.settings != settings:  # a shipped set of other settings: served, but said
                import warnings

                asked, made = settings.to_dict(), ds.settings.to_dict()
                diff = ", ".join(
                    f"{k} {made.get(k)!r} (asked {asked.get(k)!r})"
                    for k in sorted(set(asked) | set(made))
                    if asked.get(k) != made.get(k)
                )
                warnings.warn(
                    f"{path} was made with {diff}; `femubench data {case} --force` remakes it",
                    stacklevel=2,
                )
            return ds
    if progress:
        print(
            f"computing data for {case} on mesh {settings.mesh} (cached in {path}) ...", flush=True
        )
    ds = make_data(case, settings, progress=progress, image_dir=dic_image_dir(path))
    save(ds, path)
    return ds

"""Local-sensitivity, identifiability, global-sensitivity and uncertainty studies (orchestration
and I/O).

The mathematics lives in :mod:`problems.analysis.local_sensitivity`,
:mod:`problems.analysis.identifiability` and
:mod:`problems.analysis.global_sensitivity`. Each study is two steps, as the suites and their
reports:

* ``run_<study>(...)`` builds the objective, runs the forward evaluations through
  :func:`bench.parallel.mapper` (the suites' evaluator), writes the raw results (CSV, JSON,
  markdown tables, the MCMC chain) into one output folder and returns a dataclass;
* ``render_<study>(folder)`` reads only that folder and draws the figures
  (:mod:`bench.studies.figures`), so figures can be re-drawn without re-running anything.

Output folder: ``--out DIR``, else ``<results root>/studies/<study>/<case>/`` with the results
root of :mod:`bench.paths` (the checkout's ``results/`` or ``$FEMUBENCH_RESULTS_DIR``).
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Iterable

import numpy as np

from problems.io import jsonio

DATA_CHOICES = "auto | shipped | synthetic | PATH"
DATA_HELP = (
    "data the objective is compared with: shipped (the case's pseudo-experimental data from the "
    "fine mesh, computed and cached if missing), synthetic (this mesh's own response at the "
    "reference, unrounded: no model error, cost 0 at the reference), a data-file PATH, or auto "
    "(shipped if already on disk, else synthetic). Default: auto"
)


def default_output_dir(command: str, case: str) -> Path:
    """``<results root>/studies/<command>/<case>`` (not created; see :mod:`bench.paths`)."""
    from bench.paths import results_root

    return results_root() / "studies" / command / case


def output_dir(command: str, case: str, out: str | Path | None = None) -> Path:
    """``out`` or :func:`default_output_dir`, created."""
    path = Path(out) if out else default_output_dir(command, case)
    path.mkdir(parents=True, exist_ok=True)
    return path


def existing_dir(command: str, case: str, out: str | Path | None = None) -> Path:
    """The output folder a previous run wrote (``out`` or the default); FileNotFoundError if
    absent."""
    path = Path(out) if out else default_output_dir(command, case)
    if not path.is_dir():
        raise FileNotFoundError(
            f"no results of `femubench {command}` in {path}: run the study first"
        )
    return path


def case_names(items: Iterable[str]) -> list[str]:
    """Expand ``all`` to the nine FE cases; validate the others."""
    from problems.inverse.cases import CASES, get_case

    names: list[str] = []
    for item in items:
        if item == "all":
            names += [n for n in CASES if n not in names]
        else:
            get_case(item)  # ValueError listing the allowed names
            if item not in names:
                names.append(item)
    if not names:
        raise ValueError("no case given")
    return names


def study_objective(
    case_name: str,
    *,
    mesh: str = "coarse",
    data: str = "auto",
    mapper=None,
    tier: str | None = None,
    correction: str = "none",
    plate_margin_mm: float = 0.0,
):
    """``(objective, description of the data)`` for the studies (see :data:`DATA_HELP`).

    tier            : ``consistent`` or ``model-error``: the tier's shipped data set for the
                      inverse ``mesh`` (in place of ``data``, which must then be ``auto``)
    correction      : model-error treatment of the objective: ``none``, ``one-point`` (at the
                      default start), ``bae`` or ``default`` (the case's default treatment, with its
                      plate margin); see :func:`bench.experiment.objective.assemble`
    plate_margin_mm : the measurement region's plate margin (problems.inverse.build.Region)
    """
    from bench.experiment.objective import assemble
    from bench.experiment.spec import DataSpec, RunSpec, Treatment
    from problems.inverse.cases import get_case

    case = get_case(case_name)
    if case.is_analytic:
        text = "analytic synthetic data (noise-free, at the reference)"
        return assemble(RunSpec(case.name, "none"), mapper=mapper), text
    from problems.inverse.data import default_path, get_data, make_data

    if correction == "default" and plate_margin_mm:
        raise ValueError(
            "the default treatment sets the plate margin itself (see `femubench cases`); to change "
            "it name the treatment, e.g. --correction bae"
        )
    if tier is not None:
        if data != "auto":
            raise ValueError(
                f"--tier {tier} and --data {data}: give one of them (--tier picks the tier's "
                "shipped data set)"
            )
        ds = None  # the tier's data set for the inverse mesh
        text = f"{tier}-tier data"
    else:
        if data == "auto":
            data = "shipped" if default_path(case.name).exists() else "synthetic"
        if data == "shipped":
            ds = get_data(case.name, progress=True)
            text = f"shipped data {default_path(case.name)}"
        elif data == "synthetic":
            ds = make_data(
                case, mesh=mesh, resolution_um=0.0, force_resolution_kN=0.0, tier="consistent"
            )
            text = (
                f"synthetic data: the {mesh} mesh's own response at the reference, unrounded "
                f"(weights as for 1 um rounding; no model error)"
            )
        else:
            path = Path(data)
            if not path.exists():
                raise ValueError(f"--data {data!r}: no such file; allowed: {DATA_CHOICES}")
            ds = data
            text = f"data file {path}"
    spec = RunSpec(
        case.name,
        "none",
        mesh=mesh,
        data=DataSpec(tier or "model-error"),
        treatment=Treatment(correction, plate_margin_mm),
    )
    obj = assemble(spec, mapper=mapper, dataset=ds)
    prov = obj.provenance
    text += (
        f" ({prov['data_tier']} tier, data mesh {prov['data_mesh']}, hash "
        f"{str(prov['data_hash'])[:12]}); treatment {prov['treatment']}"
        + (f" (high-fidelity mesh {prov['hifi_mesh']})" if prov.get("hifi_mesh") else "")
        + (" = the case's default" if correction == "default" else "")
        + (
            f"; points within {prov['region_plate_margin_mm']:g} mm of the plates left out"
            if prov.get("region_plate_margin_mm")
            else ""
        )
    )
    return obj, text


def outside_bounds(what: str, case_name: str, obj, z) -> str | None:
    """``"<what> outside the case's bounds: E = 1e+06 is outside [15000, 45000] MPa; ..."`` for the
    scaled point ``z`` of ``obj``, or None when it lies in the box."""
    from problems.inverse.cases import get_case

    z = np.asarray(z, float)
    bad = [i for i in range(obj.n_params) if not obj.lower_z[i] <= z[i] <= obj.upper_z[i]]
    if not bad:
        return None
    units = {p.name: p.unit for p in get_case(case_name).parameters if p.unit not in ("", "-")}
    x = obj.to_physical(z)
    return f"{what} outside the case's bounds: " + "; ".join(
        f"{obj.names[i]} = {x[i]:g} is outside [{obj.lower[i]:g}, {obj.upper[i]:g}] "
        f"{units.get(obj.names[i], '')}".rstrip()
        for i in bad
    )


def parse_assignments(items: list[str] | None, names: tuple[str, ...]) -> dict[str, float]:
    """``["E=3e4", "psi=14"]`` -> dict; unknown names or malformed items raise ValueError."""
    out: dict[str, float] = {}
    for item in items or []:
        name, sep, value = item.partition("=")
        name = name.strip()
        try:
            if not sep or not name:
                raise ValueError
            out[name] = float(value)
        except ValueError:
            raise ValueError(f"{item!r} is malformed: expected NAME=VALUE with a number") from None
        if name not in names:
            raise ValueError(f"parameter {name!r} is unknown; allowed: {', '.join(names)}")
    return out


def write_csv(path: Path, rows: list[dict]) -> Path:
    path = Path(path)
    with path.open("w", newline="") as fh:
        if rows:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    return path


def write_json(path: Path, doc: dict) -> Path:
    path = Path(path)
    path.write_text(jsonio.dumps(doc, indent=1) + "\n")
    return path


def read_json(path: Path) -> dict:
    """A JSON file written by :func:`write_json` (non-finite floats were written as strings);
    ValueError naming the file when it is not JSON."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path} does not exist: run the study first")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path} is not valid JSON ({exc}): run the study again") from None


def render_from(render, folder, *args) -> list:
    """``render(folder, *args)`` with a malformed output folder (a missing field, a corrupt chain)
    reported as one ValueError naming the folder instead of the reader's own exception."""
    import zipfile

    try:
        return render(folder, *args)
    except (KeyError, IndexError, TypeError, AttributeError, EOFError, zipfile.BadZipFile) as exc:
        raise ValueError(
            f"{folder}: the files of an earlier run are incomplete or malformed "
            f"({type(exc).__name__}: {exc}); run the study again"
        ) from None
    except ValueError as exc:
        if str(folder) in str(exc):
            raise
        raise ValueError(f"{folder}: {exc}") from None


def as_float(value) -> float:
    """A number read back from :func:`write_json` (``"nan"``, ``"inf"`` strings included);
    None -> nan."""
    return math.nan if value is None else float(value)


def markdown_table(rows: list[dict], formats: dict[str, str] | None = None) -> str:
    """A GitHub markdown table of ``rows`` (floats formatted by ``formats[column]`` or ``.4g``)."""
    if not rows:
        return ""
    formats = formats or {}
    cols = list(rows[0])

    def cell(c, v):
        if isinstance(v, float):
            return format(v, formats.get(c, ".4g")) if math.isfinite(v) else str(v)
        return str(v)

    lines = ["| " + " | ".join(cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    lines += ["| " + " | ".join(cell(c, r[c]) for c in cols) + " |" for r in rows]
    return "\n".join(lines) + "\n"

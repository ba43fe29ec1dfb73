"""Sensitivity, identifiability, global-sensitivity and uncertainty studies (orchestration and I/O).

The mathematics lives in :mod:`problems.analysis.sensitivity`, :mod:`problems.analysis.identifiability` and
:mod:`problems.analysis.global_sensitivity`; this package builds the objectives, runs the forward
evaluations through :func:`bench.parallel.mapper` (the suites' evaluator), and writes CSV,
markdown, JSON and figures (:mod:`bench.studies.figures`). Default output directory:
``results/studies/<command>/<case>/``.
"""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Iterable

import numpy as np

RESULTS = Path("results") / "studies"

DATA_CHOICES = "auto | shipped | synthetic | PATH"
DATA_HELP = ("data the objective is compared with: shipped (the case's pseudo-experimental data from the "
             "fine mesh, computed and cached if missing), synthetic (this mesh's own response at the "
             "reference, unrounded: no model error, cost 0 at the reference), a data-file PATH, or auto "
             "(shipped if already on disk, else synthetic). Default: auto")


def output_dir(command: str, case: str, out: str | Path | None = None) -> Path:
    """``out`` or ``results/studies/<command>/<case>``, created."""
    path = Path(out) if out else RESULTS / command / case
    path.mkdir(parents=True, exist_ok=True)
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


def study_objective(case_name: str, *, mesh: str = "coarse", data: str = "auto", mapper=None):
    """``(objective, description of the data)`` for the studies (see :data:`DATA_HELP`)."""
    from problems.inverse.cases import get_case
    from problems.inverse.build import build_objective

    case = get_case(case_name)
    if case.name.startswith("analytic-"):
        return build_objective(case, mapper=mapper), "analytic synthetic data (noise-free, at the reference)"
    from problems.inverse.data import default_path, get_data, make_data

    if data == "auto":
        data = "shipped" if default_path(case.name).exists() else "synthetic"
    if data == "shipped":
        ds = get_data(case.name, progress=True)
        text = f"shipped data {default_path(case.name)} (mesh {ds.settings.mesh})"
    elif data == "synthetic":
        ds = make_data(case, mesh=mesh, resolution_um=0.0, force_resolution_kN=0.0)
        text = (f"synthetic data: the {mesh} mesh's own response at the reference, unrounded "
                f"(weights as for 1 um rounding; no model error)")
    else:
        path = Path(data)
        if not path.exists():
            raise ValueError(f"--data {data!r}: no such file; allowed: {DATA_CHOICES}")
        ds = data
        text = f"data file {path}"
    return build_objective(case, mesh=mesh, data=ds, mapper=mapper), text


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


def _plain(obj):
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _plain(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if math.isfinite(v) else str(v)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def write_json(path: Path, doc: dict) -> Path:
    path = Path(path)
    path.write_text(json.dumps(_plain(doc), indent=1) + "\n")
    return path


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

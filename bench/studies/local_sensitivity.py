"""Local sensitivity study (eqs. 16-18, Fig. 5) of one FE case.

:func:`run_sensitivity` computes and writes ``sensitivity.csv``, ``sensitivity_snapshots.csv``,
``sensitivity.md`` and ``sensitivity.json``; :func:`render_sensitivity` draws ``sensitivity.png``
(Fig. 5) and ``sensitivity_snapshots.png`` from ``sensitivity.json`` alone.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bench.studies import as_float, markdown_table, output_dir, read_json, write_csv, write_json


@dataclass
class SensitivityRun:
    """What :func:`run_sensitivity` computed and wrote."""

    case: str
    mesh: str
    delta: float  # relative perturbation (-)
    result: object  # problems.analysis.local_sensitivity.LocalSensitivities
    snapshots_mm: np.ndarray  # top-plate displacement of each snapshot (mm)
    wall_s: float  # wall time of the FE runs (s)
    dir: Path
    paths: list[Path] = field(default_factory=list)


def fe_sensitivities(
    case_name: str, *, mesh: str = "coarse", delta: float = 0.01, mapper=None, loading=None
):
    """:class:`~problems.analysis.local_sensitivity.LocalSensitivities` of the FE case at its
    reference (1 + n runs)."""
    from problems.analysis.local_sensitivity import ModelFields, local_sensitivities
    from problems.fe.newton import Loading
    from problems.inverse.cases import get_case
    from problems.inverse.forward import FEForwardModel

    case = get_case(case_name)
    if case.is_analytic:
        raise ValueError(
            f"case {case.name}: local sensitivities need the FE measurement layout [u_h, u_v, r]; "
            "analytic cases do not have it"
        )
    model = FEForwardModel(case, mesh, loading or Loading())
    N, m = model.loading.snapshots, len(model.points)
    fields = ModelFields(model, N, m)
    return local_sensitivities(
        fields, case.reference, delta=delta, names=case.names, mapper=mapper
    ), model


def run_sensitivity(
    case_name: str, *, mesh: str = "coarse", delta: float = 0.01, mapper=None, out=None
) -> SensitivityRun:
    """Compute the sensitivities (1 + n FE runs) and write the CSV, markdown and JSON files."""
    t0 = time.perf_counter()
    sens, model = fe_sensitivities(case_name, mesh=mesh, delta=delta, mapper=mapper)
    wall = time.perf_counter() - t0
    d = output_dir("sensitivity", case_name, out)
    paths = [
        write_csv(d / "sensitivity.csv", sens.rows()),
        write_csv(d / "sensitivity_snapshots.csv", sens.snapshot_rows()),
    ]
    ranking = sens.ranking()
    md = [
        f"# Local sensitivities of {case_name} (mesh {mesh}, delta = {delta:g})",
        "",
        "Eqs. 16-18: s = sum over the snapshots of (1 - ||u_n(x_i (1 + delta))|| / "
        "||u_n(x_ref)||) / delta (r_n for the force); dimensionless, negative when the field "
        "grows with the parameter.",
        "",
        markdown_table(sens.rows(), {"reference": ".6g", "delta": "g"}),
        f"Least to most sensitive (sum of |s|): {', '.join(ranking)}.",
        "",
        f"Cost: {sens.n_evals} FE evaluations, {wall:.1f} s wall.",
    ]
    md += [f"- {m}" for m in sens.messages]
    (d / "sensitivity.md").write_text("\n".join(md) + "\n")
    paths.append(d / "sensitivity.md")
    snapshots_mm = np.asarray(model.loading.snapshots_mm, float)
    paths.append(
        write_json(
            d / "sensitivity.json",
            {
                "case": case_name,
                "mesh": mesh,
                "delta": delta,
                "names": sens.names,
                "reference": sens.x_ref,
                "deltas": sens.deltas,
                "summed": sens.summed,
                "per_snapshot": sens.per_snapshot,
                "sum_abs": sens.total_abs,
                "ranking": ranking,
                "n_snapshots": sens.n_snapshots,
                "snapshots_mm": snapshots_mm,
                "n_evals": sens.n_evals,
                "wall_s": wall,
                "messages": sens.messages,
            },
        )
    )
    return SensitivityRun(case_name, mesh, delta, sens, snapshots_mm, wall, Path(d), paths)


def render_sensitivity(folder) -> list[Path]:
    """Draw ``sensitivity.png`` and ``sensitivity_snapshots.png`` from
    ``folder/sensitivity.json``."""
    from bench.studies.figures import sensitivity_bars, sensitivity_snapshots

    d = Path(folder)
    doc = read_json(d / "sensitivity.json")
    names = doc["names"]
    summed = {m: [as_float(v) for v in vals] for m, vals in doc["summed"].items()}
    per_snapshot = {
        m: [[as_float(v) for v in r] for r in rows] for m, rows in doc["per_snapshot"].items()
    }
    n_snapshots = doc.get("n_snapshots") or len(per_snapshot["ux"][0])
    title = f"{doc['case']}, mesh {doc['mesh']}, $\\delta$ = {doc['delta']:g}"
    return [
        sensitivity_bars(names, summed, n_snapshots, d / "sensitivity.png", title),
        sensitivity_snapshots(
            names, per_snapshot, d / "sensitivity_snapshots.png", doc.get("snapshots_mm"), title
        ),
    ]

"""Local sensitivity study (eqs. 16-18, Fig. 5) of one FE case: CSV, markdown and figures."""
from __future__ import annotations

import time
from pathlib import Path

from bench.studies import markdown_table, output_dir, write_csv, write_json


def fe_sensitivities(case_name: str, *, mesh: str = "coarse", delta: float = 0.01, mapper=None, loading=None):
    """:class:`~problems.analysis.sensitivity.LocalSensitivities` of the FE case at its reference (1 + n runs)."""
    from problems.inverse.cases import get_case
    from problems.fe.newton import Loading
    from problems.inverse.forward import FEForwardModel, measurement_blocks
    from problems.analysis.sensitivity import ModelFields, local_sensitivities

    case = get_case(case_name)
    if case.name.startswith("analytic-"):
        raise ValueError(f"case {case.name}: local sensitivities need the FE measurement layout [u_h, u_v, r]; "
                         "analytic cases do not have it")
    model = FEForwardModel(case, mesh, loading or Loading())
    N, m = model.loading.snapshots, len(model.points)
    fields = ModelFields(model, N, m, measurement_blocks(N, m))
    return local_sensitivities(fields, case.reference, delta=delta, names=case.names, mapper=mapper), model


def run_sensitivity(case_name: str, *, mesh: str = "coarse", delta: float = 0.01, mapper=None, out=None,
                    figures: bool = True) -> dict:
    """Compute and write ``sensitivity.csv``, ``sensitivity_snapshots.csv``, ``sensitivity.md``,
    ``sensitivity.json``, ``sensitivity.png`` (Fig. 5) and ``sensitivity_snapshots.png``."""
    t0 = time.perf_counter()
    sens, model = fe_sensitivities(case_name, mesh=mesh, delta=delta, mapper=mapper)
    wall = time.perf_counter() - t0
    d = output_dir("sensitivity", case_name, out)
    paths = [write_csv(d / "sensitivity.csv", sens.rows()), write_csv(d / "sensitivity_snapshots.csv", sens.snapshot_rows())]
    ranking = sens.ranking()
    md = [f"# Local sensitivities of {case_name} (mesh {mesh}, delta = {delta:g})", "",
          "Eqs. 16-18: s = sum over the snapshots of (1 - ||u_n(x_i (1 + delta))|| / ||u_n(x_ref)||) / delta "
          "(r_n for the force); dimensionless, negative when the field grows with the parameter.", "",
          markdown_table(sens.rows(), {"reference": ".6g", "delta": "g"}),
          f"Least to most sensitive (sum of |s|): {', '.join(ranking)}.", "",
          f"Cost: {sens.n_evals} FE evaluations, {wall:.1f} s wall."]
    md += [f"- {m}" for m in sens.messages]
    (d / "sensitivity.md").write_text("\n".join(md) + "\n")
    paths.append(d / "sensitivity.md")
    paths.append(write_json(d / "sensitivity.json", {
        "case": case_name, "mesh": mesh, "delta": delta, "names": sens.names, "reference": sens.x_ref,
        "deltas": sens.deltas, "summed": sens.summed, "per_snapshot": sens.per_snapshot, "sum_abs": sens.total_abs,
        "ranking": ranking, "n_evals": sens.n_evals, "wall_s": wall, "messages": sens.messages}))
    if figures:
        from bench.studies.figures import sensitivity_bars, sensitivity_snapshots

        title = f"{case_name}, mesh {mesh}, $\\delta$ = {delta:g}"
        paths.append(sensitivity_bars(sens, d / "sensitivity.png", title))
        paths.append(sensitivity_snapshots(sens, d / "sensitivity_snapshots.png",
                                           model.loading.snapshots_mm, title))
    return {"result": sens, "paths": paths, "wall_s": wall, "dir": Path(d)}

"""A final parameter on a bound of its box is flagged: in Table 1 (marker and footnote) and in the
history figure (the box as a bracket, a ring around the final value)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from bench.report import tables as T
from problems.inverse.cases import get_case

CASE = "linear-compression"


def _runs(values_E: list[float]) -> pd.DataFrame:
    """Runs of lm on CASE whose final E are ``values_E`` (physical) and psi at its reference."""
    case = get_case(CASE)
    ref = dict(zip(case.names, case.reference))
    rows = []
    for seed, e in enumerate(values_E):
        rows.append(
            {
                "case": CASE,
                "method": "lm",
                "budget": 100,
                "seed": seed,
                "start": "default",
                "start_index": 0,
                "crashed": False,
                "cost": 1.0,
                "n_evals": 10,
                "x.E": e,
                "err.E": 100.0 * (e / ref["E"] - 1),
                "x.psi": ref["psi"],
                "err.psi": 0.0,
            }
        )
    runs = pd.DataFrame(rows)
    runs.attrs["parameters"] = ["E", "psi"]
    return runs


def test_bound_side_uses_a_tolerance_relative_to_the_box_width():
    assert T.bound_side(15000.0, 15000.0, 45000.0) == -1
    assert T.bound_side(15000.0 + 0.5e-6 * 30000, 15000.0, 45000.0) == -1
    assert T.bound_side(15000.0 + 2e-6 * 30000, 15000.0, 45000.0) == 0
    assert T.bound_side(45000.0, 15000.0, 45000.0) == 1
    assert T.bound_side(math.nan, 15000.0, 45000.0) == 0 and T.bound_side(1.0, 1.0, 1.0) == 0


def test_table1_flags_a_parameter_on_a_bound():
    lower, upper, _ = T.case_box(CASE)["E"]
    t = T.table1(_runs([lower]), "lm")
    assert t.attrs["on_bound"] == {("E", CASE): (1, 1)}
    disp = T.table1_display(t)
    assert disp.loc["E", CASE].endswith(T.BOUND_MARK) and T.BOUND_MARK not in disp.loc["psi", CASE]
    assert "ended on a bound" in T.bound_note(t)
    tex = T.to_latex(disp, caption="c", label="l")
    assert r"\textsuperscript{\dag}" in tex
    # one of two runs on the upper bound: counted
    t2 = T.table1(_runs([upper, 0.5 * (lower + upper)]), "lm")
    assert t2.attrs["on_bound"] == {("E", CASE): (1, 2)}
    assert T.table1_display(t2).loc["E", CASE].endswith("†1/2")
    # inside the box: nothing flagged, no footnote
    t3 = T.table1(_runs([lower + 1e-3 * (upper - lower)]), "lm")
    assert not t3.attrs["on_bound"] and T.bound_note(t3) == ""
    assert T.BOUND_MARK not in T.table1_display(t3).to_string()


def test_history_figure_draws_the_box_and_rings_a_final_value_on_a_bound(monkeypatch, tmp_path):
    import bench.report.figures as F

    figs = []
    monkeypatch.setattr(F, "save", lambda fig, path, pdf=False: figs.append(fig) or path)
    box = T.normalised_box(CASE)
    it = np.arange(1, 21)
    cost = np.geomspace(1e4, 1.0, 20)
    hist = pd.DataFrame(
        {
            "iteration": it,
            "cost": cost,
            "best_cost": cost,
            "xn.E": np.linspace(1.1, box["E"][0], 20),
            "xn.psi": np.linspace(0.9, 1.0, 20),
        }
    )
    run = pd.Series(
        {
            "case": CASE,
            "method": "lm",
            "budget": 100,
            "seed": 0,
            "start": "default",
            "start_index": 0,
            "n_evals": 20,
            "status": "converged",
        }
    )
    F.history_figure(run, hist, ["E", "psi"], tmp_path / "h")
    ax = figs[0].axes[0]
    rings = [ln for ln in ax.get_lines() if ln.get_label() == "on a bound"]
    assert len(rings) == 1
    assert rings[0].get_xydata().tolist() == [[20.0, pytest.approx(box["E"][0])]]
    ys = {round(float(y), 9) for ln in ax.get_lines() for y in np.atleast_1d(ln.get_ydata())}
    for p in ("E", "psi"):  # both boxes are drawn
        assert round(box[p][0], 9) in ys and round(box[p][1], 9) in ys
    assert max(ax.get_xticks()) <= 20  # no iteration ticks under the brackets
    assert "box [lower, upper]" in [t.get_text() for t in ax.get_legend().get_texts()]

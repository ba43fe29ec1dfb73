"""The generated Findings section quotes numbers computed from the frames."""

from __future__ import annotations

import pandas as pd
import pytest

from bench.report import metrics as M
from bench.report import tables as T
from bench.report.findings import findings
from tests.test_report_metrics import EXP, LIN, frame, run_row


def _frames():
    rows = []
    # LM from the default start: succeeds on LIN (30 fe), fails on EXP (a off by 25 %)
    rows.append(run_row(LIN, {"E": 0.5}, forward_equivalents=30.0))
    rows.append(run_row(EXP, {"pt0": 25.0}, forward_equivalents=40.0))
    # CMA from the default start: succeeds on both, 600 fe each (3 seeds on LIN, one fails)
    for seed, e in enumerate([0.1, 0.2, 9.0]):
        rows.append(
            run_row(
                LIN,
                {"E": e},
                method="cma (consistent)",
                solver="cma",
                seed=seed,
                forward_equivalents=600.0,
                n_evals=600,
            )
        )
    rows.append(
        run_row(
            EXP,
            {"pt0": 1.0},
            method="cma (consistent)",
            solver="cma",
            forward_equivalents=600.0,
            n_evals=600,
        )
    )
    # LM from two random starts on LIN: one success, one failure
    rows.append(run_row(LIN, {"E": 0.3}, start="random", start_index=0, forward_equivalents=20.0))
    rows.append(run_row(LIN, {"E": 50.0}, start="random", start_index=1, forward_equivalents=25.0))
    runs, _ = M.prepare(frame(rows))
    return runs


def test_findings_quote_winners_and_costs():
    runs = _frames()
    ok = T.success(runs)
    e = M.ert_table(runs, n_boot=200)
    text = "\n".join(findings(runs, e, ok, rule=T.success_rule()))
    # LIN: lm wins (default and random pooled: 2 successes of 3, (30 + 20 + 25) / 2 = 37.5 fe)
    assert "| linear-compression | lm (consistent) | 2/3 (67 %) | 38 [" in text
    # EXP: only cma succeeds (600 fe); lm fails because a is 25 % off
    assert "| exponent-shear | cma (consistent) | 1/1 (100 %) | 600 [600, 600] |" in text
    assert "the winners: lm (consistent) on 1, cma (consistent) on 1" in text
    # global vs lm from the default start: lm 1/2, cma 3/4 at 600 / 35 = 17 x the median cost
    assert "consistent data, default start(s)** (pooled over 2 case(s)): lm (FE) 1/2 (50 %)" in text
    assert "cma (FE) 3/4 (75 %)" in text
    assert "cma (FE), succeeds more often than lm (75 % against 50 %) at 17 × its median" in text
    assert "random start(s)** (pooled over 1 case(s)): lm (FE) 1/2 (50 %)" in text
    # worst-identified: a on the exponent cases; lm's a is 25 % off, cma's 1 %
    assert "|error of a| has median 13 % (range 1–25 %; the paper's Table 1: 11–46 %)" in text
    assert "no posterior" in text


def test_findings_without_global_methods_or_lm():
    runs, _ = M.prepare(frame([run_row(LIN, {"E": 0.5})]))
    e = M.ert_table(runs, n_boot=50)
    text = "\n".join(findings(runs, e, T.success(runs)))
    assert "No global method ran in these records" in text
    runs2, _ = M.prepare(frame([run_row(LIN, {"E": 0.5}, method="cma (consistent)", solver="cma")]))
    text2 = "\n".join(findings(runs2, M.ert_table(runs2, n_boot=50), T.success(runs2)))
    assert "No Levenberg–Marquardt run" in text2


def test_findings_fd_versus_exact_and_posterior():
    rows = [
        run_row(LIN, {"E": 0.1}, jacobian="exact", n_iterations=5, forward_equivalents=10.0),
        run_row(LIN, {"E": 0.1}, jacobian="forward", n_iterations=6, forward_equivalents=25.0),
    ]
    runs, _ = M.prepare(frame(rows))
    jac = M.jacobian_table(runs)
    post = pd.DataFrame(
        {
            "case": [EXP, EXP],
            "tier": ["consistent"] * 2,
            "source": ["s"] * 2,
            "parameter": ["a", "pt0"],
            "width95_pct": [30.0, 8.0],
            "laplace_width_pct": [28.0, float("nan")],
            "q025_n": [0.85, 0.96],
            "q975_n": [1.15, 1.04],
        }
    )
    text = "\n".join(
        findings(runs, M.ert_table(runs, n_boot=50), T.success(runs), post=post, jac=jac)
    )
    assert "forward differences against exact Jacobians (1 pairs of runs): " in text
    assert "forward-equivalents × 2.5 (median" in text and "iterations +1 (median)" in text
    assert "a 95 % width 30–30 % of the reference, Laplace ±2 sd 28–28 %" in text
    assert "contains the reference in 1 of 1" in text


def test_global_on_the_surrogate_track_is_compared_with_lm_on_fe():
    rows = [
        run_row(LIN, {"E": 0.5}, forward_equivalents=30.0),
        run_row(LIN, {"E": 0.5}, jacobian="forward", forward_equivalents=90.0),  # not counted
        run_row(
            LIN,
            {"E": 0.2},
            method="ga (consistent, surrogate + FE polish)",
            solver="ga",
            track="surrogate",
            forward_equivalents=15.0,
            charged_equivalents=300.0,
        ),
    ]
    runs, _ = M.prepare(frame(rows))
    text = "\n".join(findings(runs, M.ert_table(runs, n_boot=50), T.success(runs)))
    assert "lm (FE) 1/1 (100 %), median max |error| 0.5 %, median 30 fe" in text
    assert "ga (surrogate) 1/1 (100 %), median max |error| 0.2 %, median 315 fe" in text
    assert "the best, ga (surrogate), costs 10 × as much (median fe)" in text


def test_posterior_coverage_per_tier():
    runs, _ = M.prepare(frame([run_row(LIN, {"E": 0.5})]))
    post = pd.DataFrame(
        {
            "case": [LIN] * 3,
            "tier": ["consistent", "model-error", "model-error"],
            "source": ["s"] * 3,
            "parameter": ["E", "E", "H"],
            "width95_pct": [1.0, 1.0, 1.0],
            "laplace_width_pct": [float("nan")] * 3,
            "mean_n": [1.0, 0.97, 1.01],
            "q025_n": [0.99, 0.96, 1.005],
            "q975_n": [1.01, 0.98, 1.015],
        }
    )
    text = "\n".join(findings(runs, M.ert_table(runs, n_boot=20), T.success(runs), post=post))
    assert "none of these cases identifies a or pt0" in text
    assert "coverage, consistent data**: 1 of 1 95 % intervals" in text
    assert "coverage, model-error data**: 0 of 2 95 % intervals" in text
    assert "farthest: E of linear-compression, posterior mean 0.97 × reference" in text


def test_shared_charges_paid_by_both_are_also_compared_without_them():
    """On BAE-treated data LM and a global method pay the same statistics: the verdict gives the
    ratio of totals and of their own costs."""
    rows = [
        run_row(
            LIN,
            {"E": 3.0},
            tier="model-error",
            forward_equivalents=10.0,
            charged_equivalents=1000.0,
        ),
        run_row(
            LIN,
            {"E": 3.0},
            method="pso+lm (model-error)",
            solver="pso+lm",
            tier="model-error",
            forward_equivalents=100.0,
            charged_equivalents=1000.0,
        ),
    ]
    runs, _ = M.prepare(frame(rows))
    recs = [
        {
            "config_hash": h,
            "result": {
                "charges": {"hifi": {"forward_equivalents": 1000.0}},
                "provenance": {"treatment": "bae"},
            },
        }
        for h in runs["config_hash"]
    ]
    runs = M.add_shared_charges(runs, recs)
    text = "\n".join(findings(runs, M.ert_table(runs, n_boot=20), T.success(runs)))
    # totals 1100 / 1010 = 1.1; own 100 / 10 = 10
    assert "costs 1.1 × as much (median fe; 10 × without the shared charges)" in text


def test_the_surrogate_alone_is_judged_before_its_polish():
    rows = [
        run_row(
            LIN,
            {"E": 0.1},
            method="cma (consistent, surrogate + FE polish)",
            solver="cma",
            track="surrogate",
            seed=s,
            forward_equivalents=15.0,
        )
        for s in range(3)
    ]
    runs, _ = M.prepare(frame(rows))
    before = ([1.03, 1.0], [1.001, 0.99], [1.0, 0.5])  # largest errors 3 %, 1 %, 50 %
    recs = [
        {
            "config_hash": h,
            "result": {
                "reference": [100.0, 2.0],
                "extra": {"surrogate": {"x": [100.0 * a, 2.0 * b]}, "polish": {"n_evals": n}},
            },
        }
        for h, (a, b), n in zip(runs["config_hash"], before, (5, 7, 30))
    ]
    runs = M.add_surrogate_optimum(runs, recs)
    assert runs["sur_max_err"].tolist() == pytest.approx([3.0, 1.0, 50.0])
    text = "\n".join(findings(runs, M.ert_table(runs, n_boot=20), T.success(runs), tol=2.0))
    assert "within 2 % in 1/3 (33 %) of them" in text
    assert "| linear-compression | 3 | 3 | 1/3 (33 %) | 0.1 | 7 |" in text
    fe = M.add_surrogate_optimum(M.prepare(frame([run_row(LIN, {"E": 0.1})]))[0], [])
    assert fe["sur_max_err"].isna().all()
    assert "before the FE polish" not in "\n".join(
        findings(fe, M.ert_table(fe, n_boot=5), T.success(fe))
    )

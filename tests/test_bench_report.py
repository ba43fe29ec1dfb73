"""Reports: Table 1 shape and numbers, comparison table, figures and report.md."""

from __future__ import annotations

import math

import pandas as pd
import pytest

from bench.experiment import store
from bench.experiment.runner import make_record, run_suite
from bench.experiment.spec import RunSpec
from bench.experiment.suite import parse_suite
from bench.report import write_report
from bench.report.tables import DASH, comparison, table1

SMOOTH = ["E", "sigma0", "H", "psi"]
SMOOTH_REF = [30_000.0, 20.0, 1_500.0, 15.0]
LINEAR = ["p", "q", "r"]
LINEAR_REF = [1.0, 2.0, 3.0]


def fake_record(
    case,
    names,
    ref,
    errors_pct,
    *,
    method="lm",
    seed=0,
    start="default",
    index=0,
    n_evals=40,
    cost=1e-3,
    status="converged",
):
    """A record whose identified parameters have the given signed errors (percent)."""
    from solvers.result import RunResult

    xn = [1.0 + e / 100.0 for e in errors_pct]
    x = [r * v for r, v in zip(ref, xn)]
    hist = [
        {
            "iteration": 0,
            "n_evals": 1,
            "best_cost": 10.0,
            "cost": 10.0,
            "x": [1.2 * r for r in ref],
        },
        {"iteration": 1, "n_evals": n_evals, "best_cost": cost, "cost": cost, "x": x},
    ]
    res = RunResult(
        method=method,
        options={},
        seed=seed,
        budget=100,
        parameter_names=names,
        reference=ref,
        x0=hist[0]["x"],
        x=x,
        x_normalised=xn,
        cost=cost,
        status=status,
        success=True,
        message="",
        n_evals=n_evals,
        n_iterations=1,
        wall_s=0.5,
        history=hist,
    )
    cfg = RunSpec(case, method, seed, start, index, 100, "coarse")
    return make_record(cfg, res, suite="fake", data_hash="d" * 64, started="t0", finished="t1")


@pytest.fixture
def fake_dir(tmp_path):
    # analytic-smooth, lm: three runs; errors per parameter chosen so that medians are known
    for seed, errs in enumerate(
        [[1.0, -2.0, 0.5, 10.0], [3.0, -1.0, 0.1, -4.0], [2.0, 5.0, 0.3, 0.0]]
    ):
        store.write_record(
            tmp_path,
            fake_record(
                "analytic-smooth", SMOOTH, SMOOTH_REF, errs, seed=seed, n_evals=30 + 10 * seed
            ),
        )
    store.write_record(
        tmp_path, fake_record("analytic-linear", LINEAR, LINEAR_REF, [0.2, -0.4, 0.9])
    )
    # gauss-newton on the linear case only
    store.write_record(
        tmp_path,
        fake_record("analytic-linear", LINEAR, LINEAR_REF, [0.0, 2.0, 0.0], method="gauss-newton"),
    )
    return tmp_path


def test_table1_shape_and_numbers(fake_dir):
    runs, _ = store.to_frames(fake_dir)
    t = table1(runs, "lm")
    assert list(t.columns) == ["analytic-linear", "analytic-smooth"]
    assert list(t.index) == ["E", "psi", "sigma0", "H", "p", "q", "r"]  # study order first
    assert t.loc["E", "analytic-smooth"] == pytest.approx(2.0)  # median of 1, 3, 2
    assert t.loc["sigma0", "analytic-smooth"] == pytest.approx(-1.0)  # median of -2, -1, 5
    assert t.loc["H", "analytic-smooth"] == pytest.approx(0.3)
    assert t.loc["psi", "analytic-smooth"] == pytest.approx(0.0)
    assert t.loc["q", "analytic-linear"] == pytest.approx(-0.4)
    assert math.isnan(t.loc["E", "analytic-linear"]) and math.isnan(t.loc["p", "analytic-smooth"])
    gn = table1(runs, "gauss-newton")
    assert gn["analytic-smooth"].isna().all() and gn.loc["q", "analytic-linear"] == pytest.approx(
        2.0
    )


def test_report_files_table1_csv_and_md(fake_dir):
    md = write_report(fake_dir, ["md", "csv", "tex"], tol=1.0, figures=False)
    assert md == fake_dir / "report" / "report.md"
    csv = pd.read_csv(
        fake_dir / "report" / "tables" / "table1__lm.csv", index_col=0, keep_default_na=False
    )
    assert csv.shape == (7, 2)
    assert csv.loc["E", "analytic-linear"] == DASH and float(
        csv.loc["E", "analytic-smooth"]
    ) == pytest.approx(2.0)
    mdt = (fake_dir / "report" / "tables" / "table1__lm.md").read_text()
    assert "| sigma0 | – | -1 |" in mdt
    tex = (fake_dir / "report" / "tables" / "table1__lm.tex").read_text()
    assert r"$\sigma_0$ & -- & -1 \\" in tex and r"\toprule" in tex
    text = md.read_text()
    for name in (
        "tables/table1__lm.csv",
        "tables/table1__gauss-newton.tex",
        "tables/comparison.md",
        "tables/success.csv",
    ):
        assert name in text and (fake_dir / "report" / name).is_file()


def test_comparison_success_rate_and_evaluations(fake_dir):
    runs, _ = store.to_frames(fake_dir)
    c = comparison(runs, tol=2.5).set_index(["case", "method"])
    # smooth/lm: max |err| = 10, 4, 5 -> none within 2.5 %; with 12 % all three
    assert c.loc[("analytic-smooth", "lm"), "success_pct"] == 0.0
    assert (
        comparison(runs, tol=12.0)
        .set_index(["case", "method"])
        .loc[("analytic-smooth", "lm"), "success_pct"]
        == 100.0
    )
    assert c.loc[("analytic-linear", "lm"), "success_pct"] == 100.0
    assert c.loc[("analytic-linear", "gauss-newton"), "success_pct"] == 100.0  # |2| <= 2.5
    assert c.loc[("analytic-smooth", "lm"), "evals_median"] == 40.0
    assert (
        c.loc[("analytic-smooth", "lm"), "evals_q25"],
        c.loc[("analytic-smooth", "lm"), "evals_q75"],
    ) == (35.0, 45.0)
    assert c.loc[("analytic-smooth", "lm"), "runs"] == 3


def test_tiny_suite_report_end_to_end(tmp_path):
    suite = parse_suite(
        {
            "suite": {
                "name": "t",
                "cases": ["analytic-smooth", "analytic-linear"],
                "methods": ["lm", "gauss-newton"],
                "budgets": [80],
            }
        }
    )
    run_suite(suite, tmp_path, workers=1, progress=False)
    md = write_report(tmp_path, ["md", "csv", "pdf", "parquet"])
    rep = tmp_path / "report"
    runs, _ = store.to_frames(tmp_path)
    t = pd.read_csv(rep / "tables" / "table1__lm.csv", index_col=0, keep_default_na=False)
    assert t.shape == (7, 2) and list(t.columns) == ["analytic-linear", "analytic-smooth"]
    for p in SMOOTH:  # the numbers are those of the records
        want = runs[(runs["method"] == "lm") & (runs["case"] == "analytic-smooth")][
            f"err.{p}"
        ].iloc[0]
        assert float(t.loc[p, "analytic-smooth"]) == pytest.approx(want, abs=1e-12)
        assert t.loc[p, "analytic-linear"] == DASH
    # figures: one convergence figure per case x method family (lm and gauss-newton are both
    # local), a runtime ECDF per case, the overall ECDF
    figs = sorted(p.relative_to(rep).as_posix() for p in rep.rglob("*.png"))
    assert figs == sorted(
        [f"figures/convergence/{c}__local.png" for c in ("analytic-smooth", "analytic-linear")]
        + [f"figures/{c}__ecdf.png" for c in ("analytic-smooth", "analytic-linear")]
        + ["figures/all__ecdf.png"]
    )
    assert len(list(rep.rglob("*.pdf"))) == len(figs)
    text = md.read_text()
    assert all(f in text for f in figs)  # report.md points to every figure
    assert (rep / "runs.parquet").is_file() and (rep / "history.parquet").is_file()
    # a second report replaces the first completely (no stale files)
    write_report(tmp_path, ["csv"], figures=False)
    assert not list(rep.rglob("*.png")) and not (rep / "tables" / "table1__lm.md").exists()


def test_report_of_an_empty_directory_is_an_error(tmp_path):
    with pytest.raises(ValueError, match="no run records"):
        write_report(tmp_path, ["md"])


def test_report_cli_rejects_unknown_format(tmp_path, capsys):
    from bench.cli import main

    assert main(["report", str(tmp_path), "--format", "md,docx"]) == 2
    assert "unknown format(s) docx" in capsys.readouterr().err

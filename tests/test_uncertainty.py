"""MCMC against Laplace: the verdict rule, and agreement on a linear-Gaussian problem."""

import json
import warnings

import numpy as np
import pytest

from bench.studies.uncertainty import compare, verdict
from problems.analysis.identifiability import analyse_jacobian, refine_mode
from problems.inverse.analytic import analytic_model, analytic_objective


def test_verdict_rule():
    assert verdict(1.0, 0.1, 1.04, 0.1) == "agree"
    assert verdict(1.0, 0.1, 1.0, 0.068) == "agree" and verdict(1.0, 0.1, 1.0, 0.149) == "agree"
    assert verdict(1.0, 0.1, 1.06, 0.1) == "means differ by 0.6 posterior sd"
    assert "too narrow" in verdict(1.0, 0.1, 1.0, 0.05)
    assert "too wide" in verdict(1.0, 0.1, 1.0, 0.2)
    both = verdict(1.0, 0.1, 0.8, 0.5)
    assert "means differ by 2 posterior sd" in both and "5 x the MCMC sd" in both
    assert verdict(1.0, float("nan"), 1.0, 0.1).startswith("not comparable")
    assert verdict(1.0, 0.0, 1.0, 0.1).startswith("not comparable")


def test_compare_rows():
    mcmc = {"mean": {"a": 1.0}, "std": {"a": 0.1}, "q2.5": {"a": 0.8}, "q97.5": {"a": 1.2}}
    (row,) = compare(("a",), mcmc, [1.01], [0.1])
    assert row["verdict"] == "agree"
    assert row["laplace_q2.5"] == pytest.approx(1.01 - 1.959964 * 0.1)
    assert row["laplace_q97.5"] == pytest.approx(1.01 + 1.959964 * 0.1)


def test_mcmc_and_laplace_agree_on_a_linear_gaussian_problem():
    """y = A x + noise, flat prior on a wide box: the posterior *is* the Laplace Gaussian, so MCMC
    must agree with it (and both with the closed-form posterior) up to Monte-Carlo error."""
    from solvers import solve

    obj = analytic_objective("analytic-linear", noise=1.0, seed=7)
    model = analytic_model("analytic-linear")
    mean_exact, cov_exact = model.posterior(obj.data)
    pol = refine_mode(obj, np.ones(3), max_steps=3)
    lap = analyse_jacobian(pol.jacobian, obj.reference, x=obj.to_physical(pol.z), names=obj.names)
    assert np.allclose(lap.x, mean_exact, rtol=1e-6)
    assert np.allclose(lap.cov_x, cov_exact, rtol=1e-4)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        run = solve(obj, "mcmc", budget=16 * 1500, seed=3, x0=lap.x, n_walkers=16, ball_size=0.01)
    rows = compare(obj.names, run.extra, lap.x, lap.std_x)
    assert [r["verdict"] for r in rows] == ["agree"] * 3, rows
    sd = np.sqrt(np.diag(cov_exact))
    for i, n in enumerate(obj.names):  # 95 % intervals of both within 0.3 sd of the exact ones
        assert abs(run.extra["q2.5"][n] - (mean_exact[i] - 1.96 * sd[i])) < 0.3 * sd[i]
        assert abs(rows[i]["laplace_q97.5"] - (mean_exact[i] + 1.96 * sd[i])) < 1e-3 * sd[i]


def test_uncertainty_cli_on_the_analytic_linear_case(tmp_path, capsys):
    from bench.cli import main

    out = tmp_path / "unc"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert (
            main(
                [
                    "uncertainty",
                    "analytic-linear",
                    "--budget",
                    "16000",
                    "--walkers",
                    "16",
                    "--out",
                    str(out),
                ]
            )
            == 0
        )
    text = capsys.readouterr().out
    assert (
        "agree on every parameter" in text
        and "cost: Laplace" in text
        and "MCMC 16000 evaluations" in text
    )
    doc = json.loads((out / "uncertainty.json").read_text())
    assert doc["cost"]["mcmc_evaluations"] == 16000 and len(doc["table"]) == 3
    assert all(r["verdict"] == "agree" for r in doc["table"])
    for name in ("uncertainty.csv", "uncertainty.md", "corner.png", "chain.npz"):
        assert (out / name).stat().st_size > 0
    # the chain is an emcee backend persisted to chain.npz (z = x / reference, with its scale)
    from solvers.npz_backend import NpzBackend

    backend = NpzBackend.load(out / "chain.npz")
    mcmc = doc["mcmc"]
    assert backend.iteration == mcmc["n_steps"] and backend.shape == (16, 3)
    assert list(backend.metadata["names"]) == doc["names"]
    kept = backend.get_chain(discard=mcmc["burn"], flat=True) * backend.metadata["scale"]
    assert np.allclose(kept.mean(axis=0), [mcmc["mean"][n] for n in doc["names"]])
    assert (
        0
        < np.mean(backend.accepted / backend.iteration)
        == pytest.approx(mcmc["acceptance_fraction"])
    )
    # figures are re-drawn from the folder alone
    (out / "corner.png").unlink()
    assert main(["uncertainty", "analytic-linear", "--render", "--out", str(out)]) == 0
    assert (out / "corner.png").stat().st_size > 0
    assert main(["uncertainty", "analytic-linear", "--x", "p=9", "--out", str(out)]) == 2
    assert main(["uncertainty", "analytic-linear", "--x", "zz=1", "--out", str(out)]) == 2
    assert "unknown" in capsys.readouterr().err

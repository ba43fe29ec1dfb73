"""Evidence of a calibrated variant: the Laplace evidence is exact for a linear model (against a
brute-force quadrature), the box mass handles bounds and unseen directions, the bridge estimate
agrees with it from posterior draws, model probabilities normalise."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.calibration_evidence import (
    bridge_log_evidence,
    laplace_log_evidence,
    model_probabilities,
)


def _linear(seed=0):
    """chi2(x) = |A x - b|^2 for a 2-parameter linear model, its optimum and Fisher matrix."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(30, 2)) * np.array([2.0, 0.5])
    b = A @ np.array([0.3, -0.2]) + rng.normal(size=30)
    x = np.linalg.lstsq(A, b, rcond=None)[0]
    chi2 = lambda X: np.sum((np.atleast_2d(X) @ A.T - b) ** 2, axis=1)  # noqa: E731
    return chi2, x, A.T @ A


def _quadrature(chi2, lo, hi, n=801):
    g = [np.linspace(lo[i], hi[i], n) for i in range(2)]
    X = np.stack(np.meshgrid(*g, indexing="ij"), -1).reshape(-1, 2)
    f = np.exp(-0.5 * chi2(X)).reshape(n, n)
    integral = np.trapezoid(np.trapezoid(f, g[1], axis=1), g[0])
    return math.log(integral) - math.log(np.prod(np.subtract(hi, lo)))


@pytest.mark.parametrize("box", ["wide", "on-bound"])
def test_laplace_evidence_is_exact_for_a_linear_model(box):
    chi2, x, F = _linear()
    lo, hi = (x - 3.0, x + 3.0) if box == "wide" else (np.array([x[0], x[1] - 3]), x + 3.0)
    lap = laplace_log_evidence(float(chi2(x)[0]), F, x, lo, hi)
    assert lap["log_evidence"] == pytest.approx(_quadrature(chi2, lo, hi), abs=2e-3)
    if box == "on-bound":  # about half the Gaussian's mass is cut off (correlation moves it)
        assert -1.2 < lap["log_box_mass"] < -0.3
    else:
        assert lap["log_box_mass"] == pytest.approx(0.0, abs=1e-6)


def test_unseen_direction_counts_the_prior_width():
    """A parameter the data do not see: the evidence is the seen one's alone (the prior's width
    cancels), not +inf from a singular F."""
    F = np.diag([4.0, 0.0])
    lap = laplace_log_evidence(2.0, F, [0.0, 0.0], [-5.0, -1.0], [5.0, 1.0])
    seen = -1.0 + 0.5 * math.log(2 * math.pi) - 0.5 * math.log(4.0) - math.log(10.0)
    assert lap["log_evidence"] == pytest.approx(seen, abs=1e-3)


@pytest.mark.parametrize("scale", [1.0, 1e7])
def test_bridge_estimate_agrees_with_the_exact_evidence(scale):
    """Also with parameters of very different magnitudes (E in MPa next to K near 1)."""
    chi2_u, x, F = _linear(1)
    S = np.array([scale, 1.0])
    chi2 = lambda X: chi2_u(np.atleast_2d(X) / S)  # noqa: E731
    x, F = x * S, F / np.outer(S, S)
    lo, hi = x - np.array([0.05, 3.0]) * S, x + 3.0 * S  # one bound cuts the posterior
    exact = laplace_log_evidence(float(chi2(x)[0]), F, x, lo, hi)["log_evidence"]
    rng = np.random.default_rng(2)
    cov = np.linalg.inv(F)
    X = rng.multivariate_normal(x, cov, size=20000)
    X = X[np.all((X >= lo) & (X <= hi), axis=1)][:4000]  # exact draws of the truncated posterior

    def log_post(X):
        X = np.atleast_2d(X)
        inside = np.all((X >= lo) & (X <= hi), axis=1)
        out = np.full(len(X), -np.inf)
        out[inside] = -0.5 * chi2(X[inside]) - np.sum(np.log(hi - lo))
        return out

    est = bridge_log_evidence(log_post(X), X, log_post, rng)
    assert est["log_evidence"] == pytest.approx(exact, abs=0.05)
    assert 0 < est["relative_error"] < 0.05
    assert est["proposal_outside_support"] > 0  # the Gaussian proposal crosses the bound


def test_model_probabilities():
    p = model_probabilities({"a": -10.0, "b": -10.0 - math.log(3.0), "c": -math.inf})
    assert p["a"] == pytest.approx(0.75) and p["b"] == pytest.approx(0.25) and p["c"] == 0.0


def _tiny_experiment(tmp_path):
    """A virtual linear-compression test on a 3,3,6 mesh at three levels (seconds to calibrate
    on 2,2,4); returns its experiment file."""
    from problems.inverse.virtual_experiment import VirtualTest, write_virtual_experiment

    t = VirtualTest(
        "linear-compression",
        (31000.0, 33.0, 0.88, 11.0, 21.5, 1300.0),
        data_mesh="3,3,6",
        levels_mm=(0.05, 0.2, 0.5),
        spacing_mm=20.0,
        seed=3,
    )
    return write_virtual_experiment(t, tmp_path / "ve", "mc")


def test_mcmc_on_the_fe_model_checks_the_laplace_evidence(tmp_path, monkeypatch):
    """A tiny virtual experiment (data on 3,3,6, inverse mesh 2,2,4): a short emcee run on the FE
    model itself. E is well identified: its posterior sd is Laplace's; beta is not, and its box
    cuts the Gaussian, so the Laplace evidence is only near the bridge one (measured: -6.0 at
    60 steps, -3.7 at 150, -3.0 at 400: a real non-Gaussian posterior, not chain noise). The
    optimum lies in the chain's 95 % intervals; the report has the section; a rerun reads the
    chain back."""
    import bench.calibration as cal
    from bench.calibration import CalibrationSettings, McmcSettings, calibrate

    exp = _tiny_experiment(tmp_path)
    kw = dict(
        models=["linear-compression"],
        settings=CalibrationSettings("2,2,4", 20, check_mesh=""),
        figures=False,
        mcmc=McmcSettings("fe", n_steps=80, n_bridge=200),
        progress=lambda s: None,
    )
    rep = calibrate(exp, tmp_path / "out", **kw)
    c = rep["mcmc"]["linear-compression"]
    assert c["n_evals"] == c["n_walkers"] * 81 and c["n_walkers"] == 16  # + the start
    assert -8.0 < c["log_evidence_bridge"] - c["log_evidence_laplace"] < 0.0, c
    assert 0.7 < c["sd_ratio"][0] < 1.4 and c["sd_ratio"][1] < 0.3
    v = rep["variants"]["linear-compression"]
    inside = np.array(c["q025"]) <= v["x"]
    inside &= np.array(v["x"]) <= np.array(c["q975"])
    assert v["x"][1] == v["lower"][1] and inside[[0, 2, 3, 4, 5]].all()  # beta sits on its bound
    assert c["chi2_best_draw"] > c["chi2_optimum"] - 1.0  # lm found the mode
    assert c["chi2_optimum_fe"] == pytest.approx(c["chi2_optimum"], rel=1e-9)
    assert c["chi2_optimum_sampled"] == pytest.approx(c["chi2_optimum"], rel=1e-9)  # FE chain
    assert c["chi2_best_draw_fe"] == pytest.approx(c["chi2_best_draw"], rel=1e-9)
    assert "model_probability_bridge" in rep["ranking"][0]
    assert "bridge-sampling evidence" in (tmp_path / "out" / "report.md").read_text()
    monkeypatch.setattr(cal, "mcmc_variant", lambda *a, **k: pytest.fail("rerun"))
    again = calibrate(exp, tmp_path / "out", **kw)
    assert again["mcmc"]["linear-compression"]["log_evidence_bridge"] == c["log_evidence_bridge"]


def test_mcmc_bad_input_is_one_line_exit_2(tmp_path, capsys):
    from pathlib import Path

    from bench.cli import main

    exp = str(Path(__file__).resolve().parent.parent / "suites/experiments/cube100/experiment.toml")
    for argv, said in (
        (["--mcmc", "nope"], "--mcmc 'nope': nope unknown"),
        (["--mcmc", "best", "--correction", "iterated"], "--mcmc with --correction iterated"),
        (["--mcmc", "best", "--mcmc-forward", "x"], "--mcmc-forward"),
    ):
        assert main(["calibrate", exp, "--out", str(tmp_path / "o"), *argv]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and said in err[0], err
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_mcmc_on_a_surrogate(tmp_path):
    """The surrogate route on the tiny test of the FE chain above: a surrogate trained in the
    local box, a longer chain on it; E's sd is Laplace's, and the evidence difference with the
    surrogate's offset taken out is of the FE chain's size."""
    from bench.calibration import CalibrationSettings, McmcSettings, calibrate

    exp = _tiny_experiment(tmp_path)
    rep = calibrate(
        exp,
        tmp_path / "out",
        models=["linear-compression"],
        settings=CalibrationSettings("2,2,4", 20, check_mesh=""),
        figures=False,
        mcmc=McmcSettings("surrogate", n_steps=400, n_bridge=1000, n_train=40, n_holdout=10),
        progress=lambda s: None,
    )
    c = rep["mcmc"]["linear-compression"]
    assert c["surrogate"]["holdout_rms_sigma"]["u_h"] < 0.5
    assert 0.7 < c["sd_ratio"][0] < 1.4
    assert -8.0 < c["evidence_difference_offset_removed"] < 2.0, c

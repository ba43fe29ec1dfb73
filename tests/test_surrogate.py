"""Surrogate forward models (POD + RBF / GP): truncation rule, accuracy, failures, extrapolation,
Jacobian, store/load with hash check, pickling; on a cheap analytic model with the FE protocol."""

from __future__ import annotations

import json
import math
import pickle

import numpy as np
import pytest

from problems.inverse.protocol import ForwardResult
from problems.surrogate import SurrogateSettings, build_surrogate, fit_surrogate, load, save
from problems.surrogate.design import make_design
from problems.surrogate.pod import fit_pod
from problems.surrogate.regression import fit_gp, fit_rbf
from problems.surrogate.training import run_points

LOWER, UPPER = np.array([1.0, 0.0, -1.0]), np.array([2.0, 1.0, 1.0])
SIGMA = 1e-3
BLOCKS = {"wave": slice(0, 200), "decay": slice(200, 300)}


class ToyModel:
    """Smooth nonlinear map (a, b, c) -> 300 values, with a failing and an infeasible corner.

    wave  (200): a sin(2 pi t (1 + 0.3 b)) + c t^2 ;  decay (100): a b exp(-(1 + c^2) t) + 0.2 c
    fails (ok=False) for a > 1.93; infeasible (check) for b + c > 1.7.
    """

    names = ("a", "b", "c")

    def __init__(self, n_wave: int = 200, n_decay: int = 100):
        self.n_wave, self.n_decay = n_wave, n_decay
        self.t1, self.t2 = np.linspace(0, 1, n_wave), np.linspace(0, 2, n_decay)

    def to_spec(self) -> dict:
        return {"n_wave": self.n_wave, "n_decay": self.n_decay}

    def check(self, x) -> str | None:
        return "b + c > 1.7 is infeasible" if x[1] + x[2] > 1.7 else None

    def __call__(self, x) -> ForwardResult:
        a, b, c = x
        if a > 1.93:
            return ForwardResult(False, None, "diverged")
        wave = a * np.sin(2 * np.pi * self.t1 * (1 + 0.3 * b)) + c * self.t1**2
        decay = a * b * np.exp(-(1 + c * c) * self.t2) + 0.2 * c
        return ForwardResult(True, np.concatenate([wave, decay]))


def settings(**kw) -> SurrogateSettings:
    base = dict(
        n_train=90,
        n_holdout=30,
        seed=3,
        regression="rbf",
        tol_sigma=0.05,
        gp_restarts=0,
        gp_individual=3,
    )
    return SurrogateSettings(**{**base, **kw})


@pytest.fixture(scope="module")
def rbf_surrogate():
    return build_surrogate(
        ToyModel(), LOWER, UPPER, SIGMA, settings=settings(rbf_smoothing=(0.0,)), blocks=BLOCKS
    )


def test_design_is_seeded_in_the_box_and_local_part_near_the_centre():
    d1 = make_design(LOWER, UPPER, 20, seed=1, center=[1.5, 0.5, 0.0], n_local=10, local_scale=0.1)
    d2 = make_design(LOWER, UPPER, 20, seed=1, center=[1.5, 0.5, 0.0], n_local=10, local_scale=0.1)
    np.testing.assert_array_equal(d1.X, d2.X)
    assert np.all(d1.X >= LOWER) and np.all(d1.X <= UPPER)
    local = d1.X[d1.origin == "local"]
    assert len(local) == 10 and np.all(
        np.abs(local - [1.5, 0.5, 0.0]) <= 0.1 * (UPPER - LOWER) + 1e-12
    )
    sob = make_design(LOWER, UPPER, 12, seed=1, method="sobol")
    assert sob.X.shape == (12, 3) and not np.allclose(
        sob.X, make_design(LOWER, UPPER, 12, seed=[1, 1]).X
    )


def test_pod_truncation_meets_its_criterion_and_is_minimal():
    model = ToyModel()
    X = make_design(LOWER, [1.9, 1.0, 0.6], 60, seed=0).X
    Y = np.array([model(x).values for x in X])
    tol = 0.05
    pod = fit_pod(Y, SIGMA, tol_sigma=tol, blocks=BLOCKS)

    def rms(p):
        E = (p.reconstruct(p.coefficients(Y)) - Y) / SIGMA
        return {k: float(np.sqrt(np.mean(E[:, sl] ** 2))) for k, sl in BLOCKS.items()}

    measured = rms(pod)
    for k in BLOCKS:
        assert measured[k] <= tol
        assert measured[k] == pytest.approx(pod.projection_rms[k], rel=1e-6, abs=1e-9)
    fewer = fit_pod(Y, SIGMA, tol_sigma=tol, blocks=BLOCKS, max_modes=pod.n_modes - 1)
    assert max(rms(fewer).values()) > tol
    assert 1 < pod.n_modes < 60


def test_failed_and_infeasible_training_points_are_recorded_and_excluded(rbf_surrogate):
    model, s = ToyModel(), settings()
    X = make_design(LOWER, UPPER, s.n_train, seed=s.seed).X
    infeasible = X[:, 1] + X[:, 2] > 1.7
    failing = ~infeasible & (X[:, 0] > 1.93)
    assert infeasible.any() and failing.any()
    runs = run_points(model, X, batch=7)
    assert runs.n_infeasible == infeasible.sum() and runs.n_failed == failing.sum()
    assert (
        runs.n_ok == len(X) - infeasible.sum() - failing.sum()
        and runs.n_runs == runs.n_ok + runs.n_failed
    )
    assert np.all(runs.X[:, 0] <= 1.93) and np.all(runs.X[:, 1] + runs.X[:, 2] <= 1.7)
    assert {m for _, m in runs.failed} == {"diverged"}
    info = rbf_surrogate.info
    assert (
        info["training"]["n_failed"] == runs.n_failed
        and info["training"]["n_infeasible"] == runs.n_infeasible
    )
    assert info["training"]["n_runs"] == runs.n_runs and len(rbf_surrogate.train_z) == runs.n_ok
    assert len(info["failed"]) == runs.n_failed and len(info["infeasible"]) == runs.n_infeasible
    assert info["cost"]["holdout"]["n_runs"] >= 1


def test_rbf_surrogate_reproduces_training_points_and_generalises(rbf_surrogate):
    sur = rbf_surrogate
    assert sur.regression.smoothing == 0.0
    model = ToyModel()
    X = sur.lower + sur.train_z * (sur.upper - sur.lower)
    E = (sur.predict(X) - np.array([model(x).values for x in X])) / SIGMA
    for _k, sl in BLOCKS.items():  # interpolation: only the POD truncation remains
        assert np.sqrt(np.mean(E[:, sl] ** 2)) <= sur.pod.tol_sigma * (1 + 1e-6)
    val = sur.info["validation"]
    assert val["n_points"] >= 20
    for k in BLOCKS:
        # stated tolerance: hold-out RMS within 2 sigma, 0.2 % of the outputs' range (~1000 sigma)
        assert val["blocks"][k]["rms_sigma"] < 2.0, val["blocks"]
    assert sur.hold_out_variance.shape == (300,) and np.all(sur.hold_out_variance >= 0)
    assert val["speed_ratio"] > 0 and val["surrogate_eval_s"] > 0


def test_rbf_and_gp_fits_match_their_libraries():
    from scipy.interpolate import RBFInterpolator
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import ConstantKernel, Matern

    rng = np.random.default_rng(0)
    Z, Zq = rng.random((30, 3)), rng.random((7, 3))
    A = np.c_[np.sin(3 * Z[:, 0]) + Z[:, 1] ** 2, Z[:, 2] * Z[:, 0]]
    for kernel, eps in (("thin_plate_spline", 1.0), ("quintic", 1.0), ("gaussian", 2.0)):
        f = fit_rbf(Z, A, kernel=kernel, epsilon=eps, smoothing=1e-5)
        ref = RBFInterpolator(Z, A, kernel=kernel, epsilon=eps, smoothing=1e-5)(Zq)
        np.testing.assert_allclose(f.predict(Zq), ref, rtol=1e-10, atol=1e-12)
    g = fit_gp(Z, A, nu=2.5, n_individual=1, restarts=0)
    c = g.components[0]
    kernel = ConstantKernel(c.amplitude, "fixed") * Matern(c.length_scale, "fixed", nu=2.5)
    gp = GaussianProcessRegressor(kernel, normalize_y=True, optimizer=None, alpha=1e-10).fit(
        Z, A[:, :1]
    )
    np.testing.assert_allclose(c.predict(Zq)[:, 0], gp.predict(Zq).ravel(), rtol=1e-4, atol=1e-6)


def _fd_jacobian(sur, x, h):
    cols = []
    for i in range(len(x)):
        step = h * (sur.upper[i] - sur.lower[i])
        xp, xm = x.copy(), x.copy()
        xp[i] += step
        xm[i] -= step
        cols.append((sur(xp).values - sur(xm).values) / (2 * step))
    return np.array(cols).T


def test_surrogate_jacobian_matches_its_finite_differences(rbf_surrogate):
    x = np.array([1.41, 0.37, -0.22])
    res = rbf_surrogate(x, jacobian=True)
    assert res.ok and res.jacobian.shape == (300, 3)
    J = _fd_jacobian(rbf_surrogate, x, 1e-5)
    assert np.abs(res.jacobian - J).max() <= 1e-6 * np.abs(res.jacobian).max()
    np.testing.assert_allclose(res.values, rbf_surrogate(x).values, rtol=0, atol=0)


def test_gp_surrogate_jacobian_and_auto_selection():
    model = ToyModel()
    runs = run_points(model, make_design(LOWER, UPPER, 50, seed=5).X)
    fast = dict(gp_individual=1, rbf_kernels=(("thin_plate_spline", 1.0), ("cubic", 1.0)))
    sur = fit_surrogate(
        runs,
        LOWER,
        UPPER,
        SIGMA,
        names=model.names,
        settings=settings(regression="auto", **fast),
        blocks=BLOCKS,
        checker=model,
    )
    sel = sur.info["selection"]
    assert sel["chosen"] == sur.kind and set(sel["scores"]) == {"rbf", "gp"}
    assert sel["n_fit"] + sel["n_selection"] == runs.n_ok
    gp = fit_surrogate(
        runs,
        LOWER,
        UPPER,
        SIGMA,
        names=model.names,
        settings=settings(regression="gp", **fast),
        blocks=BLOCKS,
        checker=model,
    )
    assert gp.kind == "gp"
    x = np.array([1.41, 0.37, -0.22])
    res = gp(x, jacobian=True)
    # a GP mean with a tiny nugget is ill-conditioned: central differences are accurate to ~1e-6
    # only
    J = _fd_jacobian(gp, x, 1e-3)
    assert np.abs(res.jacobian - J).max() <= 1e-5 * np.abs(res.jacobian).max()
    err = (gp.predict(runs.X) - runs.Y) / SIGMA  # nearly interpolates its training points
    assert np.sqrt(np.mean(err**2)) < 0.5


def test_extrapolation_is_flagged_and_invalid_points_rejected():
    model = ToyModel()
    lo, hi = np.array([1.2, 0.2, -0.6]), np.array([1.8, 0.8, 0.6])
    runs = run_points(model, make_design(lo, hi, 50, seed=2).X)
    sur = fit_surrogate(
        runs,
        LOWER,
        UPPER,
        SIGMA,
        names=model.names,
        settings=settings(),
        blocks=BLOCKS,
        design_box=(lo, hi),
        checker=model,
    )
    inside = sur(np.array([1.5, 0.5, 0.0]))
    assert inside.ok and inside.message == ""
    outside = sur(np.array([1.9, 0.5, 0.0]))
    assert outside.ok and outside.message.startswith("extrapolation") and "a by" in outside.message
    ex = sur.extrapolation(np.array([1.9, 0.5, 0.0]), hull=True)
    assert ex["outside_box"] and not ex["in_hull"] and ex["box_excess"][0] == pytest.approx(0.1)
    assert not sur.extrapolation(np.array([1.5, 0.5, 0.0]))["outside_box"]
    bad = sur(np.array([1.5, 0.9, 0.9]))
    assert not bad.ok and "infeasible" in bad.message
    assert not sur(np.array([2.5, 0.5, 0.0])).ok and "outside the box" in sur.check(
        np.array([2.5, 0.5, 0.0])
    )


def test_save_load_round_trip_and_tampering(rbf_surrogate, tmp_path):
    folder = save(rbf_surrogate, tmp_path / "toy")
    back = load(folder)
    for name, array in rbf_surrogate.regression.arrays().items():  # the model itself, exactly
        np.testing.assert_array_equal(back.regression.arrays()[name], array)
    np.testing.assert_array_equal(back.pod.modes, rbf_surrogate.pod.modes)
    # its values: BLAS may take other kernels for other memory (alignment): rounding apart
    X = make_design(LOWER, UPPER, 10, seed=9).X
    np.testing.assert_allclose(back.predict(X), rbf_surrogate.predict(X), rtol=0, atol=1e-10)
    x = np.array([1.3, 0.4, 0.1])
    J_back, J = back(x, jacobian=True).jacobian, rbf_surrogate(x, jacobian=True).jacobian
    np.testing.assert_allclose(J_back, J, rtol=0, atol=1e-10)
    np.testing.assert_array_equal(back.hold_out_variance, rbf_surrogate.hold_out_variance)
    assert back.hash == rbf_surrogate.hash and len(back.hash) == 64
    assert back.info["training_hash"] == rbf_surrogate.info["training_hash"]
    assert isinstance(back.checker, ToyModel) and back.check(np.array([1.5, 0.9, 0.9])) is not None
    assert load("toy", root=tmp_path).hash == back.hash  # a name in a root folder
    with pytest.raises(FileNotFoundError):
        load("absent", root=tmp_path)

    # a changed array
    with np.load(folder / "surrogate.npz") as z:
        arrays = {k: z[k] for k in z.files}
    arrays["pod_mean"] = arrays["pod_mean"].copy()
    arrays["pod_mean"][3] += 1e-9
    np.savez(folder / "surrogate.npz", **arrays)
    with pytest.raises(ValueError, match="hash"):
        load(folder)
    # a changed setting
    save(rbf_surrogate, folder)
    doc = json.loads((folder / "surrogate.json").read_text())
    doc["pod"]["tol_sigma"] = 1.0
    (folder / "surrogate.json").write_text(json.dumps(doc))
    with pytest.raises(ValueError, match="hash"):
        load(folder)


def test_surrogate_pickles_and_serves_an_evaluator(rbf_surrogate):
    from problems.inverse.evaluator import Evaluator
    from problems.inverse.problem import LeastSquaresProblem

    again = pickle.loads(pickle.dumps(rbf_surrogate))
    x = np.array([1.3, 0.4, 0.1])
    np.testing.assert_array_equal(again(x).values, rbf_surrogate(x).values)
    data = ToyModel()(x).values
    sigma = rbf_surrogate.inflated_sigma(SIGMA)
    assert np.all(sigma >= SIGMA)
    ev = Evaluator(
        LeastSquaresProblem(
            rbf_surrogate, data, LOWER, UPPER, np.array([1.5, 0.5, 0.5]), sigma=sigma
        )
    )
    z = ev.to_scaled(np.array([1.35, 0.45, 0.05]))
    J = ev.jacobian(z)
    assert J.shape == (300, 3) and np.all(np.isfinite(J))
    # surrogate error within the inflated sigma: chi^2 below m
    assert ev.cost(ev.to_scaled(x)) < 300


def test_cli_rejects_bad_input(capsys):
    from bench.cli import main

    assert main(["surrogate", "linear-compression", "--samples", "2"]) == 2
    assert "error" in capsys.readouterr().err
    assert main(["surrogate", "no-such-case"]) == 2
    assert main(["surrogate", "analytic-smooth"]) == 2


@pytest.mark.slow
def test_surrogate_of_the_fe_model_on_a_small_mesh(tmp_path):
    from bench.cli import main

    out = tmp_path / "sur"
    assert (
        main(
            [
                "surrogate",
                "linear-compression",
                "--mesh",
                "3,3,6",
                "--samples",
                "40",
                "--holdout",
                "10",
                "--workers",
                "1",
                "--regression",
                "rbf",
                "--out",
                str(out),
                "--json",
                str(tmp_path / "s.json"),
                "--quiet",
            ]
        )
        == 0
    )
    doc = json.loads((tmp_path / "s.json").read_text())
    for key in (
        "holdout",
        "surrogate_eval_s",
        "fe_eval_s",
        "n_train",
        "n_failed",
        "hash",
        "n_modes",
        "regression",
    ):
        assert key in doc
    for block in ("u_h", "u_v", "force"):
        assert (
            math.isfinite(doc["holdout"][block]["rms_sigma"])
            and doc["holdout"][block]["max_sigma"] >= 0
        )
    assert doc["fe_eval_s"] > doc["surrogate_eval_s"] > 0
    assert doc["clock"] == "cpu" and doc["fe_worker_wall_s"] > 0
    sur = load(out)
    assert sur.hash == doc["hash"] and sur.n_values == 8130
    from problems.inverse.cases import CASES

    res = sur(CASES["linear-compression"].reference, jacobian=True)
    assert res.ok and res.jacobian.shape == (8130, 6)


def test_validation_times_the_model_in_process_on_the_cpu_clock(rbf_surrogate):
    """The speed ratio compares CPU times measured in this process: a model that burns ~20 ms of
    CPU per run is timed at that, whatever wall time its hold-out runs took on workers."""
    import time

    from problems.surrogate.training import Runs
    from problems.surrogate.validation import validate

    class Busy(ToyModel):
        def __call__(self, x):
            t0 = time.process_time()
            while time.process_time() - t0 < 0.02:
                pass
            return super().__call__(x)

    model = Busy()
    X = make_design(LOWER, [1.9, 0.5, 0.5], 12, seed=5).X
    Y = np.array([model(x).values for x in X[:2]] + [ToyModel()(x).values for x in X[2:]])
    runs = Runs(X, Y, np.full(len(X), 7.0), [], [], 84.0, 84.0)  # workers' wall: 7 s per run
    val = validate(rbf_surrogate, runs, SIGMA, BLOCKS, model=model)
    assert val.clock == "cpu" and 0.019 <= val.fe_eval_s < 0.2
    assert val.fe_worker_wall_s == 7.0 and val.summary()["fe_worker_wall_s"] == 7.0
    assert 0 < val.surrogate_eval_s < val.fe_eval_s
    # the objective's evaluation on the surrogate (its cost path) is what the ratio compares
    assert 0 < val.misfit_batch_eval_s and 0 < val.misfit_eval_s < val.fe_eval_s
    assert val.speed_ratio == pytest.approx(val.fe_eval_s / val.misfit_eval_s)
    assert val.summary()["misfit_eval_s"] == val.misfit_eval_s
    without = validate(rbf_surrogate, runs, SIGMA, BLOCKS)
    assert without.fe_eval_s == 7.0 and without.clock.startswith("wall")
    assert without.blocks == val.blocks  # the errors do not depend on the timing


def test_cli_builds_several_cases_and_skips_the_built_ones(tmp_path, monkeypatch, capsys):
    """``femubench surrogate all --skip-done`` (the shipped defaults' rebuild, resumable): a case
    whose folder holds surrogate.json and build.json is skipped, the others are built in turn."""
    import problems.surrogate as surrogate_pkg
    from bench.cli import main
    from problems.inverse.cases import CASES
    from problems.surrogate.store import SURROGATE_DIR_ENV

    monkeypatch.setenv(SURROGATE_DIR_ENV, str(tmp_path))
    names = list(CASES)
    for name in names[:-1]:
        folder = tmp_path / f"{name}__coarse"
        folder.mkdir()
        (folder / "surrogate.json").write_text("{}")
        (folder / "build.json").write_text("{}")
    (tmp_path / f"{names[-1]}__coarse").mkdir()  # a build that stopped: no build.json

    def build_case_surrogate(case, **kwargs):
        raise ValueError(f"building {case.name} with {kwargs['settings'].n_train} samples")

    monkeypatch.setattr(surrogate_pkg, "build_case_surrogate", build_case_surrogate)
    assert main(["surrogate", "all", "--samples", "300", "--skip-done", "--quiet"]) == 2
    out, err = capsys.readouterr()
    assert out.count("skip ") == len(names) - 1 and f"=== {names[-1]}" in out
    assert f"building {names[-1]} with 300 samples" in err
    # without --skip-done the first built one is refused before any work
    assert main(["surrogate", names[0], "linear-shear"]) == 2
    assert "already holds a surrogate" in capsys.readouterr().err
    assert main(["surrogate", names[0], "linear-shear", "--out", str(tmp_path / "x")]) == 2
    assert "--out and --json take one case" in capsys.readouterr().err

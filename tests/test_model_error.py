"""Model-error treatments: the honesty rule, one-point and BAE corrections on analytic model
pairs."""

import numpy as np
import pytest

from problems.inverse.model_error import (
    Correction,
    HonestyError,
    bae_statistics,
    check_honest,
    one_point,
)
from problems.inverse.problem import LeastSquaresProblem
from problems.inverse.protocol import ForwardResult

T = np.linspace(0.0, 1.0, 30)


class Coarse:
    """U(x) = x0 sin(T) + x1 T^2: the 'inverse model'."""

    names = ("x0", "x1")

    def check(self, x):
        return None

    def values(self, x):
        return x[0] * np.sin(T) + x[1] * T**2

    def __call__(self, x):
        return ForwardResult(True, self.values(np.asarray(x)))


class Fine(Coarse):
    """The 'high-fidelity model': the coarse one plus a parameter-dependent bias
    b(x) = 0.01 x0 T + 0.003."""

    def values(self, x):
        return super().values(x) + 0.01 * x[0] * T + 0.003


def test_honesty_rule_refuses_the_data_discretisation_in_the_loop():
    check_honest("fine/eighth", "model-error", forward="coarse/eighth", hifi="paper/eighth")
    with pytest.raises(HonestyError, match="hifi model uses discretisation fine/eighth"):
        check_honest("fine/eighth", "model-error", forward="coarse/eighth", hifi="fine/eighth")
    with pytest.raises(HonestyError, match="forward"):
        check_honest("coarse/eighth", "model-error", forward="coarse/eighth")
    # the labelled consistent tier
    check_honest("coarse/eighth", "consistent", forward="coarse/eighth")


def test_one_point_correction_removes_the_bias_at_its_point_and_is_charged():
    x0 = np.array([2.0, 1.0])
    c = one_point(Fine(), Coarse(), x0)
    np.testing.assert_allclose(c.shift, 0.01 * 2.0 * T + 0.003, atol=1e-15)
    assert (c.n_hifi, c.n_inverse) == (1, 1) and c.hifi_wall_s > 0
    data = Fine().values(np.array([2.1, 0.9]))
    p = LeastSquaresProblem(Coarse(), data - c.shift, [1, 0.5], [3, 2], [2, 1], sigma=1e-3)
    r, _ = p.residual(Coarse().values(np.array([2.1, 0.9])))
    # the remaining error is the bias difference between x0 and the true point only: 0.01 * 0.1 * T
    np.testing.assert_allclose(np.abs(r) * 1e-3, 0.001 * T, atol=1e-12)


def test_bae_statistics_mean_and_covariance_of_the_model_error():
    c = bae_statistics(Fine(), Coarse(), [1.0, 0.5], [3.0, 1.5], samples=40, seed=1)
    X = c.points
    E = 0.01 * X[:, :1] * T[None, :] + 0.003
    np.testing.assert_allclose(c.shift, E.mean(axis=0), atol=1e-14)
    np.testing.assert_allclose(c.factor @ c.factor.T, np.cov(E.T), atol=1e-12)
    assert c.n_hifi == 40 and c.n_failed == 0
    # same seed, same statistics
    assert (
        bae_statistics(Fine(), Coarse(), [1.0, 0.5], [3.0, 1.5], samples=40, seed=1).hash == c.hash
    )


def test_correction_round_trip_and_tamper_detection(tmp_path):
    c = bae_statistics(
        Fine(), Coarse(), [1.0, 0.5], [3.0, 1.5], samples=8, seed=0, provenance={"hifi": "f"}
    )
    path = tmp_path / "bae.npz"
    c.save(path)
    back = Correction.load(path)
    assert back.hash == c.hash and back.provenance["hifi"] == "f" and back.n_hifi == 8
    with np.load(path) as f:
        arrays = dict(f)
    arrays["shift"] = arrays["shift"] + 1e-9
    np.savez(path, **arrays)
    with pytest.raises(ValueError, match="hash mismatch"):
        Correction.load(path)


def _objective(correction, data):
    from problems.inverse.evaluator import Evaluator

    shift = 0.0 if correction is None else correction.shift
    ev = Evaluator(
        LeastSquaresProblem(Coarse(), data - shift, [1.0, 0.5], [3.0, 1.5], [2.0, 1.0], sigma=1e-3)
    )
    if correction is not None:
        ev.charge("hifi", correction.n_hifi, correction.hifi_wall_s)
    return ev


def test_iterated_correction_converges_to_the_truth_where_one_point_does_not():
    from solvers import solve
    from solvers.corrected import solve_iterated

    truth, x0 = np.array([2.4, 0.8]), np.array([1.6, 1.2])
    data = Fine().values(truth)
    plain = solve(_objective(None, data), "lm", budget=200, x0=x0)
    once = solve(_objective(one_point(Fine(), Coarse(), x0), data), "lm", budget=200, x0=x0)
    it = solve_iterated(
        lambda c: _objective(c, data),
        lambda x: one_point(Fine(), Coarse(), x),
        "lm",
        budget=400,
        x0=x0,
        tol=1e-6,
    )
    err = {
        k: np.max(np.abs(np.asarray(r.x) / truth - 1))
        for k, r in {"none": plain, "one-point": once, "iterated": it}.items()
    }
    assert err["iterated"] < 1e-6 < err["one-point"] < err["none"]
    assert it.extra["correction_converged"] and len(it.extra["correction_rounds"]) >= 2
    assert it.charges["hifi"]["n"] == len(it.extra["correction_rounds"])
    assert it.n_evals == sum(r["n_evals"] for r in it.extra["correction_rounds"]) <= 400


# --- on the FE model (tiny meshes) -------------------------------------------------------------


def _fe_data(mesh, tier="model-error"):
    from problems.inverse.data import make_data

    return make_data("linear-compression", mesh=mesh, snapshots=2, tier=tier)


def test_build_objective_refuses_the_data_mesh_in_the_loop_and_labels_the_tiers():
    from problems.inverse.build import build_objective

    data = _fe_data("2,2,4")
    with pytest.raises(HonestyError, match="forward model uses discretisation 2,2,4"):
        build_objective("linear-compression", mesh="2,2,4", data=data)
    with pytest.raises(HonestyError, match="forward"):
        # the quarter model of the same mesh too
        build_objective("linear-compression", mesh="2,2,4:quarter", data=data)
    corr = Correction("one-point", shift=np.zeros(1))
    with pytest.raises(HonestyError, match="hifi model"):
        build_objective(
            "linear-compression", mesh="1,1,2", data=data, correction=corr, hifi_mesh="2,2,4"
        )
    obj = build_objective("linear-compression", mesh="1,1,2", data=data)
    assert obj.provenance["data_tier"] == "model-error" and obj.provenance["data_mesh"] == "2,2,4"
    consistent = _fe_data("1,1,2", tier="consistent")
    assert (
        build_objective("linear-compression", mesh="1,1,2", data=consistent).provenance["data_tier"]
        == "consistent"
    )
    with pytest.raises(ValueError, match="consistent-tier data were made on mesh 1,1,2"):
        build_objective("linear-compression", mesh="2,2,4", data=consistent)


def test_region_leaves_out_the_points_near_the_plates():
    from problems.inverse.build import Region, build_objective

    data = _fe_data("2,2,4")
    full = build_objective("linear-compression", mesh="1,1,2", data=data)
    inner = build_objective("linear-compression", mesh="1,1,2", data=data, region=Region(30.0))
    z = data.points[:, 1]
    kept = int(np.sum((z >= 30) & (z <= 120)))
    assert inner.n_residuals == 2 * 2 * kept + 2 and full.n_residuals == 2 * 2 * len(z) + 2
    assert inner.provenance["region_plate_margin_mm"] == 30.0
    with pytest.raises(ValueError, match="plate_margin_mm"):
        Region(80.0)


def test_one_point_fe_correction_is_applied_and_charged():
    from problems.inverse.build import build_objective, model_pair
    from problems.inverse.cases import CASES

    data = _fe_data("2,2,4")
    case = CASES["linear-compression"]
    hifi, inverse = model_pair(case, "1,1,2", "1,1,4", data)
    corr = one_point(hifi, inverse, case.start)
    plain = build_objective(case, mesh="1,1,2", data=data)
    fixed = build_objective(case, mesh="1,1,2", data=data, correction=corr, hifi_mesh="1,1,4")
    assert fixed.charges["hifi"]["n"] == 1 and fixed.provenance["treatment"] == "one-point"
    z = np.ones(6)
    np.testing.assert_allclose(
        fixed.residual(z) - plain.residual(z), fixed.whiten(-corr.shift), rtol=1e-12
    )

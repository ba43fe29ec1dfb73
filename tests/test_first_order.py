"""The first-order consistent model-error correction (treatment ``first-order``): its fixed point
is the high-fidelity model's own optimum, where the zero-order ``iterated`` stops elsewhere."""

import hashlib
from pathlib import Path

import numpy as np
import pytest

from problems.inverse.evaluator import Evaluator
from problems.inverse.model_error import Correction, corrected_model, first_order, one_point
from problems.inverse.problem import LeastSquaresProblem
from problems.inverse.protocol import ForwardResult
from solvers.corrected import solve_iterated

T = np.linspace(0.0, 1.0, 24)
#: inverse model U = A x + a, high-fidelity model U = B x + b (x physical, 2 parameters)
A = np.column_stack([np.sin(3 * T), T**2])
B = A + np.column_stack([0.15 * T, 0.1 * np.cos(2 * T)])
a, b = 0.01 * T, 0.01 * T + 0.02 * T**3
SIGMA = 1e-3 * (1.0 + T)
#: data the high-fidelity model does not fit: a pattern outside span(B)
DATA = B @ np.array([200.0, 0.05]) + b + 0.05 * np.cos(7 * T)
LOWER, UPPER, REFERENCE = np.array([100.0, -0.2]), np.array([400.0, 0.3]), np.array([250.0, 0.08])


class Linear:
    """U(x) = M x + c, with its exact Jacobian (physical units)."""

    names = ("E", "k")
    provides_jacobian = True
    jacobian_cost = 2

    def __init__(self, M, c):
        self.M, self.c = M, c

    def check(self, x):
        return None

    def __call__(self, x, jacobian=False):
        x = np.asarray(x, float)
        return ForwardResult(True, self.M @ x + self.c, jacobian=self.M if jacobian else None)


def _objective(correction):
    p = LeastSquaresProblem(
        corrected_model(Linear(A, a), correction),
        DATA - correction.shift,
        LOWER,
        UPPER,
        REFERENCE,
        sigma=SIGMA,
    )
    ev = Evaluator(p)
    ev.charge("hifi", correction.n_hifi, correction.hifi_wall_s)
    ev.charge("inverse-for-correction", correction.n_inverse, correction.inverse_wall_s)
    return ev


def _weighted_solve(P, Q):
    """x with ``P^T W (DATA - b - Q x) = 0`` (W = diag(SIGMA^-2))."""
    W = 1.0 / SIGMA**2
    return np.linalg.solve(P.T @ (W[:, None] * Q), P.T @ (W * (DATA - b)))


def test_first_order_converges_to_the_hifi_optimum_where_iterated_does_not():
    hifi, inverse = Linear(B, b), Linear(A, a)
    x0 = np.array([205.0, 0.1])
    x_hifi = _weighted_solve(B, B)  # J_hifi^T W (U_E - U_hifi) = 0
    x_iter = _weighted_solve(A, B)  # J_inv^T W (U_E - U_hifi) = 0: the zero-order fixed point
    gap = np.max(np.abs(x_iter / x_hifi - 1))
    assert gap > 0.02  # the two fixed points differ clearly (analytically)
    runs = {
        name: solve_iterated(
            _objective,
            lambda x, f=f: f(hifi, inverse, x),
            "lm",
            budget=600,
            x0=x0,
            tol=1e-9,
            max_rounds=40,
        )
        for name, f in (("iterated", one_point), ("first-order", first_order))
    }
    fo, it = runs["first-order"], runs["iterated"]
    np.testing.assert_allclose(fo.x, x_hifi, rtol=1e-8)
    np.testing.assert_allclose(it.x, x_iter, rtol=1e-6)
    assert np.max(np.abs(np.asarray(it.x) / np.asarray(fo.x) - 1)) > gap / 2
    assert fo.provenance["treatment"] == "first-order" and it.provenance["treatment"] == "iterated"
    # linear models: the first round already lands on the optimum, the second confirms it
    assert fo.extra["correction_converged"] and len(fo.extra["correction_rounds"]) == 2
    # one hifi and one inverse run with sensitivities per round, charged
    assert fo.charges["hifi"]["n"] == fo.charges["inverse-for-correction"]["n"] == 2


def test_affine_correction_values_and_scaled_jacobian():
    c = first_order(Linear(B, b), Linear(A, a), REFERENCE)
    np.testing.assert_allclose(c.slope, B - A, atol=1e-15)
    np.testing.assert_allclose(c.shift, (B - A) @ REFERENCE + b - a, atol=1e-12)
    ev = _objective(c)
    z = np.array([1.2, 0.7])
    x = z * REFERENCE
    e = ev.evaluate(z, with_jacobian=True)
    # the corrected model is the high-fidelity one (linear): its residual and dR/dz
    np.testing.assert_allclose(e.residual, (DATA - B @ x - b) / SIGMA, rtol=1e-10)
    np.testing.assert_allclose(e.jacobian, -(B / SIGMA[:, None]) * REFERENCE, rtol=1e-12)


def test_first_order_needs_exact_jacobians():
    class NoJacobian(Linear):
        provides_jacobian = False

    with pytest.raises(ValueError, match="needs exact Jacobians: the high-fidelity model"):
        first_order(NoJacobian(B, b), Linear(A, a), REFERENCE)


def test_zero_order_hash_is_unchanged_and_the_slope_enters_it(tmp_path):
    shift, points = np.arange(5.0), np.array([[1.0, 2.0]])
    old = hashlib.sha256(b"one-point")
    for arr in (shift, points):
        old.update(np.ascontiguousarray(arr, dtype=float).tobytes())
    assert Correction("one-point", shift=shift, points=points).hash == old.hexdigest()
    c = first_order(Linear(B, b), Linear(A, a), REFERENCE)
    moved = Correction(**{**c.__dict__, "slope": c.slope * (1 + 1e-12)})
    assert moved.hash != c.hash
    c.save(tmp_path / "c.npz")
    back = Correction.load(tmp_path / "c.npz")
    assert back.hash == c.hash and np.array_equal(back.anchor, REFERENCE)


def test_cli_and_suites_accept_first_order(tmp_path, capsys):
    from bench.calibration import CalibrationSettings
    from bench.cli import build_parser, main
    from bench.experiment.spec import Treatment
    from bench.experiment.suite import load_suite

    parser = build_parser()
    ident = ["identify", "linear-shear", "--solver", "lm", "--correction"]
    assert parser.parse_args([*ident, "first-order"]).correction == "first-order"
    toml = tmp_path / "x.toml"
    toml.write_text("")
    args = parser.parse_args(["calibrate", str(toml), "--correction", "first-order"])
    assert args.correction == "first-order"
    assert CalibrationSettings("6,6,12:g8:hex27", correction="first-order").fine_mesh
    assert Treatment("first-order").name == "first-order"
    root = Path(__file__).resolve().parents[1]
    runs = load_suite(root / "suites" / "table1-first-order.toml").runs()
    assert sorted((r.case, r.treatment.name) for r in runs) == [
        ("exponent-shear", "first-order"),
        ("exponent-tension", "first-order"),
    ]
    assert main([*ident, "second-order"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "invalid choice: 'second-order'" in err
    with pytest.raises(ValueError, match="--correction 'second-order' is unknown; allowed: none"):
        CalibrationSettings(correction="second-order")


def test_first_order_fe_correction_matches_the_hifi_response_and_jacobian_at_its_anchor():
    """FE: inverse mesh 1,1,2 corrected with hifi 1,1,4 (data made on 2,2,4): at the anchor the
    corrected objective's residual and Jacobian are the hifi mesh's own (first-order
    consistency), and both runs with sensitivities are charged."""
    from problems.inverse.build import build_objective, model_pair
    from problems.inverse.cases import CASES
    from problems.inverse.data import make_data

    data = make_data("linear-compression", mesh="2,2,4", snapshots=2, tier="model-error")
    case = CASES["linear-compression"]
    hifi, inverse = model_pair(case, "1,1,2", "1,1,4", data)
    corr = first_order(hifi, inverse, case.start)
    assert (corr.n_hifi, corr.n_inverse) == (1, 1) and corr.hifi_wall_s > 0
    fixed = build_objective(case, mesh="1,1,2", data=data, correction=corr, hifi_mesh="1,1,4")
    direct = build_objective(case, mesh="1,1,4", data=data)
    z = fixed.to_scaled(case.start)
    got, want = fixed.evaluate(z, with_jacobian=True), direct.evaluate(z, with_jacobian=True)
    np.testing.assert_allclose(got.residual, want.residual, rtol=1e-9, atol=1e-9)
    scale = np.max(np.abs(want.jacobian))
    np.testing.assert_allclose(got.jacobian, want.jacobian, rtol=0, atol=1e-9 * scale)
    assert fixed.provenance["treatment"] == "first-order"
    assert fixed.charges["hifi"]["n"] == fixed.charges["inverse-for-correction"]["n"] == 1
    # away from the anchor the two differ (the inverse mesh's curvature is its own)
    z2 = z + 0.3 * (fixed.problem.upper_z - z)
    assert not np.allclose(fixed.residual(z2), direct.residual(z2), rtol=1e-6)

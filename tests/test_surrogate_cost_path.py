"""The surrogate's cost path: compiled exponential and GP mean (against long-double evaluations
within their rounding bounds), the material screen (classifies every point as the rule does),
the misfit in the space of the POD coefficients (against the whole residual for every whitening),
and the evaluator's use of it (same costs, counts, failures, cache and budget as the model's
call)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from problems.inverse.cases import CASES
from problems.inverse.evaluator import BudgetExhausted, Evaluator
from problems.inverse.problem import LeastSquaresProblem
from problems.inverse.reduced import AffineMisfit
from problems.materials.drucker_prager import validate_parameters
from problems.surrogate._kernels import EXP_REACH, PackedGP, exp_neg_array
from problems.surrogate.regression import GPComponent, GPFit
from problems.surrogate.screen import Screen

FE_CASES = [n for n, c in CASES.items() if not c.is_analytic]
EPS = np.finfo(float).eps


def test_exp_neg_is_exp_to_rounding():
    x = np.concatenate([np.linspace(0.0, EXP_REACH, 200_001), [1e-300, 1.0 / 128, EXP_REACH]])
    got = exp_neg_array(x)
    exact = np.exp(-x.astype(np.longdouble))
    assert float(np.max(np.abs(got / exact - 1))) <= 3 * EPS


def _gp(d=4, n=60, ls=(0.5, 0.8, 1.3), seed=0) -> GPFit:
    """A GP of shared training points: one component per length scale (the last of three
    outputs), with large alternating weights (the cancellation of an ill-conditioned GP)."""
    rng = np.random.default_rng(seed)
    X = rng.random((n, d))
    comps, r = [], 0
    for i, s in enumerate(ls):
        k = 3 if i == len(ls) - 1 else 1
        comps.append(
            GPComponent(
                np.arange(r, r + k),
                X,
                rng.normal(size=(n, k)) * 10.0 ** rng.uniform(0, 6, size=(n, 1)),
                rng.normal(size=k),
                rng.uniform(0.5, 3.0, size=k),
                float(rng.uniform(0.5, 2.0)),
                s * rng.uniform(0.7, 1.3, size=d),
                2.5,
            )
        )
        r += k
    return GPFit(tuple(comps), r)


def _long_double_mean(fit: GPFit, Z):
    """The GP mean in long double and the rounding bound ``sum |k alpha| y_std`` per output."""
    out = np.empty((len(Z), fit.n_outputs), dtype=np.longdouble)
    bound = np.empty_like(out)
    for c in fit.components:
        X = c.X.astype(np.longdouble)
        for p, z in enumerate(Z):
            diff = z.astype(np.longdouble) - X
            s = np.sqrt(np.longdouble(5)) * np.sqrt(
                np.sum(diff * diff / c.length_scale.astype(np.longdouble) ** 2, axis=1)
            )
            k = c.amplitude * (1 + s + s * s / 3) * np.exp(-s)
            out[p, c.outputs] = (k @ c.alpha) * c.y_std + c.y_mean
            bound[p, c.outputs] = (np.abs(k) @ np.abs(c.alpha)) * c.y_std
    return out, bound


@pytest.mark.parametrize("ls", [(0.5, 0.8, 1.3), (0.03, 0.8, 1.3)], ids=["table", "short-scales"])
def test_compiled_gp_mean_is_the_gp_mean_within_its_rounding_bound(ls):
    fit = _gp(ls=ls)
    packed = PackedGP.of(fit)
    assert packed is not None
    assert packed.args[-1] == (ls[0] > 0.1)  # short length scales: beyond the table's reach
    rng = np.random.default_rng(1)
    Z = np.vstack(
        [rng.random((40, 4)), rng.uniform(-0.5, 1.5, (20, 4)), np.eye(4), fit.components[0].X[:3]]
    )
    exact, bound = _long_double_mean(fit, Z)
    tol = 16 * EPS * bound + 16 * EPS * np.abs(exact)
    for got in (packed.mean(Z), fit.predict(Z)):  # the compiled mean and numpy's
        assert np.all(np.abs(got - exact) <= tol)
    # one point at a time is the batch, bit for bit
    assert np.array_equal(np.vstack([packed.mean(z) for z in Z[:5]]), packed.mean(Z[:5]))


def test_compiled_gp_mean_is_declined_for_other_kernels():
    fit = _gp()
    other = GPFit(
        tuple(
            GPComponent(
                *[
                    getattr(c, f)
                    for f in (
                        "outputs",
                        "X",
                        "alpha",
                        "y_mean",
                        "y_std",
                        "amplitude",
                        "length_scale",
                    )
                ],
                1.5,
            )
            for c in fit.components
        ),
        fit.n_outputs,
    )
    assert PackedGP.of(other) is None


def _case_points(case, rng, n=1500):
    lo, hi = case.lower, case.upper
    w = hi - lo
    inside = lo + rng.random((n, len(lo))) * w
    faces = lo + rng.integers(0, 2, (200, len(lo))) * w  # corners of the box
    wide = lo - 2 * w + rng.random((300, len(lo))) * 5 * w  # far outside, negative values too
    return np.vstack([inside, faces, wide, [case.reference]])


def _rule(case, x) -> bool:
    try:
        validate_parameters(case.form, case.hardening, case.material_parameters(x))
    except (ValueError, ZeroDivisionError, OverflowError):
        return False
    return True


@pytest.mark.parametrize("name", FE_CASES)
def test_screen_passes_only_points_the_rule_accepts(name):
    case = CASES[name]
    screen = Screen.of(case)
    assert screen is not None
    rng = np.random.default_rng(7)
    X = _case_points(case, rng)
    # points close to the form's boundary: bisect between an accepted and a rejected point
    rejected = [x for x in X[:1500] if not _rule(case, x)]
    near = []
    for x_bad in rejected[:20]:
        a, b = case.reference.copy(), x_bad.copy()
        for _ in range(60):
            mid = 0.5 * (a + b)
            a, b = (mid, b) if _rule(case, mid) else (a, mid)
        near += [a, b]
    X = np.vstack([X] + ([np.array(near)] if near else []))
    passed = screen(X)
    accepted = np.array([_rule(case, x) for x in X])
    assert not np.any(passed & ~accepted)  # never passes a point the rule rejects
    # and it is worth having: nearly every accepted point strictly inside the box passes
    # (the boundary points, last, aside)
    n = len(X) - len(near)
    strictly = accepted[:n] & np.all((X[:n] > case.lower) & (X[:n] < case.upper), axis=1)
    assert passed[:n][strictly].mean() > 0.99
    if near:
        assert not np.all(passed[-len(near) :])  # points at the boundary are left to the rule


def _problem(m=240, r=6, whitening="diagonal", seed=0):
    rng = np.random.default_rng(seed)
    c, B = rng.normal(size=m), rng.normal(size=(m, r))
    data = c + B @ rng.normal(size=r) + 0.1 * rng.normal(size=m)
    sigma = rng.uniform(0.05, 0.2, size=m)
    kw = {"sigma": sigma}
    if whitening == "low-rank":
        kw["covariance_factor"] = rng.normal(size=(m, 3)) * 0.3
    elif whitening == "full":
        V = rng.normal(size=(m, m)) * 0.01
        kw = {"covariance": np.diag(sigma**2) + V @ V.T}
    one = np.ones(1)
    return LeastSquaresProblem(None, data, -one, one, one, **kw), c, B


@pytest.mark.parametrize("whitening", ["diagonal", "low-rank", "full"])
def test_misfit_in_coefficient_space_is_the_whitened_misfit(whitening):
    problem, c, B = _problem(whitening=whitening)
    misfit = AffineMisfit.of(problem, c, B)
    A = np.random.default_rng(3).normal(size=(25, B.shape[1])) * [[1, 3, 0.1, 10, 1, 1]]
    for a, cost in zip(A, misfit.costs(A)):
        r = problem.whiten(problem.data - c - B @ a)
        assert cost == pytest.approx(r @ r, rel=1e-12)
        np.testing.assert_allclose(misfit.residual(a), r, rtol=0, atol=1e-10 * np.abs(r).max())
    # at the best coefficients only the part outside the basis remains
    best = np.linalg.lstsq(misfit.Bw, misfit.g0, rcond=None)[0]
    assert misfit.costs(best)[0] == pytest.approx(misfit.c_perp, rel=1e-10)
    with pytest.raises(ValueError, match="does not match"):
        AffineMisfit.of(problem, c[:-1], B[:-1])


@pytest.fixture(scope="module")
def shipped():
    """Small surrogates of the two cases' FE layouts (no FE run; the shipped ones may be absent:
    they are release artefacts, see docs/artefacts.md)."""
    from tests.test_surrogate_identify import fake_surrogate

    return {n: fake_surrogate(case=n) for n in ("hyperbolic-tension", "linear-shear")}


def _objectives(sur, name, **kw):
    from problems.inverse.build import build_objective
    from problems.surrogate.model import VectorisedMapper

    fast = build_objective(name, tier="consistent", forward=sur, mapper=VectorisedMapper(), **kw)
    plain = Evaluator(fast.problem, mapper=VectorisedMapper(), cost_path=False)
    return fast, plain


@pytest.mark.parametrize("name", ["hyperbolic-tension", "linear-shear"])
def test_evaluator_cost_path_equals_the_models_call(shipped, name):
    sur = shipped[name]
    fast, plain = _objectives(sur, name)
    assert fast._misfit is not None and plain._misfit is None
    rng = np.random.default_rng(5)
    Z = (sur.lower + rng.random((150, len(sur.names))) * (sur.upper - sur.lower)) / fast.reference
    Z = np.vstack([Z, Z[:5], fast.lower_z, fast.upper_z, 2 * fast.upper_z, np.full(6, np.nan)])
    a, b = fast.evaluate_many(Z), plain.evaluate_many(Z)
    for ea, eb in zip(a, b):
        assert (ea.ok, ea.feasible, ea.cached, ea.message) == (
            eb.ok,
            eb.feasible,
            eb.cached,
            eb.message,
        )
        assert ea.cost == pytest.approx(eb.cost, rel=1e-12)
        np.testing.assert_allclose(ea.residual, eb.residual, rtol=0, atol=1e-9 * math.sqrt(eb.cost))
    for k in ("n_evals", "n_failed", "n_infeasible", "n_cache_hits"):
        assert getattr(fast, k) == getattr(plain, k), k
    assert fast.best.cost == pytest.approx(plain.best.cost, rel=1e-12)
    if name == "hyperbolic-tension":
        assert fast.n_infeasible > 3  # the box holds points the material rule rejects
    # single points and the budget behave alike
    for ev in (fast, plain):
        ev.reset()
        ev.set_budget(3)
        with pytest.raises(BudgetExhausted):
            ev.evaluate_many(Z[10:15])
        assert ev.n_evals == 3 and len(ev.log) == 3
        ev.set_budget(None)
    assert fast.cost(Z[20]) == pytest.approx(plain.cost(Z[20]), rel=1e-12)


def test_a_failing_cost_path_falls_back_to_the_models_call(shipped):
    name = "hyperbolic-tension"
    fast, plain = _objectives(shipped[name], name)

    def broken(X):
        raise RuntimeError("boom")

    fast._misfit = type("Broken", (), {"__call__": staticmethod(broken)})()
    Z = np.vstack([fast.reference / fast.reference, fast.upper_z])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        a = fast.evaluate_many(Z)
    assert any("cost path failed" in str(w.message) for w in caught)
    b = plain.evaluate_many(Z)
    assert [(e.cost, e.feasible) for e in a] == [(e.cost, e.feasible) for e in b]
    assert fast._misfit is None


def test_surrogate_command_times_a_stored_surrogate_without_changing_it(
    shipped, tmp_path, capsys, monkeypatch
):
    import json

    from bench.cli import main
    from bench.experiment.surrogate_track import load_for
    from problems.surrogate.store import save

    save(shipped["linear-shear"], tmp_path / "linear-shear__coarse")
    monkeypatch.setenv("FEMUBENCH_SURROGATE_DIR", str(tmp_path))
    before = load_for("default", "linear-shear", "coarse").hash
    out = tmp_path / "t.json"
    assert main(["surrogate", "linear-shear", "--time", "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["hash"] == before == load_for("default", "linear-shear", "coarse").hash
    assert doc["clock"] == "cpu" and 0 < doc["misfit_batch_eval_s"] and 0 < doc["misfit_eval_s"]
    assert doc["misfit_eval_s"] < doc["surrogate_eval_s"] < doc["fe_eval_s"]
    assert doc["speed_ratio"] == pytest.approx(doc["fe_eval_s"] / doc["misfit_eval_s"])
    assert "one misfit evaluation" in capsys.readouterr().out

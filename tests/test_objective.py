"""The weighted least-squares objective: whitening, counting, cache, budget, failures, Jacobian,
mapper."""

from __future__ import annotations

import math
import pickle
from dataclasses import replace

import numpy as np
import pytest

from problems.inverse.evaluator import DEFAULT_JACOBIAN_COST, BudgetExhausted, Evaluator
from problems.inverse.problem import FAILURE_COST, LeastSquaresProblem
from problems.inverse.protocol import ForwardResult, RunModel
from tests.support import evaluator


class Quadratic:
    """U_N(x) = [x0, x1, x0 * x1, x0^2]; fails for x0 > 1.8, infeasible for x1 > 1.8."""

    names = ("x0", "x1")

    def __init__(self):
        self.calls = 0

    def check(self, x):
        return "x1 too large" if x[1] > 1.8 else None

    def values(self, x):
        return np.array([x[0], x[1], x[0] * x[1], x[0] ** 2])

    def jacobian(self, x):
        return np.array([[1.0, 0.0], [0.0, 1.0], [x[1], x[0]], [2 * x[0], 0.0]])

    def __call__(self, x):
        self.calls += 1
        if x[0] > 1.8:
            return ForwardResult(False, None, "did not converge")
        return ForwardResult(True, self.values(x))


def make(sigma=None, covariance=None, **kw):
    model = Quadratic()
    data = model.values(np.array([1.0, 1.0])) + np.array([0.01, -0.02, 0.03, 0.0])
    obj = evaluator(
        model,
        data,
        lower=[0.5, 0.5],
        upper=[2.0, 2.0],
        reference=[1.0, 1.0],
        sigma=sigma,
        covariance=covariance,
        **kw,
    )
    return obj, model


class CountingMapper:
    def __init__(self):
        self.calls = 0
        self.items = 0

    def __call__(self, fn, items):
        self.calls += 1
        self.items += len(items)
        return [fn(x) for x in items]


def test_cost_is_whitened_sum_of_squares():
    obj, model = make(sigma=[0.1, 0.2, 0.1, 0.5])
    x = np.array([1.2, 0.9])
    d = obj.data - model.values(x)
    expected = float(np.sum((d / np.array([0.1, 0.2, 0.1, 0.5])) ** 2))
    assert obj.cost(x) == pytest.approx(expected, rel=1e-14)
    assert obj.residual(x) @ obj.residual(x) == pytest.approx(expected, rel=1e-14)


def test_full_covariance_matches_diagonal_when_diagonal():
    s = np.array([0.1, 0.2, 0.1, 0.5])
    diag, _ = make(sigma=s)
    full, _ = make(covariance=np.diag(s**2))
    z = np.array([1.3, 0.7])
    np.testing.assert_allclose(full.residual(z), diag.residual(z), rtol=1e-13)
    assert full.cost(z) == pytest.approx(diag.cost(z), rel=1e-13)


def test_full_covariance_cost_is_mahalanobis_distance():
    rng = np.random.default_rng(0)
    B = rng.standard_normal((4, 4))
    C = B @ B.T + 4 * np.eye(4)
    obj, model = make(covariance=C)
    z = np.array([1.1, 1.4])
    d = obj.data - model.values(z)
    assert obj.cost(z) == pytest.approx(float(d @ np.linalg.solve(C, d)), rel=1e-12)


def test_cost_split_sums_to_total():
    obj, _ = make(sigma=0.1, blocks={"first": slice(0, 2), "second": slice(2, 4)})
    split = obj.cost_split(np.array([1.2, 0.9]))
    assert split["first"] + split["second"] == pytest.approx(split["total"], rel=1e-14)
    assert split["first"] > 0 and split["second"] > 0


def test_scaling_and_bounds():
    model = Quadratic()
    obj = evaluator(
        model,
        model.values(np.array([2.0, 3.0])),
        lower=[1.0, 1.5],
        upper=[4.0, 6.0],
        reference=[2.0, 3.0],
    )
    np.testing.assert_allclose(obj.lower_z, [0.5, 0.5])
    np.testing.assert_allclose(obj.upper_z, [2.0, 2.0])
    np.testing.assert_allclose(obj.to_physical([1.5, 0.5]), [3.0, 1.5])
    np.testing.assert_allclose(obj.to_scaled([3.0, 1.5]), [1.5, 0.5])
    assert obj.n_params == 2 and obj.n_residuals == 4 and obj.names == ("x0", "x1")


def test_counting_repeats_charged_cache_hits_apart():
    obj, model = make()
    assert obj.repeats_rule == "charged"
    z = np.array([1.1, 0.9])
    c1 = obj.cost(z)
    c2 = obj.cost(z.copy())  # a repeat: served from the cache, but a call: charged
    assert c1 == c2
    assert (obj.n_evals, obj.n_cache_hits, obj.n_repeats, model.calls) == (2, 1, 1, 1)
    assert [e["cached"] for e in obj.log] == [False, True]
    assert [e["charged"] for e in obj.log] == [True, True]
    costs = obj.costs([z, z, [1.2, 0.9], [1.2, 0.9]])  # two hits from before, one new + its repeat
    assert (obj.n_evals, obj.n_cache_hits, obj.n_repeats, model.calls) == (6, 4, 4, 2)
    assert costs[0] == costs[1] == c1 and costs[2] == costs[3] != c1
    assert obj.nominal_equivalents() == 6
    obj.evaluate(z, reuse=True)  # the wrapper asking again for what it holds: free
    assert (obj.n_evals, obj.n_cache_hits) == (6, 5)


def test_free_repeats_restore_fe_economy():
    obj, model = make(free_repeats=True)
    assert obj.repeats_rule == "free"
    z = np.array([1.1, 0.9])
    c1 = obj.cost(z)
    c2 = obj.cost(z.copy())
    assert c1 == c2
    assert (obj.n_evals, obj.n_cache_hits, obj.n_repeats, model.calls) == (1, 1, 0, 1)
    assert [e["charged"] for e in obj.log] == [True, False]
    costs = obj.costs([z, z, [1.2, 0.9], [1.2, 0.9]])  # two hits from before, one new + its repeat
    assert (obj.n_evals, obj.n_cache_hits, model.calls) == (2, 4, 2)
    assert costs[0] == costs[1] == c1 and costs[2] == costs[3] != c1


def test_charged_repeats_stop_at_the_budget():
    obj, model = make()
    obj.set_budget(3)
    z = np.array([1.1, 0.9])
    obj.cost(z)
    with pytest.raises(BudgetExhausted):
        obj.costs([z, z, z])  # two repeats fit, the third does not
    assert (obj.n_evals, obj.n_repeats, model.calls) == (3, 2, 1)
    obj, model = make(free_repeats=True)
    obj.set_budget(1)
    obj.cost(z)
    assert len(obj.costs([z, z, z])) == 3 and obj.n_evals == 1  # free: never exhausted


def test_trace_is_exact_per_evaluation():
    obj, _ = make()
    obj.costs([[1.5, 1.5], [1.2, 0.9], [1.4, 1.4], [1.0, 1.0], [1.0, 1.0]])
    costs = [e["cost"] for e in obj.log]
    assert [n for n, _ in obj.trace] == [1, 2, 4]
    best = np.minimum.accumulate(costs)
    for n, c in obj.trace:
        assert c == best[n - 1]


def test_cache_off_counts_every_call():
    obj, model = make(cache=False)
    for _ in range(3):
        obj.cost([1.1, 0.9])
    assert (obj.n_evals, obj.n_cache_hits, model.calls) == (3, 0, 3)


def test_infeasible_counted_not_run_and_failed_counted():
    obj, model = make()
    ev = obj.evaluate([1.0, 1.9])  # x1 > 1.8: check() rejects it
    assert not ev.feasible and ev.cost == FAILURE_COST and "x1 too large" in ev.message
    assert model.calls == 0 and obj.n_evals == 1 and obj.n_infeasible == 1
    ev = obj.evaluate([1.9, 1.0])  # x0 > 1.8: the model fails
    assert ev.feasible and not ev.ok and ev.cost == FAILURE_COST
    assert model.calls == 1 and obj.n_evals == 2 and obj.n_failed == 1
    # the failure residual has squared norm FAILURE_COST (a trust region then rejects the step)
    assert ev.residual @ ev.residual == pytest.approx(FAILURE_COST, rel=1e-12)
    assert obj.best is None
    ev = obj.evaluate([2.5, 1.0])  # outside the box: infeasible, counted, not run
    assert (
        not ev.feasible
        and "outside the bounds" in ev.message
        and model.calls == 1
        and obj.n_infeasible == 2
    )


def test_model_exception_becomes_failure():
    class Raising(Quadratic):
        def __call__(self, x):
            raise ZeroDivisionError("boom")

    obj = evaluator(Raising(), np.zeros(4), lower=[0.5, 0.5], upper=[2, 2], reference=[1, 1])
    with pytest.warns(RuntimeWarning, match="boom"):
        ev = obj.evaluate([1.0, 1.0])
    assert not ev.ok and ev.cost == FAILURE_COST and obj.n_failed == 1


def test_best_tracks_lowest_successful_point():
    obj, _ = make()
    obj.costs([[1.5, 1.5], [1.0, 1.0], [1.9, 1.0], [1.2, 1.2]])
    assert obj.best.cost == pytest.approx(obj.cost([1.0, 1.0]))
    np.testing.assert_allclose(obj.best.x, [1.0, 1.0])


def test_budget_single_and_batch():
    obj, model = make()
    obj.set_budget(3)
    obj.cost([1.0, 1.0])
    obj.evaluate([1.0, 1.0], reuse=True)  # a reuse: free
    with pytest.raises(BudgetExhausted):
        obj.costs([[1.1, 1.0], [1.2, 1.0], [1.3, 1.0], [1.4, 1.0]])
    # the two points that fitted were evaluated and recorded, in order
    assert obj.n_evals == 3 and model.calls == 3
    np.testing.assert_allclose([e["x"][0] for e in obj.log if not e["cached"]], [1.0, 1.1, 1.2])
    assert obj.evaluate([1.2, 1.0], reuse=True).cost > 0  # still served from the cache
    with pytest.raises(BudgetExhausted):
        obj.cost([1.2, 1.0])  # a repeat is a call: it needs budget
    assert obj.n_evals == 3


def test_infeasible_points_are_charged_to_the_budget():
    obj, model = make()
    obj.set_budget(2)
    obj.costs([[1.0, 1.9], [1.0, 1.95]])
    with pytest.raises(BudgetExhausted):
        obj.cost([1.0, 1.0])
    assert model.calls == 0 and obj.n_evals == 2


def test_fd_jacobian_matches_analytic_and_columns_are_counted():
    obj, model = make(sigma=[0.1, 0.2, 0.1, 0.5])
    z = np.array([1.3, 0.7])
    J_exact = -(model.jacobian(z) / np.array([0.1, 0.2, 0.1, 0.5])[:, None])
    obj.evaluate(z)
    n0 = obj.n_evals
    J = obj.jacobian(z)
    assert obj.n_evals - n0 == 2  # one forward-difference column per parameter, r0 from the cache
    np.testing.assert_allclose(J, J_exact, rtol=1e-5, atol=1e-6 * np.abs(J_exact).max())
    Jc = obj.jacobian(z, scheme="central", rel_step=1e-5)
    assert obj.n_evals - n0 == 6
    np.testing.assert_allclose(Jc, J_exact, rtol=1e-8, atol=1e-8 * np.abs(J_exact).max())


def test_fd_steps_flipped_inward_at_the_bound():
    obj, model = make()
    z = np.array([2.0, 0.5])  # upper bound in x0, lower bound in x1
    J = obj.jacobian(z)
    inside = [e["x"] for e in obj.log if not e["cached"]]
    assert all(np.all(x >= obj.lower) and np.all(x <= obj.upper) for x in inside)
    assert obj.n_infeasible == 0
    # x0 = 2 > 1.8 lies in the failing region: r0 failed -> zero Jacobian, no columns evaluated
    assert np.all(J == 0) and obj.n_evals == 1
    J = obj.jacobian(np.array([1.8, 0.5]), scheme="central")
    np.testing.assert_allclose(J[0, 0], -1.0, rtol=1e-5)  # one-sided inward at x0 = 1.8 (+h fails)


def test_mapper_called_once_per_batch():
    mapper = CountingMapper()
    obj, _ = make(mapper=mapper)
    # 2 new feasible, 1 infeasible, 1 repeat
    obj.costs([[1.0, 1.0], [1.1, 1.0], [1.0, 1.9], [1.0, 1.0]])
    assert (mapper.calls, mapper.items) == (1, 2)
    obj.jacobian(np.array([1.0, 1.0]))
    assert (mapper.calls, mapper.items) == (2, 4)
    obj.costs([[1.0, 1.0]])  # all cached: no mapper call
    assert mapper.calls == 2


def test_model_and_worker_function_pickle():
    obj, _ = make()
    fn = pickle.loads(pickle.dumps(RunModel(obj.model)))
    res = fn(np.array([1.0, 1.0]))
    assert res.ok and res.wall_s >= 0
    np.testing.assert_allclose(res.values, [1.0, 1.0, 1.0, 1.0])


def test_invalid_inputs_raise_value_error():
    model = Quadratic()
    with pytest.raises(ValueError, match="not both"):
        evaluator(
            model,
            np.zeros(4),
            lower=[0, 0],
            upper=[1, 1],
            reference=[1, 1],
            sigma=1.0,
            covariance=np.eye(4),
        )
    with pytest.raises(ValueError, match="positive definite"):
        evaluator(
            model, np.zeros(4), lower=[0, 0], upper=[1, 1], reference=[1, 1], covariance=-np.eye(4)
        )
    with pytest.raises(ValueError, match="non-zero"):
        evaluator(model, np.zeros(4), lower=[0, 0], upper=[1, 1], reference=[0, 1])
    obj, _ = make()
    with pytest.raises(ValueError, match="expected 2"):
        obj.cost([1.0, 1.0, 1.0])
    assert math.isinf(obj.remaining)


class ExactQuadratic(Quadratic):
    """Quadratic with exact sensitivities: ``model(x, jacobian=True)`` returns dU/dx too."""

    provides_jacobian = True

    def __call__(self, x, jacobian=False):
        res = super().__call__(x)
        if jacobian and res.ok:
            return ForwardResult(True, res.values, jacobian=self.jacobian(x), wall_s=3.0)
        return ForwardResult(res.ok, res.values, res.message, wall_s=1.0)


def test_exact_jacobian_is_used_and_charged_as_one_run_in_forward_equivalents():
    model = ExactQuadratic()
    data = model.values(np.array([1.0, 1.0])) + np.array([0.01, -0.02, 0.03, 0.0])
    obj = evaluator(
        model,
        data,
        lower=[0.5, 0.5],
        upper=[2.0, 2.0],
        reference=[2.0, 1.0],
        sigma=[0.1, 0.2, 0.1, 0.5],
    )
    assert obj.exact_jacobian
    z = np.array([0.6, 1.1])
    obj.cost(z + 0.01)  # one plain run: 1 s, the forward-equivalent unit
    J = obj.jacobian(z)
    x = obj.to_physical(z)
    expected = -model.jacobian(x) / np.array([0.1, 0.2, 0.1, 0.5])[:, None] * np.array([2.0, 1.0])
    np.testing.assert_allclose(J, expected, rtol=1e-14)
    fd = evaluator(
        Quadratic(),
        data,
        lower=[0.5, 0.5],
        upper=[2.0, 2.0],
        reference=[2.0, 1.0],
        sigma=[0.1, 0.2, 0.1, 0.5],
    ).jacobian(z, scheme="central", rel_step=1e-6)
    np.testing.assert_allclose(J, fd, rtol=1e-6, atol=1e-8)
    assert obj.n_evals == 2  # the run with sensitivities is one evaluation ...
    assert obj.forward_equivalents() == pytest.approx(1.0 + 3.0)  # ... costing 3 plain runs
    assert obj.log[-1]["kind"] == "jacobian"
    obj.jacobian(z)  # cached with its Jacobian: no new run, and a reuse: free
    assert obj.n_evals == 2 and obj.n_cache_hits == 1
    cost, grad = obj.gradient(z, reuse=True)
    np.testing.assert_allclose(grad, 2.0 * J.T @ obj.residual(z), rtol=1e-14)
    assert obj.n_evals == 3  # the residual(z) call is a repeat: charged


def test_low_rank_plus_diagonal_covariance_whitens_like_the_full_one():
    rng = np.random.default_rng(3)
    m, k = 40, 3
    sigma = rng.uniform(0.5, 2.0, m)
    V = rng.normal(size=(m, k))
    d = rng.normal(size=m)
    ref = np.ones(2)
    full = LeastSquaresProblem(
        Quadratic(), np.zeros(m), [0.5, 0.5], [2, 2], ref, covariance=np.diag(sigma**2) + V @ V.T
    )
    low = LeastSquaresProblem(
        Quadratic(), np.zeros(m), [0.5, 0.5], [2, 2], ref, sigma=sigma, covariance_factor=V
    )
    cinv = np.linalg.inv(np.diag(sigma**2) + V @ V.T)
    assert low.whiten(d) @ low.whiten(d) == pytest.approx(d @ cinv @ d, rel=1e-12)
    assert full.whiten(d) @ full.whiten(d) == pytest.approx(d @ cinv @ d, rel=1e-12)
    D = rng.normal(size=(m, 2))
    np.testing.assert_allclose(low.whiten(D)[:, 1], low.whiten(D[:, 1]), rtol=1e-13)
    with pytest.raises(ValueError, match="covariance_factor"):
        LeastSquaresProblem(
            Quadratic(),
            np.zeros(m),
            [0.5, 0.5],
            [2, 2],
            ref,
            covariance=np.eye(m),
            covariance_factor=V,
        )


def test_charges_survive_reset_and_convert_to_forward_equivalents():
    model = ExactQuadratic()
    obj = evaluator(model, np.zeros(4), lower=[0.5, 0.5], upper=[2.0, 2.0], reference=[1.0, 1.0])
    obj.charge("hifi", 2, 10.0)  # two high-fidelity runs, 5 s each
    obj.reset()
    obj.costs([[1.0, 1.0], [1.1, 1.0]])  # plain runs of 1 s each
    assert obj.charges == {"hifi": {"n": 2, "wall_s": 10.0}}
    assert obj.charged_equivalents() == {"hifi": pytest.approx(10.0)}


def test_observers_see_every_recorded_evaluation():
    obj, _ = make()
    seen = []
    obj.observers.append(lambda ev_, e: seen.append((ev_.n_evals, e.cached)))
    obj.costs([[1.0, 1.0], [1.1, 1.0], [1.0, 1.0]])
    assert seen == [(1, False), (2, False), (3, True)]


def exact_objective(**kw):
    model = ExactQuadratic()
    data = model.values(np.array([1.0, 1.0])) + np.array([0.01, -0.02, 0.03, 0.0])
    problem = LeastSquaresProblem(
        model, data, lower=[0.5, 0.5], upper=[2.0, 2.0], reference=[1.0, 1.0]
    )
    return Evaluator(problem, **kw), model


def test_nominal_forward_equivalents_charge_the_declared_jacobian_cost():
    """Deterministic: plain and infeasible runs 1, a run with sensitivities jacobian_cost, cache
    hits 0 -- whatever the measured wall times (3 s against 1 s here)."""
    obj, model = exact_objective()
    assert obj.jacobian_cost == DEFAULT_JACOBIAN_COST  # ExactQuadratic declares none
    ExactQuadratic.jacobian_cost = 1.6
    try:
        obj, _ = exact_objective()
        obj2, _ = exact_objective(jacobian_cost=2.5)
    finally:
        del ExactQuadratic.jacobian_cost
    assert obj.jacobian_cost == 1.6 and obj2.jacobian_cost == 2.5
    obj.cost([1.0, 1.0])
    obj.jacobian([1.1, 1.0])
    obj.jacobian([1.1, 1.0])  # cache hit with its Jacobian
    obj.cost([1.0, 1.9])  # infeasible: not run, charged 1
    obj.jacobian([1.2, 1.0])
    assert obj.n_evals == 4 and obj.n_cache_hits == 1 and obj.n_jacobian_runs == 2
    assert obj.nominal_equivalents() == pytest.approx(1 + 1.6 + 1 + 1.6)
    assert obj.forward_equivalents() == pytest.approx(1 + 3 + 1 + 3)  # measured, as before
    assert obj.counters()["nominal_equivalents"] == pytest.approx(5.2)
    for bad in (0.5, float("nan")):
        with pytest.raises(ValueError, match="jacobian_cost"):
            exact_objective(jacobian_cost=bad)
    with pytest.raises(ValueError, match="budget_unit = 'runs' is unknown; allowed: evaluations"):
        exact_objective(budget_unit="runs")


def test_budget_in_forward_equivalents_caps_the_nominal_charge():
    ExactQuadratic.jacobian_cost = 1.6
    try:
        obj, _ = exact_objective(budget_unit="forward-equivalents")
    finally:
        del ExactQuadratic.jacobian_cost
    obj.set_budget(4.5)
    obj.jacobian([1.0, 1.0])  # 1.6
    obj.jacobian([1.1, 1.0])  # 3.2
    assert obj.spent == pytest.approx(3.2) and obj.remaining == 1  # one plain run still fits
    with pytest.raises(BudgetExhausted, match="4.5 forward-equivalents"):
        obj.jacobian([1.2, 1.0])  # 4.8 > 4.5: not run
    assert obj.n_evals == 2
    obj.cost([1.2, 1.0])  # a plain run fits: 4.2
    assert obj.remaining == 0 and obj.spent == pytest.approx(4.2)
    # a batch: the points that fit are evaluated first
    obj.set_budget(6.2)
    with pytest.raises(BudgetExhausted):
        obj.costs(np.array([[0.6, 0.6], [0.7, 0.7], [0.8, 0.8]]))
    assert obj.n_evals == 5 and obj.spent == pytest.approx(6.2)
    # the same sequence counted in evaluations
    ev, _ = exact_objective()
    ev.set_budget(3)
    ev.jacobian([1.0, 1.0])
    ev.jacobian([1.1, 1.0])
    ev.cost([1.2, 1.0])
    assert ev.spent == 3 and ev.remaining == 0


def test_finite_difference_jacobians_when_exact_ones_are_declined():
    obj, model = exact_objective(exact_jacobian=False)
    assert not obj.exact_jacobian
    J = obj.jacobian([1.0, 1.0], scheme="central", rel_step=1e-6)
    assert obj.n_evals == 5 and obj.n_jacobian_runs == 0  # 1 + 2 n plain runs
    assert obj.nominal_equivalents() == 5.0
    exact, _ = exact_objective()
    np.testing.assert_allclose(J, exact.jacobian([1.0, 1.0]), rtol=1e-7, atol=1e-9)


def test_measured_forward_equivalents_without_a_plain_run_use_the_nominal_price():
    obj, _ = exact_objective(jacobian_cost=1.7)
    obj.evaluate([1.0, 1.0], with_jacobian=True)
    obj.evaluate([1.1, 1.0], with_jacobian=True)
    assert obj.forward_equivalents() == pytest.approx(3.4)  # no plain run measured
    obj.cost([1.2, 1.0])  # 1 s: the unit; the runs with sensitivities took 3 s
    assert obj.forward_equivalents() == pytest.approx(3 + 3 + 1)


class TimedExactQuadratic(ExactQuadratic):
    """Reports the plain part of its runs with sensitivities: 2 s of their 3 s."""

    def __call__(self, x, jacobian=False):
        res = super().__call__(x, jacobian)
        return replace(res, plain_wall_s=2.0) if jacobian else res


def test_measured_forward_equivalents_of_jacobian_runs_against_their_own_plain_part():
    data = np.zeros(4)
    problem = LeastSquaresProblem(
        TimedExactQuadratic(), data, lower=[0.5, 0.5], upper=[2.0, 2.0], reference=[1.0, 1.0]
    )
    obj = Evaluator(problem, jacobian_cost=1.7)
    obj.evaluate([1.0, 1.0], with_jacobian=True)
    obj.evaluate([1.1, 1.0], with_jacobian=True)
    assert obj.forward_equivalents() == pytest.approx(2 * 1.5)  # 3 s / 2 s each
    assert obj.nominal_equivalents() == pytest.approx(2 * 1.7)
    obj.cost([1.2, 1.0])  # a plain run (1 s) is the unit again, as before
    assert obj.forward_equivalents() == pytest.approx(3 + 3 + 1)

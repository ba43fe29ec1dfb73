"""Fairness of the comparison (issue 27): every call charged, wrappers as strong as their
libraries, statuses from an optimality test, infinite bounds, fair multistart budgets."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from problems.benchmarks import nist
from problems.inverse.analytic import ANALYTIC_CASES, analytic_objective
from problems.inverse.evaluator import Evaluator
from problems.inverse.protocol import ForwardResult
from problems.user import correct_digits
from solvers import METHODS, solve
from tests.support import evaluator

SMOOTH = ANALYTIC_CASES["analytic-smooth"]


@pytest.fixture(autouse=True)
def _quiet():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        yield


class Counting:
    """values = x (identity), counting the model's runs."""

    names = ("a", "b")

    def __init__(self):
        self.calls = 0

    def check(self, x):
        return None

    def __call__(self, x):
        self.calls += 1
        return ForwardResult(True, np.array(x, float))


def _identity(data, lower, upper, **kw):
    model = Counting()
    data = np.asarray(data, float)
    obj = evaluator(model, data, lower=lower, upper=upper, reference=[1.0, 1.0], **kw)
    return obj, model


def test_repeats_are_charged_to_a_method_that_reproposes_points():
    """ESCH re-proposes points (11 751 proposals on a "5 000" budget before); every call counts
    (COCO's rule), the model runs once per distinct point, free_repeats gives the FE economy."""
    obj, model = _identity([0.3, 0.7], [0.0, 0.0], [1.0, 1.0])
    res = solve(obj, "nlopt:ESCH", budget=300, seed=0)
    assert res.repeats == "charged" and res.n_evals == 300
    assert res.n_repeats > 0 and model.calls == res.n_evals - res.n_repeats
    free, fmodel = _identity([0.3, 0.7], [0.0, 0.0], [1.0, 1.0], free_repeats=True)
    res_free = solve(free, "nlopt:ESCH", budget=300, seed=0)
    assert res_free.repeats == "free" and res_free.n_repeats == 0
    assert fmodel.calls == res_free.n_evals == 300 and res_free.n_cache_hits > 0
    # the exact trace: best-so-far after every charged evaluation
    costs = [e["cost"] for e in obj.log if e["charged"]]
    best = np.minimum.accumulate(costs)
    assert res.trace[0][0] == 1 and all(c == best[n - 1] for n, c in res.trace)
    improved = np.flatnonzero(np.diff(best, prepend=np.inf) < 0)
    assert [n for n, _ in res.trace] == [i + 1 for i in improved]


def test_sa_local_search_stays_in_the_box():
    """The optimum sits on the box's corner: scipy's L-BFGS-B gets the box (scipy adds it only
    to empty minimizer_kwargs), so no out-of-box point is ever charged, and the corner is found."""
    obj, _ = _identity([3.0, -2.0], [0.0, 0.0], [2.0, 2.0])
    res = solve(obj, "sa", budget=400, seed=1, x0=[1.0, 1.0])
    assert res.n_infeasible == 0 and res.n_evals <= 400
    assert res.x == pytest.approx([2.0, 0.0], abs=1e-9)


def test_sa_defaults_equal_scipys():
    import inspect

    from scipy.optimize import dual_annealing

    sig = inspect.signature(dual_annealing).parameters
    o = METHODS["sa"].options
    for k in ("maxiter", "initial_temp", "restart_temp_ratio", "visit", "accept"):
        assert o[k].default == sig[k].default, k


def test_fd_steps_are_relative_so_small_parameters_keep_their_digits():
    """b2 of Misra1a is 5.5e-4 with reference 1: a step relative to |z| (scipy's sqrt(eps))
    differences it as accurately as b1 = 239; max(|z|, 1) would step it by 3 % of its value."""
    ev = Evaluator(nist.problem("Misra1a"))
    z = nist.certified("Misra1a")
    J = ev.jacobian(z)
    Jc = ev.jacobian(z, scheme="central", rel_step=1e-5)
    err = np.abs(J - Jc).max(axis=0) / np.abs(Jc).max(axis=0)
    assert err.max() < 1e-6, err
    assert ev.fd_rel_step("forward") == pytest.approx(np.sqrt(np.finfo(float).eps))
    assert ev.fd_rel_step("central") == pytest.approx(np.cbrt(np.finfo(float).eps))


@pytest.mark.parametrize("method", ["gauss-newton", "lm", "trf", "lm-minpack"])
def test_statuses_on_hard_nist_starts(method):
    """No run reports converged without >= 2 correct digits, on the hard starts where the
    libraries' own stops lied (MGH10 s1: exp underflow, a flat region at cost 3.9e9; MGH17 s1
    and Rat43 s1: a rank-deficient point; MGH09 s1), and converged runs have a small step."""
    for name in ("MGH10", "MGH17", "Rat43", "MGH09"):
        ev = Evaluator(nist.problem(name, 1))
        res = solve(ev, method, budget=400, x0=nist.start(name, 1))
        digits = correct_digits(res.x, nist.certified(name))
        if res.status == "converged":
            assert digits >= 2, (method, name, res.message)
            assert res.extra["optimality_step"] <= 1e-4
        else:
            assert not res.success


def test_gauss_newton_converges_at_the_optimum_and_stalls_on_a_flat_region():
    ev = Evaluator(nist.problem("Misra1a"))
    res = solve(ev, "gauss-newton", budget=50, x0=nist.certified("Misra1a"))
    assert res.status == "converged" and res.success, res.message
    assert res.n_evals <= 5  # the start, its two columns, a step or two that cannot improve
    flat = solve(Evaluator(nist.problem("MGH10", 1)), "gauss-newton", budget=50, x0=[2, 4e5, 2.5e4])
    assert flat.status == "stalled" and not flat.success and flat.cost > 1e9, flat.message


# every method on a problem with infinite bounds: the local ones run, the others refuse
INFINITE_OK = ["lm", "trf", "lm-minpack", "gauss-newton", "nlopt:BOBYQA", "nlopt:NELDERMEAD",
               "nlopt:SBPLX", "nlopt:COBYLA", "nlopt:LBFGS"]  # fmt: skip


@pytest.mark.parametrize("method", sorted(METHODS))
def test_infinite_bounds_per_method(method):
    p = nist.problem("Misra1a", 2)
    if METHODS[method].family == "local":
        res = solve(Evaluator(p), method, budget=60, x0=nist.start("Misra1a", 2))
        assert np.all(np.isfinite(res.x)) and res.status != "failed", res.message
        assert res.cost < 10.0 * Evaluator(p).cost(nist.start("Misra1a", 2))
        assert method in INFINITE_OK
    else:
        with pytest.raises(ValueError) as info:
            solve(Evaluator(p), method, budget=60, x0=nist.start("Misra1a", 2))
        text = str(info.value)
        assert "needs finite bounds" in text and "b1 has [-inf, inf]" in text and "\n" not in text


def test_default_start_with_infinite_bounds_and_minpack_refuses_a_box():
    from problems.user import least_squares

    def model(x):
        return np.array([x[0] - 3.0, x[1] - 4.0, x[0] * x[1] - 12.0])

    p = least_squares(model, np.zeros(3), [0.0, -np.inf], [10.0, np.inf], reference=[1.0, 2.0])
    res = solve(Evaluator(p), "lm", budget=100)  # x0 = None: (5, 2) (centre; reference)
    assert res.x0 == [5.0, 2.0] and res.status == "converged"
    assert res.x == pytest.approx([3.0, 4.0], rel=1e-6)
    with pytest.raises(ValueError, match="lm-minpack: MINPACK's Levenberg-Marquardt cannot honour"):
        solve(Evaluator(p), "lm-minpack", budget=100)
    with pytest.raises(ValueError, match="x0 must be finite"):
        solve(Evaluator(p), "lm", budget=100, x0=[np.nan, 1.0])


def test_multistart_gives_the_first_start_the_whole_budget_and_succeeds_only_converged():
    """The first start of multistart-lm follows a single lm run step for step (it may use all the
    budget, not budget/5); with too small a budget it is not a success."""
    single = solve(analytic_objective("analytic-smooth"), "lm", budget=60, x0=SMOOTH.start)
    assert single.status == "converged"
    ms = solve(analytic_objective("analytic-smooth"), "multistart-lm", budget=60, seed=0,
               x0=SMOOTH.start)  # fmt: skip
    first = ms.extra["starts"][0]
    assert first["n_evals"] == single.n_evals > 60 // 5
    assert first["x"] == single.x and first["status"] == "converged"
    assert ms.status == "converged" and ms.success
    short = solve(analytic_objective("analytic-smooth"), "multistart-lm", budget=4, seed=0,
                  x0=SMOOTH.start)  # fmt: skip
    assert short.status == "budget" and not short.success


@pytest.mark.parametrize("budget", [1, 29])
def test_minpack_keeps_the_budget_and_counts_match(budget):
    ev = Evaluator(nist.problem("MGH09", 1))
    res = solve(ev, "lm-minpack", budget=budget, x0=nist.start("MGH09", 1))
    assert res.n_evals == budget and res.status == "budget" and not res.success
    assert res.n_evals == sum(1 for e in ev.log if e["charged"])


def test_a_suite_sets_free_repeats_and_its_records_say_so():
    """``free_repeats = true`` in a suite reaches the evaluator and the record; left at its
    default it changes no run's hash (records of earlier suites stay valid)."""
    from bench.experiment.runner import run_one
    from bench.experiment.spec import config_hash
    from bench.experiment.suite import parse_suite

    raw = {"suite": {"name": "t", "cases": ["analytic-smooth"], "methods": ["nlopt:ESCH"],
                     "budgets": [120], "seeds": [0]}}  # fmt: skip
    charged = parse_suite(raw).runs()[0]
    raw["suite"]["free_repeats"] = True
    free = parse_suite(raw).runs()[0]
    assert free.free_repeats and not charged.free_repeats
    assert "free_repeats" not in charged.to_dict() and config_hash(free) != config_hash(charged)
    rec_c, rec_f = run_one(charged), run_one(free)
    assert rec_c["result"]["repeats"] == "charged" and rec_f["result"]["repeats"] == "free"
    assert rec_c["result"]["n_repeats"] > 0 and rec_f["result"]["n_repeats"] == 0
    assert rec_f["result"]["n_cache_hits"] > 0 and rec_f["result"]["n_evals"] == 120
    with pytest.raises(ValueError, match="free_repeats = 'yes' is not true/false"):
        raw["suite"]["free_repeats"] = "yes"
        parse_suite(raw)


def test_least_squares_start_strictly_inside_keeps_the_box_relative_margin():
    # a finite box: the margin 1e-10 * (hi - lo) lm's shipped records were made with (a start on
    # a bound of the default suite, e.g. hyperbolic-tension, moved by scipy's rule instead took
    # 9 evaluations where its record says 7); a half-infinite bound: scipy's own rule
    from scipy.optimize._lsq.common import make_strictly_feasible

    from solvers.scipy_ import strictly_inside

    lo, hi = np.array([0.5, 0.5, 0.0, -np.inf]), np.array([1.5, 1.5, np.inf, 2.0])
    z = np.array([0.5, 1.5, 0.0, 2.0])
    got = strictly_inside(z, lo, hi)
    assert got[0] == 0.5 + 1e-10 and got[1] == 1.5 - 1e-10  # box-relative, not 1e-10 * |bound|
    box = np.isfinite(lo) & np.isfinite(hi)
    assert np.array_equal(got[box], np.clip(z, lo + 1e-10 * (hi - lo), hi - 1e-10 * (hi - lo))[box])
    assert np.array_equal(got[~box], make_strictly_feasible(z, lo, hi)[~box])
    assert np.array_equal(make_strictly_feasible(got, lo, hi)[[0, 2, 3]], got[[0, 2, 3]])


def _bound_problem():
    """x1 starts on its lower bound 1 and the gradient and the Gauss-Newton step both push it
    out: the bounded minimum is (0.5, 1)."""
    from problems.user import least_squares

    def model(x):
        return np.array([x[0], x[1], x[0] + 10.0 * x[1]])

    return least_squares(model, np.array([3.0, 0.5, 8.0]), [0.0, 1.0], [10.0, 2.0])


def test_lm_start_on_a_bound_is_not_a_stall():
    """The failure mode of hyperbolic-tension's untreated Table 1 run (pt0 starts on its lower
    bound; LM stopped at the start with ``xtol`` after 2 evaluations): dogbox from a start nudged
    1e-10 inside the box takes a first step ~1e-10 long (cut where the free variable meets its
    bound) and its xtol test ends the run there. lm continues once from that point with the
    variable on its bound, where dogbox's active set holds it, and converges."""
    from scipy.optimize import least_squares as scipy_ls

    from solvers.scipy_ import dogbox_start, strictly_inside

    p = _bound_problem()
    ev = Evaluator(p)
    lo, hi, z0 = p.lower, p.upper, np.array([1.0, 1.0])
    tol = {"xtol": 1e-10, "ftol": 1e-10, "gtol": 1e-10}
    nudged = scipy_ls(
        lambda z: ev.evaluate(z).residual, strictly_inside(z0, lo, hi), bounds=(lo, hi),
        method="dogbox", **tol,
    )  # fmt: skip
    assert nudged.status == 3 and nudged.nfev == 2 and abs(nudged.x[0] - 1.0) < 1e-9  # the stall
    assert np.array_equal(dogbox_start(z0, lo, hi), z0)  # on the bound: left there
    assert np.array_equal(dogbox_start([1.0, 1.0 + 1e-12], lo, hi), z0)  # a hair inside: onto it
    assert np.array_equal(dogbox_start([1.0, 1.5], lo, hi), [1.0, 1.5])  # inside: untouched
    res = solve(Evaluator(p), "lm", budget=100, x0=[1.0, 1.0])
    assert res.status == "converged" and res.n_evals <= 10, res.message
    assert res.message.startswith("continued once after an xtol stop in the first step")
    assert res.x == pytest.approx([0.5, 1.0], abs=1e-9)
    # a start whose first step is not cut short runs as before: no continuation
    inside = solve(Evaluator(p), "lm", budget=100, x0=[1.0, 1.5])
    assert inside.status == "converged" and "continued" not in inside.message


def test_status_at_a_bound_is_the_first_order_truth():
    """The status test on the problem above: the stalled start (x1 1e-10 inside its bound) is not
    a first-order point (Gauss-Newton step 0.5 in x0); the bounded minimum is one, exactly on the
    bound (dogbox) or a hair inside it (trf returns 1 + 2e-16; before the epsilon-active set that
    was a Gauss-Newton step of 5, "stalled"), and trf's run says so."""
    from solvers.optimality import data_cost, first_order

    p = _bound_problem()
    ev = Evaluator(p)

    def test(z):
        e = ev.evaluate(np.asarray(z, float))
        return first_order(z, e.residual, ev.jacobian(np.asarray(z, float)), p.lower, p.upper,
                           data_cost(ev))  # fmt: skip

    stalled = test([1.0, 1.0 + 1e-10])
    assert not stalled.converged and stalled.step == pytest.approx(0.5, rel=1e-6)
    assert test([0.5, 1.0]).converged and test([0.5, 1.0 + 2e-16]).converged
    outward = test([0.5, 1.0 + 1e-3])  # 1e-3 off the bound: free, not a first-order point
    assert not outward.converged and outward.step > 1e-3
    res = solve(Evaluator(p), "trf", budget=100, x0=[1.0, 1.0])
    assert res.status == "converged" and res.x == pytest.approx([0.5, 1.0], abs=1e-6)

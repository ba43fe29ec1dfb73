"""Every registered method through the real objective: budget, counts, JSON, seeds, convergence."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from problems.inverse.analytic import ANALYTIC_CASES, analytic_objective
from problems.inverse.protocol import ForwardResult
from solvers import METHODS, RunResult, solve
from solvers.base import FAMILIES, get_method
from solvers.options import Option
from tests.support import evaluator

# lm-minpack refuses a finite box (MINPACK has no bounds): its runs are in test_fairness/test_nist
ALL = sorted(m for m in METHODS if m != "lm-minpack")
LOCAL = [m for m in ALL if METHODS[m].family == "local"]
GLOBAL = [m for m in ALL if METHODS[m].family == "global"]
STOCHASTIC = [m for m in ALL if METHODS[m].stochastic]

SMOOTH = ANALYTIC_CASES["analytic-smooth"]
MULTI = ANALYTIC_CASES["analytic-multimodal"]


@pytest.fixture(autouse=True)
def _quiet():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # short MCMC chains warn by design
        yield


def _comparable(res: RunResult) -> dict:
    d = res.to_dict()
    d.pop("wall_s")
    return d


def test_registry_lists_the_required_methods():
    required = {
        "lm",
        "gauss-newton",
        "ga",
        "de",
        "pso",
        "sa",
        "mcmc",
        "multistart-lm",
        "pso+lm",
        "nlopt:BOBYQA",
        "nlopt:SBPLX",
        "nlopt:NELDERMEAD",
        "nlopt:CRS2_LM",
        "nlopt:DIRECT_L",
        "nlopt:ESCH",
        "nlopt:ISRES",
        "nlopt:MLSL",
    }
    assert required <= set(METHODS)
    for name, info in METHODS.items():
        assert info.name == name and info.family in FAMILIES and info.library
        assert all(isinstance(v, Option) and v.help for v in info.options.values())
        json.dumps(info.to_dict())
    assert METHODS["mcmc"].family == "sampling" and METHODS["lm"].family == "local"


@pytest.mark.parametrize("budget", [1, 29])
@pytest.mark.parametrize("method", ALL)
def test_budget_never_exceeded_and_counts_match(method, budget):
    for name in ("analytic-failing", "analytic-infeasible"):
        obj = analytic_objective(name)
        case = ANALYTIC_CASES[name]
        # next to the failing/infeasible regions
        x0 = case.reference * np.array([0.8, 1.18, 1.2, 1.6])
        res = solve(obj, method, budget=budget, seed=1, x0=x0)
        assert res.n_evals <= budget
        assert res.n_evals == obj.n_evals == sum(1 for e in obj.log if e["charged"])
        assert res.n_evals - res.n_repeats == sum(1 for e in obj.log if not e["cached"])
        assert (res.n_failed, res.n_infeasible, res.n_cache_hits, res.n_repeats) == (
            obj.n_failed,
            obj.n_infeasible,
            obj.n_cache_hits,
            obj.n_repeats,
        )
        assert res.repeats == "charged"
        assert res.status in ("converged", "budget", "max_iterations", "failed", "stalled")
        if obj.best is not None:
            assert res.cost == obj.best.cost and np.allclose(res.x, obj.best.x, rtol=0, atol=0)
        assert RunResult.from_json(res.to_json()) == res


@pytest.mark.parametrize("method", ALL)
def test_json_round_trip_and_history(method):
    obj = analytic_objective("analytic-smooth")
    res = solve(obj, method, budget=90, seed=2, x0=SMOOTH.start)
    back = RunResult.from_json(json.dumps(json.loads(res.to_json())))
    assert back == res
    assert back.x_normalised == pytest.approx(
        list(np.array(res.x) / np.array(res.reference)), rel=1e-15
    )
    assert (
        back.method == method and back.budget == 90 and back.parameter_names == list(SMOOTH.names)
    )
    assert len(res.history) >= 1
    n_evals = [row["n_evals"] for row in res.history]
    best = [row["best_cost"] for row in res.history]
    assert n_evals == sorted(n_evals) and n_evals[-1] <= res.n_evals
    assert all(b2 <= b1 for b1, b2 in zip(best, best[1:]))
    assert best[-1] >= res.cost
    assert all(len(row["x"]) == 4 for row in res.history if row["x"])


@pytest.mark.parametrize("method", ALL)
def test_same_seed_same_run(method):
    runs = [
        solve(analytic_objective("analytic-multimodal"), method, budget=70, seed=s, x0=MULTI.start)
        for s in (5, 5, 6)
    ]
    a, b, c = (_comparable(r) for r in runs)
    assert a == b  # bit for bit
    a.pop("seed"), c.pop("seed")
    if METHODS[method].stochastic:
        assert a["history"] != c["history"]
    else:
        assert a == c


def test_global_numpy_rng_untouched():
    np.random.seed(123)
    expected = np.random.random()
    np.random.seed(123)
    for method in ("pso", "ga", "de", "mcmc", "pso+lm"):
        solve(analytic_objective("analytic-smooth"), method, budget=60, seed=9)
    assert np.random.random() == expected


def test_pso_leaves_logging_and_cwd_alone(tmp_path, monkeypatch):
    import logging

    monkeypatch.chdir(tmp_path)
    before = list(logging.getLogger().handlers)
    solve(analytic_objective("analytic-smooth"), "pso", budget=40, seed=0)
    assert logging.getLogger().handlers == before
    assert not (tmp_path / "report.log").exists()


@pytest.mark.parametrize("method", LOCAL)
def test_local_methods_converge_from_a_near_start(method):
    s = np.where(np.arange(4) % 2 == 0, 1.0, -1.0)
    x0 = SMOOTH.reference * (1 + 0.05 * s)
    obj = analytic_objective("analytic-smooth")
    res = solve(obj, method, budget=3000, seed=0, x0=x0)
    err = np.max(np.abs(np.array(res.x_normalised) - 1))
    tol = 1e-4 if method in ("nlopt:SBPLX", "nlopt:COBYLA") else 1e-6
    assert err < tol, (res.status, res.n_evals, err)
    assert res.status in ("converged", "budget")
    if method in ("lm", "gauss-newton", "nlopt:LBFGS"):
        assert res.status == "converged" and res.n_evals < 150


@pytest.mark.parametrize("method", ["lm", "gauss-newton"])
def test_local_methods_stay_in_the_local_minimum_of_the_multimodal_problem(method):
    res = solve(analytic_objective("analytic-multimodal"), method, budget=300, x0=MULTI.start)
    assert res.cost > 1e4  # the default start is in a wrong basin: a global method is needed


GLOBAL_OPTIONS = {"multistart-lm": {"n_starts": 12}}


@pytest.mark.parametrize("method", GLOBAL)
def test_global_methods_find_the_global_basin(method):
    obj = analytic_objective("analytic-multimodal")
    res = solve(obj, method, budget=600, seed=0, x0=MULTI.start, **GLOBAL_OPTIONS.get(method, {}))
    assert res.n_evals <= 600
    # in the global basin: a local polish from the point found reaches the global minimum
    polished = solve(obj, "lm", budget=300, x0=res.x)
    assert polished.cost < 1e-8, (res.x, res.cost)
    assert polished.x_normalised == pytest.approx([1.0, 1.0, 1.0], abs=1e-6)
    assert abs(res.x[1] / MULTI.reference[1] - 1) < 0.15  # omega in the global basin already


def test_mcmc_recovers_the_linear_gaussian_posterior():
    obj = analytic_objective("analytic-linear", noise=1.0, seed=11)
    mean, cov = obj.model.posterior(obj.data)
    std = np.sqrt(np.diag(cov))
    res = solve(
        obj,
        "mcmc",
        budget=32 * 1200 + 32,
        seed=4,
        x0=ANALYTIC_CASES["analytic-linear"].start,
        n_walkers=32,
        init="lhs",
    )  # default moves: DE mixture, tau ~ 11 steps
    ex = res.extra
    got_mean = np.array([ex["mean"][n] for n in obj.names])
    got_std = np.array([ex["std"][n] for n in obj.names])
    # effective sample size >= 32 * 840 / tau ~ 500: standard error of the mean < 0.05 std
    assert np.all(np.abs(got_mean - mean) < 0.2 * std), (got_mean - mean) / std
    np.testing.assert_allclose(got_std, std, rtol=0.12)
    lo = np.array([ex["q2.5"][n] for n in obj.names])
    hi = np.array([ex["q97.5"][n] for n in obj.names])
    np.testing.assert_allclose(hi - lo, 2 * 1.96 * std, rtol=0.15)
    assert 0.2 < ex["acceptance_fraction"] < 0.8
    assert res.status == "converged" and not ex["warnings"]
    assert res.n_evals <= res.budget
    chain = np.array(ex["chain"])
    assert chain.shape == (ex["n_steps"], 32, 3)
    assert res.cost <= ex["map_cost"] + 1e-12


def test_mcmc_stops_when_the_chain_is_converged_and_not_before():
    obj = analytic_objective("analytic-linear", noise=1.0, seed=11)
    kw = dict(seed=4, x0=ANALYTIC_CASES["analytic-linear"].start, n_walkers=32, init="lhs")
    res = solve(obj, "mcmc", budget=32 * 5000 + 32, check_every=100, **kw)
    ex = res.extra
    steps, burn = ex["n_steps"], ex["burn"]
    tau = max(ex["autocorr_time"].values())
    assert ex["stopped_converged"] and res.status == "converged"
    assert steps % 100 == 0 and steps < 5000  # stopped at a check, long before the cap
    assert steps - burn >= 50 * tau  # the rule held where it stopped ...
    # ... and not at the previous check: the same chain 100 steps shorter is not yet converged
    from solvers.emcee_ import converged_at

    chain = np.array(ex["chain"]) / obj.reference
    prev_ok, prev_tau = converged_at(chain[: steps - 200], 0.3, 50.0, 0.05, np.inf)
    ok, _ = converged_at(chain[: steps - 100], 0.3, 50.0, 0.05, prev_tau)
    assert not ok
    assert not obj._cache and obj.cache  # a chain's points are not kept (memory); setting restored
    full = solve(obj, "mcmc", budget=32 * 1500 + 32, stop_converged=False, **kw)
    assert full.extra["n_steps"] >= 1500 and not full.extra["stopped_converged"]  # whole budget


def test_mcmc_warns_on_a_short_chain_and_writes_the_chain_file(tmp_path):
    obj = analytic_objective("analytic-linear")
    path = tmp_path / "chain.npz"
    with pytest.warns(RuntimeWarning, match="autocorrelation"):
        res = solve(obj, "mcmc", budget=400, seed=0, chain_path=str(path))
    assert res.extra["warnings"] and res.status == "budget" and "chain" not in res.extra
    data = np.load(path)
    assert data["chain"].shape == (res.extra["n_steps"], res.extra["n_walkers"], 3)


def test_lm_rejects_failed_trial_points_and_shrinks():
    class Bowl:
        """Zero-residual bowl with its minimum at x = (2, 1), but the model fails for x0 > 1.5."""

        names = ("u", "v")

        def check(self, x):
            return None

        def __call__(self, x):
            if x[0] > 1.5:
                return ForwardResult(False, None, "diverged")
            return ForwardResult(True, np.array([x[0] - 2.0, x[1] - 1.0, 0.1 * x[0] * x[1]]))

    obj = evaluator(Bowl(), np.zeros(3), lower=[0.5, 0.5], upper=[3.0, 3.0], reference=[1.0, 1.0])
    res = solve(obj, "lm", budget=200, x0=[1.0, 1.5])
    assert res.n_failed >= 1 and res.n_evals <= 200
    assert 1.4 < res.x[0] <= 1.5  # pushed against the failing region, never inside it
    assert res.status != "failed"


def test_all_failed_run_reports_failed():
    obj = analytic_objective("analytic-failing")
    x0 = ANALYTIC_CASES["analytic-failing"].reference.copy()
    x0[1] = 25.0
    res = solve(obj, "lm", budget=50, x0=x0)
    assert (
        res.status == "failed" and not res.success and res.cost == float("inf") and res.n_evals == 1
    )
    assert res.x == list(x0)


def test_hybrids_report_their_phases():
    obj = analytic_objective("analytic-multimodal")
    res = solve(obj, "multistart-lm", budget=400, seed=3, x0=MULTI.start, n_starts=4)
    starts = res.extra["starts"]
    assert len(starts) == 4 and starts[0]["x0"] == pytest.approx(list(MULTI.start))
    assert sum(s["n_evals"] for s in starts) == res.n_evals
    assert min(s["cost"] for s in starts) == res.cost
    res = solve(
        analytic_objective("analytic-multimodal"), "pso+lm", budget=300, seed=3, x0=MULTI.start
    )
    phases = [row["phase"] for row in res.history]
    assert phases[0] == "pso" and phases[-1] == "lm"
    assert res.extra["pso_evals"] <= 150


def test_population_methods_evaluate_one_batch_per_generation():
    class Mapper:
        calls = 0

        def __call__(self, fn, items):
            Mapper.calls += 1
            return [fn(x) for x in items]

    for method, size in (("ga", "pop_size"), ("de", "pop_size"), ("pso", "n_particles")):
        Mapper.calls = 0
        obj = analytic_objective("analytic-smooth", mapper=Mapper())
        res = solve(obj, method, budget=200, seed=0, **{size: 20})
        # one mapper call per generation (the last may be cut)
        assert Mapper.calls <= len(res.history) + 1
        assert res.n_evals / Mapper.calls > 15


def test_solve_input_checks_and_defaults():
    obj = analytic_objective("analytic-smooth")
    res = solve(obj, "nlopt:NELDERMEAD", budget=5)
    assert res.x0 == pytest.approx(list(0.5 * (SMOOTH.lower + SMOOTH.upper)))  # x0=None: box centre
    with pytest.raises(ValueError, match="unknown option"):
        solve(obj, "lm", budget=5, bogus=1)
    with pytest.raises(ValueError, match="unknown"):
        solve(obj, "simplex", budget=5)
    with pytest.raises(ValueError, match="outside the bounds"):
        solve(obj, "lm", budget=5, x0=SMOOTH.upper * 2)
    res = solve(obj, "lm", budget=5, seed=None)
    assert isinstance(res.seed, int)
    res = solve(obj, "nlopt:LN_PRAXIS", budget=300, x0=SMOOTH.start)  # any nlopt algorithm resolves
    assert get_method("nlopt:LN_PRAXIS").family == "local" and res.method == "nlopt:LN_PRAXIS"
    assert res.cost < 0.05 * obj.cost(obj.to_scaled(SMOOTH.start))

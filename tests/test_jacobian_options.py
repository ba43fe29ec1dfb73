"""Exact or finite-difference Jacobians as an option of an identification, and the LM/GN runs
that use exact ones (one run with sensitivities per trial point, dogbox bounds)."""

from __future__ import annotations

import numpy as np
import pytest

from bench.experiment.identify import identify, jacobian_options
from bench.experiment.spec import RunSpec
from problems.inverse.evaluator import Evaluator
from problems.inverse.problem import LeastSquaresProblem
from problems.inverse.protocol import ForwardResult
from solvers import solve


class Exponential:
    """U(x) = [exp(-t_k x0) x1 + x2 t_k], t_k = 0..1 (12 points); exact Jacobian on request."""

    names = ("a", "b", "c")
    provides_jacobian = True
    jacobian_cost = 1.5
    t = np.linspace(0.0, 1.0, 12)

    def check(self, x):
        return None

    def values(self, x):
        return np.exp(-self.t * x[0]) * x[1] + x[2] * self.t

    def __call__(self, x, jacobian=False):
        J = None
        if jacobian:
            e = np.exp(-self.t * x[0])
            J = np.column_stack([-self.t * e * x[1], e, self.t])
        return ForwardResult(True, self.values(x), jacobian=J, wall_s=1.0)


def objective(**kw):
    model = Exponential()
    data = model.values(np.array([2.0, 1.0, 0.5]))
    problem = LeastSquaresProblem(
        model,
        data,
        lower=[0.5, 0.2, 0.1],
        upper=[4.0, 3.0, 2.0],
        reference=[2.0, 1.0, 0.5],
        sigma=0.01,
    )
    return Evaluator(problem, **kw)


def test_the_run_spec_validates_jacobian_and_budget_unit():
    with pytest.raises(ValueError) as exc:
        RunSpec("analytic-smooth", "lm", jacobian="numeric")
    assert str(exc.value) == "jacobian = 'numeric' is unknown; allowed: exact, forward, central"
    with pytest.raises(ValueError, match="budget_unit = 'runs' is unknown; allowed: evaluations"):
        RunSpec("analytic-smooth", "lm", budget_unit="runs")
    assert RunSpec("analytic-smooth", "lm").jacobian == "exact"


def test_jacobian_option_sets_the_scheme_of_methods_that_have_one():
    assert jacobian_options("lm", {"ftol": 1e-8}, "central") == {"ftol": 1e-8, "scheme": "central"}
    assert jacobian_options("gauss-newton", {}, "forward") == {"scheme": "forward"}
    assert jacobian_options("lm", {"scheme": "central"}, "exact") == {"scheme": "central"}
    assert jacobian_options("cma", {}, "central") == {}  # derivative-free: nothing to set
    with pytest.raises(ValueError, match="option scheme = 'forward' contradicts jacobian"):
        jacobian_options("lm", {"scheme": "forward"}, "central")


@pytest.mark.parametrize("method", ["lm", "gauss-newton"])
def test_exact_jacobians_run_each_trial_point_once_with_its_jacobian(method):
    exact = solve(objective(), method, budget=200, x0=[1.0, 2.0, 1.5])
    fd = solve(
        objective(exact_jacobian=False), method, budget=200, x0=[1.0, 2.0, 1.5], scheme="central"
    )
    for res in (exact, fd):
        assert res.status == "converged"
        np.testing.assert_allclose(res.x_normalised, 1.0, atol=1e-6)
    # every evaluation of the exact run is a run with sensitivities, none is repeated plain
    assert exact.extra["n_jacobian_runs"] == exact.n_evals
    assert exact.forward_equivalents_nominal == pytest.approx(1.5 * exact.n_evals)
    assert exact.n_iterations <= exact.n_evals
    # central differences: 2 n + 1 plain runs per iteration at least
    assert "n_jacobian_runs" not in fd.extra and fd.forward_equivalents_nominal == fd.n_evals
    assert fd.n_evals >= 7 * fd.n_iterations


def test_lm_leaves_a_start_on_a_bound_in_few_iterations():
    """The start sits on two lower bounds (the solution does not): dogbox drops them from the
    step, where trf's reflective scaling takes many short steps."""
    runs = {
        m: solve(objective(), "lm", budget=200, x0=[0.5, 0.2, 1.5], ls_method=m)
        for m in ("dogbox", "trf")
    }
    for res in runs.values():
        np.testing.assert_allclose(res.x_normalised, 1.0, atol=1e-6)
    assert runs["dogbox"].n_iterations <= 12
    assert runs["dogbox"].n_iterations <= runs["trf"].n_iterations
    with pytest.raises(ValueError, match="ls_method = 'lm' is unknown; allowed: dogbox, trf"):
        solve(objective(), "lm", budget=20, x0=[1.0, 1.0, 1.0], ls_method="lm")


def test_budget_in_forward_equivalents_through_solve():
    res = solve(objective(budget_unit="forward-equivalents"), "lm", budget=6, x0=[1.0, 2.0, 1.5])
    assert res.budget_unit == "forward-equivalents" and res.status == "budget"
    assert res.forward_equivalents_nominal <= 6.0 and res.n_evals == 4  # 4 x 1.5


def test_identify_passes_jacobian_and_budget_unit_on_an_analytic_case():
    """Analytic models offer no exact Jacobian: ``central`` still sets the scheme (2 n + 1 runs
    per iteration, n = 3), ``forward`` n + 1."""
    runs = {
        j: identify(RunSpec("analytic-smooth", "gauss-newton", budget=300, jacobian=j))
        for j in ("forward", "central")
    }
    assert runs["central"].options["scheme"] == "central"
    assert runs["forward"].options["scheme"] == "forward"
    assert runs["central"].n_evals > runs["forward"].n_evals
    unit = identify(
        RunSpec(
            "analytic-smooth", "lm", budget=40, budget_unit="forward-equivalents", jacobian="exact"
        )
    )
    assert unit.budget_unit == "forward-equivalents" and unit.forward_equivalents_nominal <= 40


def test_cli_jacobian_option(capsys):
    from bench.cli import main

    argv = ["identify", "analytic-smooth", "--solver", "lm", "--quiet"]
    assert main([*argv, "--jacobian", "central", "--budget-unit", "forward-equivalents"]) == 0
    out = capsys.readouterr().out
    assert "nominal (budget in forward-equivalents)" in out
    assert main([*argv, "--jacobian", "numeric"]) == 2
    assert "invalid choice: 'numeric'" in capsys.readouterr().err
    assert main([*argv, "--jacobian", "forward", "--option", "scheme=central"]) == 2
    assert "contradicts jacobian" in capsys.readouterr().err


@pytest.mark.parametrize("method", ["multistart-lm", "pso+lm", "cma"])
def test_composite_and_population_methods_keep_a_budget_in_forward_equivalents(method):
    """Phases split the budget in the objective's unit: exact Jacobian runs cost 1.5 each."""
    obj = objective(budget_unit="forward-equivalents")
    res = solve(obj, method, budget=30, x0=[1.0, 2.0, 1.5], seed=1)
    assert res.forward_equivalents_nominal <= 30.0 + 1e-9
    runs = res.extra.get("n_jacobian_runs", 0)
    # a repeat of a point run with its Jacobian (a later start reaching the same optimum) is
    # charged what the run cost
    repeats = sum(1 for e in obj.log if e["cached"] and e["charged"] and e["kind"] == "jacobian")
    assert res.forward_equivalents_nominal == pytest.approx(res.n_evals + 0.5 * (runs + repeats))

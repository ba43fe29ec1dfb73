"""The analytic forward models: known optima, derivatives, noise, failure regions."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from problems.inverse.analytic import (
    ANALYTIC_CASES,
    LinearModel,
    RastriginModel,
    SinusoidModel,
    StressStrainModel,
    analytic_model,
    analytic_objective,
)
from problems.inverse.cases import get_case
from problems.inverse.problem import FAILURE_COST

NAMES = sorted(ANALYTIC_CASES)


def test_cases_are_registered_and_consistent():
    assert {
        "analytic-smooth",
        "analytic-multimodal",
        "analytic-linear",
        "analytic-infeasible",
        "analytic-failing",
        "analytic-rastrigin",
    } <= set(NAMES)
    for name in NAMES:
        case = get_case(name)
        assert case is ANALYTIC_CASES[name]
        assert case.names == analytic_model(name).names
        assert np.all(case.lower <= case.start) and np.all(case.start <= case.upper)
        assert case.to_dict()["name"] == name


@pytest.mark.parametrize("name", NAMES)
def test_zero_cost_at_reference_and_positive_at_start(name):
    obj = analytic_objective(name)
    case = ANALYTIC_CASES[name]
    assert obj.cost(np.ones(obj.n_params)) == pytest.approx(0.0, abs=1e-20)
    assert obj.cost(obj.to_scaled(case.start)) > 10.0
    np.testing.assert_allclose(obj.reference, case.reference)


@pytest.mark.parametrize("name", ["analytic-smooth", "analytic-linear", "analytic-multimodal"])
def test_noise_is_seeded_and_has_the_nominal_scale(name):
    a = analytic_objective(name, noise=1.0, seed=7)
    b = analytic_objective(name, noise=1.0, seed=7)
    c = analytic_objective(name, noise=1.0, seed=8)
    np.testing.assert_array_equal(a.data, b.data)
    assert not np.array_equal(a.data, c.data)
    m = a.n_residuals  # cost at the truth ~ chi^2(m): mean m, std sqrt(2m)
    assert abs(a.cost(np.ones(a.n_params)) - m) < 5 * np.sqrt(2 * m)


@pytest.mark.parametrize(
    "model_cls", [StressStrainModel, SinusoidModel, RastriginModel, LinearModel]
)
def test_objective_fd_jacobian_matches_model_jacobian(model_cls):
    name = {
        StressStrainModel: "analytic-smooth",
        SinusoidModel: "analytic-multimodal",
        RastriginModel: "analytic-rastrigin",
        LinearModel: "analytic-linear",
    }[model_cls]
    obj = analytic_objective(name)
    case = ANALYTIC_CASES[name]
    x = 0.5 * (case.reference + case.start)
    z = obj.to_scaled(x)
    exact = -obj.whiten(obj.model.jacobian(x)) * obj.reference  # dR/dz = -C^-1/2 dU/dx * ref
    J = obj.jacobian(z, scheme="central", rel_step=1e-6)
    np.testing.assert_allclose(J, exact, rtol=1e-6, atol=1e-7 * np.abs(exact).max())


def test_smooth_problem_is_well_conditioned():
    obj = analytic_objective("analytic-smooth")
    J = obj.jacobian(np.ones(4), scheme="central")
    assert np.linalg.cond(J) < 50


def test_multimodal_problem_has_a_local_minimum_near_the_start():
    from scipy.optimize import least_squares

    obj = analytic_objective("analytic-multimodal")
    case = ANALYTIC_CASES["analytic-multimodal"]
    res = least_squares(obj.residual, obj.to_scaled(case.start), bounds=(obj.lower_z, obj.upper_z))
    assert 2 * res.cost > 1e4  # stuck in the local minimum near omega = 1.5
    assert obj.to_physical(res.x)[1] == pytest.approx(1.5, abs=0.05)
    res = least_squares(
        obj.residual, obj.to_scaled([1.2, 1.8, 0.9]), bounds=(obj.lower_z, obj.upper_z)
    )
    assert 2 * res.cost < 1e-12  # inside the global basin


def test_linear_posterior_is_the_weighted_least_squares_solution():
    obj = analytic_objective("analytic-linear", noise=1.0, seed=3)
    model = obj.model
    mean, cov = model.posterior(obj.data)
    sol = np.linalg.lstsq(model.A / model.sigma, obj.data / model.sigma, rcond=None)[0]
    np.testing.assert_allclose(mean, sol, rtol=1e-12)
    # the posterior is far inside the box (flat prior = untruncated Gaussian)
    std = np.sqrt(np.diag(cov))
    assert np.all((mean - obj.lower) / std > 15) and np.all((obj.upper - mean) / std > 15)
    assert obj.cost(obj.to_scaled(mean)) < obj.cost(np.ones(3))


def test_infeasible_and_failing_regions():
    obj = analytic_objective("analytic-infeasible")
    ev = obj.evaluate(obj.to_scaled([30000, 20, 1500, 27.0]))
    assert not ev.feasible and "psi" in ev.message and obj.n_infeasible == 1
    obj = analytic_objective("analytic-failing")
    ev = obj.evaluate(obj.to_scaled([30000, 25.0, 1500, 15.0]))
    assert ev.feasible and not ev.ok and ev.cost == FAILURE_COST and obj.n_failed == 1
    assert obj.evaluate(obj.to_scaled([30000, 23.0, 1500, 15.0])).ok


def test_models_pickle():
    for name in NAMES:
        model = pickle.loads(pickle.dumps(analytic_model(name)))
        x = ANALYTIC_CASES[name].reference
        np.testing.assert_array_equal(model(x).values, analytic_model(name)(x).values)


def test_unknown_case_raises():
    with pytest.raises(ValueError, match="allowed"):
        analytic_objective("analytic-nope")

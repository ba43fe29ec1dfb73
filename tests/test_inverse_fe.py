"""The FE-backed inverse problem: data sets, the objective at the reference, Jacobians.

A 3 x 3 x 6 mesh keeps these fast; the physics is the same as on the presets.
"""

import json

import numpy as np
import pytest

from problems.inverse.build import build_objective
from problems.inverse.cases import CASES
from problems.inverse.data import DataSettings, load, make_data, save
from problems.inverse.forward import FEForwardModel
from problems.inverse.starts import feasible_toward_reference, start_point

MESH = "3,3,6"
CASE = CASES["linear-compression"]


@pytest.fixture(scope="module")
def exact_data():
    return make_data(
        CASE, mesh=MESH, resolution_um=0.0, force_resolution_kN=0.0, snapshots=4, tier="consistent"
    )


@pytest.fixture(scope="module")
def central_jacobian(exact_data):
    obj = build_objective(CASE, mesh=MESH, data=exact_data)
    obj.exact_jacobian = False  # finite differences here (the FE model offers exact Jacobians)
    J = obj.jacobian(np.ones(6), scheme="central", rel_step=1e-4)
    return obj, J


@pytest.fixture(scope="module")
def rounded_data():
    return make_data(CASE, mesh=MESH, resolution_um=1.0, force_resolution_kN=0.0, tier="consistent")


def test_cost_is_zero_at_the_reference_and_jacobian_has_full_rank(central_jacobian):
    obj, J = central_jacobian
    assert obj.cost(np.ones(6)) < 1e-12
    s = np.linalg.svd(J, compute_uv=False)
    assert s[-1] / s[0] > 1e-8, s  # every parameter moves the measurements
    assert np.linalg.matrix_rank(J) == 6
    # central differences: two runs per column, then the centre; the cost asked at the centre
    # again is a repeat: charged, not run
    assert obj.n_evals == 12 + 1 + 1 and obj.n_repeats == 1


def test_finite_difference_jacobian_is_clean_across_step_sizes(exact_data, central_jacobian):
    """FE tolerances are tight enough that forward differences agree with central ones from
    h = 1e-4 (truncation-dominated) down to h = 1e-7 (where solver noise would show first)."""
    _, Jc = central_jacobian
    obj = build_objective(CASE, mesh=MESH, data=exact_data)
    obj.exact_jacobian = False
    z = np.ones(6)
    r0 = obj.residual(z)
    err = {}
    for h in (1e-4, 1e-7):
        Jh = obj.jacobian(z, scheme="forward", rel_step=h, r0=r0)
        err[h] = (np.linalg.norm(Jh - Jc, axis=0) / np.linalg.norm(Jc, axis=0)).max()
    assert err[1e-4] < 5e-2, err
    assert err[1e-7] < 1e-3, err  # noise / h is still small at 1e-7: the FE is clean
    assert err[1e-7] < err[1e-4], err  # and the error still shrinks with the step


def test_rounding_to_1um_gives_unit_mean_square_whitened_residuals(rounded_data):
    obj = build_objective(CASE, mesh=MESH, data=rounded_data)
    r = obj.residual(np.ones(6))
    disp = r[obj.blocks["displacement"]]
    # uniform rounding error over [-0.5, 0.5] um whitened by (1 um)/sqrt(12): mean square 1
    nonzero = disp[np.abs(disp) > 0]
    assert abs(np.mean(disp**2) - 1.0) < 0.08, np.mean(disp**2)
    assert len(nonzero) > 0.9 * len(disp)
    assert np.max(np.abs(disp)) <= np.sqrt(12) / 2 + 1e-9


def test_infeasible_points_are_rejected_without_fe_and_counted():
    case = CASES["hyperbolic-tension"]
    obj = build_objective(
        case,
        mesh=MESH,
        data=make_data(case, mesh=MESH, resolution_um=0, force_resolution_kN=0, tier="consistent"),
    )
    x = case.reference.copy()
    x[case.names.index("sigma0")] = case.upper[case.names.index("sigma0")]
    # pt0 < sigma0/3: degenerate hyperbola
    x[case.names.index("pt0")] = case.lower[case.names.index("pt0")]
    ev = obj.evaluate(x / case.reference)
    assert not ev.feasible and not ev.ok
    assert "pt0" in ev.message
    assert obj.n_evals == 1 and obj.n_infeasible == 1 and ev.wall_s == 0.0
    # how a random start is repaired
    back = feasible_toward_reference(case, x, FEForwardModel(case).check)
    assert FEForwardModel(case).check(back) is None
    assert np.all(np.sign(back - case.reference) == np.sign(x - case.reference))


@pytest.mark.parametrize("name", list(CASES))
def test_every_default_start_is_valid_and_yields_before_the_last_snapshot(name):
    case = CASES[name]
    model = FEForwardModel(case, MESH)
    assert model.check(case.start) is None
    assert np.array_equal(start_point(case), case.start)
    resp = model.response(case.start)
    assert resp.converged and resp.state[-1, :, 0].max() > 1e-4  # equivalent plastic strain


def test_data_files_are_deterministic_and_hash_checked(tmp_path, rounded_data):
    again = make_data(
        CASE, mesh=MESH, resolution_um=1.0, force_resolution_kN=0.0, tier="consistent"
    )
    assert again.to_json() == rounded_data.to_json()
    path = save(rounded_data, tmp_path / "d.json")
    back = load(path)
    assert back.hash == rounded_data.hash and np.array_equal(back.values, rounded_data.values)
    assert np.all(np.abs(back.u_h * 1000 - np.round(back.u_h * 1000)) < 1e-9)  # 1 um steps
    doc = json.loads(path.read_text())
    doc["u_h"][0][0] += 0.001
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match="hash"):
        load(path)


def test_noise_is_seeded():
    a = make_data(CASE, mesh="2,2,4", noise_um=2.0, seed=1, snapshots=2)
    b = make_data(CASE, mesh="2,2,4", noise_um=2.0, seed=1, snapshots=2)
    c = make_data(CASE, mesh="2,2,4", noise_um=2.0, seed=2, snapshots=2)
    assert np.array_equal(a.values, b.values) and not np.array_equal(a.values, c.values)
    assert np.isclose(a.std_u_mm.flat[0], np.hypot(1e-3 / np.sqrt(12), 2e-3))


def test_bad_data_settings_name_the_field():
    with pytest.raises(ValueError, match="noise_um"):
        DataSettings(noise_um=-1)
    with pytest.raises(ValueError, match="route"):
        DataSettings(route="laser")
    with pytest.raises(ValueError, match="case"):
        build_objective(
            "hyperbolic-shear", mesh=MESH, data=make_data(CASE, mesh="2,2,4", snapshots=1)
        )


def test_the_exact_jacobian_of_the_objective_matches_central_differences(
    exact_data, central_jacobian
):
    """The FE model's DDM Jacobian, whitened and scaled by the evaluator: one evaluation."""
    _, Jc = central_jacobian
    obj = build_objective(CASE, mesh=MESH, data=exact_data)
    assert obj.exact_jacobian
    J = obj.jacobian(np.ones(6))
    assert obj.n_evals == 1
    assert (np.linalg.norm(J - Jc, axis=0) / np.linalg.norm(Jc, axis=0)).max() < 1e-5

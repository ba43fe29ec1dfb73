"""The Drucker-Prager family in the cube : all nine variants converge, quadratically,
and the B-bar element does not lock under isochoric plastic flow."""

import numpy as np
import pytest

from problems.fe.mesh import box_mesh
from problems.fe.newton import Loading, discretise, run
from problems.inverse.cases import CASES
from problems.inverse.forward import FORWARD_SETTINGS, case_material, discretisation
from problems.materials.drucker_prager import make_material


@pytest.mark.parametrize("name", sorted(CASES))
def test_all_nine_variants_run_the_default_test_on_coarse(name):
    case = CASES[name]
    r = run(
        discretisation("coarse"), case_material(case, case.reference), Loading(), FORWARD_SETTINGS
    )
    assert r.converged, r.message
    assert len(r.snapshots_mm) == 10 and np.isclose(r.snapshots_mm[-1], 1.5)
    eqps = r.state[:, :, r.state_names.index("eqps")]
    assert eqps[-1].max() > 1e-3  # the test really goes plastic
    assert np.all(np.diff(eqps.max(axis=1)) >= 0)  # and plastic strain only grows
    # the plate force stays far below the elastic one (E A delta / L = 6 750 kN frictionless)
    assert 300 < r.reaction_kN[-1] < 3000
    # quadratic convergence: once the residual is small, each iteration roughly squares it
    rates = []
    for h in r.residual_history:
        for a, b in zip(h[:-1], h[1:]):
            if 1e-12 < b and a < 1e-2:
                rates.append(np.log(b) / np.log(a))
    assert len(rates) >= 5
    assert np.median(rates) > 1.7, rates


def test_newton_residual_ratios_show_quadratic_convergence():
    case = CASES["linear-compression"]
    r = run(
        discretisation("coarse"),
        case_material(case, case.reference),
        Loading(1.5, 5),
        FORWARD_SETTINGS,
    )
    assert r.converged
    longest = max(r.residual_history, key=len)
    assert len(longest) >= 3
    # r_{k+1} <= C r_k^2 with a modest C on the tail of the longest increment
    tail = [(a, b) for a, b in zip(longest[:-1], longest[1:]) if a < 1e-3]
    assert tail and all(b <= 10.0 * a**2 + 1e-13 for a, b in tail), longest


def test_b_bar_does_not_lock_under_isochoric_plastic_flow():
    """Von Mises limit of the linear form (K = 1, beta -> 0, psi = 0, H = 0): standard B locks,
    B-bar does not."""
    vm = make_material(
        "linear",
        "compression",
        {"E": 30_000.0, "nu": 0.3, "beta": 1e-6, "K": 1.0, "psi": 0.0, "sigma0": 20.0, "H": 0.0},
    )
    load = Loading(3.0, 6, "friction")
    forces = {}
    for n in (3, 6):
        m = box_mesh(n, n, 2 * n)
        forces[n] = [
            run(discretise(m, use_b_bar=b), vm, load, FORWARD_SETTINGS) for b in (True, False)
        ]
    limit_kN = 20.0 * 150**2 / 1000  # uniaxial limit load sigma0 * A
    for _n, (rb, _rs) in forces.items():
        assert rb.converged, rb.message
        # B-bar: close to the limit load (friction adds a little), and mesh-insensitive
        assert 1.0 < rb.reaction_kN[-1] / limit_kN < 1.15
    assert abs(forces[3][0].reaction_kN[-1] / forces[6][0].reaction_kN[-1] - 1) < 0.02
    # standard B: spurious hardening from volumetric locking, worse on the coarser mesh
    if forces[3][1].converged:
        assert forces[3][1].reaction_kN[-1] > 1.1 * forces[3][0].reaction_kN[-1]

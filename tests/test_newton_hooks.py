"""The Newton solver's settings and public hooks: sensitivity settings are settings (no module
switches), and another predictor plugs in without copying the Newton loop."""

from __future__ import annotations

import numpy as np
import pytest

from problems.fe.ddm import SensitivitySettings
from problems.fe.mesh import parse_mesh_spec
from problems.fe.newton import Loading, NewtonSettings, discretise, run
from problems.inverse.cases import get_case
from problems.inverse.forward import FORWARD_SETTINGS, case_material


class Tangent:
    """The production predictor through the hook."""

    def __init__(self):
        self.converged_increments = 0

    def predict(self, du, dtop_mm, tangent):
        return tangent()

    def converged(self, du):
        self.converged_increments += 1


class Extrapolated(Tangent):
    """The last converged increment scaled to the new step (no predictor solve)."""

    def __init__(self):
        super().__init__()
        self.last = None

    def predict(self, du, dtop_mm, tangent):
        self.dtop = dtop_mm
        if self.last is None:
            return tangent()
        return self.last[0] * (dtop_mm / self.last[1]), ""

    def converged(self, du):
        super().converged(du)
        self.last = (du.copy(), self.dtop)


@pytest.fixture(scope="module")
def setup():
    case = get_case("hyperbolic-shear")
    disc = discretise(parse_mesh_spec("2,2,4").mesh, symmetry="eighth")
    return disc, case_material(case, case.reference)


def test_the_tangent_predictor_through_the_hook_is_the_plain_run(setup):
    disc, mat = setup
    plain = run(disc, mat, Loading(), FORWARD_SETTINGS)
    hook = Tangent()
    r = run(disc, mat, Loading(), FORWARD_SETTINGS, predictor=hook)
    np.testing.assert_array_equal(r.reaction_kN, plain.reaction_kN)
    np.testing.assert_array_equal(r.displacements, plain.displacements)
    assert r.iterations == plain.iterations
    assert hook.converged_increments == r.increments > 0


def test_another_predictor_changes_the_work_not_the_answer(setup):
    disc, mat = setup
    plain = run(disc, mat, Loading(), FORWARD_SETTINGS)
    r = run(disc, mat, Loading(), FORWARD_SETTINGS, predictor=Extrapolated())
    assert r.converged and r.iterations != plain.iterations
    rel = np.linalg.norm(r.reaction_kN - plain.reaction_kN) / np.linalg.norm(plain.reaction_kN)
    assert rel < 1e-7


def test_sensitivity_settings_are_checked_and_default_in_the_newton_settings():
    with pytest.raises(ValueError, match="sensitivity solve mode 'fast' is unknown; allowed"):
        SensitivitySettings(mode="fast")
    assert NewtonSettings().sensitivity == SensitivitySettings()
    assert SensitivitySettings().mode == "auto" and SensitivitySettings().affine

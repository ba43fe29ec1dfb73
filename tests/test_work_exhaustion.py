"""The one failure of the coarse robustness run (exponent-tension, results/perf/robustness_coarse.*)
is the model's, not the return map's: under high confinement the dilatant flow does negative
plastic work, the work-equivalent eqps decreases, sigma_bar = sigma0 + H eqps falls, and it
reaches 0 at a finite strain, past which the hardening law is not defined. The backward-Euler
return can take at most half of sigma_bar_n per increment (the fold of the work rule's quadratic),
so cutting the increment only approaches that point. The return map diagnoses it, and the FE
message names it."""

import numpy as np
import pytest

from problems.inverse.cases import CASES
from problems.inverse.forward import FEForwardModel, case_material
from problems.materials import _kernels as K

# the failing point of the robustness run: (E, psi, sigma0, H, pt0, b)
X = np.array(
    [
        39736.755432756065,
        25.909795575327504,
        3.469664951689394,
        255.02123616713928,
        3.210620473184979,
        1.826513904633143,
    ]
)
# the first Gauss point whose return failed in that run (coarse, last snapshot): the strain
# increment of a Newton iterate, the converged stress and state before it
DE = np.array(
    [
        [
            0.0014186210163040613,
            0.00141862101630406,
            -0.001286475645125604,
            0.003839504976785437,
            0.0038395049767854243,
            -0.00017748184938480007,
        ]
    ]
)
SIG_N = np.array(
    [
        [
            -51.33487326174908,
            -51.33487326174908,
            -62.38930995267573,
            7.589068262609141,
            7.589068262609135,
            -0.3692090927760138,
        ]
    ]
)
STATE_N = np.array(
    [
        [
            -0.00022779139057104667,
            0.013877661922324997,
            0.013877661922324992,
            -0.012850650316313935,
            0.030387380234960116,
            0.030387380234960074,
            -0.0003796711701669702,
        ]
    ]
)


@pytest.fixture(scope="module")
def material():
    return case_material(CASES["exponent-tension"], X)


def _exhaustion(material, de, sig_n, state_n):
    sig_tr = material._elastic_trial(de, sig_n, np.ascontiguousarray(state_n[:, 0]))[0]
    return K.work_exhaustion(
        material._kernel_params,
        material.yield_function.kernel_params,
        material.potential.kernel_params,
        sig_tr,
        np.ascontiguousarray(state_n[:, 0]),
    )


def test_the_failed_return_is_diagnosed_as_strength_exhaustion(material):
    up = material.update(DE, SIG_N, STATE_N)
    assert not up.ok[0]
    exhausted, dl_fold, f_fold, sbar_fold = _exhaustion(material, DE, SIG_N, STATE_N)
    sbar_n = material.yield_stress(STATE_N[0, 0])
    assert sbar_n == pytest.approx(3.41157, rel=1e-5)  # already softened: eqps_n < 0
    assert exhausted[0]
    # the fold of the work rule: half of sigma_bar_n, and F still 17.7 MPa outside there
    assert sbar_fold[0] == pytest.approx(sbar_n / 2, rel=1e-6)  # sqrt at the fold
    assert dl_fold[0] == pytest.approx(3.5436e-3, rel=1e-3)
    assert f_fold[0] == pytest.approx(17.67, rel=1e-3)
    reason = material.failure_reason(DE, SIG_N, STATE_N, up.ok)
    assert reason.startswith("strength exhausted at 1 of them") and "3.41 MPa" in reason
    # half the increment has a return: it softens (sigma_bar falls) but by less than half
    half = material.update(DE / 2, SIG_N, STATE_N)
    assert half.ok[0]
    sbar = material.yield_stress(half.state[0, 0])
    assert sbar_n / 2 < sbar < sbar_n
    assert sbar == pytest.approx(2.04366, rel=1e-4)
    assert not _exhaustion(material, DE / 2, SIG_N, STATE_N)[0][0]
    assert material.failure_reason(DE / 2, SIG_N, STATE_N, half.ok) == ""


def test_finer_increments_only_approach_sigma_bar_zero(material):
    """March the point along the failing increment's direction: sigma_bar falls steadily and the
    return fails (exhausted) near the same total strain whatever the step, with sigma_bar at the
    failure shrinking as the step does: the model has no solution beyond that strain."""
    where, last = [], []
    for m in (16, 64):
        sig, st = SIG_N.copy(), STATE_N.copy()
        sbars = [material.yield_stress(st[0, 0])]
        steps = 0
        while (up := material.update(DE / m, sig, st)).ok[0] and steps < 10 * m:
            sig, st = up.stress, up.state
            sbars.append(material.yield_stress(st[0, 0]))
            steps += 1
        assert not up.ok[0]
        assert material.failure_reason(DE / m, sig, st, up.ok).startswith("strength exhausted")
        assert np.all(np.diff(sbars) < 0)  # softening all the way
        where.append(steps / m)
        last.append(sbars[-1])
    assert where == pytest.approx([0.9375, 1.015625])
    assert last[1] < 0.6 * last[0] and last[0] == pytest.approx(0.87732, rel=1e-4)


def test_the_fe_run_reports_the_exhaustion():
    r = FEForwardModel(CASES["exponent-tension"], "coarse").response(X)
    assert not r.converged
    assert len(r.snapshots_mm) == 9 and r.snapshots_mm[-1] == pytest.approx(1.35)
    assert "strength exhausted" in r.message and "gave up after 8 cuts" in r.message


def test_no_exhaustion_diagnosis_for_the_linear_form_or_elastic_points():
    lin = case_material(CASES["linear-compression"], CASES["linear-compression"].reference)
    sig_tr = np.array([[-200.0, 0.0, 0.0, 50.0, 0.0, 0.0]])
    out = K.work_exhaustion(
        lin._kernel_params,
        lin.yield_function.kernel_params,
        lin.potential.kernel_params,
        sig_tr,
        np.zeros(1),
    )
    assert not out[0][0] and np.isinf(out[1][0])
    assert lin.failure_reason(np.zeros((1, 6)), sig_tr, np.zeros((1, 7)), np.ones(1, bool)) == ""

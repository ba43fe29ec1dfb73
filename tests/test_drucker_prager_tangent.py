"""Extended Drucker-Prager: consistent tangent against finite differences of the return map,
isotropy, and the von Mises limit.

Finite differences are central, with a step relative to the increment's largest component:
1e-6 for elastic and generic plastic states and 1e-5 at the tip/apex, where the tangent is
two orders smaller than E so the same round-off in the stress weighs 100x more; the truncation
error stays < 1e-8 either way. Comparisons are Frobenius-norm relative per point.
"""

import math

import numpy as np
import pytest

from problems.materials import drucker_prager as dp
from problems.materials.invariants import M_VEC, mises
from problems.materials.verification import (
    fd_tangent,
    relative_difference,
    rotation_matrix,
    voigt_rotations,
)
from tests.support import VARIANTS, material
from tests.test_drucker_prager import apex_trials, is_apex, random_deviators, trial_strain

TOL = 1e-6


def _yielded_states(mat, n, rng):
    """(stress, state) of n points that yielded once: on the surface with eqps > 0."""
    s0 = mat.law.sigma0
    de = rng.normal(size=(n, 6)) * 4.0 * s0 / mat.E
    de[:, :3] -= 1.0 * s0 / mat.E  # mostly compressive: keeps the hyperbolic tips out of this set
    first = mat.update(de, np.zeros((n, 6)), mat.initial_state(n))
    keep = first.ok & (first.state[:, 0] > 0)
    return first.stress[keep], first.state[keep]


def _check(mat, de, sig, st, rel_step):
    up = mat.update(de, sig, st)
    assert up.ok.all()
    err = relative_difference(fd_tangent(mat, de, sig, st, rel_step), up.tangent)
    return up, err


@pytest.mark.parametrize("form,hardening", VARIANTS)
def test_tangent_matches_finite_differences(form, hardening):
    rng = np.random.default_rng(100 + VARIANTS.index((form, hardening)))
    mat = material(form, hardening)
    s0 = mat.law.sigma0

    # 1. elastic states: from yielded points, small unloading-biased increments
    sig, st = _yielded_states(mat, 160, rng)
    de = rng.normal(size=sig.shape) * 0.05 * s0 / mat.E
    f_trial = mat.yield_value(sig + de @ mat.stiffness.T, st[:, 0])
    elastic = f_trial < -1e-3 * s0
    assert elastic.sum() >= 10
    up, err = _check(mat, de[elastic], sig[elastic], st[elastic], 1e-6)
    np.testing.assert_array_equal(up.tangent, np.broadcast_to(mat.stiffness, up.tangent.shape))
    assert err.max() < TOL

    # 2. plastic states: continued loading from yielded points, away from the yield onset
    de = rng.normal(size=sig.shape) * 1.5 * s0 / mat.E
    f_trial = mat.yield_value(sig + de @ mat.stiffness.T, st[:, 0])
    plastic = f_trial > 1e-2 * s0
    up, err = _check(mat, de[plastic], sig[plastic], st[plastic], 1e-6)
    went = (up.state[:, 0] > st[plastic, 0]) & (
        mises(up.stress) > 0.1 * mises(sig[plastic] + de[plastic] @ mat.stiffness.T)
    )
    assert went.sum() >= 20
    assert err[went].max() < TOL

    # 3. near the apex / tip: hydrostatic tension beyond the apex plus a deviator
    n = 60
    if form == "linear":
        trials = apex_trials(mat, n, rng, (0.2, 2.0), (0.0, 2.0))
        up, err = _check(
            mat, trial_strain(mat, trials), np.zeros((n, 6)), mat.initial_state(n), 1e-5
        )
        apex = is_apex(up.stress)
        near = ~apex & (mises(up.stress) < 0.5 * mises(trials))
        assert apex.sum() >= 10 and near.sum() >= 5
        checked = apex | near
        # at the apex the tangent is volumetric:
        # K_b d_hat c H / (K_b tan psi tan beta + d_hat c H) m m
        yf = mat.yield_function
        dhcH = yf.d_hat * mat.eqps_rule.c * mat.law.H
        k_alg = (
            mat.bulk_modulus
            * dhcH
            / (mat.bulk_modulus * mat.potential.tan_psi * yf.tan_beta + dhcH)
        )
        np.testing.assert_allclose(
            up.tangent[apex], np.broadcast_to(k_alg * np.outer(M_VEC, M_VEC), (apex.sum(), 6, 6))
        )
    else:
        # trial p beyond the tension strength, small q: returns to within a few % of q = 0
        pt = (
            mat.params["pt0"]
            if form == "hyperbolic"
            else mat.yield_function.tension_strength(s0)[0]
        )
        p_tr = -pt - rng.uniform(0.2, 3.0, n) * s0
        trials = -p_tr[:, None] * M_VEC + rng.uniform(0.0, 2.0, n)[:, None] * s0 * random_deviators(
            n, rng
        )
        up, err = _check(
            mat, trial_strain(mat, trials), np.zeros((n, 6)), mat.initial_state(n), 1e-5
        )
        near = (up.state[:, 0] > 0) & (mises(up.stress) < 0.05 * mises(trials))
        assert near.sum() >= 30
        checked = near
    assert err[checked].max() < TOL


@pytest.mark.parametrize(
    "form,hardening", [("linear", "compression"), ("linear", "tension"), ("hyperbolic", "shear")]
)
def test_tangent_is_non_symmetric_unless_associated(form, hardening):
    rng = np.random.default_rng(8)
    for psi, symmetric in ((15.0, False), (35.0, form == "linear")):
        mat = material(form, hardening, psi=psi)
        sig, st = _yielded_states(mat, 40, rng)
        # proportional reloading with some noise: continued plastic flow
        de = trial_strain(mat, 0.3 * sig) + rng.normal(size=sig.shape) * 1e-5
        up = mat.update(de, sig, st)
        D = up.tangent[(up.state[:, 0] > st[:, 0]) & ~is_apex(up.stress)]  # the apex tangent is m m
        assert len(D) >= 10
        asym = np.linalg.norm(D - D.transpose(0, 2, 1), axis=(1, 2)) / np.linalg.norm(
            D, axis=(1, 2)
        )
        if symmetric:  # psi = beta: associated flow, symmetric algorithmic tangent
            assert asym.max() < 1e-10
        else:
            assert asym.min() > 1e-3


@pytest.mark.parametrize("form,hardening", VARIANTS)
def test_isotropy(form, hardening):
    """Rotating the old stress and the strain increment rotates the new stress and the
    tangent, and leaves eqps unchanged."""
    rng = np.random.default_rng(3)
    mat = material(form, hardening)
    sig, st = _yielded_states(mat, 40, rng)
    de = rng.normal(size=sig.shape) * 2.0 * mat.law.sigma0 / mat.E
    base = mat.update(de, sig, st)
    assert (base.state[:, 0] > st[:, 0]).sum() >= 10
    Ts, Te = voigt_rotations(rotation_matrix([0.3, -1.0, 0.6], 1.1))
    rot = mat.update(de @ Te.T, sig @ Ts.T, st)
    scale = np.abs(base.stress).max()
    np.testing.assert_allclose(rot.stress, base.stress @ Ts.T, rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(rot.state[:, 0], base.state[:, 0], rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose(rot.tangent, Ts @ base.tangent @ Ts.T, rtol=0, atol=1e-8 * mat.E)


def _von_mises_return(de, sig_n, eqps_n, E, nu, sigma0, H):
    """Closed-form radial return of J2 plasticity with linear hardening (reference)."""
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    G = E / (2 * (1 + nu))
    eps = de * np.array([1, 1, 1, 0.5, 0.5, 0.5])
    tr = eps[:, :3].sum(axis=1)
    sig_tr = sig_n + 2 * G * eps + lam * tr[:, None] * M_VEC
    q_tr = mises(sig_tr)
    f = q_tr - (sigma0 + H * eqps_n)
    dl = np.maximum(f, 0.0) / (3 * G + H)
    mean = sig_tr[:, :3].mean(axis=1)
    dev = sig_tr - mean[:, None] * M_VEC
    return mean[:, None] * M_VEC + dev * (1 - 3 * G * dl / q_tr)[:, None], eqps_n + dl


def test_linear_form_reduces_to_von_mises():
    """K = 1, beta -> 0, psi = 0, compression hardening: d = sigma_c, t = q, c = 1."""
    E, nu, s0, H = 30_000.0, 0.2, 20.0, 1_500.0
    mat = dp.make_material(
        "linear",
        "compression",
        {"E": E, "nu": nu, "beta": 1e-9, "K": 1.0, "psi": 0.0, "sigma0": s0, "H": H},
    )
    rng = np.random.default_rng(6)
    n = 200
    sig_n = rng.normal(size=(n, 6)) * 5.0
    eqps_n = rng.uniform(0, 2e-3, n)
    state = mat.initial_state(n)
    state[:, 0] = eqps_n
    de = rng.normal(size=(n, 6)) * 1e-3
    up = mat.update(de, sig_n, state)
    ref_sig, ref_eqps = _von_mises_return(de, sig_n, eqps_n, E, nu, s0, H)
    assert (ref_eqps > eqps_n).sum() > n // 2
    np.testing.assert_allclose(up.stress, ref_sig, rtol=0, atol=1e-8 * np.abs(ref_sig).max())
    np.testing.assert_allclose(up.state[:, 0], ref_eqps, rtol=1e-8, atol=1e-14)
    # and its tangent is that of the J2 return (finite differences of the closed form)
    h = 1e-6 * np.abs(de).max(axis=1)
    fd = np.empty((n, 6, 6))
    for k in range(6):
        e = np.eye(6)[k] * h[:, None]
        fd[:, :, k] = (
            _von_mises_return(de + e, sig_n, eqps_n, E, nu, s0, H)[0]
            - _von_mises_return(de - e, sig_n, eqps_n, E, nu, s0, H)[0]
        ) / (2 * h[:, None])
    assert relative_difference(up.tangent, fd).max() < TOL
    assert math.isclose(mat.eqps_rule.c, 1.0) and math.isclose(
        mat.yield_function.d_hat, 1.0, rel_tol=1e-10
    )

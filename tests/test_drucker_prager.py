"""Extended Drucker-Prager: hardening tests, return-mapping properties, apex, failure flags."""

import math

import numpy as np
import pytest

from problems.materials import drucker_prager as dp
from problems.materials.drucker_prager import FORMS
from problems.materials.hardening import HARDENINGS
from problems.materials.invariants import M_VEC, deviator, mises, pressure
from problems.materials.point_driver import run_material_point
from problems.materials.verification import typical_parameters
from tests.support import VARIANTS, material

PATH = {"compression": "uniaxial-compression", "tension": "uniaxial-tension", "shear": "shear"}


def _alternative(form, hardening):
    """A second parameter set away from the typical one (stiffer, steeper, other K/psi/b)."""
    over = {
        "E": 42_000.0,
        "sigma0": typical_parameters(form, hardening)["sigma0"] * 1.3,
        "H": 400.0,
        "psi": 25.0,
    }
    if form == "linear":
        over.update(K=0.778, beta=28.0)
    elif form == "hyperbolic":
        over.update(beta=25.0, pt0=2.0 if hardening != "tension" else 3.0)
    else:
        over.update(b=1.8, a=0.04)
    return over


@pytest.mark.parametrize("alternative", [False, True])
@pytest.mark.parametrize("form,hardening", VARIANTS)
def test_hardening_test_yields_at_sigma0_with_slope_H(form, hardening, alternative):
    """In its own hardening test each variant is elastic up to sigma0, then sigma_bar(eqps) =
    sigma0 + H eqps exactly, with eqps the test's plastic strain measure (|eps11_pl|, eps11_pl or
    gamma_pl/sqrt(3))."""
    mat = material(form, hardening, **(_alternative(form, hardening) if alternative else {}))
    s0, H, E, G = mat.law.sigma0, mat.law.H, mat.E, mat.shear_modulus
    modulus = G if hardening == "shear" else E
    # no step lands on sigma0
    res = run_material_point(mat, PATH[hardening], 4.0 * s0 / modulus, 37)
    eps, sig, eqps = (
        np.abs(res.column("eps_axial")),
        np.abs(res.column("sig_axial")),
        res.column("eqps"),
    )
    plastic = eqps > 0
    assert 15 <= plastic.sum() <= 35  # both regimes are exercised
    # elastic part: Hooke, below sigma0; the first plastic step starts from sigma0
    np.testing.assert_allclose(sig[~plastic], modulus * eps[~plastic], rtol=1e-9)
    assert sig[~plastic].max() < s0 < sig[plastic].min()
    # post-yield: intercept sigma0 and slope H to 1e-6 relative
    slope, intercept = np.polyfit(eqps[plastic], sig[plastic], 1)
    assert slope == pytest.approx(H, rel=1e-6)
    assert intercept == pytest.approx(s0, rel=1e-6)
    np.testing.assert_allclose(sig[plastic], s0 + H * eqps[plastic], rtol=1e-8)
    # eqps is the test's plastic strain measure
    plastic_strain = eps - sig / modulus
    measure = plastic_strain / math.sqrt(3.0) if hardening == "shear" else plastic_strain
    np.testing.assert_allclose(eqps, np.where(plastic, measure, 0.0), rtol=1e-7, atol=1e-12)
    # the test's other stresses stay zero
    other = np.delete(res.stress, 5 if hardening == "shear" else 0, axis=1)
    assert np.abs(other).max() < 1e-8 * s0


def _random_plastic_states(mat, n, rng, scale=1.0, compressive=False):
    """Points that yielded once (eqps > 0 on the surface) and then get a second random increment.

    compressive: increments without volume increase, so that no trial lies beyond the
    hydrostatic tension strength (which a non-dilatant hyperbolic/exponent material cannot
    return from: its flow has no volumetric part there).
    """
    s0 = mat.law.sigma0

    def increments(size):
        de = rng.normal(size=(n, 6)) * size * s0 / mat.E * scale
        if compressive:
            tr = de[:, :3].sum(axis=1)
            de[:, :3] -= ((tr + np.abs(tr)) / 3.0)[:, None]
        return de

    first = mat.update(increments(4.0), np.zeros((n, 6)), mat.initial_state(n))
    assert first.ok.all()
    return increments(2.0), first.stress, first.state


@pytest.mark.parametrize("psi", [0.0, 15.0])
@pytest.mark.parametrize("form,hardening", VARIANTS)
def test_return_lands_on_the_surface_along_dG(form, hardening, psi):
    """After every plastic return F = 0; the plastic strain increment is dlambda dG/dsigma at the
    end point (backward Euler) with dlambda > 0; psi > 0 dilates, psi = 0 is isochoric; eqps
    follows its rule (c dlambda, or plastic-work equivalence)."""
    rng = np.random.default_rng(11)
    mat = material(form, hardening, psi=psi)
    n = 300
    de, sig_n, st_n = _random_plastic_states(
        mat, n, rng, compressive=(psi == 0.0 and form != "linear")
    )
    up = mat.update(de, sig_n, st_n)
    assert up.ok.all()
    d_eqps = up.state[:, 0] - st_n[:, 0]
    q = mises(up.stress)
    smooth = (d_eqps > 0) & (q > 1e-6 * mat.law.sigma0)
    assert smooth.sum() > n // 8
    F = mat.yield_value(up.stress[smooth], up.state[smooth, 0])
    assert np.abs(F).max() < 1e-10 * np.abs(up.stress[smooth]).max()
    d_ep = up.state[smooth, 1:] - st_n[smooth, 1:]
    g = mat.flow_direction(up.stress[smooth])
    dlam = np.einsum("ni,ni->n", d_ep, g) / np.einsum("ni,ni->n", g, g)
    assert (dlam > 0).all()
    np.testing.assert_allclose(d_ep, dlam[:, None] * g, rtol=0, atol=1e-9 * np.abs(d_ep).max())
    vol = d_ep[:, :3].sum(axis=1)
    if psi > 0:
        assert (vol > 0).all()
        np.testing.assert_allclose(vol, dlam * math.tan(math.radians(psi)), rtol=1e-8)
    else:
        assert np.abs(vol).max() < 1e-10 * np.abs(d_ep).max()
    if form == "linear":
        np.testing.assert_allclose(d_eqps[smooth], mat.eqps_rule.c * dlam, rtol=1e-9)
    else:  # q_hat sigma_bar d eqps = sigma : d eps_pl
        sbar = mat.yield_stress(up.state[smooth, 0])
        work = np.einsum("ni,ni->n", up.stress[smooth], d_ep)
        np.testing.assert_allclose(
            mat.eqps_rule.q_hat * sbar * d_eqps[smooth], work, rtol=1e-8, atol=1e-14 * sbar.max()
        )


def is_apex(stress):
    """Exactly hydrostatic stresses (the apex return builds them as -p I)."""
    return np.all(stress[:, 3:] == 0.0, axis=1) & np.all(stress[:, :3] == stress[:, [0]], axis=1)


def trial_strain(mat, sig_trial):
    """The strain increment (from zero stress) whose elastic trial stress is sig_trial."""
    return np.linalg.solve(mat.stiffness, np.asarray(sig_trial, float).T).T


def random_deviators(n, rng):
    """Random deviatoric stress directions with q = 1, (n, 6)."""
    s = deviator(rng.normal(size=(n, 6)))
    return s / mises(s)[:, None]


def apex_trials(mat, n, rng, beyond, spread):
    """Trial stresses of the linear cone beyond its apex: p_trial = p_apex - beyond * sigma0 and
    q_trial = spread * 3 G dlambda_apex (the apex is certain for spread <= K, impossible for
    spread > 1), with beyond and spread drawn uniformly from the given ranges."""
    yf, s0 = mat.yield_function, mat.law.sigma0
    u = rng.uniform(*beyond, n)
    v = rng.uniform(*spread, n)
    p_apex = -yf.d_hat * s0 / yf.tan_beta
    den = (
        mat.bulk_modulus * mat.potential.tan_psi * yf.tan_beta
        + yf.d_hat * mat.eqps_rule.c * mat.law.H
    )
    dlam = u * s0 * yf.tan_beta / den
    q = v * 3.0 * mat.shear_modulus * dlam
    return -(p_apex - u * s0)[:, None] * M_VEC + q[:, None] * random_deviators(n, rng)


@pytest.mark.parametrize("K", [0.778, 0.85, 1.0])
@pytest.mark.parametrize("hardening", HARDENINGS)
def test_linear_cone_returns_to_its_apex(hardening, K):
    """Deep hydrostatic tension returns the linear cone to its apex: hydrostatic stress at
    p = -d(sigma_bar)/tan(beta), all deviatoric trial strain plastic, volumetric plastic strain
    dlambda tan(psi) with d eqps = c dlambda; the apex is chosen only when the trial deviator is
    inside the apex's cone of flow directions (K = 1: q_trial <= 3 G dlambda)."""
    rng = np.random.default_rng(5)
    mat = material("linear", hardening, K=K)
    n = 200
    de = trial_strain(mat, apex_trials(mat, n, rng, (0.1, 2.0), (0.0, 1.3)))
    up = mat.update(de, np.zeros((n, 6)), mat.initial_state(n))
    assert up.ok.all()
    apex = is_apex(up.stress)
    assert 20 < apex.sum() < n  # both apex and smooth returns occur
    tb, tp, c = mat.yield_function.tan_beta, mat.potential.tan_psi, mat.eqps_rule.c
    eqps = up.state[apex, 0]
    p = pressure(up.stress[apex])
    np.testing.assert_allclose(
        p, -mat.yield_function.d_hat * mat.yield_stress(eqps) / tb, rtol=1e-12
    )
    d_ep = up.state[apex, 1:]
    np.testing.assert_allclose(
        deviator(d_ep * np.array([1, 1, 1, 0.5, 0.5, 0.5])) * np.array([1, 1, 1, 2, 2, 2]),
        deviator(de[apex] * np.array([1, 1, 1, 0.5, 0.5, 0.5])) * np.array([1, 1, 1, 2, 2, 2]),
        atol=1e-14,
    )
    dlam = d_ep[:, :3].sum(axis=1) / tp
    np.testing.assert_allclose(eqps, c * dlam, rtol=1e-10)
    # the smooth returns are genuinely off the apex and on the surface
    q = mises(up.stress[~apex])
    assert q.min() > 0.0
    assert (
        np.abs(mat.yield_value(up.stress[~apex], up.state[~apex, 0])).max()
        < 1e-10 * mat.law.sigma0 * 10
    )
    if K == 1.0:
        q_tr = mises(de @ mat.stiffness.T)
        np.testing.assert_array_less(q_tr[apex], 3.0 * mat.shear_modulus * dlam * (1 + 1e-12))
    # continuity across the apex boundary: stretch a deviator from inside to outside the apex set
    base = apex_trials(mat, 1, np.random.default_rng(1), (1.0, 1.0), (0.0, 0.0))[0]
    unit = random_deviators(1, np.random.default_rng(2))[0]
    q_apex = apex_trials(mat, 1, np.random.default_rng(1), (1.0, 1.0), (1.0, 1.0))
    amps = np.linspace(0.0, 1.6, 301) * mises(q_apex)[0]
    out = mat.update(
        trial_strain(mat, base + amps[:, None] * unit), np.zeros((301, 6)), mat.initial_state(301)
    )
    at_apex = is_apex(out.stress)
    assert out.ok.all() and at_apex.any() and not at_apex.all()
    jumps = np.abs(np.diff(out.stress, axis=0)).max(axis=1)
    assert jumps.max() < 3.0 * np.median(jumps[jumps > 0]) + 1e-9


def test_hyperbolic_and_exponent_tips_need_no_apex_branch():
    """Their flow potential is smooth at q = 0: a purely hydrostatic trial returns to the tip at
    p = -pt(sigma_bar) with a purely volumetric plastic strain."""
    for form in ("hyperbolic", "exponent"):
        mat = material(form, "compression")
        de = np.array([[1e-3, 1e-3, 1e-3, 0, 0, 0]])
        up = mat.update(de, np.zeros((1, 6)), mat.initial_state(1))
        assert up.ok[0] and up.state[0, 0] > 0
        assert mises(up.stress)[0] < 1e-9
        np.testing.assert_allclose(up.state[0, 4:], 0.0, atol=1e-15)
        assert mat.yield_value(up.stress, up.state[0, 0])[0] == pytest.approx(0.0, abs=1e-10)


def test_unreturnable_points_are_flagged_not_raised():
    """psi = 0 and H = 0: no flow can bring the apex to a trial beyond it. The point is flagged
    (ok False) and keeps the trial stress, elastic tangent and old state; the others are fine."""
    mat = material("linear", "compression", psi=0.0, H=0.0)
    de = np.array(
        [[2e-3, 2e-3, 2e-3, 0, 0, 0], [-1e-3, 2e-4, 2e-4, 0, 0, 0], [1e-5, 0, 0, 0, 0, 0]]
    )
    st = mat.initial_state(3)
    up = mat.update(de, np.zeros((3, 6)), st)
    assert up.ok.tolist() == [False, True, True]
    np.testing.assert_allclose(up.stress[0], de[0] @ mat.stiffness.T)
    np.testing.assert_array_equal(up.tangent[0], mat.stiffness)
    np.testing.assert_array_equal(up.state[0], st[0])
    assert up.state[1, 0] > 0  # the uniaxial point did yield


def test_elastic_points_cost_no_newton_work(monkeypatch):
    mat = material("linear", "compression")
    calls = []
    original = dp.DruckerPrager._plastic_return
    monkeypatch.setattr(
        dp.DruckerPrager,
        "_plastic_return",
        lambda self, sig, *a: calls.append(len(sig)) or original(self, sig, *a),
    )
    rng = np.random.default_rng(2)
    de = rng.normal(size=(1000, 6)) * 1e-5  # all well inside the surface
    up = mat.update(de, np.zeros((1000, 6)), mat.initial_state(1000))
    assert calls == [] and up.ok.all()
    np.testing.assert_allclose(up.stress, de @ mat.stiffness.T, rtol=1e-12, atol=1e-14)
    de[::100] *= 300.0  # ten points now yield: only they reach the return mapping
    mat.update(de, np.zeros((1000, 6)), mat.initial_state(1000))
    assert calls == [10]


@pytest.mark.parametrize("form", FORMS)
def test_batch_equals_pointwise(form):
    rng = np.random.default_rng(4)
    mat = material(form, "compression")
    de, sig_n, st_n = _random_plastic_states(mat, 20, rng)
    batch = mat.update(de, sig_n, st_n)
    for i in range(0, 20, 4):
        one = mat.update(de[i : i + 1], sig_n[i : i + 1], st_n[i : i + 1])
        np.testing.assert_allclose(one.stress[0], batch.stress[i], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(one.tangent[0], batch.tangent[i], rtol=1e-9, atol=1e-9)

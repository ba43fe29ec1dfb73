"""Robust starting point for the return mapping of the hyperbolic and exponent forms.

Both forms have a von Mises (circular) deviatoric section and the flow potential
G = sqrt(e^2 + q^2) - p tan(psi), so with isotropic elasticity the backward-Euler return keeps
the deviator's direction and reduces to the meridional plane (p, q) with one unknown, the plastic
multiplier dlambda >= 0 (K_b bulk, G_s shear modulus, MPa)::

    p(dl)    = p_trial + K_b tan(psi) dl                     (volumetric flow)
    q(dl)    : q (1 + 3 G_s dl / sqrt(e^2 + q^2)) = q_trial   (deviatoric flow, radial)
    eqps(dl) : q_hat sigma_bar(eqps) (eqps - eqps_n) = dl (q^2/sqrt(e^2+q^2) - p tan(psi))
    f(dl)    = F(p, q, sigma_bar(eqps)) = 0

Each inner relation is solved exactly (q by a monotone Newton iteration, eqps by the quadratic
formula) and f is bracketed and solved by the Illinois variant of regula falsi, which cannot
diverge however far the trial state lies outside the surface or however sharp the hyperbola's
tip (e = 0.1 sigma0 tan(psi) is a fraction of an MPa). The full-space Newton of
:mod:`drucker_prager` then polishes this point and provides the consistent tangent.
"""
from __future__ import annotations

import numpy as np


def radial_q(q_trial: np.ndarray, c: np.ndarray, e: float) -> np.ndarray:
    """Solve ``q (1 + c / sqrt(e^2 + q^2)) = q_trial`` for q in [0, q_trial] (MPa), c = 3 G dl.

    The left side is increasing and concave in q, so Newton started left of the root
    (q0 = q_trial / (1 + c/e), where the left side is <= q_trial) climbs monotonically to it.
    """
    q = q_trial / (1.0 + c / e)
    for _ in range(100):
        R = np.sqrt(e * e + q * q)
        phi = q * (1.0 + c / R) - q_trial
        dphi = 1.0 + c * e * e / R**3
        dq = -phi / dphi
        q = q + dq
        if np.all(np.abs(dq) <= 1e-15 * np.maximum(q_trial, e)):
            break
    return np.minimum(q, q_trial)


def work_eqps_increment(dl, w, sbar_n, H, q_hat):
    """Solve ``q_hat (sbar_n + H u) u = dl w`` for u = d eqps >= 0 (the root that vanishes with
    dl); NaN where it has no real root (plastic work rate w strongly negative)."""
    rhs = dl * w / q_hat
    disc = sbar_n * sbar_n + 4.0 * H * rhs
    with np.errstate(invalid="ignore"):
        return np.where(disc >= 0.0, 2.0 * rhs / (sbar_n + np.sqrt(np.maximum(disc, 0.0))), np.nan)


def meridional_return(p_tr, q_tr, eqps_n, *, bulk, shear, tan_psi, e, q_hat, law, yield_pq, f_tol):
    """Backward-Euler return in the meridional plane for m trial states with f(0) > 0.

    yield_pq(p, q, sbar) -> F (MPa) is the yield function in invariants; f_tol (m,) the
    tolerance on |F| in MPa. Returns p, q, eqps, dlambda and a convergence flag (m,).
    """
    sbar_n = law.yield_stress(eqps_n)

    def state(dl, i):
        q = radial_q(q_tr[i], 3.0 * shear * dl, e)
        p = p_tr[i] + bulk * tan_psi * dl
        w = q * q / np.sqrt(e * e + q * q) - p * tan_psi
        eqps = eqps_n[i] + work_eqps_increment(dl, w, sbar_n[i], law.H, q_hat)
        return p, q, eqps

    def f(dl, i):
        p, q, eqps = state(dl, i)
        with np.errstate(invalid="ignore"):
            return yield_pq(p, q, law.yield_stress(eqps))

    m = p_tr.shape[0]
    every = np.arange(m)
    lo, f_lo = np.zeros(m), f(np.zeros(m), every)
    # bracket: the multiplier that would relax the trial excess by shear alone sets the scale
    hi = np.maximum(f_lo, 1e-12) / (3.0 * shear)
    f_hi = f(hi, every)
    for _ in range(200):
        # f > 0: the root lies further out. f = NaN: eqps has no real root there, i.e. the plastic
        # work turned strongly negative far beyond the return; come back towards lo.
        grow = np.flatnonzero(f_hi > 0.0)
        back = np.flatnonzero(np.isnan(f_hi))
        if grow.size == 0 and back.size == 0:
            break
        lo[grow], f_lo[grow] = hi[grow], f_hi[grow]
        hi[grow] *= 4.0
        hi[back] = 0.5 * (lo[back] + hi[back])
        moved = np.concatenate([grow, back])
        f_hi[moved] = f(hi[moved], moved)
    ok = np.isfinite(f_lo) & np.isfinite(f_hi) & (f_hi <= 0.0)

    a, fa, b, fb = lo, f_lo, hi, f_hi
    act = np.flatnonzero(ok & (np.abs(fb) > f_tol))
    for _ in range(200):
        if act.size == 0:
            break
        A, FA, B, FB = a[act], fa[act], b[act], fb[act]
        C = B - FB * (B - A) / (FB - FA)
        C = np.where((C > np.minimum(A, B)) & (C < np.maximum(A, B)), C, 0.5 * (A + B))
        FC = f(C, act)
        flip = FC * FB < 0.0  # root between B and C: the old B becomes the other end
        A = np.where(flip, B, A)
        FA = np.where(flip, FB, 0.5 * FA)  # Illinois: halve the stale end's value
        a[act], fa[act], b[act], fb[act] = A, FA, C, FC
        done = (np.abs(FC) <= f_tol[act]) | ~np.isfinite(FC) | (np.abs(A - C) <= 1e-16 * np.abs(C))
        act = act[~done]
    p, q, eqps = state(b, every)
    ok &= np.isfinite(fb) & np.isfinite(eqps)
    return p, q, eqps, b, ok

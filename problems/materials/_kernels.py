"""Compiled (numba) per-point kernels of the extended Drucker-Prager family: the third invariant
and its derivatives, the yield functions and flow potentials with the derivatives the return
mapping needs, the apex return of the linear cone, the meridional-plane start, the Newton
return mapping with its consistent tangent, and the parameter sensitivities of the update
(direct differentiation of the converged return).

This module is the one implementation of that arithmetic. The dataclasses of
:mod:`yield_surfaces`, the functions of :mod:`invariants` and the material of
:mod:`drucker_prager` hold the parameters and call the vectorised entry points at the bottom of
this file; the equations are documented there and in ``docs/drucker_prager.md``.

Why one file: numba's on-disk cache (``cache=True``) is invalidated only when the file that
defines a cached function changes, not when a function it calls from *another* file does, so
kernels spread over several modules could silently keep running stale compiled code (the
sensitivity kernels call the residual, the potentials and the apex return, hence live here too).

Conventions are those of :mod:`invariants`: Voigt ``[xx, yy, zz, yz, xz, xy]`` with tensor shear
components for stresses; gradients with respect to the six Voigt components are strain-like
(engineering shear). Everything is scalar code looping over points (no temporaries); the first
call of each entry point compiles it (a few seconds for :func:`plastic_return`) and stores the
machine code next to this file, later processes load it in milliseconds.

Parameter vectors (built by the dataclasses, see ``kernel_params``):

* yield surface ``yp`` (6): ``[code, ...]`` with code LINEAR ``[tan_beta, A, B, d_hat, K]``,
  HYPERBOLIC ``[tan_beta, l0, q_hat, p_hat, 0]``, EXPONENT ``[a, b, q_hat, p_hat, 0]``;
* flow potential ``gp`` (4): CONE ``[code, tan_psi, A, B]``, HYPERBOLA ``[code, tan_psi, e, 0]``;
* material ``mp``: see the ``M_*`` indices below;
* sensitivities: the chain-rule matrix ``dtheta`` (TH_SIZE, P) from the physical parameters to
  the kernel parameters theta, rows indexed by ``TH_*`` (built by :mod:`ddm`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from problems.numba_cache import heal as heal_numba_cache

# numpy semantics: x/0 gives inf/nan, no raise
_JIT = dict(cache=True, nogil=True, error_model="numpy")

#: yield-surface codes (``yp[0]``)
LINEAR, HYPERBOLIC, EXPONENT = 0, 1, 2
#: flow-potential codes (``gp[0]``): the linear form's cone G = t - p tan(psi), the hyperbola
#: G = sqrt(e^2 + q^2) - p tan(psi)
CONE, HYPERBOLA = 0, 1
#: equivalent-plastic-strain rules (``mp[M_RULE]``): d eqps = c dlambda, or plastic-work equivalence
PROPORTIONAL, WORK = 0, 1
#: material vector ``mp``: E, nu (elasticity), sigma0, H (hardening sigma0 + H eqps), the rule and
#: its constant (c, or q_hat), the local Newton tolerance and iteration limit
M_E, M_NU, M_S0, M_H, M_RULE, M_RULE_C, M_TOL, M_MAXIT = range(8)
M_SIZE = 8
#: kernel parameters theta (rows of the chain-rule matrix ``dtheta`` (TH_SIZE, P) that maps the
#: physical parameters to them): E, nu, sigma0, H, the eqps-rule constant of ``mp``, then
#: ``yp[1:6]`` and ``gp[1:4]``
TH_E, TH_NU, TH_S0, TH_H, TH_C = range(5)
TH_Y, TH_G = 5, 10
TH_SIZE = 13
# column of d R / d eqps_n in the partials array, after the TH_SIZE parameter columns
_TH_EQPS_N = TH_SIZE

# Below this q (MPa) the deviator is treated as zero: it only guards 0/0 in terms that vanish
# with the deviator (the return mapping never iterates that close to an apex). Small enough to be
# meaningless in MPa, large enough that 1/q^4 does not overflow.
_Q_TINY = 1e-60
_INF = math.inf


@njit(**_JIT)
def _finite(x):
    """x is neither inf nor NaN (cheaper to compile than np.isfinite on a scalar)."""
    return abs(x) < _INF


@njit(**_JIT)
def _inv(q):
    """1/q, and 0 where q is (numerically) zero: every 1/q^k term multiplies a deviator power."""
    return 1.0 / q if q > _Q_TINY else 0.0


# Hot-path data are tuples (registers), not array views: a view costs reference counting.


@njit(**_JIT)
def _comb(a, x, b, y):
    """a x + b y for 6-tuples."""
    return (
        a * x[0] + b * y[0],
        a * x[1] + b * y[1],
        a * x[2] + b * y[2],
        a * x[3] + b * y[3],
        a * x[4] + b * y[4],
        a * x[5] + b * y[5],
    )


@njit(**_JIT)
def _plus_normal(c, x):
    """x + c m (m = [1, 1, 1, 0, 0, 0]) for a 6-tuple."""
    return (x[0] + c, x[1] + c, x[2] + c, x[3], x[4], x[5])


# --------------------------------------------------------------------------------------------
# Invariants (p = -tr/3 compression positive, s deviator, J2 = s:s/2, J3 = det s)
# --------------------------------------------------------------------------------------------


@njit(**_JIT)
def _deviator(v):
    """p and the deviator (6-tuple) of the stress v[:6]."""
    p = -(v[0] + v[1] + v[2]) / 3.0
    return p, (v[0] + p, v[1] + p, v[2] + p, v[3], v[4], v[5])


@njit(**_JIT)
def _j2(s):
    return 0.5 * (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]) + s[3] * s[3] + s[4] * s[4] + s[5] * s[5]


@njit(**_JIT)
def _j3(s):
    xx, yy, zz, yz, xz, xy = s
    return xx * yy * zz + 2.0 * yz * xz * xy - xx * yz * yz - yy * xz * xz - zz * xy * xy


@njit(**_JIT)
def _grad_j2(s):
    """d J2 / d sigma: the deviator with engineering (doubled) shear entries."""
    return (s[0], s[1], s[2], 2.0 * s[3], 2.0 * s[4], 2.0 * s[5])


@njit(**_JIT)
def _grad_j3(s, J2):
    """d J3 / d sigma = dev(s.s) with doubled shear entries."""
    xx, yy, zz, yz, xz, xy = s
    c = (2.0 / 3.0) * J2
    return (
        xx * xx + xy * xy + xz * xz - c,
        xy * xy + yy * yy + yz * yz - c,
        xz * xz + yz * yz + zz * zz - c,
        2.0 * (xy * xz + yy * yz + yz * zz),
        2.0 * (xx * xz + xy * yz + xz * zz),
        2.0 * (xx * xy + xy * yy + xz * yz),
    )


@njit(**_JIT)
def _add_hess_j3(s, f, H):
    """H[:6, :6] += f d2J3/dsigma^2, which is linear in s: P Hd P with Hd the Hessian of det(s)
    in the deviator's Voigt components and P the deviatoric projector (identity on shear)."""
    x, y, z, yz, xz, xy = s
    # normal block of Hd: [[0, z, y], [z, 0, x], [y, x, 0]]; P Hd P = Hd - (r_i + r_j)/3 + S/9
    r0, r1, r2 = z + y, z + x, y + x
    S9 = (r0 + r1 + r2) / 9.0
    H[0, 0] += f * (S9 - 2.0 * r0 / 3.0)
    H[1, 1] += f * (S9 - 2.0 * r1 / 3.0)
    H[2, 2] += f * (S9 - 2.0 * r2 / 3.0)
    a = f * (z - (r0 + r1) / 3.0 + S9)
    H[0, 1] += a
    H[1, 0] += a
    a = f * (y - (r0 + r2) / 3.0 + S9)
    H[0, 2] += a
    H[2, 0] += a
    a = f * (x - (r1 + r2) / 3.0 + S9)
    H[1, 2] += a
    H[2, 1] += a
    # mixed block: P diag(-2 yz, -2 xz, -2 xy)
    m = (-2.0 * f * yz, -2.0 * f * xz, -2.0 * f * xy)
    for i in range(3):
        for j in range(3):
            a = m[j] * ((1.0 if i == j else 0.0) - 1.0 / 3.0)
            H[i, j + 3] += a
            H[j + 3, i] += a
    H[3, 3] -= 2.0 * f * x
    H[4, 4] -= 2.0 * f * y
    H[5, 5] -= 2.0 * f * z
    a = 2.0 * f * xy
    H[3, 4] += a
    H[4, 3] += a
    a = 2.0 * f * xz
    H[3, 5] += a
    H[5, 3] += a
    a = 2.0 * f * yz
    H[4, 5] += a
    H[5, 4] += a


@njit(**_JIT)
def _add_hess_j2(a, H):
    """H[:6, :6] += a d2J2/dsigma^2 (deviatoric projector on the normal block, 2 on the shear
    diagonal)."""
    for i in range(3):
        for j in range(3):
            H[i, j] += a * ((1.0 if i == j else 0.0) - 1.0 / 3.0)
        H[i + 3, i + 3] += 2.0 * a


@njit(**_JIT)
def _lode_xi(s, J2):
    """(r/q)^3 = 27 J3 / (2 q^3) in [-1, 1] (0 where q = 0)."""
    q = math.sqrt(3.0 * J2)
    if not q > _Q_TINY:
        return 0.0
    return min(max(13.5 * _j3(s) / (q * q * q), -1.0), 1.0)


# --------------------------------------------------------------------------------------------
# Lode-dependent deviatoric measure of the linear form: t = A q + B J3 / q^2
# --------------------------------------------------------------------------------------------


@njit(**_JIT)
def _lode_t(A, B, s, J2):
    q = math.sqrt(3.0 * J2)
    qi = _inv(q)
    return A * q + B * _j3(s) * qi * qi


@njit(**_JIT)
def _lode(A, B, s, J2, hess, w, H):
    """t and dt/dsigma (6-tuple); if hess, also sets H[:6, :6] = w d2t/dsigma^2.

    With t(q, J3): dt = t_q dq + t_J dJ3, t_q = A - 2 B J3/q^3, t_J = B/q^2, and
    dq = 3/(2q) dJ2, d2q = 3/(2q) d2J2 - (1/q) dq dq, so
    ``d2t = t_J d2J3 + 3/(2q) t_q d2J2 + dq (x) v1 + dJ3 (x) v2`` with
    v1 = (t_qq - t_q/q) dq + t_qJ dJ3, v2 = t_qJ dq, t_qq = 6 B J3/q^4, t_qJ = -2 B/q^3.
    """
    q = math.sqrt(3.0 * J2)
    qi = _inv(q)
    gq = (
        1.5 * qi * s[0],
        1.5 * qi * s[1],
        1.5 * qi * s[2],
        3.0 * qi * s[3],
        3.0 * qi * s[4],
        3.0 * qi * s[5],
    )
    if B == 0.0:  # K = 1: t = q, no third-invariant terms
        if hess:
            c = w * qi
            for i in range(6):
                for j in range(6):
                    H[i, j] = -c * gq[i] * gq[j]
            _add_hess_j2(1.5 * w * qi, H)
        return q, gq
    J3 = _j3(s)
    gJ = _grad_j3(s, J2)
    qi2 = qi * qi
    t_q = A - 2.0 * B * J3 * qi2 * qi
    t_J = B * qi2
    if hess:
        c1 = w * (6.0 * B * J3 * qi2 * qi2 - t_q * qi)  # w (t_qq - t_q/q)
        c2 = w * (-2.0 * B * qi2 * qi)  # w t_qJ
        for i in range(6):
            for j in range(6):
                H[i, j] = gq[i] * (c1 * gq[j] + c2 * gJ[j]) + c2 * gJ[i] * gq[j]
        _add_hess_j3(s, w * t_J, H)
        _add_hess_j2(1.5 * w * t_q * qi, H)
    return A * q + B * J3 * qi2, _comb(t_q, gq, t_J, gJ)


# --------------------------------------------------------------------------------------------
# Yield functions F = phi(p, q, J3) - k(sigma_bar)
# --------------------------------------------------------------------------------------------


@njit(**_JIT)
def _strength(yp, sbar):
    """k(sigma_bar) and dk/dsigma_bar: linear d = d_hat sigma_bar; hyperbolic
    d' = sqrt(l0^2 + (q_hat sigma_bar)^2) - p_hat sigma_bar tan(beta); exponent
    pt = a (q_hat sigma_bar)^b - p_hat sigma_bar."""
    code = int(yp[0])
    if code == LINEAR:
        return yp[4] * sbar, yp[4]
    if code == HYPERBOLIC:
        tb, l0, qh, ph = yp[1], yp[2], yp[3], yp[4]
        root = math.sqrt(l0 * l0 + qh * sbar * qh * sbar)
        return root - ph * sbar * tb, qh * qh * sbar / root - ph * tb
    a, b, qh, ph = yp[1], yp[2], yp[3], yp[4]
    pw = a * (qh * sbar) ** b
    return pw - ph * sbar, b * pw / sbar - ph


@njit(**_JIT)
def _yield_pq(yp, p, q2, sbar):
    """F of the von Mises-section surfaces (hyperbolic, exponent) from p, q^2 and sigma_bar, with
    (dF/dq)/q, dF/dp and dF/dsigma_bar. Hyperbolic: F = sqrt(l0^2 + q^2) - p tan(beta) - d';
    exponent: F = a q^b - p - pt, whose (dF/dq)/q = a b q^(b-2) vanishes with q for b > 2 and is
    taken as 0 at q = 0 (the gradient multiplies the deviator)."""
    k, dk = _strength(yp, sbar)
    if int(yp[0]) == HYPERBOLIC:
        root = math.sqrt(yp[2] * yp[2] + q2)
        return root - p * yp[1] - k, 1.0 / root, -yp[1], -dk
    aqb = yp[1] * q2 ** (0.5 * yp[2])
    return aqb - p - k, (yp[2] * aqb / q2 if q2 > _Q_TINY * _Q_TINY else 0.0), -1.0, -dk


@njit(**_JIT)
def _yield_value(yp, s, p, J2, sbar):
    """F (MPa) from the deviator s, p and J2."""
    if int(yp[0]) == LINEAR:
        return _lode_t(yp[2], yp[3], s, J2) - p * yp[1] - _strength(yp, sbar)[0]
    return _yield_pq(yp, p, 3.0 * J2, sbar)[0]


@njit(**_JIT)
def _yield_gradient(yp, s, p, J2, sbar, H):
    """F, dF/dsigma (6-tuple) and dF/dsigma_bar (H: unused work array). dp/dsigma = -m/3 and
    dq/dsigma = 3/(2q) dJ2/dsigma."""
    if int(yp[0]) == LINEAR:
        tb = yp[1]
        k, dk = _strength(yp, sbar)
        t, gt = _lode(yp[2], yp[3], s, J2, False, 0.0, H)
        return t - p * tb - k, _plus_normal(tb / 3.0, gt), -dk
    F, Fq_q, Fp, Fs = _yield_pq(yp, p, 3.0 * J2, sbar)
    return F, _plus_normal(-Fp / 3.0, _comb(1.5 * Fq_q, _grad_j2(s), 0.0, s)), Fs


# --------------------------------------------------------------------------------------------
# Flow potentials G = t - p tan(psi) (cone) and sqrt(e^2 + q^2) - p tan(psi) (hyperbola)
# --------------------------------------------------------------------------------------------


@njit(**_JIT)
def _potential(gp, s, J2, hess, w, H):
    """dG/dsigma (6-tuple); if hess, also sets H[:6, :6] = w d2G/dsigma^2
    (singular at the cone's apex)."""
    if int(gp[0]) == CONE:
        g = _lode(gp[2], gp[3], s, J2, hess, w, H)[1]
    else:
        e = gp[2]
        root = max(math.sqrt(e * e + 3.0 * J2), _Q_TINY)
        gJ2 = _grad_j2(s)
        if hess:
            c = 2.25 * w / (root * root * root)
            for i in range(6):
                for j in range(6):
                    H[i, j] = -c * gJ2[i] * gJ2[j]
            _add_hess_j2(1.5 * w / root, H)
        g = _comb(1.5 / root, gJ2, 0.0, gJ2)
    return _plus_normal(gp[1] / 3.0, g)


@njit(**_JIT)
def _plastic_work_rate(gp, sig, s, p, J2, g):
    """w = sigma : dG/dsigma (plastic work per unit multiplier) and dw/dsigma (6-tuple), given
    g = dG/dsigma. Cone: w = G (degree-one homogeneous), dw = g. Hyperbola:
    w = q^2/R - p tan(psi), dw = g + (3/(2R)) (e^2/R^2) dJ2 (R = sqrt(e^2 + q^2))."""
    if int(gp[0]) == CONE:
        w = (
            sig[0] * g[0]
            + sig[1] * g[1]
            + sig[2] * g[2]
            + sig[3] * g[3]
            + sig[4] * g[4]
            + sig[5] * g[5]
        )
        return w, g
    e = gp[2]
    root = max(math.sqrt(e * e + 3.0 * J2), _Q_TINY)
    return 3.0 * J2 / root - p * gp[1], _comb(
        1.0, g, 1.5 * e * e / (root * root * root), _grad_j2(s)
    )


# --------------------------------------------------------------------------------------------
# Dense LU with partial pivoting of the 8 x 8 local systems
# --------------------------------------------------------------------------------------------


@njit(**_JIT)
def _lu8(A, piv):
    """In-place LU with row pivoting of A (8, 8); False if a pivot is zero or not finite."""
    for k in range(8):
        r = k
        big = abs(A[k, k])
        for i in range(k + 1, 8):
            v = abs(A[i, k])
            if v > big:
                big, r = v, i
        if not (big > 0.0 and big < _INF):
            return False
        piv[k] = r
        if r != k:
            for j in range(8):
                A[k, j], A[r, j] = A[r, j], A[k, j]
        inv = 1.0 / A[k, k]
        for i in range(k + 1, 8):
            f = A[i, k] * inv
            A[i, k] = f
            for j in range(k + 1, 8):
                A[i, j] -= f * A[k, j]
    return True


@njit(**_JIT)
def _lu8_solve(A, piv, b):
    """Solve in place with the factors of :func:`_lu8`; b (8, r). False if not finite."""
    r = b.shape[1]
    for k in range(8):
        if piv[k] != k:
            for c in range(r):
                b[k, c], b[piv[k], c] = b[piv[k], c], b[k, c]
    ok = True
    for c in range(r):
        for i in range(1, 8):
            acc = b[i, c]
            for j in range(i):
                acc -= A[i, j] * b[j, c]
            b[i, c] = acc
        for i in range(7, -1, -1):
            acc = b[i, c]
            for j in range(i + 1, 8):
                acc -= A[i, j] * b[j, c]
            b[i, c] = acc / A[i, i]
            ok = ok and abs(b[i, c]) < _INF
    return ok


# --------------------------------------------------------------------------------------------
# Return mapping
# --------------------------------------------------------------------------------------------


@njit(**_JIT)
def _residual(mp, yp, gp, x, st, eqps_n, R, J):
    """Residuals R (8) in MPa at x = [sigma (6), E dlambda, E eqps] for the trial stress st
    (6-tuple) and their Jacobian J (8, 8) with respect to x (always formed: the Jacobian-free
    variant would be one more compiled function for the rare backtracking steps).

    The stress residual is written in strain space and scaled by E,
    ``R1 = E C (sigma - sigma_trial) + (E dlambda) dG/dsigma``, so that its Jacobian
    ``E C + (E dlambda) d2G/dsigma2`` is symmetric and needs no product with D::

        R2 = F(sigma, sigma_bar(eqps))
        R3 = E (eqps - eqps_n) - c (E dlambda)                                   (proportional)
        R3 = (q_hat sigma_bar (E eqps - E eqps_n) - (E dlambda) sigma:dG/dsigma) / sigma0  (work)
    """
    E, nu, s0, Hh = mp[M_E], mp[M_NU], mp[M_S0], mp[M_H]
    lam, kap = x[6], x[7]
    dkap = kap - E * eqps_n
    sbar = s0 + Hh * kap / E
    p, s = _deviator(x)
    J2 = _j2(s)
    g = _potential(gp, s, J2, True, lam, J)  # J[:6, :6] = lam d2G/dsigma2
    d0, d1, d2 = x[0] - st[0], x[1] - st[1], x[2] - st[2]
    R[0] = d0 - nu * (d1 + d2) + lam * g[0]
    R[1] = d1 - nu * (d0 + d2) + lam * g[1]
    R[2] = d2 - nu * (d0 + d1) + lam * g[2]
    for i in range(3, 6):
        R[i] = 2.0 * (1.0 + nu) * (x[i] - st[i]) + lam * g[i]
    proportional, c = int(mp[M_RULE]) == PROPORTIONAL, mp[M_RULE_C]
    if proportional:
        R[7] = dkap - c * lam
    F, dF, dF_dsbar = _yield_gradient(yp, s, p, J2, sbar, J)
    R[6] = F
    for i in range(6):
        J[i, 6] = g[i]
        J[i, 7] = 0.0
        J[6, i] = dF[i]
    for i in range(3):
        for j in range(3):
            J[i, j] += 1.0 if i == j else -nu
        J[i + 3, i + 3] += 2.0 * (1.0 + nu)
    J[6, 6] = 0.0
    J[6, 7] = dF_dsbar * Hh / E
    if proportional:
        for j in range(6):
            J[7, j] = 0.0
        J[7, 6] = -c
        J[7, 7] = 1.0
    else:
        w, dw = _plastic_work_rate(gp, x, s, p, J2, g)
        R[7] = (c * sbar * dkap - lam * w) / s0
        for j in range(6):
            J[7, j] = -(lam / s0) * dw[j]
        J[7, 6] = -w / s0
        J[7, 7] = c * (sbar + Hh * dkap / E) / s0


@njit(**_JIT)
def _deviator_dot(a, b):
    """s_a : s_b of two Voigt deviators (tensor shear components)."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + 2.0 * (a[3] * b[3] + a[4] * b[4] + a[5] * b[5])


@njit(**_JIT)
def _polar_factor(xi, K):
    """m(xi) = max over Lode angles phi of cos(phi - phi_y) / h(phi), with cos 3 phi_y = xi the
    Lode measure (r/q)^3 of a deviator y and h(phi) = t/q at Lode angle phi.

    The gauge of y with respect to the subdifferential of t at s = 0 (the deviatoric flow
    directions the apex admits) is ``sup_s (y:s)/t(s) = 2/3 q_y m(xi)``; for K = 1 that set is a
    ball and m = 1, in general K <= m <= 1. The maximiser is bracketed on a grid around phi_y
    and polished by Newton steps on f'(phi) = 0 with analytic derivatives of f = cos(u)/h,
    u = phi - phi_y, h' = 3/2 (1 - 1/K) sin 3 phi, h'' = 9/2 (1 - 1/K) cos 3 phi.
    """
    if K == 1.0:
        return 1.0
    k1 = 1.0 - 1.0 / K
    k0 = 1.0 + 1.0 / K
    phi_y = math.acos(min(max(xi, -1.0), 1.0)) / 3.0
    best, u = -_INF, 0.0
    for i in range(361):
        off = -0.5 * math.pi + i * (math.pi / 360.0)
        v = math.cos(off) / (0.5 * (k0 - k1 * math.cos(3.0 * (phi_y + off))))
        if v > best:
            best, u = v, off
    for _ in range(4):
        phi = phi_y + u
        c, s = math.cos(u), math.sin(u)
        h = 0.5 * (k0 - k1 * math.cos(3.0 * phi))
        h1 = 1.5 * k1 * math.sin(3.0 * phi)
        h2 = 4.5 * k1 * math.cos(3.0 * phi)
        f1 = (-s * h - c * h1) / (h * h)
        f2 = ((-c * h - c * h2) * h + 2.0 * h1 * (s * h + c * h1)) / (h * h * h)
        if f2 < 0.0:  # only where f is locally concave (a maximum)
            u = u - f1 / f2
    return math.cos(u) / (0.5 * (k0 - k1 * math.cos(3.0 * (phi_y + u))))


@njit(**_JIT)
def _apex_return(mp, yp, gp, p_tr, s_tr, J2_tr, eqps_n):
    """Closed-form return of the linear cone to its apex, if that is the solution.

    At the apex sigma = -p I, s = 0, so the whole trial deviator becomes plastic: the flow
    s_trial / (2 G) must lie in dlambda * (subdifferential of t at 0), and the volumetric part is
    dlambda tan(psi). The pressure and the hardening then give
    ``p = p_trial + K_b tan(psi) dlambda`` and
    ``-p tan(beta) - d_hat sigma_bar(eqps_n + c dlambda) = 0`` (linear in dlambda). The apex
    applies iff dlambda > 0 and ``q_trial m(xi_trial) <= 3 G dlambda`` (the gauge, see
    :func:`_polar_factor`; K <= m <= 1 decides most points without it). Returns
    (is apex, p, dlambda, k_alg) with the volumetric tangent k_alg m (x) m.
    """
    E, nu, H = mp[M_E], mp[M_NU], mp[M_H]
    Kb, G = E / (3.0 * (1.0 - 2.0 * nu)), E / (2.0 * (1.0 + nu))
    tb, dh, K, tp, c = yp[1], yp[4], yp[5], gp[1], mp[M_RULE_C]
    den = Kb * tp * tb + dh * c * H
    if den <= 0.0:  # psi = 0 and H = 0: the apex cannot be reached by any flow
        return False, 0.0, 0.0, 0.0
    dlam = (-p_tr * tb - dh * (mp[M_S0] + H * eqps_n)) / den
    q_tr = math.sqrt(3.0 * J2_tr)
    apex = dlam > 0.0 and q_tr * K <= 3.0 * G * dlam
    if apex and q_tr > 3.0 * G * dlam:
        apex = q_tr * _polar_factor(_lode_xi(s_tr, J2_tr), K) <= 3.0 * G * dlam
    # dp/dp_trial = d_hat c H / den and dp_trial/d eps = -K_b m  =>  D_apex = K_b (dhcH/den) m m
    return apex, p_tr + Kb * tp * dlam, dlam, Kb * dh * c * H / den


@njit(**_JIT)
def _radial_q(q_trial, c, e):
    """Solve ``q (1 + c / sqrt(e^2 + q^2)) = q_trial`` for q in [0, q_trial] (MPa), c = 3 G dl.

    The left side is increasing and concave in q, so Newton started left of the root climbs
    monotonically to it. Both q_trial / (1 + c/e) and q_trial - c are left of it (the left side
    is <= q_trial there, since sqrt(e^2 + q^2) >= e and >= q); the larger is the closer.
    """
    q = max(q_trial / (1.0 + c / e), q_trial - c)
    tol = 1e-15 * max(q_trial, e)
    for _ in range(100):
        R = math.sqrt(e * e + q * q)
        dq = -(q * (1.0 + c / R) - q_trial) / (1.0 + c * e * e / (R * R * R))
        q = q + dq
        if abs(dq) <= tol:
            break
    return min(q, q_trial)


@njit(**_JIT)
def _meridional_state(mp, gp, p_tr, q_tr, sbar_n, eqps_n, dl):
    """p, q, eqps after the multiplier dl on the meridional plane (see
    :func:`_meridional_return`)."""
    E, nu, H, q_hat = mp[M_E], mp[M_NU], mp[M_H], mp[M_RULE_C]
    tp, e = gp[1], gp[2]
    q = _radial_q(q_tr, 3.0 * E / (2.0 * (1.0 + nu)) * dl, e)
    p = p_tr + E / (3.0 * (1.0 - 2.0 * nu)) * tp * dl
    w = q * q / math.sqrt(e * e + q * q) - p * tp
    # q_hat (sbar_n + H u) u = dl w for u = d eqps >= 0 (the root that vanishes with dl);
    # no real root (NaN) where the plastic work rate w is strongly negative
    rhs = dl * w / q_hat
    disc = sbar_n * sbar_n + 4.0 * H * rhs
    u = 2.0 * rhs / (sbar_n + math.sqrt(disc)) if disc >= 0.0 else np.nan
    return p, q, eqps_n + u


@njit(**_JIT)
def _meridional_f(mp, yp, gp, p_tr, q_tr, sbar_n, eqps_n, dl):
    p, q, eqps = _meridional_state(mp, gp, p_tr, q_tr, sbar_n, eqps_n, dl)
    return _yield_pq(yp, p, q * q, mp[M_S0] + mp[M_H] * eqps)[0]


@njit(**_JIT)
def _meridional_return(mp, yp, gp, p_tr, q_tr, eqps_n, f_tol):
    """Backward-Euler return of the von Mises-section forms in the meridional plane (the
    equations are those of :func:`_meridional_illinois`): Newton on the pair (q, dl), with
    eqps from the quadratic of the work rule, from the trial state (q_trial, 0). Where it leaves
    the admissible range or does not settle within a few steps, the bracketing Illinois solver
    takes over. Returns p, q, eqps, dl and a success flag (f_tol: |F| in MPa)."""
    E, nu, H, q_hat = mp[M_E], mp[M_NU], mp[M_H], mp[M_RULE_C]
    tp, e = gp[1], gp[2]
    Kb, G = E / (3.0 * (1.0 - 2.0 * nu)), E / (2.0 * (1.0 + nu))
    sbar_n = mp[M_S0] + H * eqps_n
    q, dl = q_tr, 0.0
    for _ in range(12):
        R = math.sqrt(e * e + q * q)
        r1 = q * (1.0 + 3.0 * G * dl / R) - q_tr  # radial (deviatoric) flow
        p = p_tr + Kb * tp * dl  # volumetric flow
        w = q * q / R - p * tp  # plastic work per unit multiplier
        rhs = dl * w / q_hat
        disc = sbar_n * sbar_n + 4.0 * H * rhs
        if not disc >= 0.0:
            break
        sq = math.sqrt(disc)
        u = 2.0 * rhs / (sbar_n + sq)  # q_hat (sbar_n + H u) u = dl w
        F, Fq_q, Fp, Fs = _yield_pq(yp, p, q * q, sbar_n + H * u)
        if abs(F) <= f_tol and abs(r1) <= f_tol and dl > 0.0:
            return p, q, eqps_n + u, dl, True
        r1_q, r1_dl = 1.0 + 3.0 * G * dl * e * e / (R * R * R), 3.0 * G * q / R
        D = q_hat * sq  # d(q_hat (sbar_n + H u) u)/du
        u_q = dl * q * (q * q + 2.0 * e * e) / (R * R * R) / D
        u_dl = (w - dl * Kb * tp * tp) / D
        F_q, F_dl = Fq_q * q + Fs * H * u_q, Fp * Kb * tp + Fs * H * u_dl
        det = r1_q * F_dl - r1_dl * F_q
        q_new = q + (F * r1_dl - r1 * F_dl) / det
        dl_new = dl + (F_q * r1 - r1_q * F) / det
        if not (q_new >= 0.0 and q_new <= q_tr and dl_new > 0.0):
            break
        q, dl = q_new, dl_new
    return _meridional_illinois(mp, yp, gp, p_tr, q_tr, eqps_n, f_tol)


@njit(**_JIT)
def _meridional_illinois(mp, yp, gp, p_tr, q_tr, eqps_n, f_tol):
    """Backward-Euler return of the von Mises-section forms in the meridional plane.

    With a circular section and G = sqrt(e^2 + q^2) - p tan(psi) the return keeps the
    deviator's direction, and one unknown remains, the multiplier dl >= 0::

        p(dl)    = p_trial + K_b tan(psi) dl                     (volumetric flow)
        q(dl)    : q (1 + 3 G dl / sqrt(e^2 + q^2)) = q_trial   (deviatoric flow, radial)
        eqps(dl) : q_hat sigma_bar(eqps) (eqps - eqps_n) = dl (q^2/sqrt(e^2+q^2) - p tan(psi))
        f(dl)    = F(p, q, sigma_bar(eqps)) = 0

    Each inner relation is solved exactly and f is bracketed and solved by the Illinois variant of
    regula falsi, which cannot diverge however far the trial lies outside the surface or however
    sharp the hyperbola's tip. Returns p, q, eqps, dl and a success flag (f_tol: |F| in MPa).
    """
    sbar_n = mp[M_S0] + mp[M_H] * eqps_n
    lo, f_lo = 0.0, _meridional_f(mp, yp, gp, p_tr, q_tr, sbar_n, eqps_n, 0.0)
    # bracket: the multiplier that would relax the trial excess by shear alone sets the scale
    hi = max(f_lo, 1e-12) / (3.0 * mp[M_E] / (2.0 * (1.0 + mp[M_NU])))
    f_hi = _meridional_f(mp, yp, gp, p_tr, q_tr, sbar_n, eqps_n, hi)
    for _ in range(200):
        # f > 0: the root lies further out. f = NaN: eqps has no real root there, i.e. the
        # plastic work turned strongly negative far beyond the return; come back towards lo.
        if f_hi > 0.0:
            lo, f_lo = hi, f_hi
            hi *= 4.0
        elif f_hi != f_hi:
            hi = 0.5 * (lo + hi)
        else:
            break
        f_hi = _meridional_f(mp, yp, gp, p_tr, q_tr, sbar_n, eqps_n, hi)
    ok = _finite(f_lo) and _finite(f_hi) and f_hi <= 0.0
    a, fa, b, fb = lo, f_lo, hi, f_hi
    if ok and abs(fb) > f_tol:
        for _ in range(200):
            c = b - fb * (b - a) / (fb - fa)
            if not (c > min(a, b) and c < max(a, b)):
                c = 0.5 * (a + b)
            fc = _meridional_f(mp, yp, gp, p_tr, q_tr, sbar_n, eqps_n, c)
            if fc * fb < 0.0:  # root between b and c: the old b becomes the other end
                a, fa = b, fb
            else:
                fa = 0.5 * fa  # Illinois: halve the stale end's value
            b, fb = c, fc
            if abs(fc) <= f_tol or not _finite(fc) or abs(a - c) <= 1e-16 * abs(c):
                break
    p, q, eqps = _meridional_state(mp, gp, p_tr, q_tr, sbar_n, eqps_n, b)
    ok = ok and _finite(fb) and _finite(eqps)
    return p, q, eqps, b, ok


@njit(**_JIT)
def _work_fold(mp, yp, gp, p_tr, q_tr, eqps_n):
    """Whether the meridional return of a von Mises-section form with the work rule has no
    solution because the work rule runs out of strength (see :func:`work_exhaustion`).

    The work rule q_hat (sbar_n + H u) u = dl w(dl) has a real root u iff
    ``dl w(dl) >= -q_hat sbar_n^2 / (4 H)``; w decreases with dl (q falls, p rises), so the
    multipliers with a root form an interval [0, dl_fold]. Returns (exhausted, dl_fold, F at
    dl_fold on the root's branch, sigma_bar there = sbar_n / 2): exhausted when a fold exists and
    F > 0 at the fold and at 64 equally spaced multipliers below it (no sign change of F, hence no
    return). Not exhausted (dl_fold = inf) without a fold (H = 0, or w never that negative)."""
    E, nu, H, q_hat = mp[M_E], mp[M_NU], mp[M_H], mp[M_RULE_C]
    sbar_n = mp[M_S0] + H * eqps_n
    if not (H > 0.0 and sbar_n > 0.0):
        return False, _INF, np.nan, sbar_n
    lim = -q_hat * sbar_n * sbar_n / (4.0 * H)
    lo = 0.0
    hi = max(_meridional_f(mp, yp, gp, p_tr, q_tr, sbar_n, eqps_n, 0.0), 1e-12) / (
        3.0 * E / (2.0 * (1.0 + nu))
    )
    found = False
    for _ in range(200):
        p, q, _e = _meridional_state(mp, gp, p_tr, q_tr, sbar_n, eqps_n, hi)
        if hi * (q * q / math.sqrt(gp[2] * gp[2] + q * q) - p * gp[1]) < lim:
            found = True
            break
        lo, hi = hi, 4.0 * hi
    if not found:
        return False, _INF, np.nan, sbar_n
    for _ in range(200):  # bisection: lo has a root, hi has none
        mid = 0.5 * (lo + hi)
        if not (mid > lo and mid < hi):
            break
        p, q, _e = _meridional_state(mp, gp, p_tr, q_tr, sbar_n, eqps_n, mid)
        if mid * (q * q / math.sqrt(gp[2] * gp[2] + q * q) - p * gp[1]) < lim:
            hi = mid
        else:
            lo = mid
    p, q, eqps = _meridional_state(mp, gp, p_tr, q_tr, sbar_n, eqps_n, lo)
    f_fold = _yield_pq(yp, p, q * q, mp[M_S0] + H * eqps)[0]
    exhausted = f_fold > 0.0
    for k in range(1, 65):
        if not exhausted:
            break
        fk = _meridional_f(mp, yp, gp, p_tr, q_tr, sbar_n, eqps_n, lo * k / 64.0)
        exhausted = fk > 0.0  # False for NaN as well
    return exhausted, lo, f_fold, mp[M_S0] + H * eqps


@njit(**_JIT)
def _coaxial_return(mp, yp, gp, p_tr, s_tr, J2_tr, eqps_n, a, mu, x):
    """The smooth return of the linear form solved in the trial deviator's coaxial basis; writes
    x and returns True on success (x untouched otherwise).

    With isotropic elasticity and G = t - p tan(psi) the return splits into
    p = p_trial + K_b tan(psi) dlambda and s = s_trial - 2 G dlambda N(s), N = dt/ds =
    k s + t_J dev(s^2) (k = (3/2q) t_q), so s is an isotropic function of s_trial: with
    S = s_trial/q_trial and D = dev(S^2) (Cayley-Hamilton), s/q_trial = a S + b D. The products
    reduce with S^3 = J2S S + J3S I to dev(s^2)/q_trial^2 = alpha S + beta D,
    alpha = 2/3 a b J2S + b^2 J3S, beta = a^2 - b^2 J2S/3, and the invariants of s follow from
    the Gram matrix Gm = [[S:S, S:D], [D:S, D:D]] = [[2 J2S, 3 J3S], [3 J3S, 2/3 J2S^2]]:
    J2 = 1/2 (a, b) Gm (a, b), J3 = 1/3 (a, b) Gm (alpha, beta) (times q_trial^2, ^3). With
    mu = 2 G dlambda / q_trial the unknowns (a, b, mu) solve, by Newton from (a, 0, mu) = the
    frozen-Lode-angle start,

        r1 = a - 1 + mu (k a + t_J alpha) = 0,   r2 = b + mu (k b + t_J beta) = 0,
        r3 = t/q_trial - (p tan(beta) + d_hat sigma_bar(eqps_n + c dlambda))/q_trial = 0

    (k, t_J, t scaled to the normalised deviator). The coefficient equations stay well posed when
    S is axisymmetric (D parallel to S). Success needs a converged, finite solution with
    dlambda >= 0 and the deviator on the trial's side of the apex.
    """
    E, nu, H = mp[M_E], mp[M_NU], mp[M_H]
    Kb, G = E / (3.0 * (1.0 - 2.0 * nu)), E / (2.0 * (1.0 + nu))
    tb, A, B, dh, c, tp = yp[1], yp[2], yp[3], yp[4], mp[M_RULE_C], gp[1]
    q_tr = math.sqrt(3.0 * J2_tr)
    j2, j3 = 1.0 / 3.0, _j3(s_tr) / (q_tr * q_tr * q_tr)
    g11, g12, g22 = 2.0 * j2, 3.0 * j3, 2.0 / 3.0 * j2 * j2
    P0 = (p_tr * tb + dh * (mp[M_S0] + H * eqps_n)) / q_tr
    Cmu = (Kb * tp * tb + dh * H * c) / (2.0 * G)
    b = 0.0
    done = False
    for _ in range(25):
        al = 2.0 / 3.0 * a * b * j2 + b * b * j3
        be = a * a - b * b * j2 / 3.0
        gJ2 = (g11 * a + g12 * b, g12 * a + g22 * b)  # d J2 / d(a, b) = Gm (a, b)
        gJ3 = (g11 * al + g12 * be, g12 * al + g22 * be)  # d J3 / d(a, b) = Gm (alpha, beta)
        J2 = 0.5 * (a * gJ2[0] + b * gJ2[1])
        J3 = (a * gJ3[0] + b * gJ3[1]) / 3.0
        if not J2 > 0.0:
            return False
        q = math.sqrt(3.0 * J2)
        qi = 1.0 / q
        qi2 = qi * qi
        k = 1.5 * qi * (A - 2.0 * B * J3 * qi2 * qi)
        tJ = B * qi2
        v0, v1 = k * a + tJ * al, k * b + tJ * be
        r1, r2, r3 = a - 1.0 + mu * v0, b + mu * v1, A * q + B * J3 * qi2 - P0 - mu * Cmu
        if done:
            break
        # Jacobian: d k/d J2 = -9/4 A/q^3 + 18 B J3/q^6, d k/d J3 = d t_J/d J2 = -3 B/q^4
        kJ2, kJ3 = -2.25 * A * qi2 * qi + 18.0 * B * J3 * qi2 * qi2 * qi2, -3.0 * B * qi2 * qi2
        dk0, dk1 = kJ2 * gJ2[0] + kJ3 * gJ3[0], kJ2 * gJ2[1] + kJ3 * gJ3[1]
        dt0, dt1 = kJ3 * gJ2[0], kJ3 * gJ2[1]
        m11 = 1.0 + mu * (k + a * dk0 + tJ * (2.0 / 3.0 * b * j2) + al * dt0)
        m12 = mu * (a * dk1 + tJ * (2.0 / 3.0 * a * j2 + 2.0 * b * j3) + al * dt1)
        m21 = mu * (b * dk0 + tJ * 2.0 * a + be * dt0)
        m22 = 1.0 + mu * (k + b * dk1 - tJ * (2.0 / 3.0 * b * j2) + be * dt1)
        m13, m23 = v0, v1
        m31, m32, m33 = g11 * v0 + g12 * v1, g12 * v0 + g22 * v1, -Cmu  # d r3/d(a, b) = Gm v
        c11, c12, c13 = m22 * m33 - m23 * m32, m23 * m31 - m21 * m33, m21 * m32 - m22 * m31
        det = m11 * c11 + m12 * c12 + m13 * c13
        if not (abs(det) > 0.0 and abs(det) < _INF):
            return False
        da = -(r1 * c11 + r2 * (m13 * m32 - m12 * m33) + r3 * (m12 * m23 - m13 * m22)) / det
        db = -(r1 * c12 + r2 * (m11 * m33 - m13 * m31) + r3 * (m13 * m21 - m11 * m23)) / det
        dmu = -(r1 * c13 + r2 * (m12 * m31 - m11 * m32) + r3 * (m11 * m22 - m12 * m21)) / det
        a, b, mu = a + da, b + db, mu + dmu
        # quadratic convergence: once the step is at 1e-9 the next one reaches round-off
        done = max(abs(da), abs(db), abs(dmu)) <= 1e-9
    if not (
        done and max(abs(r1), abs(r2), abs(r3)) <= 1e-13 and mu >= 0.0 and a * g11 + b * g12 > 0.0
    ):
        return False
    dl = mu * q_tr / (2.0 * G)
    p = p_tr + Kb * tp * dl
    d = _grad_j3(s_tr, J2_tr)  # dev(s_trial^2) with doubled shear entries
    f = b / q_tr
    for i in range(6):
        x[i] = a * s_tr[i] + f * (d[i] if i < 3 else 0.5 * d[i]) - (p if i < 3 else 0.0)
    x[6] = E * dl
    x[7] = E * (eqps_n + c * dl)
    return True


@njit(**_JIT)
def _start(mp, yp, gp, st, p_tr, s_tr, J2_tr, eqps_n, scale, x):
    """Newton's starting point x (8). Linear form: the exact return in the coaxial basis
    (:func:`_coaxial_return`) started from the closed-form cone return with t/q frozen at the
    trial Lode angle, or that frozen-angle return where it fails. Von Mises-section forms: the
    exact meridional-plane return, or the trial state where that failed."""
    E, nu = mp[M_E], mp[M_NU]
    Kb, G = E / (3.0 * (1.0 - 2.0 * nu)), E / (2.0 * (1.0 + nu))
    for i in range(6):
        x[i] = st[i]
    x[6] = 0.0
    x[7] = E * eqps_n
    q_tr = math.sqrt(3.0 * J2_tr)
    inv_q_tr = 1.0 / q_tr if q_tr > 0.0 else 0.0  # radial scaling of s_tr
    tp = gp[1]
    if int(yp[0]) == LINEAR:
        # The return with t/q frozen at the trial Lode angle is a Drucker-Prager cone return in
        # closed form; the Lode angle moves little, so it is close to the solution.
        tb, A, dh, c = yp[1], yp[2], yp[4], mp[M_RULE_C]
        h = A - (1.0 - A) * _lode_xi(s_tr, J2_tr)  # t/q = (1 + 1/K)/2 - (1 - 1/K)/2 xi
        f_tr = h * q_tr - p_tr * tb - dh * (mp[M_S0] + mp[M_H] * eqps_n)
        dl = max(f_tr, 0.0) / (3.0 * G * h * h + Kb * tp * tb + dh * c * mp[M_H])
        # stay off the apex, where the cone's flow direction is undefined
        q = max(q_tr - 3.0 * G * h * dl, 0.05 * q_tr)
        if q_tr > 0.0 and _coaxial_return(
            mp, yp, gp, p_tr, s_tr, J2_tr, eqps_n, q * inv_q_tr, 2.0 * G * dl * inv_q_tr, x
        ):
            return
        p = p_tr + Kb * tp * dl
        eqps = eqps_n + c * dl
    else:
        p, q, eqps, dl, ok = _meridional_return(
            mp, yp, gp, p_tr, q_tr, eqps_n, 1e-3 * mp[M_TOL] * scale
        )
        if not ok:
            return
    f = q * inv_q_tr
    for i in range(6):
        x[i] = s_tr[i] * f - (p if i < 3 else 0.0)
    x[6] = E * dl
    x[7] = E * eqps


@njit(**_JIT)
def _line_search(mp, yp, gp, x, step, R0, st, eqps_n, scale, x_new, R, J):
    """Backtracking (Armijo on ||R/scale||^2) from x along the Newton step (8, 1); writes x_new
    with its residual R and Jacobian J (which the next Newton iteration reuses) and returns True,
    or False if 12 halvings found no acceptable point (x_new is then the last, unevaluated one).

    On the linear cone a step may also not shrink q by more than 20x nor flip the deviator:
    the cone's flow direction is discontinuous at its apex, where Newton must not land.
    """
    phi0 = 0.0
    for i in range(8):
        phi0 += R0[i] * R0[i]
    phi0 /= scale * scale
    cone = int(yp[0]) == LINEAR
    s_old = _deviator(x)[1]
    q_old = math.sqrt(3.0 * _j2(s_old))
    alpha = 1.0
    for i in range(8):
        x_new[i] = x[i] + step[i, 0]
    for _ in range(12):
        _residual(mp, yp, gp, x_new, st, eqps_n, R, J)
        phi = 0.0
        for i in range(8):
            phi += R[i] * R[i]
        phi /= scale * scale
        good = _finite(phi) and phi <= (1.0 - 1e-4 * alpha) * phi0
        if good and cone:
            s_new = _deviator(x_new)[1]
            good = _deviator_dot(s_old, s_new) > 0.0 and math.sqrt(3.0 * _j2(s_new)) >= 0.05 * q_old
        if good:
            return True
        alpha *= 0.5
        for i in range(8):
            x_new[i] = x[i] + alpha * step[i, 0]
    return False


@njit(**_JIT)
def plastic_return(mp, yp, gp, sig_tr, eqps_n, scale):
    """Closest-point return of m plastic trial states (m, 6) with eqps_n (m,) and the residual
    scales (m,): returns stress (m, 6), eqps, dlambda (m,), consistent tangent (m, 6, 6), ok and
    apex flags, and the number of Jacobians formed per point.

    Per point: the linear form's apex (closed form) where it applies; otherwise Newton with line
    search on R = 0 (:func:`_residual`) from :func:`_start` until max|R| <= tol * scale, then one
    more full step (quadratic convergence takes the solution to round-off, so that finite
    differences of the map are clean) whose factorised Jacobian J also gives the tangent: only
    sigma_trial depends on the strain increment, dR/d eps = [-E C D; 0; 0] = [-E I; 0; 0], so
    d sigma / d eps = (J^-1 [E I; 0; 0])[:6] (it differs from the final J by ~tol). A point fails
    (ok False) if Newton does not converge in max_iter iterations or meets a singular Jacobian,
    ends with dlambda < 0, or (cone) ends with the deviator reversed with respect to the trial.
    """
    m = sig_tr.shape[0]
    E, tol, max_iter = mp[M_E], mp[M_TOL], int(mp[M_MAXIT])
    cone = int(yp[0]) == LINEAR
    stress = np.empty((m, 6))
    eqps = np.empty(m)
    dlam = np.empty(m)
    tangent = np.zeros((m, 6, 6))
    ok = np.zeros(m, np.bool_)
    apex = np.zeros(m, np.bool_)
    jacobians = np.zeros(m, np.int64)
    J = np.empty((8, 8))
    piv = np.empty(8, np.int64)
    x = np.empty(8)
    x_new = np.empty(8)
    R = np.empty(8)
    R_new = np.empty(8)
    rhs = np.empty((8, 7))
    step = np.empty((8, 1))
    for n in range(m):
        st = (sig_tr[n, 0], sig_tr[n, 1], sig_tr[n, 2], sig_tr[n, 3], sig_tr[n, 4], sig_tr[n, 5])
        en, sc = eqps_n[n], scale[n]
        p_tr, s_tr = _deviator(st)
        J2_tr = _j2(s_tr)
        if cone:
            is_apex, p, dl, k_alg = _apex_return(mp, yp, gp, p_tr, s_tr, J2_tr, en)
            if is_apex:
                for i in range(3):
                    stress[n, i] = -p
                    stress[n, i + 3] = 0.0
                    for j in range(3):
                        tangent[n, i, j] = k_alg
                eqps[n] = en + mp[M_RULE_C] * dl
                dlam[n] = dl
                ok[n] = apex[n] = True
                continue
        _start(mp, yp, gp, st, p_tr, s_tr, J2_tr, en, sc, x)
        conv = False
        fresh = False  # R, J already evaluated at x (by the line search)
        for it in range(max_iter + 1):
            if not fresh:
                _residual(mp, yp, gp, x, st, en, R, J)
            jacobians[n] += 1
            err = 0.0
            finite = True
            for i in range(8):
                v = abs(R[i])
                finite = finite and v < _INF  # False for inf and NaN
                err = max(err, v)
            if not finite:
                break
            if err <= tol * sc:
                # last full step and the tangent with the same factorised Jacobian
                for i in range(8):
                    rhs[i, 0] = -R[i]
                    for j in range(6):
                        rhs[i, j + 1] = E if i == j else 0.0
                if _lu8(J, piv) and _lu8_solve(J, piv, rhs):
                    for i in range(8):
                        x[i] += rhs[i, 0]
                    for i in range(6):
                        for j in range(6):
                            tangent[n, i, j] = rhs[i, j + 1]
                    conv = True
                break
            if it == max_iter:
                break
            for i in range(8):
                step[i, 0] = -R[i]
            if not (_lu8(J, piv) and _lu8_solve(J, piv, step)):
                break
            fresh = _line_search(mp, yp, gp, x, step, R, st, en, sc, x_new, R_new, J)
            for i in range(8):
                x[i] = x_new[i]
                R[i] = R_new[i]
        for i in range(6):
            stress[n, i] = x[i]
        eqps[n] = x[7] / E
        dlam[n] = x[6] / E
        # a valid smooth return has a non-negative multiplier; on the cone it must also keep the
        # deviator on the trial's side of the apex (else the apex branch applies)
        conv = conv and dlam[n] >= -tol * 1e-3
        if conv and cone:
            conv = _deviator_dot(_deviator(x)[1], s_tr) > 0.0
        ok[n] = conv
    return stress, eqps, dlam, tangent, ok, apex, jacobians


# --------------------------------------------------------------------------------------------
# Parameter sensitivities of the update (direct differentiation)
# --------------------------------------------------------------------------------------------


@njit(**_JIT)
def _potential_partials(gp, s, J2, lam, Rth):
    """Rth[:6, TH_G:] = (E dlambda) d(dG/dsigma)/d gp[1:]: cone dG/dsigma = t_q dq + t_J dJ3 +
    tan(psi) m/3 with t_q = A - 2 B J3/q^3, t_J = B/q^2; hyperbola 3/(2R) dJ2 + tan(psi) m/3,
    R = sqrt(e^2 + q^2)."""
    for i in range(3):
        Rth[i, TH_G] = lam / 3.0
    if int(gp[0]) == CONE:
        q = math.sqrt(3.0 * J2)
        qi = _inv(q)
        gq = (
            1.5 * qi * s[0],
            1.5 * qi * s[1],
            1.5 * qi * s[2],
            3.0 * qi * s[3],
            3.0 * qi * s[4],
            3.0 * qi * s[5],
        )
        gJ = _grad_j3(s, J2)
        fq = -2.0 * _j3(s) * qi * qi * qi
        for i in range(6):
            Rth[i, TH_G + 1] = lam * gq[i]
            Rth[i, TH_G + 2] = lam * (fq * gq[i] + qi * qi * gJ[i])
    else:
        e = gp[2]
        root = max(math.sqrt(e * e + 3.0 * J2), _Q_TINY)
        gJ2 = _grad_j2(s)
        f = -1.5 * lam * e / (root * root * root)
        for i in range(6):
            Rth[i, TH_G + 1] = f * gJ2[i]


@njit(**_JIT)
def _yield_partials(yp, s, p, J2, sbar, Rth):
    """Rth[6, TH_Y:] = dF/d yp[1:] (the reference-test constants q_hat, p_hat and K, which
    only selects the apex branch, are not differentiated: their columns stay zero)."""
    code = int(yp[0])
    if code == LINEAR:  # F = A q + B J3/q^2 - p tan(beta) - d_hat sigma_bar
        q = math.sqrt(3.0 * J2)
        qi = _inv(q)
        Rth[6, TH_Y] = -p
        Rth[6, TH_Y + 1] = q
        Rth[6, TH_Y + 2] = _j3(s) * qi * qi
        Rth[6, TH_Y + 3] = -sbar
    elif code == HYPERBOLIC:
        # F = sqrt(l0^2 + q^2) - p tan(beta) - sqrt(l0^2 + (qh sbar)^2) + ph sbar tan(beta)
        l0, qh, ph = yp[2], yp[3], yp[4]
        Rth[6, TH_Y] = -p + ph * sbar
        Rth[6, TH_Y + 1] = l0 / math.sqrt(l0 * l0 + 3.0 * J2) - l0 / math.sqrt(
            l0 * l0 + qh * sbar * qh * sbar
        )
    else:  # F = a q^b - p - a (qh sbar)^b + ph sbar
        a, b, qh = yp[1], yp[2], yp[3]
        q2, ref = 3.0 * J2, qh * sbar
        qb, rb = q2 ** (0.5 * b), ref**b
        Rth[6, TH_Y] = qb - rb
        Rth[6, TH_Y + 1] = a * (0.5 * qb * math.log(q2) if q2 > 0.0 else 0.0) - a * rb * math.log(
            ref
        )


@njit(**_JIT)
def _residual_partials(mp, yp, gp, x, st, eqps_n, Rth):
    """Partial derivatives of the residual R of :func:`_residual` at x with respect to the
    kernel parameters theta (Rth[:, :TH_SIZE], see ``TH_*``) and to eqps_n
    (Rth[:, TH_SIZE]); the trial stress enters only R1, as -E C (handled by the caller)."""
    E, s0, Hh, c = mp[M_E], mp[M_S0], mp[M_H], mp[M_RULE_C]
    lam, kap = x[6], x[7]
    dkap = kap - E * eqps_n
    sbar = s0 + Hh * kap / E
    p, s = _deviator(x)
    J2 = _j2(s)
    for i in range(8):
        for j in range(TH_SIZE + 1):
            Rth[i, j] = 0.0
    # R1 = E C (sigma - sigma_trial) + lam dG/dsigma: E C depends on nu only
    d = (x[0] - st[0], x[1] - st[1], x[2] - st[2], x[3] - st[3], x[4] - st[4], x[5] - st[5])
    Rth[0, TH_NU] = -(d[1] + d[2])
    Rth[1, TH_NU] = -(d[0] + d[2])
    Rth[2, TH_NU] = -(d[0] + d[1])
    for i in range(3, 6):
        Rth[i, TH_NU] = 2.0 * d[i]
    _potential_partials(gp, s, J2, lam, Rth)
    # R2 = F(sigma, sigma_bar), sigma_bar = sigma0 + H kap/E
    _yield_partials(yp, s, p, J2, sbar, Rth)
    Fs = -_strength(yp, sbar)[1]
    sb_E, sb_H = -Hh * kap / (E * E), kap / E
    Rth[6, TH_E] = Fs * sb_E
    Rth[6, TH_S0] = Fs
    Rth[6, TH_H] = Fs * sb_H
    # R3
    if int(mp[M_RULE]) == PROPORTIONAL:  # kap - E eqps_n - c lam
        Rth[7, TH_E] = -eqps_n
        Rth[7, TH_C] = -lam
        Rth[7, _TH_EQPS_N] = -E
        return
    # (c sbar dkap - lam w)/s0, w = q^2/R - p tan(psi), R = sqrt(e^2 + q^2)
    tp, e = gp[1], gp[2]
    root = max(math.sqrt(e * e + 3.0 * J2), _Q_TINY)
    w = 3.0 * J2 / root - p * tp
    Rth[7, TH_E] = c * (sb_E * dkap - sbar * eqps_n) / s0
    Rth[7, TH_S0] = (c * dkap - (c * sbar * dkap - lam * w) / s0) / s0
    Rth[7, TH_H] = c * sb_H * dkap / s0
    Rth[7, TH_C] = sbar * dkap / s0
    Rth[7, TH_G] = lam * p / s0
    Rth[7, TH_G + 1] = lam * 3.0 * J2 * e / (root * root * root * s0)
    Rth[7, _TH_EQPS_N] = -c * sbar * E / s0


@njit(**_JIT)
def _smooth_sensitivity(
    mp, yp, gp, dth, st, eqps_n, sig, eqps, dst_n, i, dstress, dstate, x, R, J, piv, Rth, rhs
):
    """Derivatives of point i's converged closest-point return by the implicit function theorem,
    ``J dx = -(dR/dtheta dtheta + dR/dsigma_trial dsigma_trial + dR/deqps_n deqps_n)`` with J
    the local Jacobian at the converged x = [sigma, E dlambda, E eqps]; eqps = x[7]/E.

    dstress[i] holds the trial stress derivative (P, 6) on entry and the stress derivative on
    return; dstate[i, :, 0] receives d eqps, dst_n[i, :, 0] is d eqps_n. False if J is singular.
    """
    E, nu = mp[M_E], mp[M_NU]
    n_p = dth.shape[1]
    # x of the converged update; E dlambda from R1 = E C (sigma - sigma_trial) + (E dlambda) g = 0
    s = _deviator(sig)[1]
    g = _potential(gp, s, _j2(s), False, 0.0, J)
    tr = (sig[0] - st[0]) + (sig[1] - st[1]) + (sig[2] - st[2])
    num, gg = 0.0, 0.0
    for a in range(6):
        d = sig[a] - st[a]
        num += ((1.0 + nu) * d - nu * tr if a < 3 else 2.0 * (1.0 + nu) * d) * g[a]
        gg += g[a] * g[a]
        x[a] = sig[a]
    x[6] = -num / gg
    x[7] = E * eqps
    _residual(mp, yp, gp, x, st, eqps_n, R, J)
    _residual_partials(mp, yp, gp, x, st, eqps_n, Rth)
    for k in range(n_p):
        for r in range(8):
            acc = Rth[r, _TH_EQPS_N] * dst_n[i, k, 0]
            for j in range(TH_SIZE):
                acc += Rth[r, j] * dth[j, k]
            rhs[r, k] = -acc
        # dR1/dsigma_trial = -E C = -[[1, -nu, -nu], ...; 2 (1 + nu)]
        t = dstress[i, k, 0] + dstress[i, k, 1] + dstress[i, k, 2]
        for a in range(6):
            v = dstress[i, k, a]
            rhs[a, k] += (1.0 + nu) * v - nu * t if a < 3 else 2.0 * (1.0 + nu) * v
    if not (_lu8(J, piv) and _lu8_solve(J, piv, rhs)):
        return False
    for k in range(n_p):
        for a in range(6):
            dstress[i, k, a] = rhs[a, k]
        dstate[i, k, 0] = (rhs[7, k] - eqps * dth[TH_E, k]) / E
    return True


@njit(**_JIT)
def _apex_sensitivity(mp, yp, gp, dth, p_tr, eqps_n, dl, dst_n, i, dstress, dstate):
    """Derivatives of point i's closed-form apex return (:func:`_apex_return`)::

        dlambda = (-p_trial tan(beta) - d_hat sigma_bar(eqps_n)) / (K_b tan(psi) tan(beta) + d_hat c
        H)
        p = p_trial + K_b tan(psi) dlambda,   eqps = eqps_n + c dlambda,   sigma = -p m

    dstress[i] holds the trial stress derivative on entry (only its trace, -3 dp_trial, is used)
    and the stress derivative on return; dstate[i, :, 0] receives d eqps."""
    E, nu, H, s0, c = mp[M_E], mp[M_NU], mp[M_H], mp[M_S0], mp[M_RULE_C]
    tb, dh, tp = yp[1], yp[4], gp[1]
    Kb = E / (3.0 * (1.0 - 2.0 * nu))
    den = Kb * tp * tb + dh * c * H
    sbar_n = s0 + H * eqps_n
    for k in range(dth.shape[1]):
        dKb = dth[TH_E, k] / (3.0 * (1.0 - 2.0 * nu)) + dth[TH_NU, k] * 2.0 * E / (
            3.0 * (1.0 - 2.0 * nu) ** 2
        )
        dtb, ddh, dtp = dth[TH_Y, k], dth[TH_Y + 3, k], dth[TH_G, k]
        dc, dH, deqps_n = dth[TH_C, k], dth[TH_H, k], dst_n[i, k, 0]
        dp_tr = -(dstress[i, k, 0] + dstress[i, k, 1] + dstress[i, k, 2]) / 3.0
        dnum = (
            -dp_tr * tb
            - p_tr * dtb
            - ddh * sbar_n
            - dh * (dth[TH_S0, k] + dH * eqps_n + H * deqps_n)
        )
        dden = (dKb * tp + Kb * dtp) * tb + Kb * tp * dtb + (ddh * c + dh * dc) * H + dh * c * dH
        ddl = (dnum - dl * dden) / den
        dp = dp_tr + (dKb * tp + Kb * dtp) * dl + Kb * tp * ddl
        for a in range(3):
            dstress[i, k, a] = -dp
            dstress[i, k, a + 3] = 0.0
        dstate[i, k, 0] = deqps_n + dc * dl + c * ddl


@njit(**_JIT)
def _trial_sensitivity(mp, dth, de, dsig_n, dde, i, dstress):
    """dstress[i] (P, 6) = dsigma_n + D ddeps + (dD/dE deps) dE/dp + (dD/dnu deps) dnu/dp: the
    derivative of point i's elastic trial stress sigma_n + D deps (D from the Lame constants
    lam, mu, as in :func:`elastic_trial`; dD/dE = D/E)."""
    E, nu = mp[M_E], mp[M_NU]
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    mu = E / (2.0 * (1.0 + nu))
    lam_nu = E * (1.0 + 2.0 * nu * nu) / ((1.0 + nu) * (1.0 - 2.0 * nu)) ** 2
    mu_nu = -E / (2.0 * (1.0 + nu) ** 2)
    d = (de[i, 0], de[i, 1], de[i, 2], de[i, 3], de[i, 4], de[i, 5])
    tr = d[0] + d[1] + d[2]
    vE = (
        (2.0 * mu * d[0] + lam * tr) / E,
        (2.0 * mu * d[1] + lam * tr) / E,
        (2.0 * mu * d[2] + lam * tr) / E,
        mu * d[3] / E,
        mu * d[4] / E,
        mu * d[5] / E,
    )
    vN = (
        2.0 * mu_nu * d[0] + lam_nu * tr,
        2.0 * mu_nu * d[1] + lam_nu * tr,
        2.0 * mu_nu * d[2] + lam_nu * tr,
        mu_nu * d[3],
        mu_nu * d[4],
        mu_nu * d[5],
    )
    for k in range(dth.shape[1]):
        dE, dnu = dth[TH_E, k], dth[TH_NU, k]
        t = lam * (dde[i, k, 0] + dde[i, k, 1] + dde[i, k, 2])
        for a in range(6):
            Dd = 2.0 * mu * dde[i, k, a] + t if a < 3 else mu * dde[i, k, a]
            dstress[i, k, a] = dsig_n[i, k, a] + Dd + dE * vE[a] + dnu * vN[a]


@njit(**_JIT)
def _plastic_strain_sensitivity(mp, dth, stress, sig_n, dsig_n, dde, dst_n, i, dstress, dstate):
    """dstate[i, :, 1:] = derivative of point i's plastic strain
    eps_pl_n + deps - C (sigma - sigma_n) as :func:`merge_update` forms it; with C = S/E,
    S = [[1, -nu, -nu], ...; 2 (1 + nu)]:
    ``deps_pl_n + ddeps
    - (S (dsigma - dsigma_n) + dnu dS/dnu (sigma - sigma_n) - dE C (sigma - sigma_n)) / E``."""
    E, nu = mp[M_E], mp[M_NU]
    d = (
        stress[i, 0] - sig_n[i, 0],
        stress[i, 1] - sig_n[i, 1],
        stress[i, 2] - sig_n[i, 2],
        stress[i, 3] - sig_n[i, 3],
        stress[i, 4] - sig_n[i, 4],
        stress[i, 5] - sig_n[i, 5],
    )
    td = d[0] + d[1] + d[2]
    Sd = (
        (1.0 + nu) * d[0] - nu * td,
        (1.0 + nu) * d[1] - nu * td,
        (1.0 + nu) * d[2] - nu * td,
        2.0 * (1.0 + nu) * d[3],
        2.0 * (1.0 + nu) * d[4],
        2.0 * (1.0 + nu) * d[5],
    )
    # dS/dnu (sigma - sigma_n)
    dSd = (d[0] - td, d[1] - td, d[2] - td, 2.0 * d[3], 2.0 * d[4], 2.0 * d[5])
    for k in range(dth.shape[1]):
        dE, dnu = dth[TH_E, k], dth[TH_NU, k]
        t = (
            (dstress[i, k, 0] - dsig_n[i, k, 0])
            + (dstress[i, k, 1] - dsig_n[i, k, 1])
            + (dstress[i, k, 2] - dsig_n[i, k, 2])
        )
        for a in range(6):
            dd = dstress[i, k, a] - dsig_n[i, k, a]
            Sdd = (1.0 + nu) * dd - nu * t if a < 3 else 2.0 * (1.0 + nu) * dd
            dstate[i, k, a + 1] = (
                dst_n[i, k, a + 1] + dde[i, k, a] - (Sdd + dnu * dSd[a] - dE * Sd[a] / E) / E
            )


# --------------------------------------------------------------------------------------------
# Vectorised entry points (arguments: C-contiguous float64 arrays)
# --------------------------------------------------------------------------------------------


@njit(**_JIT)
def elastic_trial(lam, mu, sigma0, H, yield_tol, yp, de, sig_n, eqps_n):
    """Elastic predictor of an update: trial stresses sig_n + D de (n, 6) (D from the Lame
    constants, engineering shear strains), the residual scales max(sigma0, max|sigma_trial|) and
    the plastic flags F(sigma_trial, sigma_bar(eqps_n)) > yield_tol * scale (n,)."""
    n = de.shape[0]
    sig_tr = np.empty((n, 6))
    scale = np.empty(n)
    plastic = np.empty(n, np.bool_)
    for i in range(n):
        tr = de[i, 0] + de[i, 1] + de[i, 2]
        big = sigma0
        for k in range(6):
            v = sig_n[i, k] + (2.0 * mu * de[i, k] + lam * tr if k < 3 else mu * de[i, k])
            sig_tr[i, k] = v
            big = max(big, abs(v))
        scale[i] = big
        p, s = _deviator(
            (sig_tr[i, 0], sig_tr[i, 1], sig_tr[i, 2], sig_tr[i, 3], sig_tr[i, 4], sig_tr[i, 5])
        )
        plastic[i] = _yield_value(yp, s, p, _j2(s), sigma0 + H * eqps_n[i]) > yield_tol * big
    return sig_tr, scale, plastic


@njit(**_JIT)
def merge_update(
    D,
    E,
    nu,
    de,
    sig_n,
    st_n,
    sig_tr,
    idx,
    r_stress,
    r_eqps,
    r_tangent,
    r_ok,
    stress,
    tangent,
    state,
    ok,
):
    """Assemble an update from the elastic trial and the plastic returns of the points idx:
    returned points take the return's stress, tangent and eqps, and the plastic strain
    eps_pl_n + de - C (sigma - sigma_n); the others (elastic, or ok False) keep the trial stress,
    the elastic tangent D and the old state. Fills stress (n, 6), tangent (n, 6, 6), state
    (n, n_state) and ok (n,) (allocated by the caller: numpy's allocation pattern keeps the
    caller's large temporaries on the heap)."""
    n = de.shape[0]
    slot = np.empty(n, np.int64)
    for i in range(n):  # (explicit loops: slice assignments cost seconds of compilation)
        slot[i] = -1
        ok[i] = True
        for a in range(6):
            stress[i, a] = sig_tr[i, a]
        for a in range(st_n.shape[1]):
            state[i, a] = st_n[i, a]
    for j in range(idx.shape[0]):
        slot[idx[j]] = j
        ok[idx[j]] = r_ok[j]
    for i in range(n):
        j = slot[i]
        if j < 0 or not r_ok[j]:
            for a in range(6):
                for b in range(6):
                    tangent[i, a, b] = D[a, b]
            continue
        for a in range(6):
            stress[i, a] = r_stress[j, a]
            for b in range(6):
                tangent[i, a, b] = r_tangent[j, a, b]
        state[i, 0] = r_eqps[j]
        d0, d1, d2 = (
            stress[i, 0] - sig_n[i, 0],
            stress[i, 1] - sig_n[i, 1],
            stress[i, 2] - sig_n[i, 2],
        )
        state[i, 1] += de[i, 0] - (d0 - nu * (d1 + d2)) / E
        state[i, 2] += de[i, 1] - (d1 - nu * (d0 + d2)) / E
        state[i, 3] += de[i, 2] - (d2 - nu * (d0 + d1)) / E
        for a in range(3, 6):
            state[i, a + 1] += de[i, a] - 2.0 * (1.0 + nu) * (stress[i, a] - sig_n[i, a]) / E


@njit(**_JIT)
def _point_sensitivity(
    mp,
    yp,
    gp,
    dth,
    de,
    sig_n,
    st_n,
    sig_tr,
    plastic,
    stress,
    state,
    ok,
    dsig_n,
    dst_n,
    dde,
    i,
    dstress,
    dstate,
    x,
    R,
    J,
    piv,
    Rth,
    rhs,
):
    """Row ``i`` of :func:`update_sensitivities` (its arguments, plus the row index and the
    local work arrays ``x, R, J, piv, Rth, rhs``). Returns (good, apex, p_tr, dl): whether the
    point's derivatives are finite, whether it returned to the apex of the cone and, if so, its
    trial pressure (MPa) and plastic multiplier; at a smooth return ``J`` and ``piv`` hold the
    LU factors of the local Jacobian."""
    n_p, n_st = dth.shape[1], st_n.shape[1]
    _trial_sensitivity(mp, dth, de, dsig_n, dde, i, dstress)
    good = not plastic[i] or ok[i]
    is_apex = False
    p_tr = 0.0
    dl = 0.0
    if plastic[i] and good:
        st = (
            sig_tr[i, 0],
            sig_tr[i, 1],
            sig_tr[i, 2],
            sig_tr[i, 3],
            sig_tr[i, 4],
            sig_tr[i, 5],
        )
        en = st_n[i, 0]
        if int(yp[0]) == LINEAR:
            p_tr, s_tr = _deviator(st)
            is_apex, _, dl, _ = _apex_return(mp, yp, gp, p_tr, s_tr, _j2(s_tr), en)
            if is_apex:
                _apex_sensitivity(mp, yp, gp, dth, p_tr, en, dl, dst_n, i, dstress, dstate)
        if not is_apex:
            sig = (
                stress[i, 0],
                stress[i, 1],
                stress[i, 2],
                stress[i, 3],
                stress[i, 4],
                stress[i, 5],
            )
            good = _smooth_sensitivity(
                mp,
                yp,
                gp,
                dth,
                st,
                en,
                sig,
                state[i, 0],
                dst_n,
                i,
                dstress,
                dstate,
                x,
                R,
                J,
                piv,
                Rth,
                rhs,
            )
        if good:
            _plastic_strain_sensitivity(
                mp, dth, stress, sig_n, dsig_n, dde, dst_n, i, dstress, dstate
            )
    elif good:  # elastic: the old state
        for k in range(n_p):
            for b in range(n_st):
                dstate[i, k, b] = dst_n[i, k, b]
    if not good:
        for k in range(n_p):
            for a in range(6):
                dstress[i, k, a] = np.nan
            for b in range(n_st):
                dstate[i, k, b] = np.nan
    return good, is_apex, p_tr, dl


@njit(**_JIT)
def update_sensitivities(
    mp, yp, gp, dth, de, sig_n, st_n, sig_tr, plastic, stress, state, ok, dsig_n, dst_n, dde
):
    """Parameter derivatives of one update of n points (direct differentiation).

    Inputs: the kernel vectors; dtheta (TH_SIZE, P) = d theta / d parameters; the update's
    strain increments (n, 6), old stresses (n, 6) and states (n, n_state), the trial stresses
    (n, 6) and plastic flags (n,) of :func:`elastic_trial`; the update's stress, state and ok;
    the total derivatives of the old stress (n, P, 6), old state (n, P, n_state) and strain
    increment (n, P, 6). Returns d stress (n, P, 6) and d state (n, P, n_state): elastic
    points carry the trial derivative and the old state's; returned points are differentiated
    through the converged local residual (or the apex's closed form, recognised by the same
    test as :func:`plastic_return`), with the plastic strain as :func:`merge_update` forms it;
    failed points (ok False, or a singular local Jacobian) get NaN.
    """
    n, n_p, n_st = de.shape[0], dth.shape[1], st_n.shape[1]
    dstress = np.empty((n, n_p, 6))
    dstate = np.empty((n, n_p, n_st))
    x = np.empty(8)
    R = np.empty(8)
    J = np.empty((8, 8))
    piv = np.empty(8, np.int64)
    Rth = np.empty((8, TH_SIZE + 1))
    rhs = np.empty((8, n_p))
    for i in range(n):
        _point_sensitivity(
            mp,
            yp,
            gp,
            dth,
            de,
            sig_n,
            st_n,
            sig_tr,
            plastic,
            stress,
            state,
            ok,
            dsig_n,
            dst_n,
            dde,
            i,
            dstress,
            dstate,
            x,
            R,
            J,
            piv,
            Rth,
            rhs,
        )
    return dstress, dstate


@njit(**_JIT)
def affine_sensitivities(
    mp,
    yp,
    gp,
    dth,
    de,
    sig_n,
    st_n,
    sig_tr,
    plastic,
    stress,
    state,
    ok,
    tangent,
    dsig_n,
    dst_n,
    dde,
):
    """(c, h, T) of :func:`problems.materials.ddm.affine_sensitivity`: :func:`update_sensitivities`
    for the k parameter columns (c, h), plus T (n, 6 + n_state, 6) = d(stress, state)/d(strain
    increment) per point: at a smooth return six unit strain increments (entering the local
    residual as E e_j) solved with the LU factors the parameter columns formed; at the apex the
    closed forms with six unit-strain columns; elastic points the update's ``tangent``; failed
    points NaN."""
    n, n_st = de.shape[0], st_n.shape[1]
    k = dth.shape[1]
    c = np.empty((n, k, 6))
    h = np.empty((n, k, n_st))
    T = np.zeros((n, 6 + n_st, 6))
    E, nu = mp[M_E], mp[M_NU]
    x = np.empty(8)
    R = np.empty(8)
    J = np.empty((8, 8))
    piv = np.empty(8, np.int64)
    Rth = np.empty((8, TH_SIZE + 1))
    rhs = np.empty((8, k))
    b6 = np.empty((8, 6))
    # six unit strain increments of one point (index 0), for the apex's closed form
    z6 = np.zeros((TH_SIZE, 6))
    eye = np.zeros((1, 6, 6))
    for j in range(6):
        eye[0, j, j] = 1.0
    zs6, zq6 = np.zeros((1, 6, 6)), np.zeros((1, 6, n_st))
    ds6, dq6 = np.empty((1, 6, 6)), np.empty((1, 6, n_st))
    for i in range(n):
        good, is_apex, p_tr, dl = _point_sensitivity(
            mp,
            yp,
            gp,
            dth,
            de,
            sig_n,
            st_n,
            sig_tr,
            plastic,
            stress,
            state,
            ok,
            dsig_n,
            dst_n,
            dde,
            i,
            c,
            h,
            x,
            R,
            J,
            piv,
            Rth,
            rhs,
        )
        if not good:
            for r in range(6 + n_st):
                for j in range(6):
                    T[i, r, j] = np.nan
            continue
        if is_apex:
            one = slice(i, i + 1)
            _trial_sensitivity(mp, z6, de[one], zs6, eye, 0, ds6)
            _apex_sensitivity(mp, yp, gp, z6, p_tr, st_n[i, 0], dl, zq6, 0, ds6, dq6)
            _plastic_strain_sensitivity(mp, z6, stress[one], sig_n[one], zs6, eye, zq6, 0, ds6, dq6)
            for j in range(6):
                for r in range(6):
                    T[i, r, j] = ds6[0, j, r]
                for r in range(n_st):
                    T[i, 6 + r, j] = dq6[0, j, r]
            continue
        if not plastic[i]:  # elastic: T_s = D (the update's tangent), T_q = 0
            for r in range(6):
                for j in range(6):
                    T[i, r, j] = tangent[i, r, j]
            continue
        # smooth return: the six unit strain increments enter the local residual as E e_j; one
        # multi-column solve with the LU factors of the local Jacobian the parameter columns
        # formed gives d sigma (rows 0-5) and E d eqps (row 7); the plastic strain rows are
        # e_j - C d sigma
        for a in range(8):
            for j in range(6):
                b6[a, j] = E if a == j else 0.0
        if not _lu8_solve(J, piv, b6):
            for r in range(6 + n_st):
                for j in range(6):
                    T[i, r, j] = np.nan
            continue
        for j in range(6):
            t = b6[0, j] + b6[1, j] + b6[2, j]
            T[i, 6, j] = b6[7, j] / E
            for a in range(6):
                v = b6[a, j]
                T[i, a, j] = v
                Sv = (1.0 + nu) * v - nu * t if a < 3 else 2.0 * (1.0 + nu) * v
                T[i, 7 + a, j] = (1.0 if a == j else 0.0) - Sv / E
    return c, h, T


@njit(**_JIT)
def work_exhaustion(mp, yp, gp, sig_tr, eqps_n):
    """Diagnosis of failed returns of the von Mises-section forms (hyperbolic, exponent) with the
    plastic-work rule, at trial stresses (m, 6) and eqps_n (m,): (exhausted (m,) bool, dl_fold,
    F at the fold (MPa), sigma_bar at the fold (MPa)).

    Exhausted: the backward-Euler return has no solution because negative plastic work (high
    confinement with dilatant flow, w = sigma : dG/dsigma < 0) would take more strength than the
    work rule can give in one increment -- at most sigma_bar_n / 2 (the quadratic's fold) -- and
    F is still positive there (:func:`_work_fold`). Smaller increments then only approach
    sigma_bar = 0, where the linear hardening law ends: the model itself has no continuation. Always
    False for the linear form (its eqps never decreases)."""
    m = sig_tr.shape[0]
    exhausted = np.zeros(m, np.bool_)
    dl_fold = np.full(m, _INF)
    f_fold = np.full(m, np.nan)
    sbar_fold = np.full(m, np.nan)
    if int(yp[0]) == LINEAR or int(mp[M_RULE]) != WORK:
        return exhausted, dl_fold, f_fold, sbar_fold
    for n in range(m):
        st = (sig_tr[n, 0], sig_tr[n, 1], sig_tr[n, 2], sig_tr[n, 3], sig_tr[n, 4], sig_tr[n, 5])
        p_tr, s_tr = _deviator(st)
        q_tr = math.sqrt(3.0 * _j2(s_tr))
        exhausted[n], dl_fold[n], f_fold[n], sbar_fold[n] = _work_fold(
            mp, yp, gp, p_tr, q_tr, eqps_n[n]
        )
    return exhausted, dl_fold, f_fold, sbar_fold


@njit(**_JIT)
def yield_values(yp, stress, sbar):
    """F (n,) at stresses (n, 6) and yield stresses sigma_bar (n,)."""
    out = np.empty(stress.shape[0])
    for i in range(stress.shape[0]):
        p, s = _deviator(
            (stress[i, 0], stress[i, 1], stress[i, 2], stress[i, 3], stress[i, 4], stress[i, 5])
        )
        out[i] = _yield_value(yp, s, p, _j2(s), sbar[i])
    return out


@njit(**_JIT)
def strengths(yp, sbar):
    """k(sigma_bar) and dk/dsigma_bar (n,) of F = phi(p, q, J3) - k (see :func:`_strength`)."""
    k = np.empty(sbar.shape[0])
    dk = np.empty(sbar.shape[0])
    for i in range(sbar.shape[0]):
        k[i], dk[i] = _strength(yp, sbar[i])
    return k, dk


@njit(**_JIT)
def potential_gradients(gp, stress):
    """dG/dsigma (n, 6), engineering components (undefined at the cone's apex)."""
    out = np.empty((stress.shape[0], 6))
    H = np.empty((0, 0))
    for i in range(stress.shape[0]):
        s = _deviator(stress[i])[1]
        g = _potential(gp, s, _j2(s), False, 0.0, H)
        for k in range(6):
            out[i, k] = g[k]
    return out


@njit(**_JIT)
def lode_values(A, B, stress):
    """t = A q + B J3 / q^2 (n,) of the linear form."""
    out = np.empty(stress.shape[0])
    for i in range(stress.shape[0]):
        s = _deviator(stress[i])[1]
        out[i] = _lode_t(A, B, s, _j2(s))
    return out


@njit(**_JIT)
def lode_xis(stress):
    """(r/q)^3 (n,) in [-1, 1], 0 where q = 0."""
    out = np.empty(stress.shape[0])
    for i in range(stress.shape[0]):
        s = _deviator(stress[i])[1]
        out[i] = _lode_xi(s, _j2(s))
    return out


@njit(**_JIT)
def polar_factors(xi, K):
    out = np.empty(xi.shape[0])
    for i in range(xi.shape[0]):
        out[i] = _polar_factor(xi[i], K)
    return out


@njit(**_JIT)
def third_invariants(s, order):
    """J3 (n, 1), dJ3/dsigma (n, 6) or d2J3/dsigma^2 (n, 36) of Voigt deviators s (n, 6)."""
    n = s.shape[0]
    out = np.zeros((n, (1, 6, 36)[order]))
    H = np.empty((6, 6))
    for i in range(n):
        si = (s[i, 0], s[i, 1], s[i, 2], s[i, 3], s[i, 4], s[i, 5])
        if order == 0:
            out[i, 0] = _j3(si)
        elif order == 1:
            g = _grad_j3(si, _j2(si))
            for a in range(6):
                out[i, a] = g[a]
        else:
            for a in range(6):
                for b in range(6):
                    H[a, b] = 0.0
            _add_hess_j3(si, 1.0, H)
            for a in range(6):
                for b in range(6):
                    out[i, 6 * a + b] = H[a, b]
    return out


heal_numba_cache(globals())  # a torn cache file of these kernels: named, removed

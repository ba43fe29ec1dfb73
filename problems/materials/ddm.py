"""Parameter sensitivities of the material update by direct differentiation (DDM).

Three pieces sit here beside the materials' ``sensitivity`` methods:

* :func:`kernel_parameter_jacobian`: the chain rule from the physical Drucker-Prager parameters
  (``DruckerPrager.parameter_names``: E, sigma0, H, pt0 in MPa, beta and psi in degrees, a in
  MPa^(1-b), K, b, nu -) to the kernel parameters theta that the compiled return mapping reads
  (E, nu, sigma0, H, the eqps-rule constant, ``yp[1:]``, ``gp[1:]``; see ``_kernels.TH_*``),
  written analytically after the mapping of :func:`drucker_prager.make_material`;
* :func:`affine_sensitivity`: the sensitivities of one update as an affine function of the
  unknown part of the strain-increment derivative (one kernel pass instead of two per increment
  of the global DDM, problems/fe/sensitivity.py);
* :func:`run_path_sensitivity`: a material-point DDM driver that takes points along prescribed
  strain paths through ``update`` and ``sensitivity``, carrying the derivatives of stress and
  state from increment to increment.

The equations are in ``docs/drucker_prager.md`` (section "Parameter sensitivities").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from problems.materials import _kernels as _K
from problems.materials.hardening import reference_test

_RAD = math.pi / 180.0
_JIT = dict(cache=True, nogil=True, error_model="numpy")


def _dtan_deg(tan_value: float) -> float:
    """d tan(angle)/d angle (1/deg) at tan(angle) = tan_value."""
    return _RAD * (1.0 + tan_value * tan_value)


def kernel_parameter_jacobian(material) -> np.ndarray:
    """d theta / d p (``_kernels.TH_SIZE``, P) of a Drucker-Prager material: rows the kernel
    parameters (``_kernels.TH_*``), columns ``material.parameter_names``.

    Linear form: ``yp = [tan beta, A, B, d_hat, K]``, ``gp = [tan psi, A, B]`` with
    A = (1 + 1/K)/2, B = 27/4 (1/K - 1), d_hat = q_hat (A - (1 - A) xi) - p_hat tan beta and the
    eqps constant c = A - (1 - A) xi - p_hat/q_hat tan psi (xi, p_hat, q_hat of the reference
    test). Hyperbolic: ``yp = [tan beta, l0, q_hat, p_hat]`` with l0 = (S^2 - A^2)/(2 A),
    S = q_hat sigma0, A = tan beta (pt0 + p_hat sigma0). Exponent: ``yp = [a, b, q_hat, p_hat]``.
    Both: ``gp = [tan psi, e]``, e = max(eccentricity sigma0 tan psi, 1e-6 sigma0).
    """
    names = material.parameter_names
    col = {name: j for j, name in enumerate(names)}
    v = material.params
    test = reference_test(material.hardening)
    out = np.zeros((_K.TH_SIZE, len(names)))
    out[_K.TH_E, col["E"]] = 1.0
    out[_K.TH_NU, col["nu"]] = 1.0
    out[_K.TH_S0, col["sigma0"]] = 1.0
    out[_K.TH_H, col["H"]] = 1.0
    tp = material.potential.tan_psi
    out[_K.TH_G, col["psi"]] = _dtan_deg(tp)
    if material.form == "linear":
        _linear_rows(out, col, v["K"], material.yield_function.tan_beta, tp, test)
    else:
        _eccentricity_rows(out, col, v["eccentricity"], v["sigma0"], tp)
        if material.form == "hyperbolic":
            _hyperbolic_rows(
                out, col, v["sigma0"], v["pt0"], material.yield_function.tan_beta, test
            )
        else:
            out[_K.TH_Y, col["a"]] = 1.0
            out[_K.TH_Y + 1, col["b"]] = 1.0
    return out


def _linear_rows(out, col, K, tb, tp, test) -> None:
    """Rows of A, B (in yp and gp), d_hat, K and c: functions of K, beta and psi."""
    dA, dB = -0.5 / K**2, -6.75 / K**2
    dh_K = -0.5 * (1.0 + test.xi) / K**2  # d (t_hat / q_hat) / dK
    jK, jb, jp = col["K"], col["beta"], col["psi"]
    dtb, dtp = _dtan_deg(tb), _dtan_deg(tp)
    out[_K.TH_Y, jb] = dtb
    out[_K.TH_Y + 1, jK] = out[_K.TH_G + 1, jK] = dA
    out[_K.TH_Y + 2, jK] = out[_K.TH_G + 2, jK] = dB
    out[_K.TH_Y + 3, jK] = test.q_hat * dh_K
    out[_K.TH_Y + 3, jb] = -test.p_hat * dtb
    out[_K.TH_Y + 4, jK] = 1.0
    out[_K.TH_C, jK] = dh_K
    out[_K.TH_C, jp] = -test.p_hat / test.q_hat * dtp


def _hyperbolic_rows(out, col, s0, pt0, tb, test) -> None:
    """Row of l0 = (S^2 - A^2)/(2A): dl0/dS = S/A, dl0/dA = -S^2/(2A^2) - 1/2."""
    S, A = test.q_hat * s0, tb * (pt0 + test.p_hat * s0)
    l0_S, l0_A = S / A, -0.5 * S * S / (A * A) - 0.5
    dtb = _dtan_deg(tb)
    out[_K.TH_Y, col["beta"]] = dtb
    out[_K.TH_Y + 1, col["beta"]] = l0_A * (pt0 + test.p_hat * s0) * dtb
    out[_K.TH_Y + 1, col["pt0"]] = l0_A * tb
    out[_K.TH_Y + 1, col["sigma0"]] = l0_S * test.q_hat + l0_A * tb * test.p_hat


def _eccentricity_rows(out, col, ecc, s0, tp) -> None:
    """Row of e = max(ecc sigma0 tan psi, 1e-6 sigma0) (the branch make_material takes)."""
    if ecc * s0 * tp >= 1e-6 * s0:
        out[_K.TH_G + 1, col["sigma0"]] = ecc * tp
        out[_K.TH_G + 1, col["psi"]] = ecc * s0 * _dtan_deg(tp)
    else:
        out[_K.TH_G + 1, col["sigma0"]] = 1e-6


# --------------------------------------------------------------------------------------------
# One-pass sensitivities for the global DDM
# --------------------------------------------------------------------------------------------


def affine_sensitivity(
    material,
    strain_increment,
    stress_old,
    state_old,
    update,
    dstress_old,
    dstate_old,
    dstrain_known,
    columns,
):
    """The update's parameter sensitivities as an affine function of the still unknown part of
    the strain-increment derivative, from one pass of the kernel, or None when ``material`` has
    no such pass (then call ``material.sensitivity`` twice).

    ``sensitivity`` is linear in (dtheta, dstress_old, dstate_old, dstrain_increment) jointly, so
    for ``dstrain_increment = dstrain_known + e``::

        dstress = c + T_s e,   dstate = h + T_q e

    with (c, h) the sensitivities for e = 0 and T = [T_s; T_q] = d(stress, state)/d(strain
    increment) of the update. One pass over the points gives both (:func:`_affine_kernel`): the
    k parameter ``columns`` (indices into ``parameter_names``) as ``sensitivity`` computes them,
    and T: at a smooth return, six unit strain increments solved with the LU factors of the
    local Jacobian that the parameter columns formed (e_j enters the local residual as E e_j;
    d sigma and E d eqps come out, the plastic-strain rows are I - C T_s since the plastic
    strain is formed as eps_pl_n + deps - C (sigma - sigma_n)): six back-substitutions instead
    of six more columns through the whole kernel; apex returns go through the same closed forms
    as ``sensitivity`` with six unit-strain columns; elastic points have T_s = D (the update's
    tangent), T_q = 0. Inputs: strain_increment, stress_old (n, 6), state_old (n, n_state),
    the ``update`` of them, dstress_old (n, k, 6), dstate_old (n, k, n_state), dstrain_known
    (n, k, 6) for the k columns (MPa, 1 per parameter unit). Returns (c (n, k, 6) MPa per unit,
    h (n, k, n_state) per unit, T (n, 6 + n_state, 6) MPa and -); failed points carry NaN like
    ``sensitivity``. Tested against ``DruckerPrager.sensitivity`` to round-off.
    """
    from problems.materials.drucker_prager import DruckerPrager

    if not isinstance(material, DruckerPrager):
        return None
    de, sig_n, st_n = (
        np.ascontiguousarray(a, dtype=float) for a in (strain_increment, stress_old, state_old)
    )
    dth = np.ascontiguousarray(kernel_parameter_jacobian(material)[:, list(columns)])
    sig_tr, _, plastic = material._elastic_trial(de, sig_n, np.ascontiguousarray(st_n[:, 0]))
    return _affine_kernel(
        material._kernel_params,
        material.yield_function.kernel_params,
        material.potential.kernel_params,
        dth,
        de,
        sig_n,
        st_n,
        sig_tr,
        plastic,
        np.ascontiguousarray(update.stress),
        np.ascontiguousarray(update.state),
        np.ascontiguousarray(update.ok),
        np.ascontiguousarray(update.tangent, dtype=float),
        np.ascontiguousarray(dstress_old, dtype=float),
        np.ascontiguousarray(dstate_old, dtype=float),
        np.ascontiguousarray(dstrain_known, dtype=float),
    )


@njit(**_JIT)
def _affine_kernel(
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
    """(c, h, T) of :func:`affine_sensitivity`: the loop of ``_kernels.update_sensitivities``
    for the k parameter columns, plus T per point."""
    n, k, n_st = de.shape[0], dth.shape[1], st_n.shape[1]
    c = np.empty((n, k, 6))
    h = np.empty((n, k, n_st))
    T = np.zeros((n, 6 + n_st, 6))
    cone = int(yp[0]) == _K.LINEAR
    E, nu = mp[_K.M_E], mp[_K.M_NU]
    x = np.empty(8)
    R = np.empty(8)
    J = np.empty((8, 8))
    piv = np.empty(8, np.int64)
    Rth = np.empty((8, _K.TH_SIZE + 1))
    rhs = np.empty((8, k))
    b6 = np.empty((8, 6))
    # six unit strain increments of one point (index 0), for the apex's closed form
    z6 = np.zeros((_K.TH_SIZE, 6))
    eye = np.zeros((1, 6, 6))
    for j in range(6):
        eye[0, j, j] = 1.0
    zs6, zq6 = np.zeros((1, 6, 6)), np.zeros((1, 6, n_st))
    ds6, dq6 = np.empty((1, 6, 6)), np.empty((1, 6, n_st))
    for i in range(n):
        _K._trial_sensitivity(mp, dth, de, dsig_n, dde, i, c)
        good = not plastic[i] or ok[i]
        smooth = False
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
            is_apex = False
            if cone:
                p_tr, s_tr = _K._deviator(st)
                is_apex, _, dl, _ = _K._apex_return(mp, yp, gp, p_tr, s_tr, _K._j2(s_tr), en)
                if is_apex:
                    _K._apex_sensitivity(mp, yp, gp, dth, p_tr, en, dl, dst_n, i, c, h)
                    one = slice(i, i + 1)
                    _K._trial_sensitivity(mp, z6, de[one], zs6, eye, 0, ds6)
                    _K._apex_sensitivity(mp, yp, gp, z6, p_tr, en, dl, zq6, 0, ds6, dq6)
                    _K._plastic_strain_sensitivity(
                        mp, z6, stress[one], sig_n[one], zs6, eye, zq6, 0, ds6, dq6
                    )
                    for j in range(6):
                        for r in range(6):
                            T[i, r, j] = ds6[0, j, r]
                        for r in range(n_st):
                            T[i, 6 + r, j] = dq6[0, j, r]
            if not is_apex:
                sig = (
                    stress[i, 0],
                    stress[i, 1],
                    stress[i, 2],
                    stress[i, 3],
                    stress[i, 4],
                    stress[i, 5],
                )
                good = _K._smooth_sensitivity(
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
                    c,
                    h,
                    x,
                    R,
                    J,
                    piv,
                    Rth,
                    rhs,
                )
                smooth = good
            if good:
                _K._plastic_strain_sensitivity(mp, dth, stress, sig_n, dsig_n, dde, dst_n, i, c, h)
        elif good:  # elastic: the old state
            for q in range(k):
                for b in range(n_st):
                    h[i, q, b] = dst_n[i, q, b]
        if not good:
            for q in range(k):
                for a in range(6):
                    c[i, q, a] = np.nan
                for b in range(n_st):
                    h[i, q, b] = np.nan
            for r in range(6 + n_st):
                for j in range(6):
                    T[i, r, j] = np.nan
            continue
        if plastic[i] and not smooth:
            continue  # apex: T done above
        if not smooth:  # elastic: T_s = D (the update's tangent), T_q = 0
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
        if not _K._lu8_solve(J, piv, b6):
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


# --------------------------------------------------------------------------------------------
# Material-point DDM driver
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PathSensitivity:
    """Histories of a DDM material-point run (one entry per increment, end of the increment).

    stress  : (steps, n, 6) MPa            dstress : (steps, n, P, 6) MPa per parameter unit
    state   : (steps, n, n_state)          dstate  : (steps, n, P, n_state)
    ok      : (steps, n) bool, the update's convergence flags
    parameter_names : the P parameters, in column order
    """

    stress: np.ndarray
    state: np.ndarray
    ok: np.ndarray
    dstress: np.ndarray
    dstate: np.ndarray
    parameter_names: tuple[str, ...]


def run_path_sensitivity(material, increments, stress0=None, state0=None) -> PathSensitivity:
    """Take n points through prescribed strain increments (steps, n, 6) (engineering shear),
    from stress0 (n, 6) MPa (default 0) and state0 (default the virgin state), with
    ``update`` then ``sensitivity`` per increment. The strain path and the initial state do not
    depend on the parameters, so their derivatives start at zero and ddeps/dp = 0."""
    increments = np.asarray(increments, float)
    steps, n = increments.shape[:2]
    if steps == 0:
        raise ValueError("the strain path needs at least one increment")
    n_p = len(material.parameter_names)
    stress = np.zeros((n, 6)) if stress0 is None else np.array(stress0, float)
    state = material.initial_state(n) if state0 is None else np.array(state0, float)
    dstress, dstate = np.zeros((n, n_p, 6)), np.zeros((n, n_p, state.shape[1]))
    zero_dde = np.zeros((n, n_p, 6))
    hist = {key: [] for key in ("stress", "state", "ok", "dstress", "dstate")}
    for de in increments:
        up = material.update(de, stress, state)
        dstress, dstate = material.sensitivity(de, stress, state, up, dstress, dstate, zero_dde)
        stress, state = up.stress, up.state
        for key, value in zip(hist, (stress, state, up.ok, dstress, dstate)):
            hist[key].append(value)
    return PathSensitivity(
        *(np.stack(hist[key]) for key in hist), parameter_names=tuple(material.parameter_names)
    )

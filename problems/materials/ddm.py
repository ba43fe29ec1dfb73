"""Parameter sensitivities of the material update by direct differentiation (DDM).

Two pieces sit here beside the materials' ``sensitivity`` methods (the chain rule from the
physical parameters to the kernel's, which both use, is :mod:`kernel_jacobian`):

* :func:`affine_sensitivity`: the sensitivities of one update as an affine function of the
  unknown part of the strain-increment derivative (one kernel pass instead of two per increment
  of the global DDM, problems/fe/ddm.py);
* :func:`run_path_sensitivity`: a material-point DDM driver that takes points along prescribed
  strain paths through ``update`` and ``sensitivity``, carrying the derivatives of stress and
  state from increment to increment.

The equations are in ``docs/drucker_prager.md`` (section "Parameter sensitivities").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from problems.materials import _kernels as _K
from problems.materials.kernel_jacobian import kernel_parameter_jacobian

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
    increment) of the update. One pass over the points gives both
    (:func:`_kernels.affine_sensitivities`): the
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
    return _K.affine_sensitivities(
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

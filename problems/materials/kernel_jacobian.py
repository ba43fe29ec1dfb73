"""The chain rule from the physical Drucker-Prager parameters to the kernel's.

:func:`kernel_parameter_jacobian`: d theta / d p from the physical parameters
(``DruckerPrager.parameter_names``: E, sigma0, H, pt0 in MPa, beta and psi in degrees, a in
MPa^(1-b), K, b, nu -) to the kernel parameters theta that the compiled return mapping reads
(E, nu, sigma0, H, the eqps-rule constant, ``yp[1:]``, ``gp[1:]``; see ``_kernels.TH_*``),
written analytically after the mapping of :func:`drucker_prager.make_material`. Used by the
material's ``sensitivity`` and by :func:`ddm.affine_sensitivity`; the equations are in
``docs/drucker_prager.md`` (section "Parameter sensitivities").
"""

from __future__ import annotations

import math

import numpy as np

from problems.materials import _kernels as _K
from problems.materials.hardening import reference_test

_RAD = math.pi / 180.0


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

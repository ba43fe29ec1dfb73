"""Stress invariants and their first and second derivatives, in the Voigt convention of
:mod:`problems.materials.base`.

Stress vectors are ``[xx, yy, zz, yz, xz, xy]`` with the *tensor* shear components. Every
derivative here is taken with respect to those six independent components, which is what the
return mapping needs: ``dG/dsigma_voigt`` is directly the plastic flow direction in
*engineering* strain components (a shear entry of the gradient counts the symmetric pair
``sigma_yz = sigma_zy`` once, i.e. it equals ``2 dG/dsigma_yz`` = the engineering shear rate).

Invariants (compression-positive pressure, as in the extended Drucker-Prager literature)::

    p  = -tr(sigma)/3                    s = sigma + p I  (deviator)
    J2 = s:s/2,  q = sqrt(3 J2)          (von Mises stress, MPa)
    J3 = det(s) = tr(s^3)/3,  r = cbrt(27/2 J3) = cbrt(9/2 tr(s^3))  (keeps the sign)

All functions are vectorised over the leading axis (``n`` points). The third invariant and its
derivatives are those of the compiled per-point code of :mod:`_kernels` (the return mapping's),
looped over the points.
"""

from __future__ import annotations

import numpy as np

from problems.materials import _kernels as _K

#: ``m = [1,1,1,0,0,0]``: Voigt identity, d tr(sigma) / d sigma.
M_VEC = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])

# Hessian of J2 with respect to the six Voigt stress components: the deviatoric projector on
# the normal block and 2 on the shear diagonal (each shear component appears twice in s:s).
HESS_J2 = np.zeros((6, 6))
HESS_J2[:3, :3] = np.eye(3) - 1.0 / 3.0
HESS_J2[3:, 3:] = 2.0 * np.eye(3)


def pressure(stress: np.ndarray) -> np.ndarray:
    """Equivalent pressure ``p = -tr(sigma)/3`` (MPa), compression positive; shape (n,)."""
    return -(stress[:, 0] + stress[:, 1] + stress[:, 2]) / 3.0


def deviator(stress: np.ndarray) -> np.ndarray:
    """Deviatoric stress ``s = sigma + p I`` in Voigt form (tensor shear components), (n, 6)."""
    s = stress.copy()
    s[:, :3] += pressure(stress)[:, None]
    return s


def j2(s: np.ndarray) -> np.ndarray:
    """Second deviatoric invariant ``J2 = s:s/2`` of a Voigt deviator, (n,)."""
    return 0.5 * np.einsum("ni,ni->n", s[:, :3], s[:, :3]) + np.einsum(
        "ni,ni->n", s[:, 3:], s[:, 3:]
    )


def j3(s: np.ndarray) -> np.ndarray:
    """Third deviatoric invariant ``J3 = det(s)`` of a Voigt deviator, (n,)."""
    return _K.third_invariants(_rows(s), 0)[:, 0]


def mises(stress: np.ndarray) -> np.ndarray:
    """Von Mises equivalent stress ``q = sqrt(3/2 s:s)`` (MPa), (n,)."""
    return np.sqrt(3.0 * j2(deviator(stress)))


def third_invariant_r(stress: np.ndarray) -> np.ndarray:
    """``r = (9/2 s.s:s)^(1/3)`` (MPa) with its sign (real cube root), (n,)."""
    return np.cbrt(13.5 * j3(deviator(stress)))


def grad_j2(s: np.ndarray) -> np.ndarray:
    """d J2 / d sigma_voigt = the deviator with engineering (doubled) shear entries, (n, 6)."""
    g = s.copy()
    g[:, 3:] *= 2.0
    return g


def grad_j3(s: np.ndarray) -> np.ndarray:
    """d J3 / d sigma_voigt = dev(s.s) with doubled shear entries, (n, 6)."""
    return _K.third_invariants(_rows(s), 1)


def hess_j3(s: np.ndarray) -> np.ndarray:
    """d2 J3 / d sigma_voigt^2, symmetric, linear in the deviator, (n, 6, 6)."""
    return _K.third_invariants(_rows(s), 2).reshape(-1, 6, 6)


def _rows(s) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(s, float))


def outer(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Batched outer product ``a_i b_j``, (n, 6, 6)."""
    return a[:, :, None] * b[:, None, :]

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

All functions are vectorised over the leading axis (``n`` points).
"""
from __future__ import annotations

import numpy as np

#: ``m = [1,1,1,0,0,0]``: Voigt identity, d tr(sigma) / d sigma.
M_VEC = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])

# Hessian of J2 with respect to the six Voigt stress components: the deviatoric projector on
# the normal block and 2 on the shear diagonal (each shear component appears twice in s:s).
HESS_J2 = np.zeros((6, 6))
HESS_J2[:3, :3] = np.eye(3) - 1.0 / 3.0
HESS_J2[3:, 3:] = 2.0 * np.eye(3)

_PAIRS = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))  # Voigt index -> tensor (i, j)


def _basis() -> np.ndarray:
    """``B[a]``: d sigma_tensor / d sigma_voigt[a] (3x3 each; shear ones carry both (i,j) and (j,i))."""
    B = np.zeros((6, 3, 3))
    for a, (i, j) in enumerate(_PAIRS):
        B[a, i, j] = 1.0
        B[a, j, i] = 1.0
    return B


def _hess_j3_operator() -> np.ndarray:
    """Linear map (36, 6) from the deviator in Voigt form to the Hessian of J3, flattened.

    With ``E_a = dev(B_a)`` (d s / d sigma_a) and cof(s) = s.s - J2 I the gradient of J3 is
    ``cof(s) : E_a``; since tr(E_a) = 0 the J2 I part drops from the second derivative and
    ``d2 J3 / d sigma_a d sigma_b = tr(s (E_a E_b + E_b E_a))``, linear in s.
    """
    B = _basis()
    E = B - np.einsum("a,ij->aij", np.trace(B, axis1=1, axis2=2) / 3.0, np.eye(3))
    T = np.einsum("aij,bjk->abik", E, E)
    T = T + T.transpose(1, 0, 2, 3)
    # s_tensor = sum_c s_voigt[c] B_c  =>  H[a, b] = sum_c s_voigt[c] tr(B_c T[a, b])
    return np.einsum("cij,abji->abc", B, T).reshape(36, 6)


#: (36, 6): ``hess_j3(s).reshape(-1, 36) = s @ HESS_J3_OPERATOR.T``.
HESS_J3_OPERATOR = _hess_j3_operator()


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
    return 0.5 * np.einsum("ni,ni->n", s[:, :3], s[:, :3]) + np.einsum("ni,ni->n", s[:, 3:], s[:, 3:])


def j3(s: np.ndarray) -> np.ndarray:
    """Third deviatoric invariant ``J3 = det(s)`` of a Voigt deviator, (n,)."""
    xx, yy, zz, yz, xz, xy = s.T
    return xx * yy * zz + 2.0 * yz * xz * xy - xx * yz**2 - yy * xz**2 - zz * xy**2


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
    xx, yy, zz, yz, xz, xy = s.T
    s2 = np.empty_like(s)
    s2[:, 0] = xx * xx + xy * xy + xz * xz
    s2[:, 1] = xy * xy + yy * yy + yz * yz
    s2[:, 2] = xz * xz + yz * yz + zz * zz
    s2[:, 3] = 2.0 * (xy * xz + yy * yz + yz * zz)
    s2[:, 4] = 2.0 * (xx * xz + xy * yz + xz * zz)
    s2[:, 5] = 2.0 * (xx * xy + xy * yy + xz * yz)
    s2[:, :3] -= (2.0 / 3.0) * j2(s)[:, None]
    return s2


def hess_j3(s: np.ndarray) -> np.ndarray:
    """d2 J3 / d sigma_voigt^2, symmetric, linear in the deviator, (n, 6, 6)."""
    return (s @ HESS_J3_OPERATOR.T).reshape(-1, 6, 6)


def outer(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Batched outer product ``a_i b_j``, (n, 6, 6)."""
    return a[:, :, None] * b[:, None, :]

r"""The misfit of a model that is affine in a few coefficients, computed in their space.

A surrogate predicts ``U(x) = c + B a(x)`` with ``B`` (m, r) fixed and r (a few tens) much smaller
than m (thousands of measurements). The whitened residual of a
:class:`~problems.inverse.problem.LeastSquaresProblem` is then affine in ``a``::

    R(a) = C^(-1/2) (U_E - c) - C^(-1/2) B a = g0 - B_w a

With the thin QR factorisation ``B_w = Q T`` (Q (m, r) orthonormal columns, T (r, r) upper
triangular), ``g = Q^T g0`` and the part of ``g0`` outside the range of ``B_w``,
``c_perp = ||g0 - Q g||^2`` (computed once, directly: no cancellation of large terms), the cost is
exactly (to rounding)::

    R^T R = c_perp + || g - T a ||^2

O(r^2) per point instead of O(m r). The whitening is the problem's own (diagonal, diagonal plus
low rank, or full covariance), so every treatment of the data applies unchanged. The residual
vector ``g0 - B_w a`` is produced only when a solver asks for it (:meth:`AffineMisfit.residual`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class AffineMisfit:
    """``cost(a) = c_perp + ||g - T a||^2`` and ``residual(a) = g0 - B_w a`` of a problem whose
    model is ``U = c + B a`` (see the module docstring).

    T (r, r), g (r,), c_perp : the reduced form; g0 (m,), Bw (m, r) : the whitened offset and
    basis (for residual vectors)."""

    T: np.ndarray
    g: np.ndarray
    c_perp: float
    g0: np.ndarray
    Bw: np.ndarray

    @classmethod
    def of(cls, problem, offset, basis) -> "AffineMisfit":
        """The misfit of ``problem`` (its data and whitening) for the model ``offset + basis a``
        (offset (m,), basis (m, r), the units of the data)."""
        offset = np.asarray(offset, float).ravel()
        basis = np.asarray(basis, float)
        if offset.shape != problem.data.shape or basis.shape[0] != offset.size:
            raise ValueError(
                f"affine form of {offset.size} values and basis {basis.shape} does not match "
                f"the {problem.data.size} data"
            )
        g0 = problem.whiten(problem.data - offset)
        Bw = np.ascontiguousarray(problem.whiten(basis))
        Q, T = np.linalg.qr(Bw)
        g = Q.T @ g0
        perp = g0 - Q @ g
        return cls(np.ascontiguousarray(T), g, float(perp @ perp), g0, Bw)

    @property
    def n_coefficients(self) -> int:
        return self.g.size

    def costs(self, A) -> np.ndarray:
        """(q,) costs of the coefficient rows ``A`` (q, r)."""
        E = self.g - np.atleast_2d(A) @ self.T.T
        return self.c_perp + np.einsum("qi,qi->q", E, E)

    def residual(self, a) -> np.ndarray:
        """(m,) whitened residual ``g0 - B_w a`` at the coefficients ``a`` (r,)."""
        return self.g0 - self.Bw @ np.asarray(a, float)

"""Yield functions F(sigma, sigma_bar) and flow potentials G(sigma) of the extended Drucker-Prager
family: their parameters, derived constants and vectorised evaluation.

Units: stresses and F, G in MPa; sigma_bar is the current yield stress of the reference test
(MPa). Gradients are with respect to the six Voigt stress components (see :mod:`invariants`),
so a flow gradient is a plastic strain rate per unit multiplier in engineering components.

* linear      F = t - p tan(beta) - d_hat sigma_bar,         G = t - p tan(psi)
* hyperbolic  F = sqrt(l0^2 + q^2) - p tan(beta) - d'(sigma_bar)
* exponent    F = a q^b - p - pt(sigma_bar)
  hyperbolic and exponent share G = sqrt(e^2 + q^2) - p tan(psi), e = eccentricity sigma0 tan(psi)

with t = q/2 [1 + 1/K - (1 - 1/K)(r/q)^3] = A q + B J3 / q^2, A = (1 + 1/K)/2,
B = 27/4 (1/K - 1) >= 0 (because (r/q)^3 = 27 J3 / (2 q^3)).

The classes here hold the parameters and the derived constants; the arithmetic (values,
gradients, Hessians, the plastic work rate) is the compiled per-point code of :mod:`_kernels`,
which the vectorised methods below call with ``kernel_params``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from problems.materials import _kernels as _K
from problems.materials.hardening import ReferenceTest


def _rows(stress) -> np.ndarray:
    """Stresses as a C-contiguous float (n, 6) array (what the kernels take)."""
    return np.ascontiguousarray(np.atleast_2d(np.asarray(stress, float)))


def _per_point(values, n: int) -> np.ndarray:
    return np.ascontiguousarray(np.broadcast_to(np.asarray(values, float), (n,)))


def _scalar_map(fn, yp, sbar):
    """Apply a kernel taking (yp, sbar (n,)) -> (k, dk) to a scalar or array sbar, keeping its
    shape."""
    arr = np.asarray(sbar, float)
    k, dk = fn(yp, np.ascontiguousarray(arr.ravel()))
    if arr.ndim == 0:
        return float(k[0]), float(dk[0])
    return k.reshape(arr.shape), dk.reshape(arr.shape)


# --------------------------------------------------------------------------------------------
# Lode-dependent deviatoric measure t of the linear form
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LodeMeasure:
    """t(sigma) = A q + B J3 / q^2 (MPa): q in triaxial compression, q/K in triaxial tension."""

    K: float

    @property
    def A(self) -> float:
        return 0.5 * (1.0 + 1.0 / self.K)

    @property
    def B(self) -> float:
        return 6.75 * (1.0 / self.K - 1.0)

    def per_unit_q(self, xi) -> np.ndarray:
        """t / q as a function of xi = (r/q)^3 in [-1, 1]."""
        return 0.5 * ((1.0 + 1.0 / self.K) - (1.0 - 1.0 / self.K) * np.asarray(xi))

    def value(self, stress: np.ndarray) -> np.ndarray:
        return _K.lode_values(self.A, self.B, _rows(stress))


# --------------------------------------------------------------------------------------------
# Yield functions
# --------------------------------------------------------------------------------------------


class _YieldFunction:
    """F(sigma, sigma_bar) (n,) in MPa for stresses (n, 6) and yield stresses (n,) or scalar."""

    kernel_params: np.ndarray

    def value(self, stress, sbar):
        stress = _rows(stress)
        return _K.yield_values(self.kernel_params, stress, _per_point(sbar, stress.shape[0]))


@dataclass(frozen=True)
class LinearYield(_YieldFunction):
    """F = t - p tan(beta) - d, d = d_hat sigma_bar (reference state on the surface)."""

    tan_beta: float
    lode: LodeMeasure
    test: ReferenceTest

    @property
    def d_hat(self) -> float:
        """d / sigma_bar: compression 1 - tan(beta)/3, tension 1/K + tan(beta)/3,
        shear sqrt(3)/2 (1 + 1/K)."""
        t_hat = self.test.q_hat * float(self.lode.per_unit_q(self.test.xi))
        return t_hat - self.test.p_hat * self.tan_beta

    @property
    def kernel_params(self) -> np.ndarray:
        return np.array(
            [_K.LINEAR, self.tan_beta, self.lode.A, self.lode.B, self.d_hat, self.lode.K]
        )


@dataclass(frozen=True)
class HyperbolicYield(_YieldFunction):
    """F = sqrt(l0^2 + q^2) - p tan(beta) - d'(sigma_bar),
    d' = sqrt(l0^2 + (q_hat sigma_bar)^2) - p_hat sigma_bar tan(beta)."""

    tan_beta: float
    l0: float
    test: ReferenceTest

    @property
    def kernel_params(self) -> np.ndarray:
        return np.array(
            [_K.HYPERBOLIC, self.tan_beta, self.l0, self.test.q_hat, self.test.p_hat, 0.0]
        )

    def cohesion(self, sbar):
        """d'(sigma_bar) (MPa) and its derivative d d'/d sigma_bar (-)."""
        return _scalar_map(_K.strengths, self.kernel_params, sbar)


@dataclass(frozen=True)
class ExponentYield(_YieldFunction):
    """F = a q^b - p - pt(sigma_bar), pt = a (q_hat sigma_bar)^b - p_hat sigma_bar."""

    a: float
    b: float
    test: ReferenceTest

    @property
    def kernel_params(self) -> np.ndarray:
        return np.array([_K.EXPONENT, self.a, self.b, self.test.q_hat, self.test.p_hat, 0.0])

    def tension_strength(self, sbar):
        """pt(sigma_bar) (MPa) and d pt / d sigma_bar (-)."""
        return _scalar_map(_K.strengths, self.kernel_params, sbar)


# --------------------------------------------------------------------------------------------
# Flow potentials
# --------------------------------------------------------------------------------------------


class _Potential:
    def gradient(self, stress):
        """dG/dsigma (n, 6), engineering components."""
        return _K.potential_gradients(self.kernel_params, _rows(stress))


@dataclass(frozen=True)
class LinearPotential(_Potential):
    """G = t - p tan(psi): same deviatoric shape (K) as the yield surface; a cone with an apex
    (where the gradient is undefined)."""

    tan_psi: float
    lode: LodeMeasure

    @property
    def kernel_params(self) -> np.ndarray:
        return np.array([_K.CONE, self.tan_psi, self.lode.A, self.lode.B])


@dataclass(frozen=True)
class HyperbolicPotential(_Potential):
    """G = sqrt(e^2 + q^2) - p tan(psi): smooth, asymptotic to the linear cone of angle psi.

    e = eccentricity * sigma0 * tan(psi) (MPa) is the hyperbola's distance scale at q = 0.
    """

    tan_psi: float
    e: float

    @property
    def kernel_params(self) -> np.ndarray:
        return np.array([_K.HYPERBOLA, self.tan_psi, self.e, 0.0])


def lode_xi(stress: np.ndarray) -> np.ndarray:
    """(r/q)^3 = 27 J3 / (2 q^3) in [-1, 1] (0 where q = 0), (n,)."""
    return _K.lode_xis(_rows(stress))


def tan_deg(angle: float) -> float:
    """tan of an angle given in degrees."""
    return math.tan(math.radians(angle))

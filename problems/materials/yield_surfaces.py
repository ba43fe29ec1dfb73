"""Yield functions F(sigma, sigma_bar) and flow potentials G(sigma) of the extended Drucker-Prager
family, with the derivatives the return mapping needs.

Units: stresses and F, G in MPa; sigma_bar is the current yield stress of the reference test
(MPa). Gradients are with respect to the six Voigt stress components (see :mod:`invariants`),
so a flow gradient is a plastic strain rate per unit multiplier in engineering components.

* linear      F = t - p tan(beta) - d_hat sigma_bar,         G = t - p tan(psi)
* hyperbolic  F = sqrt(l0^2 + q^2) - p tan(beta) - d'(sigma_bar)
* exponent    F = a q^b - p - pt(sigma_bar)
  hyperbolic and exponent share G = sqrt(e^2 + q^2) - p tan(psi), e = eccentricity sigma0 tan(psi)

with t = q/2 [1 + 1/K - (1 - 1/K)(r/q)^3] = A q + B J3 / q^2, A = (1 + 1/K)/2,
B = 27/4 (1/K - 1) >= 0 (because (r/q)^3 = 27 J3 / (2 q^3)).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from problems.materials.hardening import ReferenceTest
from problems.materials.invariants import (
    HESS_J2, M_VEC, deviator, grad_j2, grad_j3, hess_j3, j2, j3, outer, pressure,
)

# Below this q (MPa) the deviator is treated as zero: it only guards 0/0 in directions that are
# multiplied by a vanishing deviator (the return mapping never iterates that close to an apex).
_Q_TINY = 1e-200


def _safe(q: np.ndarray) -> np.ndarray:
    return np.maximum(q, _Q_TINY)


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
        s = deviator(stress)
        q = np.sqrt(3.0 * j2(s))
        return self.A * q + self.B * j3(s) / _safe(q) ** 2

    def gradient(self, stress: np.ndarray, hessian: bool = False):
        """t, dt/dsigma (n, 6) and, if asked, d2t/dsigma2 (n, 6, 6).

        With t(q, J3): dt = t_q dq + t_J dJ3, t_q = A - 2 B J3/q^3, t_J = B/q^2, and
        dq = 3/(2q) dJ2,  d2q = 3/(2q) d2J2 - (1/q) dq dq.
        """
        s = deviator(stress)
        q = np.sqrt(3.0 * j2(s))
        qs = _safe(q)
        J3 = j3(s)
        gq = 1.5 * grad_j2(s) / qs[:, None]
        gJ = grad_j3(s)
        t = self.A * q + self.B * J3 / qs**2
        t_q = self.A - 2.0 * self.B * J3 / qs**3
        t_J = self.B / qs**2
        grad = t_q[:, None] * gq + t_J[:, None] * gJ
        if not hessian:
            return t, grad
        hq = (1.5 / qs)[:, None, None] * HESS_J2 - outer(gq, gq) / qs[:, None, None]
        t_qq = 6.0 * self.B * J3 / qs**4
        t_qJ = -2.0 * self.B / qs**3
        cross = outer(gq, gJ)
        hess = (t_q[:, None, None] * hq + t_J[:, None, None] * hess_j3(s)
                + t_qq[:, None, None] * outer(gq, gq) + t_qJ[:, None, None] * (cross + cross.transpose(0, 2, 1)))
        return t, grad, hess


# --------------------------------------------------------------------------------------------
# Yield functions
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class LinearYield:
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

    def value(self, stress, sbar):
        return self.lode.value(stress) - pressure(stress) * self.tan_beta - self.d_hat * sbar

    def gradient(self, stress, sbar):
        """F (n,), dF/dsigma (n, 6), dF/dsigma_bar (n,)."""
        t, gt = self.lode.gradient(stress)
        F = t - pressure(stress) * self.tan_beta - self.d_hat * sbar
        return F, gt + (self.tan_beta / 3.0) * M_VEC, np.full_like(F, -self.d_hat)


@dataclass(frozen=True)
class HyperbolicYield:
    """F = sqrt(l0^2 + q^2) - p tan(beta) - d'(sigma_bar),
    d' = sqrt(l0^2 + (q_hat sigma_bar)^2) - p_hat sigma_bar tan(beta)."""

    tan_beta: float
    l0: float
    test: ReferenceTest

    def cohesion(self, sbar):
        """d'(sigma_bar) (MPa) and its derivative d d'/d sigma_bar (-)."""
        qh, ph = self.test.q_hat, self.test.p_hat
        root = np.sqrt(self.l0**2 + (qh * sbar) ** 2)
        return root - ph * sbar * self.tan_beta, qh**2 * sbar / root - ph * self.tan_beta

    def value(self, stress, sbar):
        q = np.sqrt(3.0 * j2(deviator(stress)))
        return np.sqrt(self.l0**2 + q**2) - pressure(stress) * self.tan_beta - self.cohesion(sbar)[0]

    def gradient(self, stress, sbar):
        s = deviator(stress)
        root = np.sqrt(self.l0**2 + 3.0 * j2(s))
        d, dd = self.cohesion(sbar)
        F = root - pressure(stress) * self.tan_beta - d
        grad = (1.5 / root)[:, None] * grad_j2(s) + (self.tan_beta / 3.0) * M_VEC
        return F, grad, -dd


@dataclass(frozen=True)
class ExponentYield:
    """F = a q^b - p - pt(sigma_bar), pt = a (q_hat sigma_bar)^b - p_hat sigma_bar."""

    a: float
    b: float
    test: ReferenceTest

    def tension_strength(self, sbar):
        """pt(sigma_bar) (MPa) and d pt / d sigma_bar (-)."""
        qh, ph = self.test.q_hat, self.test.p_hat
        pt = self.a * (qh * sbar) ** self.b - ph * sbar
        return pt, self.a * self.b * qh**self.b * sbar ** (self.b - 1.0) - ph

    def value(self, stress, sbar):
        q = np.sqrt(3.0 * j2(deviator(stress)))
        return self.a * q**self.b - pressure(stress) - self.tension_strength(sbar)[0]

    def gradient(self, stress, sbar):
        s = deviator(stress)
        q = np.sqrt(3.0 * j2(s))
        qs = _safe(q)
        pt, dpt = self.tension_strength(sbar)
        F = self.a * q**self.b - pressure(stress) - pt
        # a b q^(b-1) dq/dsigma with dq = 3/(2q) dJ2; vanishes with the deviator for b > 1
        coef = np.where(q > _Q_TINY, 1.5 * self.a * self.b * qs ** (self.b - 2.0), 0.0)
        grad = coef[:, None] * grad_j2(s) + M_VEC / 3.0
        return F, grad, -dpt


# --------------------------------------------------------------------------------------------
# Flow potentials
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class LinearPotential:
    """G = t - p tan(psi): same deviatoric shape (K) as the yield surface; a cone with an apex."""

    tan_psi: float
    lode: LodeMeasure

    def gradient(self, stress):
        return self.lode.gradient(stress)[1] + (self.tan_psi / 3.0) * M_VEC

    def hessian(self, stress):
        """dG/dsigma (n, 6) and d2G/dsigma2 (n, 6, 6); singular at q = 0 (the apex)."""
        _, g, h = self.lode.gradient(stress, hessian=True)
        return g + (self.tan_psi / 3.0) * M_VEC, h


@dataclass(frozen=True)
class HyperbolicPotential:
    """G = sqrt(e^2 + q^2) - p tan(psi): smooth, asymptotic to the linear cone of angle psi.

    e = eccentricity * sigma0 * tan(psi) (MPa) is the hyperbola's distance scale at q = 0.
    """

    tan_psi: float
    e: float

    def gradient(self, stress):
        s = deviator(stress)
        root = np.sqrt(self.e**2 + 3.0 * j2(s))
        return (1.5 / _safe(root))[:, None] * grad_j2(s) + (self.tan_psi / 3.0) * M_VEC

    def hessian(self, stress):
        s = deviator(stress)
        gJ2 = grad_j2(s)
        root = _safe(np.sqrt(self.e**2 + 3.0 * j2(s)))
        g = (1.5 / root)[:, None] * gJ2 + (self.tan_psi / 3.0) * M_VEC
        h = (1.5 / root)[:, None, None] * HESS_J2 - (2.25 / root**3)[:, None, None] * outer(gJ2, gJ2)
        return g, h


def lode_xi(stress: np.ndarray) -> np.ndarray:
    """(r/q)^3 = 27 J3 / (2 q^3) in [-1, 1] (0 where q = 0), (n,)."""
    s = deviator(stress)
    q = np.sqrt(3.0 * j2(s))
    return np.clip(np.where(q > _Q_TINY, 13.5 * j3(s) / _safe(q) ** 3, 0.0), -1.0, 1.0)


def tan_deg(angle: float) -> float:
    """tan of an angle given in degrees."""
    return math.tan(math.radians(angle))

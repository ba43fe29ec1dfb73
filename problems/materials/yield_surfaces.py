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
    HESS_J2, HESS_J3_OPERATOR, M_VEC, deviator, grad_j2, grad_j3, j2, j3, pressure,
)

# [s_voigt, a] (n, 7) @ _HESS_OPERATOR = d2J3 weighted by s plus a * d2J2, flattened (n, 36)
_HESS_OPERATOR = np.vstack([HESS_J3_OPERATOR.T, HESS_J2.reshape(1, 36)])

# Below this q (MPa) the deviator is treated as zero: it only guards 0/0 in terms that vanish
# with the deviator (the return mapping never iterates that close to an apex). Small enough to be
# meaningless in MPa, large enough that 1/q^4 does not overflow.
_Q_TINY = 1e-60


def _safe(q: np.ndarray) -> np.ndarray:
    return np.maximum(q, _Q_TINY)


def _inv(q: np.ndarray) -> np.ndarray:
    """1/q, and 0 where q is (numerically) zero: every 1/q^k term multiplies a deviator power."""
    return np.where(q > _Q_TINY, 1.0 / _safe(q), 0.0)


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
        return self.A * q + self.B * j3(s) * _inv(q) ** 2

    def gradient(self, stress: np.ndarray, hessian_weight: np.ndarray | None = None):
        """t (n,), dt/dsigma (n, 6) and, if a weight w (n,) is given, w * d2t/dsigma2 (n, 6, 6).

        With t(q, J3): dt = t_q dq + t_J dJ3, t_q = A - 2 B J3/q^3, t_J = B/q^2, and
        dq = 3/(2q) dJ2, d2q = 3/(2q) d2J2 - (1/q) dq dq. The Hessian is assembled as
        ``a P + t_J d2J3 + dq (x) v1 + dJ3 (x) v2`` (P = d2J2) with the scalar weights folded in
        before the (n, 6, 6) arrays are formed: it is the hot spot of the return mapping.
        """
        s = deviator(stress)
        q = np.sqrt(3.0 * j2(s))
        qi = _inv(q)
        gq = 1.5 * grad_j2(s) * qi[:, None]
        if self.B == 0.0:  # K = 1: t = q, no third-invariant terms
            t, grad = q, gq
            if hessian_weight is None:
                return t, grad
            w = hessian_weight
            hess = (1.5 * w * qi)[:, None, None] * HESS_J2
            hess -= gq[:, :, None] * (w * qi)[:, None, None] * gq[:, None, :]
            return t, grad, hess
        J3 = j3(s)
        gJ = grad_j3(s)
        t = self.A * q + self.B * J3 * qi**2
        t_q = self.A - 2.0 * self.B * J3 * qi**3
        t_J = self.B * qi**2
        grad = t_q[:, None] * gq + t_J[:, None] * gJ
        if hessian_weight is None:
            return t, grad
        w = hessian_weight
        t_qq = 6.0 * self.B * J3 * qi**4
        t_qJ = -2.0 * self.B * qi**3
        coeffs = np.concatenate([(w * t_J)[:, None] * s, (1.5 * w * t_q * qi)[:, None]], axis=1)
        hess = (coeffs @ _HESS_OPERATOR).reshape(-1, 6, 6)
        v1 = (w * (t_qq - t_q * qi))[:, None] * gq + (w * t_qJ)[:, None] * gJ
        v2 = (w * t_qJ)[:, None] * gq
        hess += gq[:, :, None] * v1[:, None, :]
        hess += gJ[:, :, None] * v2[:, None, :]
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

    def value_pq(self, p, q, sbar):
        """F from the invariants p, q (MPa)."""
        return np.sqrt(self.l0**2 + q**2) - p * self.tan_beta - self.cohesion(sbar)[0]

    def value(self, stress, sbar):
        return self.value_pq(pressure(stress), np.sqrt(3.0 * j2(deviator(stress))), sbar)

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

    def value_pq(self, p, q, sbar):
        """F from the invariants p, q (MPa)."""
        return self.a * q**self.b - p - self.tension_strength(sbar)[0]

    def value(self, stress, sbar):
        return self.value_pq(pressure(stress), np.sqrt(3.0 * j2(deviator(stress))), sbar)

    def gradient(self, stress, sbar):
        s = deviator(stress)
        q = np.sqrt(3.0 * j2(s))
        pt, dpt = self.tension_strength(sbar)
        F = self.a * q**self.b - pressure(stress) - pt
        # a b q^(b-1) dq/dsigma with dq = 3/(2q) dJ2; vanishes with the deviator for b > 1
        coef = np.where(q > _Q_TINY, 1.5 * self.a * self.b * _safe(q) ** (self.b - 2.0), 0.0)
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

    def hessian(self, stress, weight):
        """dG/dsigma (n, 6) and weight * d2G/dsigma2 (n, 6, 6); singular at q = 0 (the apex)."""
        _, g, h = self.lode.gradient(stress, hessian_weight=weight)
        return g + (self.tan_psi / 3.0) * M_VEC, h

    def work(self, stress):
        """sigma : dG/dsigma = G (degree-one homogeneous) and its gradient dG/dsigma."""
        g = self.gradient(stress)
        return np.einsum("ni,ni->n", stress, g), g


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

    def hessian(self, stress, weight):
        """dG/dsigma (n, 6) and weight * d2G/dsigma2 (n, 6, 6)."""
        s = deviator(stress)
        gJ2 = grad_j2(s)
        root = _safe(np.sqrt(self.e**2 + 3.0 * j2(s)))
        g = (1.5 / root)[:, None] * gJ2 + (self.tan_psi / 3.0) * M_VEC
        h = (1.5 * weight / root)[:, None, None] * HESS_J2
        h -= gJ2[:, :, None] * ((2.25 * weight / root**3)[:, None] * gJ2)[:, None, :]
        return g, h

    def work(self, stress):
        """Plastic work per unit multiplier w = sigma : dG/dsigma = q^2/R - p tan(psi)
        (R = sqrt(e^2 + q^2)) and dw/dsigma = dG/dsigma + d2G/dsigma2 sigma, where
        d2G sigma = dJ2 (3/(2R)) e^2/R^2 (from sigma . dJ2 = 2 J2 and d2J2 sigma = dJ2)."""
        s = deviator(stress)
        gJ2 = grad_j2(s)
        J2 = j2(s)
        root = _safe(np.sqrt(self.e**2 + 3.0 * J2))
        g = (1.5 / root)[:, None] * gJ2 + (self.tan_psi / 3.0) * M_VEC
        w = 3.0 * J2 / root - pressure(stress) * self.tan_psi
        dw = g + (1.5 * self.e**2 / root**3)[:, None] * gJ2
        return w, dw


def lode_xi(stress: np.ndarray) -> np.ndarray:
    """(r/q)^3 = 27 J3 / (2 q^3) in [-1, 1] (0 where q = 0), (n,)."""
    s = deviator(stress)
    q = np.sqrt(3.0 * j2(s))
    return np.clip(np.where(q > _Q_TINY, 13.5 * j3(s) / _safe(q) ** 3, 0.0), -1.0, 1.0)


def tan_deg(angle: float) -> float:
    """tan of an angle given in degrees."""
    return math.tan(math.radians(angle))

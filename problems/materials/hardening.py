"""Hardening of the extended Drucker-Prager family: the reference test, the yield-stress law and
the rule that turns the plastic multiplier into equivalent plastic strain.

The hardening is one scalar yield stress ``sigma_bar(eqps) = sigma0 + H eqps`` (MPa) measured in
one *reference test*: uniaxial compression (sigma_bar = sigma_c), pure shear (sigma_bar = tau) or
uniaxial tension (sigma_bar = sigma_t). Each test is a proportional stress path, so its invariants
per unit of the measure are constants (compression-positive p)::

    test         p / sigma_bar   q / sigma_bar   (r/q)^3
    compression      +1/3             1            -1
    tension          -1/3             1            +1
    shear              0            sqrt(3)          0

Every yield surface of the family derives its size (cohesion d, d' or pt) from the condition that
the reference state with ``sigma_bar`` lies on the surface; see :mod:`yield_surfaces`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

HARDENINGS = ("compression", "shear", "tension")


@dataclass(frozen=True)
class ReferenceTest:
    """Invariants of a hardening test per unit of its stress measure sigma_bar.

    p_hat : p / sigma_bar (-), compression positive
    q_hat : q / sigma_bar (-); also the factor from sigma_bar to the work-conjugate stress
            (sigma_c, sigma_t, or sqrt(3) tau so that eqps = gamma_pl / sqrt(3) in shear)
    xi    : (r/q)^3 (-), the Lode measure of the test (-1 compression, +1 tension, 0 shear)
    """

    name: str
    p_hat: float
    q_hat: float
    xi: float


REFERENCE_TESTS = {
    "compression": ReferenceTest("compression", 1.0 / 3.0, 1.0, -1.0),
    "shear": ReferenceTest("shear", 0.0, math.sqrt(3.0), 0.0),
    "tension": ReferenceTest("tension", -1.0 / 3.0, 1.0, 1.0),
}


def reference_test(hardening: str) -> ReferenceTest:
    """The :class:`ReferenceTest` named ``hardening``; unknown names raise ValueError."""
    if hardening not in REFERENCE_TESTS:
        raise ValueError(f"hardening {hardening!r} is unknown; allowed: {', '.join(HARDENINGS)}")
    return REFERENCE_TESTS[hardening]


@dataclass(frozen=True)
class LinearHardening:
    """``sigma_bar = sigma0 + H eqps`` in MPa (sigma0 > 0, H >= 0: softening is out of scope)."""

    sigma0: float
    H: float

    def yield_stress(self, eqps: np.ndarray) -> np.ndarray:
        """Current yield stress sigma_bar (MPa) in the reference-test measure."""
        return self.sigma0 + self.H * eqps


@dataclass(frozen=True)
class ProportionalEqps:
    """Linear form: ``d eqps = c d lambda`` with a constant c (-).

    c is the value of the flow potential per unit plastic multiplier in the reference test
    divided by the work-conjugate stress; see :func:`linear_eqps_constant`.
    """

    c: float


@dataclass(frozen=True)
class WorkEqps:
    """Hyperbolic and exponent forms: plastic-work equivalence
    ``q_hat sigma_bar d eqps = sigma : d eps_pl = d lambda sigma : dG/dsigma``."""

    q_hat: float


def linear_eqps_constant(test: ReferenceTest, K: float, tan_psi: float) -> float:
    """c of ``d eqps = c d lambda`` for the linear form (-).

    G = t - p tan(psi) is positively homogeneous of degree one in sigma, so in the reference
    test ``sigma : d eps_pl = d lambda sigma : dG/dsigma = d lambda G``. Plastic-work equivalence
    with the work-conjugate stress ``q_hat sigma_bar`` gives ``d eqps = d lambda G / (q_hat
    sigma_bar) = d lambda (t_hat - p_hat tan psi) / q_hat`` with t_hat = t / sigma_bar:
    compression ``1 - tan(psi)/3``, tension ``1/K + tan(psi)/3``, shear ``(1 + 1/K)/2``.
    """
    t_hat = 0.5 * test.q_hat * ((1.0 + 1.0 / K) - (1.0 - 1.0 / K) * test.xi)
    return (t_hat - test.p_hat * tan_psi) / test.q_hat

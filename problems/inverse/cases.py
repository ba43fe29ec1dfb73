"""The nine cases of the study (Table 1): three yield surfaces x three hardening definitions.

A :class:`Case` is a plain description of an identification problem: active parameters with
their reference values, bounds and default start, plus the fixed material constants. It knows
nothing of FE or solvers. The shear and tension variants describe the *same* concrete as the
compression variant: their ``sigma0`` is the yield stress of the compression variant's initial
yield surface in pure shear or uniaxial tension, and ``H = 75 sigma0`` keeps H/sigma0 fixed.

Units: MPa for E, sigma0, H, pt0; degrees for beta and psi; ``a`` in MPa^(1-b); K, b, nu -.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import brentq
from scipy.stats import qmc

FORMS = ("linear", "hyperbolic", "exponent")
HARDENINGS = ("compression", "shear", "tension")
ACTIVE = {
    "linear": ("E", "beta", "K", "psi", "sigma0", "H"),
    "hyperbolic": ("E", "beta", "psi", "sigma0", "H", "pt0"),
    "exponent": ("E", "psi", "sigma0", "H", "a", "b"),
}
UNITS = {"E": "MPa", "beta": "deg", "K": "-", "psi": "deg", "sigma0": "MPa", "H": "MPa",
         "pt0": "MPa", "a": "MPa^(1-b)", "b": "-"}
FIXED = {"nu": 0.2, "eccentricity": 0.1}

# Reference concrete (compression variants).
E_REF, BETA_REF, K_REF, PSI_REF = 30_000.0, 35.0, 0.85, 15.0
SIGMA_C0, PT0_REF, B_REF, H_OVER_SIGMA0 = 20.0, 2.5, 1.5, 75.0
A_REF = (PT0_REF + SIGMA_C0 / 3.0) / SIGMA_C0**B_REF  # exponent surface through p = -pt0, q = 0


@dataclass(frozen=True)
class Parameter:
    """One identified parameter: reference value and box bounds in physical units."""

    name: str
    unit: str
    reference: float
    lower: float
    upper: float

    def __post_init__(self):
        if not (self.lower <= self.reference <= self.upper):
            raise ValueError(f"{self.name}: reference {self.reference} outside [{self.lower}, {self.upper}]")


@dataclass(frozen=True)
class Case:
    """An identification problem: active parameters, bounds, default start and fixed constants."""

    name: str
    form: str
    hardening: str
    parameters: tuple[Parameter, ...]
    fixed: dict = field(default_factory=dict)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    @property
    def reference(self) -> np.ndarray:
        return np.array([p.reference for p in self.parameters])

    @property
    def lower(self) -> np.ndarray:
        return np.array([p.lower for p in self.parameters])

    @property
    def upper(self) -> np.ndarray:
        return np.array([p.upper for p in self.parameters])

    @property
    def start(self) -> np.ndarray:
        """Default start: reference x (1 + 0.25 s), s = +1, -1, +1, ... in listed order, clipped."""
        s = np.where(np.arange(len(self.parameters)) % 2 == 0, 1.0, -1.0)
        return np.clip(self.reference * (1.0 + 0.25 * s), self.lower, self.upper)

    def random_starts(self, n: int, seed: int) -> np.ndarray:
        """``n`` seeded Latin-hypercube points in the bounds, shape (n, n_params)."""
        unit = qmc.LatinHypercube(d=len(self.parameters), seed=np.random.default_rng(seed)).random(n)
        return qmc.scale(unit, self.lower, self.upper)

    def material_parameters(self, x) -> dict[str, float]:
        """Full material parameter dict (active values from ``x`` plus the fixed constants)."""
        x = np.asarray(x, float)
        if x.shape != (len(self.parameters),):
            raise ValueError(f"{self.name}: expected {len(self.parameters)} parameters {self.names}, got shape {x.shape}")
        return {**self.fixed, **dict(zip(self.names, map(float, x)))}

    def to_dict(self) -> dict:
        """The JSON form listed by ``femubench cases --json``."""
        return {
            "name": self.name, "form": self.form, "hardening": self.hardening,
            "parameters": [
                {"name": p.name, "unit": p.unit, "reference": p.reference, "lower": p.lower,
                 "upper": p.upper, "start": float(s)}
                for p, s in zip(self.parameters, self.start)
            ],
            "fixed": dict(self.fixed),
        }


# --- the same concrete seen through each hardening test ------------------------------------

def _sigma0_linear(hardening: str) -> float:
    tb, K = math.tan(math.radians(BETA_REF)), K_REF
    d = (1.0 - tb / 3.0) * SIGMA_C0
    return {"compression": SIGMA_C0, "tension": d / (1.0 / K + tb / 3.0),
            "shear": d / (math.sqrt(3.0) / 2.0 * (1.0 + 1.0 / K))}[hardening]


def hyperbolic_l0(sigma_c: float, pt0: float, beta_deg: float) -> float:
    """l0 (MPa) of the hyperbolic surface through p = -pt0, q = 0 and uniaxial compression sigma_c.

    From sqrt(l0^2 + sc^2) - sc tanb/3 = l0 + pt0 tanb: with A = tanb (pt0 + sc/3),
    (l0 + A)^2 = l0^2 + sc^2  =>  l0 = (sc^2 - A^2) / (2 A).
    """
    A = math.tan(math.radians(beta_deg)) * (pt0 + sigma_c / 3.0)
    return (sigma_c**2 - A**2) / (2.0 * A)


def _sigma0_hyperbolic(hardening: str) -> float:
    tb = math.tan(math.radians(BETA_REF))
    l0 = hyperbolic_l0(SIGMA_C0, PT0_REF, BETA_REF)
    d0 = l0 + PT0_REF * tb
    if hardening == "compression":
        return SIGMA_C0
    if hardening == "shear":
        return math.sqrt((d0**2 - l0**2) / 3.0)
    return brentq(lambda st: math.sqrt(l0**2 + st**2) + st * tb / 3.0 - d0, 1e-9, SIGMA_C0)


def _sigma0_exponent(hardening: str) -> float:
    a, b, pt = A_REF, B_REF, PT0_REF
    if hardening == "compression":
        return SIGMA_C0
    if hardening == "shear":
        return (pt / a) ** (1.0 / b) / math.sqrt(3.0)
    return brentq(lambda st: a * st**b + st / 3.0 - pt, 1e-9, SIGMA_C0)


_SIGMA0 = {"linear": _sigma0_linear, "hyperbolic": _sigma0_hyperbolic, "exponent": _sigma0_exponent}


def _parameter(name: str, ref: float) -> Parameter:
    absolute = {"beta": (20.0, 50.0), "psi": (5.0, 30.0), "K": (0.778, 1.0)}
    if name in absolute:
        lo, hi = absolute[name]
    else:
        rel = 0.5 if name in ("E", "H") else 0.3
        lo, hi = ref * (1 - rel), ref * (1 + rel)
    return Parameter(name, UNITS[name], ref, lo, hi)


def make_case(form: str, hardening: str) -> Case:
    """Build the case ``f"{form}-{hardening}"`` with reference values of the study."""
    if form not in FORMS:
        raise ValueError(f"form {form!r} is unknown; allowed: {', '.join(FORMS)}")
    if hardening not in HARDENINGS:
        raise ValueError(f"hardening {hardening!r} is unknown; allowed: {', '.join(HARDENINGS)}")
    sigma0 = _SIGMA0[form](hardening)
    refs = {"E": E_REF, "beta": BETA_REF, "K": K_REF, "psi": PSI_REF, "sigma0": sigma0,
            "H": H_OVER_SIGMA0 * sigma0, "pt0": PT0_REF, "a": A_REF, "b": B_REF}
    params = tuple(_parameter(n, refs[n]) for n in ACTIVE[form])
    return Case(f"{form}-{hardening}", form, hardening, params, dict(FIXED))


CASES: dict[str, Case] = {c.name: c for c in (make_case(f, h) for f in FORMS for h in HARDENINGS)}


def all_cases() -> dict[str, Case]:
    """The nine FE cases plus the analytic test problems (``analytic-*``) by name."""
    from problems.inverse.analytic import ANALYTIC_CASES  # analytic problems live with their models

    return {**CASES, **ANALYTIC_CASES}


def get_case(name: str) -> Case:
    """Look a case up by name; unknown names raise ValueError listing the allowed ones."""
    if name in CASES:
        return CASES[name]
    cases = all_cases()
    if name not in cases:
        raise ValueError(f"case {name!r} is unknown; allowed: {', '.join(cases)}")
    return cases[name]

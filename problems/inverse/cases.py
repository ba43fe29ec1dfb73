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

from scipy.optimize import brentq

from problems.inverse.analytic import ANALYTIC_CASES
from problems.inverse.case import Case, Parameter
from problems.materials.drucker_prager import (
    FORM_PARAMETERS, FORMS, OPTIONAL_PARAMETERS, PARAMETER_RANGES, hyperbolic_l0,
)
from problems.materials.hardening import HARDENINGS

#: the active (identified) parameters of each form are the material's own parameters
ACTIVE = FORM_PARAMETERS
UNITS = {name: PARAMETER_RANGES[name][4] for names in FORM_PARAMETERS.values() for name in names}
#: TeX symbol of each parameter (figure and table labels)
LABELS = {"E": r"$E$", "nu": r"$\nu$", "beta": r"$\beta$", "K": r"$K$", "psi": r"$\psi$",
          "sigma0": r"$\sigma_0$", "H": r"$H$", "pt0": r"$p_{t0}$", "a": r"$a$", "b": r"$b$"}
FIXED = dict(OPTIONAL_PARAMETERS)

# Reference concrete (compression variants).
E_REF, BETA_REF, K_REF, PSI_REF = 30_000.0, 35.0, 0.85, 15.0
SIGMA_C0, PT0_REF, B_REF, H_OVER_SIGMA0 = 20.0, 2.5, 1.5, 75.0
A_REF = (PT0_REF + SIGMA_C0 / 3.0) / SIGMA_C0**B_REF  # exponent surface through p = -pt0, q = 0


# --- the same concrete seen through each hardening test ------------------------------------

def _sigma0_linear(hardening: str) -> float:
    tb, K = math.tan(math.radians(BETA_REF)), K_REF
    d = (1.0 - tb / 3.0) * SIGMA_C0
    return {"compression": SIGMA_C0, "tension": d / (1.0 / K + tb / 3.0),
            "shear": d / (math.sqrt(3.0) / 2.0 * (1.0 + 1.0 / K))}[hardening]


def _sigma0_hyperbolic(hardening: str) -> float:
    tb = math.tan(math.radians(BETA_REF))
    l0 = hyperbolic_l0("compression", SIGMA_C0, PT0_REF, BETA_REF)
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
    return {**CASES, **ANALYTIC_CASES}


def get_case(name: str) -> Case:
    """Look a case up by name; unknown names raise ValueError listing the allowed ones."""
    if name in CASES:
        return CASES[name]
    cases = all_cases()
    if name not in cases:
        raise ValueError(f"case {name!r} is unknown; allowed: {', '.join(cases)}")
    return cases[name]

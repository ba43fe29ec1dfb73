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
from dataclasses import dataclass

from scipy.optimize import brentq

from problems.inverse.analytic import ANALYTIC_CASES
from problems.inverse.case import Case, Parameter
from problems.materials.drucker_prager import (
    FORM_PARAMETERS,
    FORMS,
    OPTIONAL_PARAMETERS,
    PARAMETER_RANGES,
    hyperbolic_l0,
)
from problems.materials.hardening import HARDENINGS, reference_test

#: the identified parameters of each form: the material's own, except that the exponent form
#: identifies its hydrostatic tension strength pt0 in place of a (every point of the box is then
#: a well-posed material; a = (pt0 + p_hat sigma0) / (q_hat sigma0)^b is reported alongside)
ACTIVE = {**FORM_PARAMETERS, "exponent": ("E", "psi", "sigma0", "H", "pt0", "b")}
UNITS = {name: PARAMETER_RANGES[name][4] for name in PARAMETER_RANGES}
FIXED = dict(OPTIONAL_PARAMETERS)

# Reference concrete (compression variants).
E_REF, BETA_REF, K_REF, PSI_REF = 30_000.0, 35.0, 0.85, 15.0
SIGMA_C0, PT0_REF, B_REF, H_OVER_SIGMA0 = 20.0, 2.5, 1.5, 75.0
A_REF = (PT0_REF + SIGMA_C0 / 3.0) / SIGMA_C0**B_REF  # exponent surface through p = -pt0, q = 0
#: the seed paper's Table 1: range of the identification error of the exponent coefficient a
#: over the exponent cases, percent (the parameter it identifies worst)
PAPER_A_ERROR = (11.0, 46.0)


# --- the same concrete seen through each hardening test ------------------------------------


def _sigma0_linear(hardening: str, sigma_c: float, beta: float, K: float) -> float:
    tb = math.tan(math.radians(beta))
    d = (1.0 - tb / 3.0) * sigma_c
    return {
        "compression": sigma_c,
        "tension": d / (1.0 / K + tb / 3.0),
        "shear": d / (math.sqrt(3.0) / 2.0 * (1.0 + 1.0 / K)),
    }[hardening]


def _sigma0_hyperbolic(hardening: str, sigma_c: float, beta: float, pt0: float) -> float:
    tb = math.tan(math.radians(beta))
    l0 = hyperbolic_l0("compression", sigma_c, pt0, beta)
    d0 = l0 + pt0 * tb
    if hardening == "compression":
        return sigma_c
    if hardening == "shear":
        return math.sqrt((d0**2 - l0**2) / 3.0)
    return brentq(lambda st: math.sqrt(l0**2 + st**2) + st * tb / 3.0 - d0, 1e-9, sigma_c)


def _sigma0_exponent(hardening: str, sigma_c: float, pt0: float, b: float) -> float:
    a = (pt0 + sigma_c / 3.0) / sigma_c**b  # the surface through p = -pt0, q = 0
    if hardening == "compression":
        return sigma_c
    if hardening == "shear":
        return (pt0 / a) ** (1.0 / b) / math.sqrt(3.0)
    return brentq(lambda st: a * st**b + st / 3.0 - pt0, 1e-9, sigma_c)


def sigma0_of(
    form: str,
    hardening: str,
    sigma_c: float = SIGMA_C0,
    *,
    beta: float = BETA_REF,
    K: float = K_REF,
    pt0: float = PT0_REF,
    b: float = B_REF,
) -> float:
    """The ``sigma0`` (MPa) of variant ``form``-``hardening`` for a concrete whose initial yield
    surface (of ``form``, shaped by beta in degrees, K, pt0 in MPa, b) yields at ``sigma_c`` MPa in
    uniaxial compression: that surface's yield stress in the variant's hardening test. The
    defaults are the study's reference concrete."""
    if form == "linear":
        return _sigma0_linear(hardening, sigma_c, beta, K)
    if form == "hyperbolic":
        return _sigma0_hyperbolic(hardening, sigma_c, beta, pt0)
    return _sigma0_exponent(hardening, sigma_c, pt0, b)


@dataclass(frozen=True)
class ExponentStrength:
    """The exponent form identified through pt0: ``a = (pt0 + p_hat sigma0) / (q_hat sigma0)^b``
    (the surface through p = -pt0, q = 0; p_hat, q_hat of the hardening's reference test)."""

    hardening: str

    def __call__(self, v: dict[str, float]) -> tuple[dict[str, float], dict[str, dict[str, float]]]:
        test = reference_test(self.hardening)
        s0, pt0, b = v["sigma0"], v["pt0"], v["b"]
        S = test.q_hat * s0
        a = (pt0 + test.p_hat * s0) / S**b
        values = {k: w for k, w in v.items() if k != "pt0"} | {"a": a}
        da = {"pt0": 1.0 / S**b, "sigma0": test.p_hat / S**b - b * a / s0, "b": -a * math.log(S)}
        return values, {"a": da}


#: relative half-width of the box of each parameter (angles and K have absolute boxes)
BOX = {
    "E": (0.5, 0.5),
    "H": (0.5, 0.5),
    "sigma0": (0.3, 0.3),
    "pt0": (0.3, 0.3),
    "a": (0.3, 0.3),
    "b": (0.3, 0.3),
}
ABSOLUTE_BOX = {"beta": (20.0, 50.0), "psi": (5.0, 30.0), "K": (0.778, 1.0)}
#: hyperbolic surfaces hardened in tension need pt0 > sigma0/3: a box reaching 20 % (not 30 %)
#: below the reference pt0 keeps >= 95 % of the box well-posed
BOX_OVERRIDES = {("hyperbolic", "tension"): {"pt0": (0.2, 0.3)}}


def _parameter(name: str, ref: float, form: str, hardening: str) -> Parameter:
    if name in ABSOLUTE_BOX:
        lo, hi = ABSOLUTE_BOX[name]
    else:
        below, above = BOX_OVERRIDES.get((form, hardening), {}).get(name, BOX[name])
        lo, hi = ref * (1 - below), ref * (1 + above)
    return Parameter(name, UNITS[name], ref, lo, hi)


def make_case(form: str, hardening: str) -> Case:
    """Build the case ``f"{form}-{hardening}"`` with reference values of the study."""
    if form not in FORMS:
        raise ValueError(f"form {form!r} is unknown; allowed: {', '.join(FORMS)}")
    if hardening not in HARDENINGS:
        raise ValueError(f"hardening {hardening!r} is unknown; allowed: {', '.join(HARDENINGS)}")
    sigma0 = sigma0_of(form, hardening)
    refs = {
        "E": E_REF,
        "beta": BETA_REF,
        "K": K_REF,
        "psi": PSI_REF,
        "sigma0": sigma0,
        "H": H_OVER_SIGMA0 * sigma0,
        "pt0": PT0_REF,
        "a": A_REF,
        "b": B_REF,
    }
    params = tuple(_parameter(n, refs[n], form, hardening) for n in ACTIVE[form])
    name = f"{form}-{hardening}"
    derive = ExponentStrength(hardening) if form == "exponent" else None
    return Case(name, form, hardening, params, dict(FIXED), derive=derive)


CASES: dict[str, Case] = {c.name: c for c in (make_case(f, h) for f in FORMS for h in HARDENINGS)}


@dataclass(frozen=True)
class DefaultTreatment:
    """The model-error treatment a case uses when ``default`` is asked for (``--correction
    default``, suite ``treatments = ["default"]``), chosen from the model-error study
    (docs/objective.md, "The default treatment"): BAE statistics of the discretisation error
    ``U_paper - U_coarse`` over ``bae_samples`` prior samples, with the plate margin
    ``plate_margin_mm`` (:class:`problems.inverse.build.Region`). ``hifi_mesh`` is the
    high-fidelity mesh for the inverse mesh ``inverse_mesh``; another inverse mesh takes its next
    finer preset."""

    treatment: str = "bae"
    plate_margin_mm: float = 30.0
    hifi_mesh: str = "paper"
    bae_samples: int = 32
    inverse_mesh: str = "coarse"

    def to_dict(self) -> dict:
        return {
            "treatment": self.treatment,
            "plate_margin_mm": self.plate_margin_mm,
            "hifi_mesh": self.hifi_mesh,
            "bae_samples": self.bae_samples,
            "inverse_mesh": self.inverse_mesh,
        }

    def label(self) -> str:
        """E.g. ``bae (32 samples on paper for coarse), plate margin 30 mm``."""
        if self.treatment == "none":
            text = "none"
        elif self.treatment == "bae":
            text = f"bae ({self.bae_samples} samples on {self.hifi_mesh} for {self.inverse_mesh})"
        else:
            text = f"{self.treatment} (high-fidelity {self.hifi_mesh} for {self.inverse_mesh})"
        margin = self.plate_margin_mm
        return text + (f", plate margin {margin:g} mm" if margin else "")


#: the default treatment of every FE case (one setting for all nine: see docs/objective.md)
DEFAULT_TREATMENTS: dict[str, DefaultTreatment] = {name: DefaultTreatment() for name in CASES}


def default_treatment(name: str) -> DefaultTreatment:
    """The default model-error treatment of case ``name`` (analytic cases: ``none``, they have no
    discretisation error)."""
    get_case(name)  # ValueError listing the allowed names
    return DEFAULT_TREATMENTS.get(name, DefaultTreatment("none", 0.0, "", 0, ""))


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

"""What the report knows about cases and methods beyond the records: a frozen table.

The report reads records only; it never asks today's ``problems``/``solvers`` code what a case or
a method is, so the report of a shipped results folder does not change when that code changes.
What older records do not carry is written down here once, as the code defined it when the table
was frozen (tests/test_report_catalogue.py compares it with the code: when that test fails, a
case or a method changed, and whoever changed it decides whether old reports should follow):

* :data:`CASE_ORDER`: the nine FE cases in the study's order (tables and figures);
* :data:`CASES`: per case (FE and analytic) its identified parameters with their box
  ``(name, lower, upper, reference)`` in physical units (MPa, degrees, 1), whether it is an
  analytic test problem (no data tiers), the reference test constants ``(p_hat, q_hat)`` of the
  exponent cases (which identify pt0 in place of a: ``a = (pt0 + p_hat sigma0) / (q_hat
  sigma0)^b``, MPa^(1-b)) and the model-error treatment ``default`` stands for ``(treatment,
  plate margin in mm, high-fidelity mesh)``;
* :data:`METHOD_FAMILIES`: every registered method in registration order with its family
  (local, global, sampling); an unknown method is of family ``other``;
* :data:`PAPER_A_ERROR`: the seed paper's Table-1 range of the identification error of a
  (percent).

The parameters' TeX symbols are presentation, not facts of a case: :data:`bench.plotting.LABELS`.

Cases or methods that are not in the table (user problems, later cases) are reported as unknown:
no box, no derived parameters, family ``other``.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class CaseInfo:
    """One case as the report knows it (see the module's docstring)."""

    parameters: tuple[tuple[str, float, float, float], ...]
    default_treatment: tuple[str, float, str]
    analytic: bool = False
    exponent_strength: tuple[float, float] | None = None

    @property
    def names(self) -> tuple[str, ...]:
        """The identified parameters, in the case's order."""
        return tuple(p[0] for p in self.parameters)

    @property
    def reference(self) -> tuple[float, ...]:
        """Their reference values (physical units)."""
        return tuple(p[3] for p in self.parameters)

    def derived(self, x) -> dict[str, float]:
        """The derived parameters at the identified point ``x`` (physical, the case's order):
        ``{"a": a}`` for an exponent case, else empty. Raises ZeroDivisionError, OverflowError or
        ValueError where a is undefined."""
        if self.exponent_strength is None:
            return {}
        p_hat, q_hat = self.exponent_strength
        v = {n: float(xi) for n, xi in zip(self.names, x)}
        s0, pt0, b = v["sigma0"], v["pt0"], v["b"]
        S = q_hat * s0
        if not S > 0:
            raise ValueError(f"a is undefined for q_hat sigma0 = {S:g} MPa (not > 0)")
        return {"a": (pt0 + p_hat * s0) / S**b}


def case_info(name: str) -> CaseInfo | None:
    """The :class:`CaseInfo` of case ``name``, None when the table does not know it."""
    return CASES.get(str(name))


def is_analytic(name: str) -> bool:
    """Whether ``name`` is one of the analytic test problems (no data tiers)."""
    info = case_info(name)
    return bool(info is not None and info.analytic)


def case_facts(name: str) -> tuple[bool, str, float] | None:
    """``(analytic, default treatment, its plate margin in mm)`` of case ``name`` (what
    :func:`bench.experiment.store.method_label` needs), None when the table does not know it."""
    info = case_info(name)
    if info is None:
        return None
    return info.analytic, info.default_treatment[0], info.default_treatment[1]


def family(method: str) -> str:
    """``local``, ``global`` or ``sampling`` (the family of a registered method), ``other`` if
    unknown."""
    return METHOD_FAMILIES.get(str(method)) or "other"


CASE_ORDER = (
    "linear-compression",
    "linear-shear",
    "linear-tension",
    "hyperbolic-compression",
    "hyperbolic-shear",
    "hyperbolic-tension",
    "exponent-compression",
    "exponent-shear",
    "exponent-tension",
)
CASES: dict[str, CaseInfo] = {
    "linear-compression": CaseInfo(
        parameters=(
            ("E", 15000.0, 45000.0, 30000.0),
            ("beta", 20.0, 50.0, 35.0),
            ("K", 0.778, 1.0, 0.85),
            ("psi", 5.0, 30.0, 15.0),
            ("sigma0", 14.0, 26.0, 20.0),
            ("H", 750.0, 2250.0, 1500.0),
        ),
        default_treatment=("bae", 30.0, "paper"),
    ),
    "linear-shear": CaseInfo(
        parameters=(
            ("E", 15000.0, 45000.0, 30000.0),
            ("beta", 20.0, 50.0, 35.0),
            ("K", 0.778, 1.0, 0.85),
            ("psi", 5.0, 30.0, 15.0),
            ("sigma0", 5.693928282179915, 10.574438238334128, 8.134183260257021),
            ("H", 305.0318722596383, 915.095616778915, 610.0637445192766),
        ),
        default_treatment=("bae", 30.0, "paper"),
    ),
    "linear-tension": CaseInfo(
        parameters=(
            ("E", 15000.0, 45000.0, 30000.0),
            ("beta", 20.0, 50.0, 35.0),
            ("K", 0.778, 1.0, 0.85),
            ("psi", 5.0, 30.0, 15.0),
            ("sigma0", 7.612291357491612, 14.137112521055853, 10.874701939273733),
            ("H", 407.80132272276495, 1223.4039681682948, 815.6026454455299),
        ),
        default_treatment=("bae", 30.0, "paper"),
    ),
    "hyperbolic-compression": CaseInfo(
        parameters=(
            ("E", 15000.0, 45000.0, 30000.0),
            ("beta", 20.0, 50.0, 35.0),
            ("psi", 5.0, 30.0, 15.0),
            ("sigma0", 14.0, 26.0, 20.0),
            ("H", 750.0, 2250.0, 1500.0),
            ("pt0", 1.75, 3.25, 2.5),
        ),
        default_treatment=("bae", 30.0, "paper"),
    ),
    "hyperbolic-shear": CaseInfo(
        parameters=(
            ("E", 15000.0, 45000.0, 30000.0),
            ("beta", 20.0, 50.0, 35.0),
            ("psi", 5.0, 30.0, 15.0),
            ("sigma0", 4.059987913881528, 7.539977554351411, 5.79998273411647),
            ("H", 217.49935252936763, 652.4980575881029, 434.99870505873525),
            ("pt0", 1.75, 3.25, 2.5),
        ),
        default_treatment=("bae", 30.0, "paper"),
    ),
    "hyperbolic-tension": CaseInfo(
        parameters=(
            ("E", 15000.0, 45000.0, 30000.0),
            ("beta", 20.0, 50.0, 35.0),
            ("psi", 5.0, 30.0, 15.0),
            ("sigma0", 3.7356869928880294, 6.937704415363484, 5.336695704125757),
            ("H", 200.12608890471586, 600.3782667141476, 400.2521778094317),
            ("pt0", 2.0, 3.25, 2.5),
        ),
        default_treatment=("bae", 30.0, "paper"),
    ),
    "exponent-compression": CaseInfo(
        parameters=(
            ("E", 15000.0, 45000.0, 30000.0),
            ("psi", 5.0, 30.0, 15.0),
            ("sigma0", 14.0, 26.0, 20.0),
            ("H", 750.0, 2250.0, 1500.0),
            ("pt0", 1.75, 3.25, 2.5),
            ("b", 1.0499999999999998, 1.9500000000000002, 1.5),
        ),
        exponent_strength=(0.3333333333333333, 1.0),
        default_treatment=("bae", 30.0, "paper"),
    ),
    "exponent-shear": CaseInfo(
        parameters=(
            ("E", 15000.0, 45000.0, 30000.0),
            ("psi", 5.0, 30.0, 15.0),
            ("sigma0", 3.399276208796827, 6.3129415306226795, 4.856108869709753),
            ("H", 182.10408261411573, 546.3122478423472, 364.20816522823145),
            ("pt0", 1.75, 3.25, 2.5),
            ("b", 1.0499999999999998, 1.9500000000000002, 1.5),
        ),
        exponent_strength=(0.0, 1.7320508075688772),
        default_treatment=("bae", 30.0, "paper"),
    ),
    "exponent-tension": CaseInfo(
        parameters=(
            ("E", 15000.0, 45000.0, 30000.0),
            ("psi", 5.0, 30.0, 15.0),
            ("sigma0", 3.1729824038048466, 5.8926816070661445, 4.532832005435496),
            ("H", 169.9812002038311, 509.94360061149325, 339.9624004076622),
            ("pt0", 1.75, 3.25, 2.5),
            ("b", 1.0499999999999998, 1.9500000000000002, 1.5),
        ),
        exponent_strength=(-0.3333333333333333, 1.0),
        default_treatment=("bae", 30.0, "paper"),
    ),
    "analytic-smooth": CaseInfo(
        parameters=(
            ("E", 15000.0, 45000.0, 30000.0),
            ("sigma0", 14.0, 26.0, 20.0),
            ("H", 750.0, 2250.0, 1500.0),
            ("psi", 5.0, 30.0, 15.0),
        ),
        analytic=True,
        default_treatment=("none", 0.0, ""),
    ),
    "analytic-multimodal": CaseInfo(
        parameters=(
            ("a", 0.5, 2.0, 1.0),
            ("omega", 1.0, 4.0, 2.0),
            ("c", 0.5, 1.5, 1.0),
        ),
        analytic=True,
        default_treatment=("none", 0.0, ""),
    ),
    "analytic-rastrigin": CaseInfo(
        parameters=(
            ("a", 1.3199999999999998, 3.12, 2.0),
            ("b", 2.4, 6.8999999999999995, 5.0),
            ("c", 5.84, 11.44, 8.0),
        ),
        analytic=True,
        default_treatment=("none", 0.0, ""),
    ),
    "analytic-linear": CaseInfo(
        parameters=(
            ("p", 0.5, 1.5, 1.0),
            ("q", 1.0, 3.0, 2.0),
            ("r", 1.5, 4.5, 3.0),
        ),
        analytic=True,
        default_treatment=("none", 0.0, ""),
    ),
    "analytic-infeasible": CaseInfo(
        parameters=(
            ("E", 15000.0, 45000.0, 30000.0),
            ("sigma0", 14.0, 26.0, 20.0),
            ("H", 750.0, 2250.0, 1500.0),
            ("psi", 5.0, 30.0, 15.0),
        ),
        analytic=True,
        default_treatment=("none", 0.0, ""),
    ),
    "analytic-failing": CaseInfo(
        parameters=(
            ("E", 15000.0, 45000.0, 30000.0),
            ("sigma0", 14.0, 26.0, 20.0),
            ("H", 750.0, 2250.0, 1500.0),
            ("psi", 5.0, 30.0, 15.0),
        ),
        analytic=True,
        default_treatment=("none", 0.0, ""),
    ),
}
METHOD_FAMILIES: dict[str, str] = {
    "lm": "local",
    "trf": "local",
    "lm-minpack": "local",
    "sa": "global",
    "gauss-newton": "local",
    "ga": "global",
    "de": "global",
    "pso": "global",
    "nlopt:BOBYQA": "local",
    "nlopt:SBPLX": "local",
    "nlopt:NELDERMEAD": "local",
    "nlopt:COBYLA": "local",
    "nlopt:LBFGS": "local",
    "nlopt:CRS2_LM": "global",
    "nlopt:DIRECT_L": "global",
    "nlopt:ESCH": "global",
    "nlopt:ISRES": "global",
    "nlopt:MLSL": "global",
    "mcmc": "sampling",
    "multistart-lm": "global",
    "pso+lm": "global",
    "cma": "global",
    "bo": "global",
    "ngopt": "global",
}
PAPER_A_ERROR: tuple[float, float] = (11.0, 46.0)

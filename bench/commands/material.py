"""``femubench material CASE``: one Drucker-Prager material point along a test path."""

from __future__ import annotations

NAME = "material"
HELP = (
    "drive one material point of a Drucker-Prager case along uniaxial compression/tension, "
    "pure shear or hydrostatic tension and print step, eps_axial, sig_axial, p, q, eqps"
)

_PATHS = ("uniaxial-compression", "uniaxial-tension", "shear", "hydrostatic")
_HARDENINGS = ("compression", "shear", "tension")


def add_arguments(parser) -> None:
    from bench.commands._args import output_file, positive_float, positive_int

    parser.add_argument(
        "case",
        metavar="CASE",
        help="a case name such as linear-compression, or a form (linear, hyperbolic, "
        "exponent) together with --hardening",
    )
    parser.add_argument(
        "--hardening",
        choices=_HARDENINGS,
        default=None,
        help="hardening test when CASE is a form (default compression)",
    )
    parser.add_argument(
        "--path",
        choices=_PATHS,
        default=None,
        help="loading path (default: the hardening test's own path); shear prescribes "
        "the engineering strain gamma_xy, hydrostatic is equal triaxial extension",
    )
    parser.add_argument(
        "--strain",
        type=positive_float,
        default=None,
        metavar="VALUE",
        help="final strain magnitude, > 0; the path sets the sign (default: 5 times "
        "the elastic strain at first yield in the hardening test)",
    )
    parser.add_argument(
        "--steps",
        type=positive_int,
        default=50,
        metavar="N",
        help="number of equal steps, >= 1 (default 50)",
    )
    parser.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="override a material parameter (repeatable); E, sigma0, H, pt0 in MPa, "
        "beta, psi in degrees; defaults are the case's reference values",
    )
    parser.add_argument(
        "--csv", metavar="FILE", default=None, type=output_file, help="also write the table as CSV"
    )


def parse_overrides(items) -> dict[str, float]:
    """``["E=30000", "psi=10"]`` -> {"E": 30000.0, "psi": 10.0}; malformed or non-finite items raise
    ValueError."""
    from bench.commands._args import assignments

    return assignments(items, "--param")


def resolve_case(case: str, hardening: str | None) -> tuple[str, str]:
    """(form, hardening) of a case name ``form-hardening`` or of a bare form plus --hardening."""
    from problems.materials.drucker_prager import FORMS

    if case in FORMS:
        return case, hardening or "compression"
    form, _, hard = case.partition("-")
    if form in FORMS and hard in _HARDENINGS:
        if hardening is not None and hardening != hard:
            raise ValueError(
                f"case {case!r} has {hard} hardening; --hardening {hardening} contradicts it"
            )
        return form, hard
    allowed = [f"{f}-{h}" for f in FORMS for h in _HARDENINGS]
    raise ValueError(
        f"case {case!r} is unknown; allowed: {', '.join(allowed)} or a form "
        f"({', '.join(FORMS)}) with --hardening"
    )


def reference_parameters(form: str, hardening: str) -> dict[str, float]:
    """The study's reference parameters of the case (problems.inverse.cases), else typical
    concrete."""
    try:
        from problems.inverse.cases import CASES
    except ImportError:  # the cases module is optional for this command
        CASES = {}
    case = CASES.get(f"{form}-{hardening}")
    if case is not None:
        return case.material_parameters(case.reference)
    from problems.materials.verification import typical_parameters

    return typical_parameters(form, hardening)


def main(args) -> int:
    import sys

    from problems.materials.drucker_prager import make_material
    from problems.materials.point_driver import run_material_point

    form, hardening = resolve_case(args.case, args.hardening)
    params = {**reference_parameters(form, hardening), **parse_overrides(args.param)}
    material = make_material(form, hardening, params)  # ValueError names the bad parameter
    path = (
        args.path
        or {"compression": "uniaxial-compression", "tension": "uniaxial-tension", "shear": "shear"}[
            hardening
        ]
    )
    strain = args.strain
    if strain is None:
        modulus = material.shear_modulus if hardening == "shear" else material.E
        strain = 5.0 * material.law.sigma0 / modulus
    result = run_material_point(material, path, strain, args.steps)
    described = " ".join(f"{k}={v:g}" for k, v in material.params.items())
    print(
        f"# {form}-{hardening} along {path} to strain {strain:g} in {args.steps} steps: {described}"
    )
    print(result.format())
    if args.csv:
        result.write_csv(args.csv)
        print(f"# table written to {args.csv}", file=sys.stderr)
    return 0

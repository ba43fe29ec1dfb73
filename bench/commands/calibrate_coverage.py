"""``femubench calibrate-coverage``: the calibration's coverage over virtual experiments.

Makes ``--n`` virtual experiments of one variant (specimens and parameters drawn, data on
``--data-mesh``, finer than ``--inverse-mesh`` and never a model of the calibration), calibrates
each with ``femubench calibrate``'s machinery and reports the parameter errors, whether the true
variant ranks first and whether the 95 % intervals cover the truth (bench/calibration_coverage.py,
docs/calibrating.md). Resumable: rerun the same command.
"""

from __future__ import annotations

NAME = "calibrate-coverage"
HELP = (
    "Coverage study of the calibration: N virtual experiments of one variant (data on a finer "
    "mesh), each calibrated; parameter errors, true variant ranked first, coverage of the "
    "95-percent intervals."
)


def _specimens(text: str) -> tuple:
    from bench.commands._args import ArgumentTypeError

    out = []
    for item in text.split(","):
        try:
            dims = tuple(float(v) for v in item.lower().split("x"))
        except ValueError:
            dims = ()
        if len(dims) != 3 or not all(0 < v < 1e4 for v in dims):
            raise ArgumentTypeError(
                f"{item!r} is not WIDTHxDEPTHxHEIGHT in mm (e.g. 100x100x300), comma-separated"
            )
        out.append(dims)
    return tuple(out)


def add_arguments(p) -> None:
    from bench.commands._args import (
        comma_list,
        finite_float,
        output_dir,
        plate_margin_or_auto,
        positive_int,
    )
    from problems.fe.presets import SPEC_PRESETS

    p.add_argument("--variant", default="linear-compression", help="the variant making the data")
    p.add_argument("--n", type=positive_int, default=10, help="virtual experiments (default 10)")
    p.add_argument(
        "--data-mesh",
        default="paper",
        help="mesh that makes the data (default paper; finer). In every mesh option a preset "
        f"such as converged is stored as its spec (today {SPEC_PRESETS['converged']})",
    )
    p.add_argument("--inverse-mesh", default="coarse", help="inverse mesh (default coarse)")
    p.add_argument(
        "--models",
        default=None,
        help="comma-separated variants calibrated and ranked (default: the three surfaces in "
        "the variant's hardening test)",
    )
    p.add_argument("--budget", type=positive_int, default=40, help="lm evaluations per variant")
    p.add_argument("--seed", type=int, default=0, help="seed of every draw (default 0)")
    p.add_argument(
        "--specimens",
        type=_specimens,
        default=None,
        help="WIDTHxDEPTHxHEIGHT mm, comma-separated (default 100x100x100,150x150x150,100x100x300)",
    )
    p.add_argument(
        "--strains",
        type=comma_list(finite_float, what="strain"),
        default=None,
        help="nominal strains of the images, comma-separated (default the example's 8)",
    )
    p.add_argument("--spacing", type=finite_float, default=5.0, help="DIC grid step, mm")
    p.add_argument(
        "--correction",
        choices=["none", "one-point", "iterated", "first-order"],
        default="none",
        help="discretisation correction of the calibration on --check-mesh (default none)",
    )
    p.add_argument(
        "--check-mesh",
        default="none",
        help="finer mesh of the discretisation check/correction ('auto': the inverse mesh's "
        "default high-fidelity mesh; default none; never the data's)",
    )
    p.add_argument(
        "--error-band",
        choices=["gci", "none"],
        default="gci",
        help="with a correction, widen each 95 %% interval by the discretisation band (default "
        "gci; none: Laplace alone)",
    )
    p.add_argument(
        "--plate-margin-mm",
        type=plate_margin_or_auto,
        default=0.0,
        metavar="MM|auto",
        help="face points closer than MM to either plate are left out of every calibration "
        "(auto: 10 %% of each specimen's smallest dimension; default 0)",
    )
    p.add_argument(
        "--noise-scale",
        type=float,
        default=1.0,
        metavar="S",
        help="multiply the experiments' noise by S (0: the noise-free twins of the same "
        "experiments, whose errors are the inverse model's alone; default 1)",
    )
    p.add_argument(
        "--experiments",
        default=None,
        metavar="I-J",
        help="run experiments I to J only (0-based, inclusive; default all): processes on "
        "disjoint ranges may share --out and --work, each summary covers every record done",
    )
    p.add_argument("--out", type=output_dir, required=True, help="records and summary folder")
    p.add_argument(
        "--work", type=output_dir, default=None, help="virtual experiments (default OUT/work)"
    )


def main(args) -> int:
    from bench.calibration_coverage import SPECIMENS, STRAINS, CoverageSettings, run_coverage
    from problems.fe.mesh import parse_mesh_spec
    from problems.inverse.experiment import parse_models

    for option, spec in (
        ("--data-mesh", args.data_mesh),
        ("--inverse-mesh", args.inverse_mesh),
        *((("--check-mesh", args.check_mesh),) if args.check_mesh not in ("none", "auto") else ()),
    ):
        try:
            parse_mesh_spec(spec)
        except ValueError as exc:
            raise ValueError(f"{option} {spec!r}: {exc}") from None
    models = ()
    if args.models is not None:
        try:
            models = tuple(parse_models(args.models))
        except ValueError as exc:
            raise ValueError(f"--models {args.models!r}: {exc}") from None
    settings = CoverageSettings(
        args.variant,
        args.n,
        args.data_mesh,
        args.inverse_mesh,
        models,
        args.budget,
        args.seed,
        args.specimens or SPECIMENS,
        tuple(args.strains) if args.strains else STRAINS,
        args.spacing,
        args.correction,
        "" if args.check_mesh == "none" else args.check_mesh,
        args.error_band,
        args.plate_margin_mm,
        args.noise_scale,
    )
    indices = None
    if args.experiments is not None:
        indices = experiment_range(args.experiments, settings.n)
    summary = run_coverage(settings, args.out, work=args.work, indices=indices)
    n = summary["n_done"]
    print(
        f"coverage of {settings.variant}: true variant first {summary['true_first_aic']}/{n} "
        f"(AIC), {summary['true_first_evidence']}/{n} (evidence)"
        + (
            f", first or not resolved from the first {summary['true_first_or_unresolved_aic']}/{n}"
            if summary["n_ranking_band"]
            else ""
        )
        + f"; all 95 % intervals cover "
        f"{summary['all_covered']}/{n}; summary {args.out}/summary.md"
    )
    return 0


def experiment_range(text: str, n: int) -> range:
    """``"I-J"`` (or ``"I"``) as the experiments I..J of a study of ``n``; ValueError (one line
    naming ``--experiments``) otherwise."""
    lo, sep, hi = text.strip().partition("-")
    try:
        i, j = int(lo), int(hi) if sep else int(lo)
    except ValueError:
        i, j = -1, -1
    if not 0 <= i <= j < n:
        raise ValueError(
            f"--experiments {text!r}: I-J or I with 0 <= I <= J < --n ({n}), whole numbers"
        )
    return range(i, j + 1)

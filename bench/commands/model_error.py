"""``femubench model-error CASE``: the parameter bias of the discretisation error and what each
model-error treatment buys, at what cost (see bench/studies/model_error.py)."""

from __future__ import annotations

NAME = "model-error"
HELP = (
    "model-error study of FE cases: LM errors and the linearised perfect-optimiser bias for "
    "inverse meshes x treatments (none, one-point, iterated, bae) x plate margins, with their costs"
)


def add_arguments(p) -> None:
    from bench.commands._args import (
        add_cluster_arguments,
        add_quiet_argument,
        comma_list,
        mesh_spec,
        nonneg_float,
        output_dir,
        positive_int,
    )

    p.add_argument("cases", nargs="+", metavar="CASE", help="FE case name(s), or all")
    p.add_argument(
        "--meshes",
        type=comma_list(mesh_spec, what="mesh"),
        default=("coarse",),
        help="inverse meshes, comma-separated (default coarse)",
    )
    p.add_argument(
        "--treatments",
        type=comma_list(_treatment, what="treatment"),
        default=("none", "one-point", "iterated", "bae"),
        help="treatments, comma-separated (default none,one-point,iterated,bae); with --bias-only "
        "also hifi-at-reference: the one-point correction made at the reference, the floor of "
        "every correction with that high-fidelity mesh",
    )
    p.add_argument(
        "--margins",
        type=comma_list(nonneg_float, what="margin"),
        default=(0.0, 30.0),
        help="plate margins of the measurement region, mm, comma-separated (default 0,30)",
    )
    p.add_argument(
        "--dic",
        action="store_true",
        help="add one row with DIC-route data (images correlated back)",
    )
    p.add_argument(
        "--bias-only",
        action="store_true",
        help="the linearised perfect-optimiser bias alone, no LM (for the expensive paper inverse "
        "mesh; not with iterated)",
    )
    p.add_argument(
        "--budget", type=positive_int, default=200, help="LM evaluations per row (default 200)"
    )
    p.add_argument(
        "--out",
        metavar="DIR",
        type=output_dir,
        help="output directory (default results/studies/model_error/<case>; with several cases "
        "DIR/<case>)",
    )
    add_cluster_arguments(
        p, default_workers=1, workers_help="Dask worker processes (default 1: in-process)"
    )
    add_quiet_argument(p)
    figures = p.add_mutually_exclusive_group()
    figures.add_argument("--no-figures", action="store_true", help="write the JSON/CSV files only")
    figures.add_argument(
        "--render", action="store_true", help="compute nothing: re-draw from the output folder"
    )


def _treatment(text: str) -> str:
    from bench.commands._args import ArgumentTypeError
    from bench.studies.model_error import HIFI_LIMIT
    from problems.inverse.model_error import CORRECTIONS

    if text == HIFI_LIMIT:
        return text  # the diagnostic (with --bias-only)
    if text not in CORRECTIONS:
        raise ArgumentTypeError(
            f"{text!r} is unknown; allowed: {', '.join(CORRECTIONS)} (the study compares the "
            "treatments; 'default' is one of its rows: bae with the case's plate margin)"
        )
    return text


def main(args) -> int:
    from pathlib import Path

    from bench.parallel import mapper
    from bench.studies import case_names, default_output_dir, existing_dir
    from bench.studies.model_error import render_model_error, render_overview, run_model_error
    from problems.inverse.cases import get_case

    cases = case_names(args.cases)
    analytic = [c for c in cases if get_case(c).is_analytic]
    if analytic:
        raise ValueError(f"case {analytic[0]}: the model-error study needs an FE case")
    outs = {
        name: args.out if args.out is None or len(cases) == 1 else Path(args.out) / name
        for name in cases
    }

    def overview():
        # every case folder under the study's root: overview.md and the all-cases figure
        if args.out is None or len(cases) > 1:
            root = (
                Path(args.out) if args.out else default_output_dir("model_error", cases[0]).parent
            )
            for path in render_overview(root):
                print(f"wrote {path}")

    if args.render:
        for name in cases:
            print(f"wrote {render_model_error(existing_dir('model_error', name, outs[name]))}")
        overview()
        return 0

    def report(cfg, row):
        if not args.quiet:
            what = "bias" if row.get("bias_only") else "error"
            values = row["linearised_bias_percent" if what == "bias" else "lm_error_percent"]
            errs = ", ".join(f"{n} {v:+.1f}" for n, v in values.items())
            print(
                f"  {row['case']} {cfg.mesh} {cfg.treatment} margin {cfg.plate_margin_mm:g} "
                f"{cfg.route}: max |{what}| {max(abs(v) for v in values.values()):.2f} % "
                f"({errs}); {row['total_forward_equivalents']:.0f} forward-equivalents",
                flush=True,
            )

    with mapper(args.workers, args.scheduler) as m:
        for name in cases:
            run = run_model_error(
                name,
                meshes=args.meshes,
                treatments=args.treatments,
                margins=args.margins,
                dic=args.dic,
                bias_only=args.bias_only,
                budget=args.budget,
                mapper=m,
                out=outs[name],
                progress=report,
            )
            if not args.no_figures:
                print(f"wrote {render_model_error(run.dir)}")
            print(f"{name}: {len(run.rows)} rows in {run.dir}")
    if not args.no_figures:
        overview()
    return 0

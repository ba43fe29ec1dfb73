"""``femubench identifiability CASE``: Fisher information, condition number, Laplace covariance."""

from __future__ import annotations

NAME = "identifiability"
HELP = (
    "Fisher information J^T J of the whitened residual, its eigenvalues and condition number, and "
    "the Laplace covariance (J^T J)^-1: predicted standard deviations and correlations, per case"
)


def add_arguments(p) -> None:
    from bench.commands._args import (
        add_cluster_arguments,
        add_mesh_argument,
        add_tier_arguments,
        float_in,
        output_dir,
        study_data,
    )
    from bench.studies import DATA_HELP

    p.add_argument(
        "cases",
        nargs="+",
        metavar="CASE",
        help="case name(s) (FE or analytic-*), or all (the nine FE cases)",
    )
    add_mesh_argument(p, "coarse")
    p.add_argument("--data", default="auto", type=study_data, help=DATA_HELP)
    add_tier_arguments(p)
    p.add_argument(
        "--x",
        nargs="+",
        action="extend",
        default=[],
        metavar="NAME=VALUE",
        help="evaluate at this point (physical units) instead of the reference, e.g. an "
        "identified one",
    )
    p.add_argument(
        "--scheme",
        default="forward",
        choices=["forward", "central"],
        help="finite-difference scheme of the Jacobian (forward: n + 1 runs, central: 2 n + 1)",
    )
    p.add_argument(
        "--rel-step",
        type=float_in(0.0, 0.1, low_open=True),
        default=1e-6,
        help="finite-difference step in z = x / reference, in (0, 0.1] (default 1e-6)",
    )
    p.add_argument(
        "--out",
        metavar="DIR",
        type=output_dir,
        help="output directory (default results/studies/identifiability/<case> in the results "
        "root, see docs/sensitivity.md; with several cases DIR/<case>)",
    )
    add_cluster_arguments(p, default_workers=1)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    figures = p.add_mutually_exclusive_group()
    figures.add_argument("--no-figures", action="store_true", help="write CSV/markdown/JSON only")
    figures.add_argument(
        "--render",
        action="store_true",
        help="compute nothing: re-draw the figures from the output folders of an earlier run",
    )


def main(args) -> int:
    from pathlib import Path

    from bench.commands._args import assignments
    from bench.parallel import mapper
    from bench.progress import enabled, warn_if_long
    from bench.studies import case_names, existing_dir, render_from
    from bench.studies.identifiability import (
        render_identifiability,
        render_summary,
        run_identifiability,
    )
    from problems.inverse.cases import get_case

    cases = case_names(args.cases)
    x = {}
    if args.x:
        if len(cases) != 1:
            raise ValueError("--x needs exactly one case")
        x = assignments(args.x, "--x", get_case(cases[0]).names)
    if args.render:
        paths = []
        for name in cases:
            paths += render_from(
                render_identifiability,
                existing_dir(
                    NAME,
                    name,
                    args.out if args.out is None or len(cases) == 1 else Path(args.out) / name,
                ),
            )
        if len(cases) > 1:
            paths += render_from(render_summary, existing_dir(NAME, "summary", args.out))
        for path in paths:
            print(f"wrote {path}")
        return 0
    fe = [c for c in cases if not get_case(c).is_analytic]
    if fe:
        # at most 6 parameters per case
        per_case = {"forward": 1 + 6, "central": 1 + 12}[args.scheme]
        warn_if_long(
            NAME, len(fe) * per_case, args.mesh, workers=args.workers, what=f"{len(fe)} FE case(s)"
        )
    with mapper(args.workers, args.scheduler) as m:
        res = run_identifiability(
            cases,
            mesh=args.mesh,
            data=args.data,
            tier=args.tier,
            correction=args.correction,
            plate_margin_mm=args.plate_margin_mm,
            x=x,
            scheme=args.scheme,
            rel_step=args.rel_step,
            mapper=m,
            out=args.out,
            progress=enabled(args.quiet) and len(cases) > 1,
        )
    if not args.no_figures:
        for d in res.dirs.values():
            res.paths += render_identifiability(d)
        if res.summary_dir is not None:
            res.paths += render_summary(res.summary_dir)
    for name, ident in res.results.items():
        row = next(r for r in res.summary if r["case"] == name)
        print(
            f"{name}: cond(J^T J) = {ident.condition:.3g}, rank {ident.rank}/{len(ident.names)}; "
            "Laplace sd (% of ref): "
            + ", ".join(f"{n} {s:.3g}" for n, s in zip(ident.names, ident.std_percent))
            + f"  [{ident.n_evals} evaluations, {row['wall_s']:.1f} s]"
        )
        for w in ident.warnings:
            print(f"  warning: {w}")
    print(f"wrote {len(res.paths)} files (e.g. {res.paths[0].parent})")
    return 0

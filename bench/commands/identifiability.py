"""``femubench identifiability CASE``: Fisher information, condition number, Laplace covariance."""
from __future__ import annotations

NAME = "identifiability"
HELP = ("Fisher information J^T J of the whitened residual, its eigenvalues and condition number, and the "
        "Laplace covariance (J^T J)^-1: predicted standard deviations and correlations, per case")


def add_arguments(p) -> None:
    from bench.studies import DATA_HELP

    p.add_argument("cases", nargs="+", metavar="CASE", help="case name(s) (FE or analytic-*), or all (the nine FE cases)")
    p.add_argument("--mesh", default="coarse", help="coarse | paper | fine | NX,NY,NZ (default: coarse)")
    p.add_argument("--data", default="auto", help=DATA_HELP)
    p.add_argument("--x", nargs="+", action="extend", default=[], metavar="NAME=VALUE",
                   help="evaluate at this point (physical units) instead of the reference, e.g. an identified one")
    p.add_argument("--scheme", default="forward", choices=["forward", "central"],
                   help="finite-difference scheme of the Jacobian (forward: n + 1 runs, central: 2 n + 1)")
    p.add_argument("--rel-step", type=float, default=1e-6, help="finite-difference step in z = x / reference")
    p.add_argument("--out", metavar="DIR",
                   help="output directory (default results/studies/identifiability/<case> in the results root, "
                        "see docs/sensitivity.md; with several cases DIR/<case>)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=1, metavar="N", help="Dask worker processes (default 1)")
    where.add_argument("--scheduler", metavar="ADDRESS", help="submit to an existing Dask cluster")
    figures = p.add_mutually_exclusive_group()
    figures.add_argument("--no-figures", action="store_true", help="write CSV/markdown/JSON only")
    figures.add_argument("--render", action="store_true",
                         help="compute nothing: re-draw the figures from the output folders of an earlier run")


def main(args) -> int:
    from pathlib import Path

    from bench.parallel import mapper
    from bench.studies import case_names, existing_dir, parse_assignments
    from bench.studies.identifiability import render_identifiability, render_summary, run_identifiability
    from problems.inverse.cases import get_case

    cases = case_names(args.cases)
    x = {}
    if args.x:
        if len(cases) != 1:
            raise ValueError("--x needs exactly one case")
        x = parse_assignments(args.x, get_case(cases[0]).names)
    if args.workers is not None and args.workers < 1:
        raise ValueError(f"--workers must be >= 1, got {args.workers}")
    if args.render:
        paths = []
        for name in cases:
            paths += render_identifiability(existing_dir(NAME, name, args.out if args.out is None or len(cases) == 1
                                                         else Path(args.out) / name))
        if len(cases) > 1:
            paths += render_summary(existing_dir(NAME, "summary", args.out))
        for path in paths:
            print(f"wrote {path}")
        return 0
    with mapper(args.workers, args.scheduler) as m:
        res = run_identifiability(cases, mesh=args.mesh, data=args.data, x=x, scheme=args.scheme,
                                  rel_step=args.rel_step, mapper=m, out=args.out)
    if not args.no_figures:
        for d in res.dirs.values():
            res.paths += render_identifiability(d)
        if res.summary_dir is not None:
            res.paths += render_summary(res.summary_dir)
    for name, ident in res.results.items():
        row = next(r for r in res.summary if r["case"] == name)
        print(f"{name}: cond(J^T J) = {ident.condition:.3g}, rank {ident.rank}/{len(ident.names)}; Laplace sd (% of ref): "
              + ", ".join(f"{n} {s:.3g}" for n, s in zip(ident.names, ident.std_percent))
              + f"  [{ident.n_evals} evaluations, {row['wall_s']:.1f} s]")
        for w in ident.warnings:
            print(f"  warning: {w}")
    print(f"wrote {len(res.paths)} files (e.g. {res.paths[0].parent})")
    return 0

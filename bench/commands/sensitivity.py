"""``femubench sensitivity CASE``: local sensitivities of the measurements (eqs. 16-18, Fig. 5)."""
from __future__ import annotations

NAME = "sensitivity"
HELP = ("local sensitivities s_ux, s_uy, s_r of the front-face displacements and plate force to each "
        "parameter (relative perturbation delta about the reference; the paper's eqs. 16-18, Fig. 5)")


def add_arguments(p) -> None:
    p.add_argument("cases", nargs="+", metavar="CASE", help="FE case name(s), or all")
    p.add_argument("--mesh", default="coarse", help="coarse | paper | fine | NX,NY,NZ (default: coarse)")
    p.add_argument("--delta", type=float, default=0.01, help="relative perturbation (default 0.01)")
    p.add_argument("--out", metavar="DIR", help="output directory (default results/studies/sensitivity/<case> in the "
                                                "results root, see docs/sensitivity.md; with several cases DIR/<case>)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=1, metavar="N",
                       help="Dask worker processes for the 1 + n FE runs of a case (default 1: in-process)")
    where.add_argument("--scheduler", metavar="ADDRESS", help="submit to an existing Dask cluster")
    figures = p.add_mutually_exclusive_group()
    figures.add_argument("--no-figures", action="store_true", help="write CSV/markdown/JSON only")
    figures.add_argument("--render", action="store_true",
                         help="compute nothing: re-draw the figures from the output folder of an earlier run")


def main(args) -> int:
    from pathlib import Path

    from bench.parallel import mapper
    from bench.studies import case_names, existing_dir
    from bench.studies.sensitivity import render_sensitivity, run_sensitivity

    if not (0 < abs(args.delta) < 1):
        raise ValueError(f"--delta {args.delta} is out of range: 0 < |delta| < 1")
    if args.workers is not None and args.workers < 1:
        raise ValueError(f"--workers must be >= 1, got {args.workers}")
    cases = case_names(args.cases)
    outs = {name: args.out if args.out is None or len(cases) == 1 else Path(args.out) / name for name in cases}
    if args.render:
        for name in cases:
            for path in render_sensitivity(existing_dir(NAME, name, outs[name])):
                print(f"wrote {path}")
        return 0
    with mapper(args.workers, args.scheduler) as m:
        for name in cases:
            res = run_sensitivity(name, mesh=args.mesh, delta=args.delta, mapper=m, out=outs[name])
            if not args.no_figures:
                res.paths += render_sensitivity(res.dir)
            sens = res.result
            print(f"{name} (mesh {args.mesh}, delta {args.delta:g}): sensitivities summed over "
                  f"{sens.n_snapshots} snapshots")
            print(f"{'parameter':>10} {'s_ux':>10} {'s_uy':>10} {'s_r':>10} {'sum |s|':>10}")
            for r in sens.rows():
                print(f"{r['parameter']:>10} {r['s_ux']:10.4g} {r['s_uy']:10.4g} {r['s_r']:10.4g} {r['sum_abs']:10.4g}")
            print(f"least to most sensitive: {', '.join(sens.ranking())}")
            for msg in sens.messages:
                print(f"note: {msg}")
            print(f"cost: {sens.n_evals} FE evaluations, {res.wall_s:.1f} s; wrote {res.dir}")
    return 0

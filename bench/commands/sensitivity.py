"""``femubench sensitivity CASE``: local sensitivities of the measurements (eqs. 16-18, Fig. 5)."""

from __future__ import annotations

NAME = "sensitivity"
HELP = (
    "local sensitivities s_ux, s_uy, s_r of the front-face displacements and plate force to each "
    "parameter (relative perturbation delta about the reference; the paper's eqs. 16-18, Fig. 5)"
)


#: allowed relative perturbations: below DELTA_MIN the differences drown in the Newton solver's
#: tolerance and round-off (1e-300 gave all-zero sensitivities); a negative one ranked a NaN first
DELTA_MIN, DELTA_MAX = 1e-6, 0.5


def _delta(text: str) -> float:
    from bench.commands._args import float_in

    return float_in(DELTA_MIN, DELTA_MAX)(text)


def add_arguments(p) -> None:
    from bench.commands._args import (
        add_cluster_arguments,
        add_mesh_argument,
        add_quiet_argument,
        output_dir,
    )

    p.add_argument("cases", nargs="+", metavar="CASE", help="FE case name(s), or all")
    add_mesh_argument(p, "coarse")
    p.add_argument(
        "--delta",
        type=_delta,
        default=0.01,
        help=f"relative perturbation, in [{DELTA_MIN:g}, {DELTA_MAX:g}] (default 0.01)",
    )
    p.add_argument(
        "--out",
        metavar="DIR",
        type=output_dir,
        help="output directory (default results/studies/sensitivity/<case> in the "
        "results root, see docs/sensitivity.md; with several cases DIR/<case>)",
    )
    add_cluster_arguments(
        p,
        default_workers=1,
        workers_help="Dask worker processes for the 1 + n FE runs of a case "
        "(default 1: in-process)",
    )
    add_quiet_argument(p)
    figures = p.add_mutually_exclusive_group()
    figures.add_argument("--no-figures", action="store_true", help="write CSV/markdown/JSON only")
    figures.add_argument(
        "--render",
        action="store_true",
        help="compute nothing: re-draw the figures from the output folder of an earlier run",
    )


def main(args) -> int:
    from pathlib import Path

    from tqdm import tqdm

    from bench.parallel import mapper
    from bench.progress import enabled, warn_if_long
    from bench.studies import case_names, existing_dir, render_from
    from bench.studies.local_sensitivity import render_sensitivity, run_sensitivity
    from problems.inverse.cases import get_case

    cases = case_names(args.cases)
    analytic = [c for c in cases if get_case(c).is_analytic]
    if analytic:
        raise ValueError(
            f"case {analytic[0]}: local sensitivities need the FE measurement layout [u_h, u_v, "
            "r]; analytic cases do not have it"
        )
    outs = {
        name: args.out if args.out is None or len(cases) == 1 else Path(args.out) / name
        for name in cases
    }
    if args.render:
        for name in cases:
            for path in render_from(render_sensitivity, existing_dir(NAME, name, outs[name])):
                print(f"wrote {path}")
        return 0
    warn_if_long(
        NAME,
        sum(1 + len(get_case(c).names) for c in cases),
        args.mesh,
        workers=args.workers,
        what=f"{len(cases)} case(s)",
    )
    with mapper(args.workers, args.scheduler) as m:
        for name in tqdm(
            cases,
            desc="sensitivity",
            unit="case",
            disable=len(cases) < 2 or not enabled(args.quiet),
        ):
            res = run_sensitivity(name, mesh=args.mesh, delta=args.delta, mapper=m, out=outs[name])
            if not args.no_figures:
                res.paths += render_sensitivity(res.dir)
            sens = res.result
            print(
                f"{name} (mesh {args.mesh}, delta {args.delta:g}): sensitivities summed over "
                f"{sens.n_snapshots} snapshots"
            )
            print(f"{'parameter':>10} {'s_ux':>10} {'s_uy':>10} {'s_r':>10} {'sum |s|':>10}")
            for r in sens.rows():
                print(
                    f"{r['parameter']:>10} {r['s_ux']:10.4g} {r['s_uy']:10.4g} {r['s_r']:10.4g} "
                    f"{r['sum_abs']:10.4g}"
                )
            print(f"least to most sensitive: {', '.join(sens.ranking())}")
            for msg in sens.messages:
                print(f"note: {msg}")
            print(f"cost: {sens.n_evals} FE evaluations, {res.wall_s:.1f} s; wrote {res.dir}")
    return 0

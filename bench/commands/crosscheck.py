"""``femubench crosscheck``: the linear Drucker-Prager form (K = 1) against OpenSees (needs the
optional ``crosscheck`` extra, openseespy)."""

from __future__ import annotations

import sys

NAME = "crosscheck"
HELP = (
    "cross-check the linear Drucker-Prager form (K = 1) against OpenSees: one element and the "
    "quarter cube on the same mesh and load steps, a tangent audit; needs openseespy (pip install "
    "'femubench[crosscheck]')"
)


def add_arguments(p) -> None:
    from bench.commands._args import (
        add_mesh_argument,
        comma_list,
        float_in,
        output_dir,
        positive_int,
    )

    p.add_argument(
        "--out",
        metavar="DIR",
        type=output_dir,
        help="output folder for opensees_dp.json and the PNGs (default results/crosscheck in the "
        "results root, see docs/crosscheck_opensees.md)",
    )
    add_mesh_argument(p, "coarse", help="cube mesh: coarse | paper | NX,NY,NZ (default: coarse)")
    p.add_argument(
        "--skip-cube", action="store_true", help="only the single element (and the tangent audit)"
    )
    p.add_argument(
        "--psi",
        default="35,15",
        type=comma_list(float_in(0.0, 35.0, unit="degrees"), what="angle"),
        help="dilatancy angles to run, degrees (0 <= psi <= beta = 35; default 35,15)",
    )
    p.add_argument(
        "--steps", type=positive_int, default=10, help="cube load steps (snapshots; default 10)"
    )
    p.add_argument(
        "--element-steps",
        type=positive_int,
        default=60,
        help="single-element load steps (default 60)",
    )
    p.add_argument(
        "--all-strategies",
        action="store_true",
        help="run every OpenSees solution strategy on the cube, not only until one converges",
    )
    figures = p.add_mutually_exclusive_group()
    figures.add_argument("--no-figures", action="store_true", help="write opensees_dp.json only")
    figures.add_argument(
        "--render",
        action="store_true",
        help="run nothing (no openseespy needed): re-draw the figures from the output folder",
    )


def main(args) -> int:
    from pathlib import Path

    from bench.crosscheck.figures import render_crosscheck
    from bench.crosscheck.loader import OpenSeesUnavailable

    out = Path(args.out) if args.out else None
    if out is None:
        from bench.paths import results_root

        out = results_root() / "crosscheck"
    if args.render:
        from bench.studies import render_from

        for path in render_from(render_crosscheck, out):
            print(f"wrote {path}")
        return 0
    psis = tuple(args.psi)  # checked by the argument type: degrees in [0, 35]
    from bench.crosscheck.report import print_report
    from bench.crosscheck.study import run_crosscheck

    try:
        res = run_crosscheck(
            out,
            mesh=args.mesh,
            psis=psis,
            steps=args.steps,
            element_steps=args.element_steps,
            skip_cube=args.skip_cube,
            all_strategies=args.all_strategies,
        )
    except OpenSeesUnavailable as exc:
        print(f"femubench crosscheck: {exc}", file=sys.stderr)
        return 2
    if not args.no_figures:
        res.paths += render_crosscheck(res.dir)
    print_report(res.report)
    print("\nwrote " + ", ".join(str(p) for p in res.paths))
    return 0

"""``femubench gsa CASE``: global sensitivity (Sobol indices or Morris screening) over the parameter
box."""

from __future__ import annotations

NAME = "gsa"
HELP = (
    "global sensitivity of the cost, peak force and lateral bulge over the parameter box: Sobol "
    "first-order and total indices (Saltelli sampling) or Morris screening (SALib); prints the FE "
    "evaluations and wall time"
)


def _box_scale(text: str):
    """``auto`` or a number in (0, 1]."""
    from bench.commands._args import ArgumentTypeError, float_in

    if text == "auto":
        return "auto"
    try:
        return float_in(0.0, 1.0, low_open=True)(text)
    except ArgumentTypeError as exc:
        raise ArgumentTypeError(f"{exc} (or auto)") from None


def add_arguments(p) -> None:
    from bench.commands._args import (
        add_cluster_arguments,
        add_mesh_argument,
        add_quiet_argument,
        add_tier_arguments,
        int_at_least,
        nonneg_int,
        output_dir,
        study_data,
    )
    from bench.studies import DATA_HELP

    p.add_argument("case", metavar="CASE", help="case name (FE or analytic-*)")
    p.add_argument("--method", default="sobol", choices=["sobol", "morris"])
    p.add_argument(
        "--samples",
        type=int_at_least(2),
        default=None,
        metavar="N",
        help="Sobol: base samples N, N (d + 2) evaluations, best a power of 2 (default 32; others "
        "are flagged); Morris: trajectories r >= 2, r (d + 1) evaluations (default 10)",
    )
    add_mesh_argument(p, "coarse")
    p.add_argument("--data", default="auto", type=study_data, help=DATA_HELP)
    add_tier_arguments(p)
    p.add_argument(
        "--box-scale",
        default="auto",
        metavar="S",
        type=_box_scale,
        help="shrink the case's box about the reference by S in (0, 1]; auto (default): 1, or the "
        "largest S whose sample points are all feasible",
    )
    p.add_argument(
        "--seed", type=nonneg_int, default=0, help="seed of the sample, >= 0 (default 0)"
    )
    p.add_argument(
        "--out",
        metavar="DIR",
        type=output_dir,
        help="output directory (default results/studies/gsa/<case> in the results root, "
        "see docs/sensitivity.md)",
    )
    add_cluster_arguments(p)
    p.add_argument(
        "--dry-run",
        action="store_true",
        help="print the planned evaluations and the box, run nothing",
    )
    add_quiet_argument(p)
    figures = p.add_mutually_exclusive_group()
    figures.add_argument("--no-figures", action="store_true", help="write CSV/markdown/JSON only")
    figures.add_argument(
        "--render",
        action="store_true",
        help="compute nothing: re-draw gsa_<method>.png from the output folder of an earlier run",
    )


def check_sample_memory(method: str, samples: int, d: int) -> None:
    """ValueError (one line naming --samples) when the sample of ``samples`` base points of ``d``
    parameters cannot fit in memory: Sobol N (d + 2) points, Morris r (d + 1), each held three
    times (drawn, unit-scaled, boxed) with its outputs (bench.resources)."""
    from bench.resources import check_memory, sample_bytes

    planned = samples * (d + 2 if method == "sobol" else d + 1)
    check_memory(
        sample_bytes(planned, 3 * d + 1),
        f"--samples {samples} ({method}: {planned:,} points of {d} parameters)",
    )


def main(args) -> int:
    import os

    from bench.parallel import mapper
    from bench.progress import enabled, warn_if_long
    from bench.studies import existing_dir, render_from
    from bench.studies.global_sensitivity import render_gsa, run_gsa
    from problems.inverse.cases import get_case

    case = get_case(args.case)
    if args.render:
        for path in render_from(
            render_gsa, existing_dir(NAME, case.name, args.out), (args.method,)
        ):
            print(f"wrote {path}")
        return 0
    samples = args.samples if args.samples is not None else (32 if args.method == "sobol" else 10)
    check_sample_memory(args.method, samples, len(case.names))
    scale = args.box_scale
    workers = 1 if case.is_analytic else (args.workers or os.cpu_count() or 1)

    def confirm(planned, box, s, n_bad):
        extra = (
            f"; box scaled by {s:g} ({n_bad} sample points infeasible in the full box)"
            if s < 1
            else ""
        )
        print(
            f"{args.method} on {case.name} (mesh {args.mesh}): {planned} evaluations "
            f"planned{extra}",
            flush=True,
        )
        if not case.is_analytic:
            warn_if_long(
                NAME,
                planned,
                args.mesh,
                workers=workers,
                what=f"{args.method} with {samples} samples",
            )
        if args.dry_run:
            for n, lo, hi in zip(case.names, *box):
                print(f"  {n:>8} [{lo:.6g}, {hi:.6g}]")
        return not args.dry_run

    with mapper(1 if case.is_analytic else args.workers, args.scheduler) as m:
        res = run_gsa(
            case.name,
            method=args.method,
            samples=samples,
            mesh=args.mesh,
            data=args.data,
            tier=args.tier,
            correction=args.correction,
            plate_margin_mm=args.plate_margin_mm,
            box_scale=scale,
            seed=args.seed,
            mapper=m,
            workers=workers,
            out=args.out,
            progress=enabled(args.quiet),
            confirm=confirm,
        )
    if res is None:  # dry run
        return 0
    if not args.no_figures:
        res.paths += render_gsa(res.dir, (args.method,))
    r, c = res.result, res.cost
    print(f"data: {res.data}")
    for w in r.warnings:
        print(f"warning: {w}")
    if args.method == "sobol":
        print(f"{'output':>14} {'param':>8} {'S1':>7} {'+-':>6} {'ST':>7} {'+-':>6}")
        for row in r.rows():
            print(
                f"{row['output']:>14} {row['parameter']:>8} {row['S1']:7.3f} {row['S1_conf']:6.3f} "
                f"{row['ST']:7.3f} {row['ST_conf']:6.3f}"
            )
    else:
        print(f"{'output':>14} {'param':>8} {'mu*':>10} {'+-':>9} {'sigma':>10}")
        for row in r.rows():
            print(
                f"{row['output']:>14} {row['parameter']:>8} {row['mu_star']:10.4g} "
                f"{row['mu_star_conf']:9.3g} {row['sigma']:10.4g}"
            )
    print(
        f"cost: {c['fe_evaluations']} forward evaluations ({c['failed']} failed, {c['infeasible']} "
        f"infeasible), {c['evaluation_wall_s']:.1f} s evaluating with {c['workers']} worker(s), "
        f"{c['total_wall_s']:.1f} s total"
    )
    print(f"wrote {res.dir}")
    return 0

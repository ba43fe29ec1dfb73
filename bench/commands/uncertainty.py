"""``femubench uncertainty CASE``: MCMC posterior against the Laplace approximation."""

from __future__ import annotations

NAME = "uncertainty"
HELP = (
    "sample the posterior with the mcmc solver and compare it with the Laplace approximation (J^T "
    "J)^-1 at the mode: corner plot, mean, sd and 95-percent interval from both, verdict per "
    "parameter; prints the cost"
)


def add_arguments(p) -> None:
    from bench.commands._args import (
        add_cluster_arguments,
        add_mesh_argument,
        add_quiet_argument,
        add_tier_arguments,
        int_at_least,
        nonneg_int,
        output_dir,
        positive_int,
        study_data,
    )
    from bench.studies import DATA_HELP

    p.add_argument("case", metavar="CASE", help="case name (FE or analytic-*)")
    add_mesh_argument(p, "coarse")
    p.add_argument("--data", default="auto", type=study_data, help=DATA_HELP)
    add_tier_arguments(p)
    p.add_argument(
        "--budget",
        type=positive_int,
        default=2000,
        metavar="N",
        help="MCMC forward evaluations (default 2000)",
    )
    p.add_argument(
        "--seed", type=nonneg_int, default=0, help="seed of the sampler, >= 0 (default 0)"
    )
    p.add_argument(
        "--x",
        nargs="+",
        action="extend",
        default=[],
        metavar="NAME=VALUE",
        help="start from this point (physical units, e.g. an identified one) instead of the "
        "reference",
    )
    p.add_argument(
        "--refine",
        type=nonneg_int,
        default=10,
        metavar="K",
        help="at most K Gauss-Newton steps polishing the start to the mode before Laplace and MCMC "
        "(default 10; 0: none)",
    )
    p.add_argument(
        "--walkers",
        type=int_at_least(2),
        default=None,
        metavar="W",
        help="MCMC walkers, at least twice the number n of parameters, odd numbers made even "
        "(default max(16, 4 n))",
    )
    p.add_argument(
        "--out",
        metavar="DIR",
        type=output_dir,
        help="output directory (default results/studies/uncertainty/<case> in the results root, "
        "see docs/sensitivity.md)",
    )
    add_cluster_arguments(p)
    add_quiet_argument(p)
    figures = p.add_mutually_exclusive_group()
    figures.add_argument(
        "--no-figures", action="store_true", help="write the tables, JSON and chain only"
    )
    figures.add_argument(
        "--render",
        action="store_true",
        help="compute nothing: re-draw corner.png from the output folder of an earlier run",
    )


def main(args) -> int:
    import os
    import warnings

    from bench.commands._args import assignments
    from bench.parallel import mapper
    from bench.progress import EvaluationProgress, enabled, warn_if_long
    from bench.resources import check_memory, sample_bytes
    from bench.studies import existing_dir, render_from
    from bench.studies.uncertainty import render_uncertainty, run_uncertainty
    from problems.inverse.cases import get_case

    case = get_case(args.case)
    if args.render:
        for path in render_from(render_uncertainty, existing_dir(NAME, case.name, args.out)):
            print(f"wrote {path}")
        return 0
    x = assignments(args.x, "--x", case.names)
    n = len(case.names)
    if args.walkers is not None and args.walkers < 2 * n:
        raise ValueError(
            f"--walkers {args.walkers} is out of range: must be >= {2 * n} "
            f"(twice the {n} parameters of {case.name})"
        )
    walkers = args.walkers or max(16, 4 * n)
    walkers += walkers % 2  # the mcmc solver makes it even
    # up front, before the Laplace step: an ensemble (walkers x (n + 1) numbers per step) and a
    # chain (budget x (n + 1): positions and log-probabilities) that cannot fit in memory
    check_memory(
        sample_bytes(walkers, n + 1), f"--walkers {walkers} (an ensemble of {n} parameters)"
    )
    if args.budget < 2 * walkers:
        raise ValueError(
            f"--budget {args.budget} is out of range: MCMC needs at least 2 steps of the {walkers} "
            f"walkers, i.e. >= {2 * walkers} evaluations"
        )
    check_memory(
        sample_bytes(args.budget, n + 1),
        f"--budget {args.budget} (an MCMC chain of {n} parameters)",
    )
    analytic = case.is_analytic
    workers = 1 if analytic else (args.workers or os.cpu_count() or 1)
    if not analytic:
        warn_if_long(
            NAME,
            args.budget + (args.refine + 1) * (n + 1),
            args.mesh,
            workers=workers,
            what=f"budget {args.budget} and --refine {args.refine}",
        )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # the short-chain warning is reported below
        with mapper(1 if analytic else args.workers, args.scheduler) as m:
            # total: the MCMC budget, once set
            with EvaluationProgress(
                desc=f"uncertainty {case.name}", disable=not enabled(args.quiet)
            ) as progress:
                res = run_uncertainty(
                    case.name,
                    mesh=args.mesh,
                    data=args.data,
                    tier=args.tier,
                    correction=args.correction,
                    plate_margin_mm=args.plate_margin_mm,
                    budget=args.budget,
                    seed=args.seed,
                    x=x,
                    refine=args.refine,
                    n_walkers=args.walkers,
                    mapper=m,
                    out=args.out,
                    workers=workers,
                    observers=[progress],
                )
    if not args.no_figures:
        res.paths += render_uncertainty(res.dir)
    print(
        f"{'parameter':>10} {'MCMC mean':>12} {'MCMC sd':>10} {'Laplace mean':>12} "
        f"{'Laplace sd':>10}  verdict"
    )
    for r in res.rows:
        print(
            f"{r['parameter']:>10} {r['mcmc_mean']:12.6g} {r['mcmc_std']:10.3g} "
            f"{r['laplace_mean']:12.6g} {r['laplace_std']:10.3g}  {r['verdict']}"
        )
    print(res.overall)
    for w in res.mcmc_warnings:
        print(f"MCMC warning: {w}")
    for w in res.notes:
        print(f"note: {w}")
    c = res.cost
    print(
        f"cost: Laplace {c['laplace_evaluations']} evaluations ({c['laplace_wall_s']:.1f} s), MCMC "
        f"{c['mcmc_evaluations']} evaluations ({c['mcmc_wall_s']:.1f} s), total "
        f"{c['total_wall_s']:.1f} s with {c['workers']} worker(s)"
    )
    print(f"wrote {res.dir}")
    return 0

"""``femubench posterior CASE...``: converged MCMC on the stored surrogate against the Laplace
approximation at the FE optimum (bench/studies/posterior.py)."""

from __future__ import annotations

NAME = "posterior"
HELP = (
    "sample a case's posterior on its stored surrogate (emcee, chain >= 50 autocorrelation "
    "times, surrogate hold-out variance added to the noise) and compare with the Laplace "
    "approximation at the FE optimum; writes summary.json, chain.npz, corner.png"
)


def add_arguments(p) -> None:
    p.add_argument("cases", nargs="+", metavar="CASE", help="FE case names, or 'all'")
    p.add_argument(
        "--tier",
        choices=["consistent", "model-error"],
        default="consistent",
        help="data tier (default consistent)",
    )
    p.add_argument(
        "--correction",
        choices=["none", "bae", "default"],
        default="none",
        help="model-error treatment (default none; 'default' = the case's, on model-error data)",
    )
    p.add_argument(
        "--surrogate",
        default="default",
        metavar="PATH_OR_NAME",
        help="stored surrogate (default: the shipped one of the case on coarse)",
    )
    p.add_argument("--walkers", type=int, default=32, metavar="N", help="walkers (default 32)")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="seed (default 0)")
    p.add_argument(
        "--tau-multiple",
        type=float,
        default=50.0,
        metavar="K",
        help="stop when the kept chain is K integrated autocorrelation times long (default 50)",
    )
    p.add_argument(
        "--max-minutes",
        type=float,
        default=15.0,
        metavar="MIN",
        help="stop sampling after MIN minutes even if not converged (default 15)",
    )
    p.add_argument(
        "--max-steps", type=int, default=60000, metavar="N", help="step cap (default 60000)"
    )
    p.add_argument(
        "--fe-budget",
        type=int,
        default=30,
        metavar="N",
        help="FE evaluations of the lm polish giving the Laplace point (default 30)",
    )
    p.add_argument("--out", metavar="DIR", help="output folder (one case only)")
    p.add_argument("--render", action="store_true", help="only redraw the figures from the files")
    p.add_argument("--skip-done", action="store_true", help="skip cases with a summary.json")
    p.add_argument("--quiet", action="store_true", help="no progress lines")


def main(args) -> int:
    from bench.studies.posterior import (
        SUMMARY,
        format_summary,
        render_posterior,
        run_posterior,
        study_folder,
    )
    from problems.inverse.cases import CASES

    names = [n for n in CASES if not CASES[n].is_analytic] if args.cases == ["all"] else args.cases
    if args.out and len(names) > 1:
        raise ValueError("--out takes one case")
    if args.walkers < 2 or args.max_steps < 10 or args.fe_budget < 1:
        raise ValueError("--walkers >= 2, --max-steps >= 10 and --fe-budget >= 1 are required")
    for name in names:
        folder = study_folder(name, args.tier, args.out)
        if args.render:
            for path in render_posterior(folder):
                print(f"wrote {path}")
            continue
        if args.skip_done and (folder / SUMMARY).is_file():
            print(f"skip {name}: {folder / SUMMARY} exists")
            continue
        res = run_posterior(
            name,
            tier=args.tier,
            treatment=args.correction,
            surrogate=args.surrogate,
            n_walkers=args.walkers,
            seed=args.seed,
            min_tau_multiple=args.tau_multiple,
            max_steps=args.max_steps,
            max_minutes=args.max_minutes,
            fe_budget=args.fe_budget,
            out=args.out,
            progress=not args.quiet,
        )
        print(format_summary(res.summary))
        for path in render_posterior(res.folder):
            print(f"wrote {path}")
    return 0

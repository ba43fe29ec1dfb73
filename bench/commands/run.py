"""``femubench run SUITE``: run a suite of identifications, resumably, in parallel."""

from __future__ import annotations

NAME = "run"
HELP = "run a suite (TOML) of identifications; resumes where a previous run stopped"


def add_arguments(parser) -> None:
    from bench.commands._args import add_cluster_arguments, output_dir
    from bench.commands.identify import add_problem_arguments

    parser.add_argument("suite", metavar="SUITE", help="suite file, e.g. suites/default.toml")
    add_problem_arguments(parser)
    parser.add_argument(
        "--out",
        metavar="DIR",
        default=None,
        type=output_dir,
        help="results directory (default: <results root>/<suite name>: $FEMUBENCH_RESULTS_DIR, "
        "else the checkout's results/)",
    )
    add_cluster_arguments(parser)
    parser.add_argument(
        "--force", action="store_true", help="rerun runs that already have a record"
    )
    parser.add_argument(
        "--retry-failed",
        action="store_true",
        help="also rerun the runs whose record is a crash (an exception, or a worker that was "
        "killed); a plain rerun keeps crash records",
    )
    parser.add_argument(
        "--fan-out",
        action="store_true",
        help="let each run send its Jacobian columns / populations to the cluster too",
    )
    parser.add_argument(
        "--dry-run",
        action="store_true",
        help="validate the suite and print what would run, without running anything",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def main(args) -> int:
    import sys
    from pathlib import Path

    from bench.commands.identify import problem_spec
    from bench.experiment.runner import default_workers, pending_runs, worker_count
    from bench.experiment.suite import load_suite, missing_surrogates
    from bench.paths import results_root
    from bench.progress import enabled, warn_if_long
    from problems.inverse.cases import get_case

    suite = load_suite(args.suite)  # ValueError -> message + exit 2 (bench.cli)
    spec = problem_spec(args)
    if spec is not None:  # the suite's methods, budgets and seeds on this problem
        suite = suite.with_problem(spec["entry"].rpartition(":")[2], spec)
    out = Path(args.out) if args.out else results_root() / suite.name
    runs, pending = pending_runs(suite, out, force=args.force, retry_failed=args.retry_failed)
    missing = missing_surrogates(pending)
    if missing:
        raise ValueError(f"{args.suite}: cannot run:\n  - " + "\n  - ".join(missing))
    if args.workers is not None and args.scheduler is None:
        n = worker_count(args.workers, len(pending))
        if n < args.workers:
            print(
                f"--workers {args.workers}: capped at {n} ({default_workers()} cores, "
                f"{len(pending)} pending runs)",
                file=sys.stderr,
            )
    fe_by_mesh: dict[str, int] = {}  # FE evaluations per inverse mesh (parts may differ)
    runs_by_mesh: dict[str, int] = {}
    for r in pending:
        if not r.problem and not get_case(r.case).is_analytic:
            n = r.polish_budget if r.track == "surrogate" else r.budget
            fe_by_mesh[r.mesh] = fe_by_mesh.get(r.mesh, 0) + n
            runs_by_mesh[r.mesh] = runs_by_mesh.get(r.mesh, 0) + 1
    fe_evals = sum(fe_by_mesh.values())
    for mesh, n in fe_by_mesh.items():
        on = f" on {mesh}" if len(fe_by_mesh) > 1 else ""
        what = f"{runs_by_mesh[mesh]} pending runs{on} (their whole budgets)"
        warn_if_long(NAME, n, mesh, workers=args.workers, what=what)

    if args.dry_run:
        for i, part in enumerate(suite.parts, 1):
            print(
                f"suite {suite.name!r}"
                + (f" part {i}" if len(suite.parts) > 1 else "")
                + f": {len(part.cases)} cases x {len(part.methods)} methods x "
                f"{len(part.budgets)} budgets x {len(part.seeds)} seeds x starts "
                f"{list(part.starts)}"
                + (f" ({part.random_starts} random per seed)" if "random" in part.starts else "")
                + (
                    f", tracks {list(part.tracks)}, tiers {list(part.tiers)}, mesh {part.mesh}"
                    if not set(part.cases) <= set(suite.problems)
                    else ""
                )
            )
        print(
            f"{len(runs)} runs, {len(runs) - len(pending)} with a record in {out}, {len(pending)} "
            f"to run; at most {sum(r.budget + r.polish_budget for r in pending)} evaluations "
            f"({fe_evals} of an FE model)"
        )
        return 0

    from bench.experiment.runner import run_suite

    try:
        summary = run_suite(
            suite,
            out,
            workers=args.workers,
            scheduler=args.scheduler,
            force=args.force,
            retry_failed=args.retry_failed,
            progress=enabled(args.quiet),
            fan_out=args.fan_out,
        )
    except KeyboardInterrupt:
        print(
            "interrupted; finished runs are kept, rerun the same command to resume", file=sys.stderr
        )
        return 130
    print(summary)
    if summary.crashed:
        print(
            f"{summary.crashed} run(s) crashed (see {summary.log_file}): "
            + ", ".join(summary.failures[:5])
            + (" ..." if summary.crashed > 5 else "")
            + "; rerun with --retry-failed to run them again",
            file=sys.stderr,
        )
    if summary.crashed_before:
        n = len(summary.crashed_before)
        print(
            f"{n} run(s) kept their crash record from an earlier run: "
            + ", ".join(summary.crashed_before[:5])
            + (" ..." if n > 5 else "")
            + "; rerun with --retry-failed to run them again",
            file=sys.stderr,
        )
    return 1 if summary.crashed or summary.crashed_before else 0

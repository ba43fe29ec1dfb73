"""``femubench surrogate CASE [CASE ...]``: build, validate and store a POD + RBF/GP surrogate of
the FE forward model, one case after another.

The nine shipped default surrogates (docs/surrogate.md §9) are rebuilt, resumably, by::

    femubench surrogate all --mesh coarse --samples 300 --local 40 --local-scale 0.1 \
        --holdout 50 --regression gp --gp-restarts 1 --workers 2 --skip-done
"""

from __future__ import annotations

NAME = "surrogate"
HELP = (
    "build a surrogate of a case's FE forward model (POD of sigma-scaled snapshots + RBF or "
    "Gaussian-process regression), validate it on fresh hold-out FE runs and store it (npz + JSON "
    "with a content hash)"
)


def add_arguments(p) -> None:
    p.add_argument(
        "cases",
        nargs="+",
        metavar="CASE",
        help="FE case name(s) (see `femubench cases`), or all; built one after another",
    )
    p.add_argument(
        "--mesh", default="coarse", help="FE mesh of the forward model (default: coarse)"
    )
    p.add_argument(
        "--data",
        metavar="FILE",
        help="data set whose loading, points and sigma are used "
        "(default: the case's shipped data set)",
    )
    p.add_argument(
        "--samples", type=int, default=200, metavar="N", help="training design points (default 200)"
    )
    p.add_argument(
        "--holdout",
        type=int,
        default=50,
        metavar="K",
        help="fresh hold-out FE points for the validation (default 50; 0: no validation)",
    )
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        metavar="S",
        help="seed of the designs and the selection (default 0)",
    )
    p.add_argument(
        "--design", choices=["lhs", "sobol"], default="lhs", help="training design (default lhs)"
    )
    p.add_argument(
        "--local",
        type=int,
        default=0,
        metavar="N",
        help="second-stage design points around the optimum of the first-stage surrogate "
        "fitted to the data (the data's own search; default 0)",
    )
    p.add_argument(
        "--local-scale",
        type=float,
        default=0.1,
        metavar="F",
        help="half-width of the local design, fraction of the box width (default 0.1)",
    )
    p.add_argument(
        "--regression",
        choices=["auto", "rbf", "gp"],
        default="auto",
        help="regression of the POD coefficients; auto chooses by error on set-aside training "
        "points",
    )
    p.add_argument(
        "--gp-restarts",
        type=int,
        default=2,
        metavar="R",
        help="optimiser restarts of each GP's marginal likelihood (default 2)",
    )
    p.add_argument(
        "--tol-sigma",
        type=float,
        default=0.1,
        metavar="T",
        help="POD truncation: RMS projection error per block <= T sigma (default 0.1)",
    )
    p.add_argument(
        "--batch", type=int, default=16, metavar="B", help="FE runs per mapper call (default 16)"
    )
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="N",
        help="local Dask worker processes (default: one per core); 1 runs in-process",
    )
    where.add_argument("--scheduler", metavar="ADDRESS", help="submit to an existing Dask cluster")
    p.add_argument(
        "--out",
        metavar="DIR",
        help="output folder, one case only (default <results root>/surrogates/<case>__<mesh>, "
        "or $FEMUBENCH_SURROGATE_DIR)",
    )
    p.add_argument(
        "--json",
        metavar="FILE",
        help="write the summary (hold-out errors, cost, hash) as JSON (one case only)",
    )
    existing = p.add_mutually_exclusive_group()
    existing.add_argument(
        "--force",
        action="store_true",
        help="replace the surrogate already stored in the output folder (e.g. a shipped default "
        "one); without it an existing surrogate is refused before any work",
    )
    existing.add_argument(
        "--skip-done",
        action="store_true",
        help="skip a case whose output folder already holds a built surrogate (surrogate.json "
        "and build.json): a batch of cases resumes where it stopped",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument(
        "--time",
        action="store_true",
        help="build nothing: time the stored surrogate of CASE (default name, or --out) against "
        "one FE run in this process (one call, one misfit evaluation single and per point in a "
        "batch of 1000; CPU clock) and print it (--json: write it); the stored model is unchanged",
    )


def time_stored(args) -> int:
    """``--time``: the evaluation costs of a stored surrogate, measured now."""
    import json

    import numpy as np

    from bench.experiment.surrogate_track import load_for
    from problems.inverse.data import get_data, load
    from problems.inverse.forward import FEForwardModel
    from problems.io.atomic import atomic_write_text
    from problems.surrogate.validation import time_evaluations

    sur = load_for(args.out or "default", args.case, args.mesh)
    data = get_data(args.case) if args.data is None else load(args.data)
    checker = sur.checker
    fe = FEForwardModel(checker.case, args.mesh, checker.loading, checker.points)
    rng = np.random.default_rng(args.seed)
    X = sur.lower + rng.random((50, len(sur.names))) * (sur.upper - sur.lower)
    X = X[[sur.check(x) is None for x in X]]
    t = time_evaluations(sur, X, data.values, data.sigma(), model=fe)
    doc = {"case": args.case, "mesh": args.mesh, "hash": sur.hash, **t}
    print(
        f"{args.case} on {args.mesh}, surrogate {str(sur.hash)[:12]} (CPU time, this process): "
        f"one call {1e6 * t['surrogate_eval_s']:.0f} us (with Jacobian "
        f"{1e6 * t['surrogate_jacobian_s']:.0f} us); one misfit evaluation "
        f"{1e6 * t['misfit_eval_s']:.1f} us, per point in a batch of 1000 "
        f"{1e6 * t['misfit_batch_eval_s']:.1f} us; one FE run {t['fe_eval_s']:.3f} s: ratio "
        f"{t['speed_ratio']:.3g} (batch {t['fe_eval_s'] / t['misfit_batch_eval_s']:.3g})"
    )
    if args.json:
        atomic_write_text(args.json, json.dumps(doc, indent=1))
    return 0


def summary(sur, folder, size_bytes: int) -> dict:
    """The document written by ``--json``."""
    info = sur.info
    val = info.get("validation") or {}
    train = info["training"]
    return {
        "case": info["description"].get("case"),
        "mesh": info["description"].get("mesh"),
        "path": str(folder),
        "size_bytes": size_bytes,
        "hash": sur.hash,
        "training_hash": info["training_hash"],
        "n_train": train["n_runs"],
        "n_train_ok": train["n_ok"],
        "n_failed": train["n_failed"],
        "n_infeasible": train["n_infeasible"],
        "training_fe_wall_s": train["fe_wall_s"],
        "n_modes": sur.n_modes,
        "regression": sur.kind,
        "regression_settings": sur.regression.settings()
        if sur.kind == "rbf"
        else {"kind": "gp", "n_components": len(sur.regression.components)},
        "pod": info["pod"],
        "selection_scores": info["selection"].get("scores"),
        "holdout": val.get("blocks", {}),
        "n_holdout": val.get("n_points", 0),
        "surrogate_eval_s": val.get("surrogate_eval_s"),
        "surrogate_jacobian_s": val.get("surrogate_jacobian_s"),
        "misfit_eval_s": val.get("misfit_eval_s"),
        "misfit_batch_eval_s": val.get("misfit_batch_eval_s"),
        "fe_eval_s": val.get("fe_eval_s"),
        "speed_ratio": val.get("speed_ratio"),
        "clock": val.get("clock", "wall (hold-out runs)"),
        "fe_worker_wall_s": val.get("fe_worker_wall_s"),
        "cost": info["cost"],
        "build_wall_s": info["cost"].get("build_wall_s"),
        "enrichment": info.get("enrichment"),
        "discretisation": info["description"].get("discretisation"),
    }


def main(args) -> int:
    """Build (or time) the surrogate of each case of ``args.cases`` in turn; a failed case stops
    the batch (run it again with ``--skip-done`` to resume)."""
    from argparse import Namespace

    from bench.studies import case_names

    names = case_names(args.cases)
    if len(names) > 1 and (args.out or args.json):
        raise ValueError(f"--out and --json take one case, got {len(names)} cases")
    for name in names:
        if len(names) > 1:
            print(f"=== {name}", flush=True)
        status = build(Namespace(**vars(args), case=name))
        if status:
            return status
    return 0


def build(args) -> int:
    """Build, validate and store the surrogate of ``args.case`` (or ``--time`` it)."""
    import json
    from pathlib import Path

    from bench.experiment.surrogate_track import surrogate_root
    from bench.outputs import refuse_inputs, same_file
    from bench.parallel import mapper
    from problems.inverse.cases import get_case
    from problems.io.atomic import atomic_write_text
    from problems.io.jsonio import encode
    from problems.surrogate import SurrogateSettings, build_case_surrogate, default_name, save
    from problems.surrogate.store import BUILD_NAME, JSON_NAME, NPZ_NAME
    from problems.surrogate.validation import format_summary

    case = get_case(args.case)
    if case.is_analytic:
        raise ValueError(f"case {case.name} is analytic: a surrogate is for the FE cases")
    if args.time:
        return time_stored(args)
    if args.samples < 10:
        raise ValueError(f"--samples {args.samples} is out of range: need at least 10")
    if args.holdout < 0:
        raise ValueError(f"--holdout {args.holdout} is out of range: must be >= 0")
    if args.local < 0:
        raise ValueError(f"--local {args.local} is out of range: must be >= 0")
    if not 0 < args.local_scale <= 0.5:
        raise ValueError(f"--local-scale {args.local_scale} is out of range: 0 < F <= 0.5")
    if not args.tol_sigma > 0:
        raise ValueError(f"--tol-sigma {args.tol_sigma} is out of range: must be > 0")
    if args.batch < 1:
        raise ValueError(f"--batch {args.batch} is out of range: must be >= 1")
    if args.workers is not None and args.workers < 1:
        raise ValueError(f"--workers must be >= 1, got {args.workers}")
    settings = SurrogateSettings(
        n_train=args.samples,
        n_holdout=args.holdout,
        seed=args.seed,
        design=args.design,
        n_local=args.local,
        local_scale=args.local_scale,
        tol_sigma=args.tol_sigma,
        regression=args.regression,
        batch=args.batch,
        gp_restarts=args.gp_restarts,
    )
    if args.gp_restarts < 0:
        raise ValueError(f"--gp-restarts {args.gp_restarts} is out of range: must be >= 0")
    folder = Path(args.out) if args.out else surrogate_root() / default_name(case.name, args.mesh)
    if args.skip_done and all((folder / f).is_file() for f in (JSON_NAME, BUILD_NAME)):
        print(f"skip {case.name}: {folder} holds a built surrogate")
        return 0
    check_folder(folder, args.force)
    refuse_inputs("--json", args.json, [args.data, folder / JSON_NAME, folder / NPZ_NAME])
    print(
        f"surrogate of {case.name} on mesh {args.mesh}: {args.samples} training + {args.local} "
        f"local + {args.holdout} hold-out FE runs planned",
        flush=True,
    )
    with mapper(args.workers, args.scheduler) as m:
        sur = build_case_surrogate(
            case,
            mesh=args.mesh,
            data=args.data,
            settings=settings,
            mapper=m,
            progress=not args.quiet,
        )
    build, written = folder / BUILD_NAME, {}

    def build_summary(size_bytes: int) -> dict:  # written with the surrogate as one unit
        written["size"] = size_bytes
        written["doc"] = json.dumps(encode(summary(sur, folder, size_bytes)), indent=1)
        return {BUILD_NAME: written["doc"]}

    save(sur, folder, extra=build_summary)
    size, doc = written["size"], written["doc"]
    info = sur.info
    t = info["training"]
    print(
        f"training: {t['n_runs']} FE runs ({t['n_failed']} failed, {t['n_infeasible']} infeasible "
        f"points skipped), {t['fe_wall_s']:.1f} s FE time, {t['elapsed_s']:.1f} s elapsed"
    )
    pod = info["pod"]
    rms = ", ".join(f"{k} {v:.3g}" for k, v in pod["projection_rms_sigma"].items())
    print(
        f"POD: {sur.n_modes} modes of {pod['n_snapshots']} snapshots (tol {pod['tol_sigma']:g} "
        f"sigma; training projection RMS/sigma: {rms})"
    )
    scores = info["selection"].get("scores")
    if scores:
        print(
            "selection on set-aside training points (RMS/sigma per block): "
            + "; ".join(
                f"{k}: " + ", ".join(f"{b} {v:.3g}" for b, v in s["rms_sigma"].items())
                for k, s in scores.items()
            )
        )
    print(
        f"regression: {sur.kind} {sur.regression.settings() if sur.kind == 'rbf' else ''}".rstrip()
    )
    if "validation" in info:
        print(format_summary(info["validation"]))
    print(f"total build time {info['cost']['build_wall_s']:.1f} s")
    print(f"wrote {folder} ({size / 1e6:.2f} MB, hash {sur.hash[:12]})")
    print(f"wrote {build}")
    if args.json and not same_file(args.json, build):
        atomic_write_text(args.json, doc)
        print(f"wrote {args.json}")
    return 0


def check_folder(folder, force: bool) -> None:
    """ValueError (before any work) when ``folder`` holds a stored surrogate and ``force`` is not
    set, or holds files that are not a surrogate's (never replaced)."""
    from problems.surrogate.store import JSON_NAME, NPZ_NAME, OWN_FILES

    if folder.exists() and not folder.is_dir():
        raise ValueError(f"--out {folder}: is a file, not a folder")
    if not folder.is_dir():
        return
    foreign = sorted(p.name for p in folder.iterdir() if p.name not in OWN_FILES)
    if foreign:
        raise ValueError(
            f"--out {folder}: holds files that are not a surrogate's ({', '.join(foreign[:3])}); "
            "the surrogate replaces its folder as a whole, give a new or empty folder"
        )
    if not force and ((folder / JSON_NAME).exists() or (folder / NPZ_NAME).exists()):
        raise ValueError(
            f"{folder} already holds a surrogate; give --force to replace it (runs with "
            "--surrogate default use it) or --out another folder"
        )

"""``femubench calibrate EXPERIMENT``: identify the Drucker-Prager variants on a real test.

Reads an experiment file (docs/calibrating.md), imports its machine log and DIC exports, and for
each chosen variant runs the default local method (``lm`` with exact Jacobians) from a start
derived from the test; writes the calibration report (``report.md``, ``report.json``, figures)
and one result per variant into ``--out`` (default ``calibration/<experiment name>``). Rerun the
same command to resume an interrupted calibration: variants already done are read back.
"""

from __future__ import annotations

NAME = "calibrate"
HELP = (
    "Calibrate a real test: identify each Drucker-Prager variant on an experiment file (machine "
    "log + DIC export), with Laplace uncertainty, identifiability warnings, fit quality and model "
    "selection (AIC/BIC)."
)


def add_arguments(p) -> None:
    from bench.commands._args import input_file, output_dir, plate_margin_or_auto, positive_int

    p.add_argument("experiment", type=input_file, help="the experiment file (TOML)")
    p.add_argument(
        "--models",
        default=None,
        help="'all' or comma-separated variants form-hardening (default: the file's "
        "[calibration] models)",
    )
    p.add_argument(
        "--out",
        type=output_dir,
        default=None,
        help="output folder (default calibration/<experiment name>; never the experiment's own)",
    )
    p.add_argument("--mesh", default=None, help="inverse mesh (default: the file's, else coarse)")
    p.add_argument(
        "--budget", type=int, default=None, help="evaluations of lm per variant (default: file's)"
    )
    p.add_argument(
        "--correction",
        choices=["none", "one-point", "iterated", "first-order"],
        default="none",
        help="one-point: subtract the discretisation error at the untreated optimum (one run on "
        "the check mesh) from the data and re-solve; iterated: repeat at each new optimum until "
        "the parameters move < 0.1 %%; first-order: iterated, also matching the check mesh's "
        "exact Jacobian at each round's start (its limit is the check mesh's own optimum; "
        "default none)",
    )
    p.add_argument(
        "--error-band",
        choices=["gci", "none"],
        default="gci",
        help="with a correction: each parameter's discretisation band (grid convergence index "
        "from the untreated and the corrected estimate) stated and added to its 95 %% interval "
        "(default gci; none: Laplace intervals alone)",
    )
    p.add_argument(
        "--check-mesh",
        default="auto",
        help="finer mesh on which the best variant is rerun once to state the inverse mesh's "
        "discretisation error ('auto': the next finer preset; 'none': skip)",
    )
    p.add_argument(
        "--plate-margin-mm",
        type=plate_margin_or_auto,
        default=None,
        metavar="MM|auto",
        help="face points closer than MM to either plate are left out (auto: 10 %% of the "
        "specimen's smallest dimension; default: the file's [calibration] plate_margin_mm)",
    )

    p.add_argument(
        "--mcmc",
        default=None,
        help="MCMC (emcee) with posterior intervals and a bridge-sampling evidence checked "
        "against the Laplace one, for: best (the first by AIC), all, or comma-separated variants",
    )
    p.add_argument(
        "--mcmc-forward",
        choices=["surrogate", "fe"],
        default="surrogate",
        help="the model sampled: a surrogate of the inverse model trained in the local box "
        "(default) or the FE model itself (small meshes)",
    )
    p.add_argument(
        "--mcmc-steps", type=positive_int, default=2000, help="steps per walker (half burnt)"
    )
    p.add_argument(
        "--mcmc-train", type=positive_int, default=120, help="FE runs training the surrogate"
    )


def main(args) -> int:
    from pathlib import Path

    from bench.calibration import CalibrationSettings, calibrate
    from problems.inverse.experiment import load_experiment, parse_models

    exp = load_experiment(args.experiment)  # every error of the file at once (exit 2)
    models = None
    if args.models is not None:
        try:
            models = parse_models(args.models)
        except ValueError as exc:
            raise ValueError(f"--models {args.models!r}: {exc}") from None
    check = "" if args.check_mesh == "none" else args.check_mesh
    if check not in ("", "auto"):
        from problems.fe.mesh import parse_mesh_spec

        try:
            parse_mesh_spec(check)
        except ValueError as exc:
            raise ValueError(f"--check-mesh {check!r}: {exc}; or auto, none") from None
    settings = CalibrationSettings(
        args.mesh or exp.mesh,
        args.budget or exp.budget,
        check_mesh=check,
        correction=args.correction,
        error_band=args.error_band,
    )
    mcmc, mcmc_models = None, "best"
    if args.mcmc is not None:
        from bench.calibration import McmcSettings

        if args.mcmc not in ("best", "all"):
            try:
                mcmc_models = parse_models(args.mcmc)
            except ValueError as exc:
                raise ValueError(f"--mcmc {args.mcmc!r}: {exc}; or best, all") from None
        else:
            mcmc_models = args.mcmc
        mcmc = McmcSettings(args.mcmc_forward, n_steps=args.mcmc_steps, n_train=args.mcmc_train)
    out = Path(args.out) if args.out else Path("calibration") / exp.name
    report = calibrate(
        exp.path,
        out,
        models=models,
        settings=settings,
        mcmc=mcmc,
        mcmc_models=mcmc_models,
        plate_margin_mm=args.plate_margin_mm,
    )
    print(f"calibration report: {out / 'report.md'}")
    for i, row in enumerate(report["ranking"], 1):
        v = report["variants"][row["variant"]]
        # the 95 % half-width: Laplace's, plus the discretisation band when one was taken
        values = ", ".join(
            f"{n} {x:.4g} +- {hi - x:.2g}" for n, x, hi in zip(v["names"], v["x"], v["ci95_upper"])
        ) + (" (95 %, with the discretisation band)" if "band_abs" in v else "")
        print(
            f"{i}. {row['variant']}: dAIC {row['delta_aic']:.3g}, rms {row['rms_sigma']:.3f} "
            f"sigma; {values}"
        )
    return 0

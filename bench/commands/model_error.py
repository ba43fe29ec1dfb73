"""``femubench model-error CASE``: the parameter bias of the discretisation error and what each
model-error treatment buys, at what cost (see bench/studies/model_error.py).

``femubench model-error --plan FILE`` runs the phases of a study plan one after another: a TOML
file of ``[[phase]]`` tables, each the cases and options of one invocation (keys
:data:`PHASE_KEYS`, spelled as the options: ``treatments = ["bae"]``, ``margins = [30]``,
``bias-only = true``), the cluster options, ``--out`` and ``--quiet`` from the command line
applying to every phase. The study is resumable (finished rows are skipped), so a plan is too.
The shipped plan of the whole study is ``suites/studies/model_error.toml``; ``--dry-run`` prints
its phases as command lines and computes nothing."""

from __future__ import annotations

import argparse

NAME = "model-error"
HELP = (
    "model-error study of FE cases: LM errors and the linearised perfect-optimiser bias for "
    "inverse meshes x treatments (none, one-point, iterated, bae) x plate margins, with their costs"
)


def add_arguments(p) -> None:
    from bench.commands._args import (
        add_cluster_arguments,
        add_quiet_argument,
        comma_list,
        mesh_spec,
        nonneg_float,
        output_dir,
        positive_int,
    )

    p.add_argument(
        "cases", nargs="*", metavar="CASE", help="FE case name(s), or all (not with --plan)"
    )
    p.add_argument(
        "--plan",
        metavar="FILE",
        help="run the [[phase]] tables of a study plan (TOML, e.g. "
        "suites/studies/model_error.toml) one after another",
    )
    p.add_argument(
        "--dry-run",
        action="store_true",
        help="with --plan: print each phase as a command line, compute nothing",
    )
    p.add_argument(
        "--meshes",
        type=comma_list(mesh_spec, what="mesh"),
        default=("coarse",),
        help="inverse meshes, comma-separated (default coarse)",
    )
    p.add_argument(
        "--treatments",
        type=comma_list(_treatment, what="treatment"),
        default=("none", "one-point", "iterated", "bae"),
        help="treatments, comma-separated (default none,one-point,iterated,bae); with --bias-only "
        "also hifi-at-reference: the one-point correction made at the reference, the floor of "
        "every correction with that high-fidelity mesh",
    )
    p.add_argument(
        "--margins",
        type=comma_list(nonneg_float, what="margin"),
        default=(0.0, 30.0),
        help="plate margins of the measurement region, mm, comma-separated (default 0,30)",
    )
    p.add_argument(
        "--dic",
        action="store_true",
        help="add one row with DIC-route data (images correlated back)",
    )
    p.add_argument(
        "--bias-only",
        action="store_true",
        help="the linearised perfect-optimiser bias alone, no LM (for the expensive paper inverse "
        "mesh; not with iterated or first-order)",
    )
    p.add_argument(
        "--budget", type=positive_int, default=200, help="LM evaluations per row (default 200)"
    )
    p.add_argument(
        "--out",
        metavar="DIR",
        type=output_dir,
        help="output directory (default results/studies/model_error/<case>; with several cases "
        "or --plan DIR/<case>)",
    )
    add_cluster_arguments(
        p, default_workers=1, workers_help="Dask worker processes (default 1: in-process)"
    )
    add_quiet_argument(p)
    figures = p.add_mutually_exclusive_group()
    figures.add_argument("--no-figures", action="store_true", help="write the JSON/CSV files only")
    figures.add_argument(
        "--render", action="store_true", help="compute nothing: re-draw from the output folder"
    )


def _treatment(text: str) -> str:
    from bench.commands._args import ArgumentTypeError
    from bench.studies.model_error import HIFI_LIMIT
    from problems.inverse.model_error import CORRECTIONS

    if text == HIFI_LIMIT:
        return text  # the diagnostic (with --bias-only)
    if text not in CORRECTIONS:
        raise ArgumentTypeError(
            f"{text!r} is unknown; allowed: {', '.join(CORRECTIONS)} (the study compares the "
            "treatments; 'default' is one of its rows: bae with the case's plate margin)"
        )
    return text


#: the keys of a plan's phase: its cases, the study's options (as on the command line) and a note
PHASE_KEYS = (
    "cases",
    "meshes",
    "treatments",
    "margins",
    "dic",
    "bias-only",
    "budget",
    "no-figures",
    "note",
)


class _PhaseParser(argparse.ArgumentParser):
    """The command's parser for one phase of a plan: an error is a ValueError naming the phase."""

    def __init__(self, where: str):
        super().__init__(prog="femubench model-error", add_help=False)
        self.where = where
        add_arguments(self)

    def error(self, message):
        raise ValueError(f"{self.where}: {message}")


def plan_phases(path) -> list[tuple[str, list[str], argparse.Namespace]]:
    """The phases of the study plan at ``path``: ``(note, argv, parsed options)`` each, checked
    as the command line is (ValueError naming the file and the phase)."""
    from problems.io.tomlio import read_toml

    raw, _ = read_toml(path, "study plan")
    phases = raw.get("phase")
    if not isinstance(phases, list) or not phases:
        raise ValueError(f"{path}: a study plan needs [[phase]] tables")
    out = []
    for i, phase in enumerate(phases, 1):
        where = f"{path}: phase {i}"
        unknown = sorted(set(phase) - set(PHASE_KEYS))
        if unknown:
            raise ValueError(
                f"{where}: unknown key {unknown[0]!r}; allowed: {', '.join(PHASE_KEYS)}"
            )
        cases = phase.get("cases")
        if not (isinstance(cases, list) and cases and all(isinstance(c, str) for c in cases)):
            raise ValueError(f'{where}: cases must be a list of case names (or ["all"])')
        argv = list(cases)
        for key, value in phase.items():
            if key in ("cases", "note"):
                continue
            if value is True:
                argv.append(f"--{key}")
            elif isinstance(value, list):
                argv += [
                    f"--{key}",
                    ",".join(f"{v:g}" if isinstance(v, float) else str(v) for v in value),
                ]
            elif value is not False:
                argv += [f"--{key}", str(value)]
        out.append((str(phase.get("note", "")), argv, _PhaseParser(where).parse_args(argv)))
    return out


def main(args) -> int:
    import shlex

    if not args.plan:
        if args.dry_run:
            raise ValueError("--dry-run goes with --plan")
        if not args.cases:
            raise ValueError("give the cases (CASE ... or all) or --plan FILE")
        return run_study(args)
    if args.cases or args.render:
        raise ValueError("--plan gives the cases of each phase: no CASE and no --render with it")
    phases = plan_phases(args.plan)
    shared = {k: getattr(args, k) for k in ("out", "workers", "scheduler", "quiet")}
    for i, (note, argv, phase) in enumerate(phases, 1):
        line = shlex.join(["femubench", "model-error", *argv])
        print(f"=== phase {i}/{len(phases)}: {note + ': ' if note else ''}{line}", flush=True)
        if not args.dry_run:
            vars(phase).update(shared, no_figures=phase.no_figures or args.no_figures)
            run_study(phase, out_is_root=True)
    return 0


def run_study(args, out_is_root: bool = False) -> int:
    """The study on ``args.cases`` with the options of ``args`` (one command line or phase).
    ``out_is_root``: ``args.out`` holds a folder per case even for one case (a plan's phases)."""
    from pathlib import Path

    from bench.parallel import mapper
    from bench.studies import case_names, default_output_dir, existing_dir
    from bench.studies.model_error import render_model_error, render_overview, run_model_error
    from problems.inverse.cases import get_case

    cases = case_names(args.cases)
    analytic = [c for c in cases if get_case(c).is_analytic]
    if analytic:
        raise ValueError(f"case {analytic[0]}: the model-error study needs an FE case")
    per_case = out_is_root or len(cases) > 1
    outs = {name: Path(args.out) / name if args.out and per_case else args.out for name in cases}

    def overview():
        # every case folder under the study's root: overview.md and the all-cases figure
        if args.out is None or per_case:
            root = (
                Path(args.out) if args.out else default_output_dir("model_error", cases[0]).parent
            )
            for path in render_overview(root):
                print(f"wrote {path}")

    if args.render:
        for name in cases:
            print(f"wrote {render_model_error(existing_dir('model_error', name, outs[name]))}")
        overview()
        return 0

    def report(cfg, row):
        if not args.quiet:
            what = "bias" if row.get("bias_only") else "error"
            values = row["linearised_bias_percent" if what == "bias" else "lm_error_percent"]
            errs = ", ".join(f"{n} {v:+.1f}" for n, v in values.items())
            print(
                f"  {row['case']} {cfg.mesh} {cfg.treatment} margin {cfg.plate_margin_mm:g} "
                f"{cfg.route}: max |{what}| {max(abs(v) for v in values.values()):.2f} % "
                f"({errs}); {row['total_forward_equivalents']:.0f} forward-equivalents",
                flush=True,
            )

    with mapper(args.workers, args.scheduler) as m:
        for name in cases:
            run = run_model_error(
                name,
                meshes=args.meshes,
                treatments=args.treatments,
                margins=args.margins,
                dic=args.dic,
                bias_only=args.bias_only,
                budget=args.budget,
                mapper=m,
                out=outs[name],
                progress=report,
            )
            if not args.no_figures:
                print(f"wrote {render_model_error(run.dir)}")
            print(f"{name}: {len(run.rows)} rows in {run.dir}")
    if not args.no_figures:
        overview()
    return 0

"""``femubench identify``: one identification run of a case with one solver."""

from __future__ import annotations

NAME = "identify"
HELP = (
    "Identify a case's parameters with one solver; print found values, errors, cost, evaluations, "
    "time."
)


def add_arguments(p) -> None:
    from bench.commands._args import add_plate_margin_argument

    p.add_argument(
        "case", nargs="?", help="case name (see `femubench cases --analytic`); or --problem"
    )
    add_problem_arguments(p)
    p.add_argument(
        "--solver", required=True, metavar="METHOD", help="method name (see `femubench solvers`)"
    )
    p.add_argument(
        "--mesh",
        default=None,
        help="FE mesh of the forward model (default: the data tier's inverse model, "
        "docs/fe_model.md: the graded 27-node default on model-error data, coarse on consistent "
        "data, with --surrogate and with --correction default, whose treatment is made for it)",
    )
    p.add_argument(
        "--tier",
        choices=["model-error", "consistent"],
        default="model-error",
        help="data tier: model-error (made on a finer discretisation than any model of the loop) "
        "or consistent (made with the inverse mesh itself: judges the optimiser alone); default "
        "model-error",
    )
    p.add_argument(
        "--data", metavar="FILE", help="data set to fit (default: the tier's shipped data set)"
    )
    p.add_argument(
        "--correction",
        choices=["none", "one-point", "iterated", "first-order", "bae", "default"],
        default="none",
        help="model-error treatment (default none); 'default' is the case's default treatment "
        "with its plate margin, high-fidelity mesh and BAE samples (listed by `femubench cases`)",
    )
    p.add_argument(
        "--hifi-mesh",
        metavar="MESH",
        help="high-fidelity mesh of the correction (default: paper for coarse, fine for paper)",
    )
    add_plate_margin_argument(p, None, "; with --correction default the case's margin")
    p.add_argument(
        "--budget",
        type=int,
        default=300,
        metavar="N",
        help="maximum forward evaluations (default 300)",
    )
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        metavar="S",
        help="seed of the solver and of random starts (default 0)",
    )
    p.add_argument(
        "--start",
        choices=["default", "random"],
        default="default",
        help="default start of the case, or a seeded Latin-hypercube point (default: default)",
    )
    p.add_argument(
        "--option",
        nargs="+",
        action="extend",
        default=[],
        metavar="NAME=VALUE",
        help="solver option (value parsed as JSON, else a string), e.g. --option scheme=central",
    )
    p.add_argument(
        "--surrogate",
        metavar="PATH_OR_NAME",
        help="run the solver on a stored surrogate (a folder, a name under results/surrogates, or "
        "'default': the shipped one of the case and mesh); its training runs are charged",
    )
    p.add_argument(
        "--polish",
        action="store_true",
        help="after the run on the surrogate, an FE lm (exact Jacobians) from its optimum",
    )
    p.add_argument(
        "--polish-budget",
        type=int,
        default=60,
        metavar="N",
        help="FE evaluations of the polish (default 60)",
    )
    p.add_argument(
        "--jacobian",
        choices=["exact", "forward", "central"],
        default="exact",
        help="Jacobians of gradient-based methods: exact (the FE model's, by direct "
        "differentiation) or finite differences (forward | central); default exact",
    )
    p.add_argument(
        "--budget-unit",
        choices=["evaluations", "forward-equivalents"],
        default="evaluations",
        help="what --budget counts: forward evaluations, or nominal forward-equivalents (a run "
        "with an exact Jacobian counts the model's declared cost); default evaluations",
    )
    p.add_argument("--json", metavar="FILE", help="write the RunResult plus errors_percent as JSON")
    p.add_argument(
        "--quiet",
        action="store_true",
        help="no progress bar (evaluations, best cost, time left; never drawn when stderr is not "
        "a terminal)",
    )


def add_problem_arguments(p) -> None:
    """``--problem ENTRY`` and ``--arg NAME=VALUE`` (a user problem, see problems.user)."""
    p.add_argument(
        "--problem",
        metavar="ENTRY",
        help="a user problem in place of a case: 'package.module:factory' or "
        "'path/to/file.py:factory' (docs/user_problems.md)",
    )
    p.add_argument(
        "--arg",
        nargs="+",
        action="extend",
        default=[],
        metavar="NAME=VALUE",
        help="keyword argument of the --problem factory (value parsed as JSON, else a string)",
    )


def problem_spec(args) -> dict | None:
    """``{"entry", "args"}`` of ``--problem``/``--arg`` (None without --problem); ValueError
    for --arg without --problem or a malformed entry point."""
    from problems.user import entry_point_error

    if not args.problem:
        if args.arg:
            raise ValueError("--arg is for the factory of --problem, which is not given")
        return None
    why = entry_point_error(args.problem)
    if why:
        raise ValueError(f"--problem {args.problem!r}: {why}")
    return {"entry": args.problem, "args": parse_options(args.arg, flag="--arg")}


def parse_options(items: list[str], flag: str = "--option") -> dict:
    """``["n_starts=4", "scheme=central"]`` -> ``{"n_starts": 4, "scheme": "central"}``."""
    import json

    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise ValueError(f"{flag} {item!r} is malformed: expected NAME=VALUE")
        try:
            out[name.strip()] = json.loads(value)
        except json.JSONDecodeError:
            out[name.strip()] = value
    return out


def default_mesh(args) -> str:
    """The inverse mesh when ``--mesh`` is not given: the surrogate track's (``coarse``) with
    ``--surrogate``; with ``--correction default`` the mesh the case's default treatment is made
    for (``femubench cases``); else the default of the data's tier (``--data``'s own tier, else
    ``--tier``; :func:`problems.inverse.data.default_inverse_mesh`)."""
    from problems.inverse.cases import default_treatment
    from problems.inverse.data import DEFAULT_INVERSE_MESH, default_inverse_mesh, load

    if args.surrogate:
        return DEFAULT_INVERSE_MESH
    if args.correction == "default" and default_treatment(args.case).inverse_mesh:
        return default_treatment(args.case).inverse_mesh
    tier = load(args.data).settings.tier if args.data else args.tier
    return default_inverse_mesh(tier)


def derived_errors(case, result) -> dict[str, dict[str, float]]:
    """The material parameters ``case`` derives from the identified ones (the exponent cases'
    ``a``, MPa^(1-b), as Table 1 shows it): ``{name: {"reference", "start", "found",
    "error_percent"}}`` (the error signed, 100 (found/reference - 1) %); empty for a case without
    a derivation. A point where the derivation is undefined gives NaN."""
    if case.derive is None:
        return {}

    def at(x) -> dict[str, float]:
        try:
            return case.derived(x)
        except (ValueError, ZeroDivisionError, OverflowError):
            return {}

    ref = at(result.reference)
    x0, found = at(result.x0), at(result.x)
    nan = float("nan")
    return {
        n: {
            "reference": r,
            "start": x0.get(n, nan),
            "found": found.get(n, nan),
            "error_percent": 100.0 * (found.get(n, nan) / r - 1.0),
        }
        for n, r in ref.items()
    }


def format_identification(case, result) -> str:
    """Parameters (reference, start, found, signed error %) and the derived ones (the exponent
    cases' ``a``), then cost, status, evaluations, time."""
    errors = result.errors_percent()
    units = {p.name: p.unit for p in case.parameters}
    lines = [
        f"{case.name}: {result.method} (seed {result.seed}, budget {result.budget})",
        f"  {'parameter':10} {'unit':10} {'reference':>12} {'start':>12} {'found':>12} "
        f"{'error %':>9}",
    ]
    for name, ref, x0, x in zip(result.parameter_names, result.reference, result.x0, result.x):
        lines.append(
            f"  {name:10} {units.get(name, ''):10} {ref:12.6g} {x0:12.6g} {x:12.6g} "
            f"{errors[name]:+9.3f}"
        )
    for name, d in derived_errors(case, result).items():
        lines.append(
            f"  {name:10} {'derived':10} {d['reference']:12.6g} {d['start']:12.6g} "
            f"{d['found']:12.6g} {d['error_percent']:+9.3f}"
        )
    lines += [
        f"  cost {result.cost:.6g}   status {result.status}: {result.message}",
        f"  forward evaluations {result.n_evals} (failed {result.n_failed}, infeasible "
        f"{result.n_infeasible}; repeats {result.n_repeats} {result.repeats}), iterations "
        f"{result.n_iterations}, wall {result.wall_s:.2f} s",
        f"  forward-equivalents {result.forward_equivalents:.1f} measured, "
        f"{result.forward_equivalents_nominal:.1f} nominal (budget in {result.budget_unit})"
        + "".join(
            f", {k} {c['n']} runs = {c['forward_equivalents']:.1f} fe"
            for k, c in result.charges.items()
        ),
    ]
    prov = result.provenance
    if prov.get("surrogate"):
        sur, pol = result.extra.get("surrogate", {}), result.extra.get("polish")
        train = result.charges.get("surrogate-training", {})
        lines.append(
            f"  surrogate {prov['surrogate']} (hash {str(prov.get('surrogate_hash'))[:12]}): "
            f"{sur.get('n_evals')} evaluations = {sur.get('forward_equivalents', 0):.3g} fe, "
            f"cost there {sur.get('cost', float('nan')):.6g}"
            + (
                f"; FE polish {pol['method']}: {pol['n_evals']} evaluations = "
                f"{pol['forward_equivalents']:.1f} fe"
                if pol
                else "; no FE polish (cost is the surrogate's)"
            )
        )
        lines.append(
            f"  cost per identification {result.forward_equivalents:.1f} fe + training "
            f"{train.get('n', 0)} FE runs = "
            f"{result.forward_equivalents + train.get('forward_equivalents', 0):.1f} fe; "
            f"amortised (training shared) {sur.get('amortised_forward_equivalents', 0):.1f} fe"
        )
    if prov.get("data_tier"):
        lines.append(
            f"  data: {prov['data_tier']} tier, mesh {prov.get('data_mesh')}, hash "
            f"{str(prov.get('data_hash'))[:12]}; inverse mesh {prov.get('inverse_mesh')}; "
            f"treatment {prov.get('treatment')}"
            + (f" (high-fidelity mesh {prov['hifi_mesh']})" if prov.get("hifi_mesh") else "")
            + (
                f", plate margin {prov['region_plate_margin_mm']:g} mm"
                if prov.get("region_plate_margin_mm")
                else ""
            )
            + (" = the case's default" if prov.get("treatment_requested") == "default" else "")
        )
    return "\n".join(lines)


def result_document(result, case=None) -> dict:
    """The JSON written by ``--json``: the RunResult (with its ``provenance``: case, data tier and
    hash, data and inverse meshes, treatment and its high-fidelity mesh, start), ``iterations``,
    ``errors_percent``, ``derived`` (:func:`derived_errors` of ``case``: the exponent cases'
    ``a`` with its error; empty without a case or a derivation) and the package version (``main``
    adds ``warnings``: the plausibility warnings, problems.inverse.plausibility)."""
    from bench.cli import package_version

    return {
        **result.to_dict(),
        "iterations": result.n_iterations,
        "errors_percent": result.errors_percent(),
        "derived": derived_errors(case, result) if case is not None else {},
        "package_version": package_version(),
    }


def main(args) -> int:
    import json
    import warnings

    from bench.experiment.identify import identify
    from bench.experiment.spec import DataSpec, RunSpec, Treatment
    from bench.outputs import refuse_inputs
    from problems.inverse.cases import get_case
    from problems.inverse.plausibility import PlausibilityWarning
    from problems.io.atomic import atomic_write_text

    refuse_inputs("--json", args.json, [args.data])
    spec = problem_spec(args)
    if spec is not None:
        if args.case:
            raise ValueError(f"give a case or --problem, not both (case {args.case!r})")
        return identify_problem(args, spec)
    if not args.case:
        raise ValueError("name a case (see `femubench cases --analytic`) or give --problem ENTRY")
    case = get_case(args.case)
    if args.correction == "default" and (
        args.plate_margin_mm is not None or args.hifi_mesh is not None
    ):
        raise ValueError(
            "--correction default sets the plate margin and the high-fidelity mesh itself (see "
            "`femubench cases`); to change them name the treatment, e.g. --correction bae"
        )
    if args.mesh is None:
        args.mesh = default_mesh(args)
    if args.hifi_mesh is not None:
        from problems.inverse.build import check_finer

        check_finer(args.hifi_mesh, args.mesh)
    if args.polish_budget < 1:
        raise ValueError(
            f"--polish-budget {args.polish_budget} is out of range: a whole number >= 1"
        )
    if args.polish and not args.surrogate:
        raise ValueError("--polish follows a run on a surrogate: give --surrogate")
    spec = RunSpec(
        case.name,
        args.solver,
        seed=args.seed,
        start=args.start,
        budget=args.budget,
        mesh=args.mesh,
        options=parse_options(args.option),
        data=DataSpec(args.tier, file=args.data),
        treatment=Treatment(args.correction, args.plate_margin_mm or 0.0, hifi_mesh=args.hifi_mesh),
        surrogate=args.surrogate,
        polish_budget=args.polish_budget if args.polish else 0,
        jacobian=args.jacobian,
        budget_unit=args.budget_unit,
    )
    from bench.progress import EvaluationProgress, enabled, warn_if_long

    if not case.is_analytic:
        warn_if_long(NAME, args.budget, args.mesh, what=f"budget {args.budget}")
    with (
        EvaluationProgress(
            total=args.budget, desc=f"{case.name} {args.solver}", disable=not enabled(args.quiet)
        ) as progress,
        warnings.catch_warnings(record=True) as caught,
    ):
        warnings.simplefilter("always", PlausibilityWarning)
        result = identify(spec, observers=[progress])
    found = []
    for w in caught:
        if issubclass(w.category, PlausibilityWarning):
            found.append(str(w.message))
        else:
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    print(format_identification(case, result))
    for message in found:
        print(f"  warning: {message}")
    if args.json:
        doc = {**result_document(result, case), "warnings": found}
        atomic_write_text(args.json, json.dumps(doc, indent=1))
        print(f"  written {args.json}")
    return 0


def identify_problem(args, spec: dict) -> int:
    """``femubench identify --problem ENTRY``: one run of a user problem, printed with its own
    success rule (evaluations, f − f_min, correct digits)."""
    import json

    from bench.experiment.spec import RunSpec
    from bench.experiment.user_problems import run_user
    from problems.io.atomic import atomic_write_text

    entry = spec["entry"]
    config = RunSpec(
        entry.rpartition(":")[2],
        args.solver,
        seed=args.seed,
        start=args.start,
        budget=args.budget,
        options=parse_options(args.option),
        budget_unit=args.budget_unit,
        problem=spec,
    )
    result = run_user(config)
    print(format_problem_run(config, result))
    if args.json:
        atomic_write_text(args.json, json.dumps(result.to_dict(), indent=1))
        print(f"  written {args.json}")
    return 0


def format_problem_run(config, result) -> str:
    """Parameters (start, found, known optimum), then f, the problem's verdict, evaluations."""
    prob = result.extra["problem"]
    ref = prob.get("x_ref") or [None] * len(result.x)
    lines = [
        f"{config.case} ({prob['kind']}, {config.problem['entry']}): {result.method} "
        f"(seed {result.seed}, budget {result.budget} evaluations)",
        f"  {'parameter':10} {'start':>14} {'found':>14} {'optimum':>14}",
    ]
    for name, x0, x, xr in zip(result.parameter_names, result.x0, result.x, ref):
        opt = f"{xr:14.8g}" if xr is not None else f"{'?':>14}"
        lines.append(f"  {name:10} {x0:14.8g} {x:14.8g} {opt}")
    gap = f", f − f_min {prob['f_gap']:.3g}" if "f_gap" in prob else ""
    digits = f", {prob['digits']:.1f} correct digits" if "digits" in prob else ""
    lines += [
        f"  f {result.cost:.10g}{gap}{digits}; status {result.status}: {result.message}",
        f"  success ({prob['success_text']}): {'yes' if prob['success'] else 'no'}",
        f"  evaluations {result.n_evals} (failed {result.n_failed}, infeasible "
        f"{result.n_infeasible}, cache hits {result.n_cache_hits}), wall {result.wall_s:.2f} s",
    ]
    return "\n".join(lines)

"""``femubench identify``: one identification run of a case with one solver."""
from __future__ import annotations

NAME = "identify"
HELP = "Identify a case's parameters with one solver; print found values, errors, cost, evaluations, time."


def add_arguments(p) -> None:
    p.add_argument("case", help="case name (see `femubench cases --analytic`)")
    p.add_argument("--solver", required=True, metavar="METHOD", help="method name (see `femubench solvers`)")
    p.add_argument("--mesh", default="coarse", help="FE mesh of the forward model (default: coarse)")
    p.add_argument("--data", metavar="FILE", help="data set to fit (default: the case's shipped pseudo-experimental data)")
    p.add_argument("--budget", type=int, default=300, metavar="N", help="maximum forward evaluations (default 300)")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="seed of the solver and of random starts (default 0)")
    p.add_argument("--start", choices=["default", "random"], default="default",
                   help="default start of the case, or a seeded Latin-hypercube point (default: default)")
    p.add_argument("--option", nargs="+", action="extend", default=[], metavar="NAME=VALUE",
                   help="solver option (value parsed as JSON, else a string), e.g. --option scheme=central")
    p.add_argument("--json", metavar="FILE", help="write the RunResult plus errors_percent as JSON")


def parse_options(items: list[str]) -> dict:
    """``["n_starts=4", "scheme=central"]`` -> ``{"n_starts": 4, "scheme": "central"}``."""
    import json

    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise ValueError(f"--option {item!r} is malformed: expected NAME=VALUE")
        try:
            out[name.strip()] = json.loads(value)
        except json.JSONDecodeError:
            out[name.strip()] = value
    return out


def format_identification(case, result) -> str:
    """Parameters (reference, start, found, signed error %), then cost, status, evaluations, time."""
    errors = result.errors_percent()
    units = {p.name: p.unit for p in case.parameters}
    lines = [f"{case.name}: {result.method} (seed {result.seed}, budget {result.budget})",
             f"  {'parameter':10} {'unit':10} {'reference':>12} {'start':>12} {'found':>12} {'error %':>9}"]
    for name, ref, x0, x in zip(result.parameter_names, result.reference, result.x0, result.x):
        lines.append(f"  {name:10} {units.get(name, ''):10} {ref:12.6g} {x0:12.6g} {x:12.6g} {errors[name]:+9.3f}")
    lines += [
        f"  cost {result.cost:.6g}   status {result.status}: {result.message}",
        f"  forward evaluations {result.n_evals} (failed {result.n_failed}, infeasible {result.n_infeasible}; "
        f"cache hits {result.n_cache_hits} not counted), iterations {result.n_iterations}, wall {result.wall_s:.2f} s",
    ]
    return "\n".join(lines)


def result_document(result, **context) -> dict:
    """The JSON written by ``--json``: the RunResult (context in ``extra``) plus ``errors_percent``."""
    result.extra.update(context)
    return {**result.to_dict(), "errors_percent": result.errors_percent()}


def main(args) -> int:
    import json
    from pathlib import Path

    from problems.inverse.cases import get_case
    from problems.inverse.build import build_objective
    from problems.inverse.starts import start_point
    from solvers import solve

    case = get_case(args.case)
    options = parse_options(args.option)
    objective = build_objective(case, mesh=args.mesh, data=args.data)
    x0 = start_point(case, kind=args.start, seed=args.seed)
    result = solve(objective, args.solver, budget=args.budget, seed=args.seed, x0=x0, **options)
    print(format_identification(case, result))
    if args.json:
        context = {"case": case.name, "mesh": args.mesh, "start": args.start, "data": args.data}
        if getattr(objective, "data_hash", None):
            context["data_hash"] = objective.data_hash
        Path(args.json).write_text(json.dumps(result_document(result, **context), indent=1))
        print(f"  written {args.json}")
    return 0

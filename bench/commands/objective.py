"""``femubench objective``: the objective of a case at one point (cost, split, feasibility)."""

from __future__ import annotations

NAME = "objective"
HELP = (
    "Evaluate a case's objective at one point: cost, its split by measurement block, feasibility."
)


def add_arguments(p) -> None:
    from bench.commands._args import add_mesh_argument, input_file

    p.add_argument("case", help="case name (see `femubench cases --analytic`)")
    p.add_argument(
        "--x",
        nargs="+",
        action="extend",
        default=[],
        metavar="NAME=VALUE",
        help="parameter values (physical units, finite); the others take their reference value; a "
        "point outside the bounds is evaluated as infeasible",
    )
    add_mesh_argument(p, "coarse", help="FE mesh of the forward model (default: coarse)")
    p.add_argument(
        "--data",
        metavar="FILE",
        type=input_file,
        help="data set (default: the case's shipped pseudo-experimental data)",
    )
    p.add_argument("--json", action="store_true", help="print the evaluation as JSON")


def point(case, items: list[str]):
    """The reference of ``case`` with the ``NAME=VALUE`` items applied (ValueError if malformed,
    non-finite or unknown)."""
    from bench.commands._args import assignments

    x = case.reference.copy()
    names = list(case.names)
    for name, value in assignments(items, "--x", names).items():
        x[names.index(name)] = value
    return x


def evaluate(objective, x) -> dict:
    """Cost, split, feasibility and counts of one evaluation at physical ``x``."""
    z = objective.to_scaled(x)
    ev = objective.evaluate(z)
    split = objective.cost_split(z)  # served from the cache
    return {
        "x": dict(zip(objective.names, map(float, x))),
        "cost": ev.cost,
        "split": split,
        "feasible": ev.feasible,
        "ok": ev.ok,
        "message": ev.message,
        "wall_s": ev.wall_s,
        "n_evals": objective.n_evals,
    }


def format_evaluation(doc: dict) -> str:
    lines = ["  " + ", ".join(f"{k} = {v:.6g}" for k, v in doc["x"].items())]
    state = "feasible" if doc["feasible"] else "INFEASIBLE"
    state += (
        ", forward model ok" if doc["ok"] else (", forward model FAILED" if doc["feasible"] else "")
    )
    lines.append(f"  {state}" + (f": {doc['message']}" if doc["message"] else ""))
    lines.append(
        f"  cost {doc['cost']:.6g}"
        + ("  (failure penalty)" if not (doc["ok"] and doc["feasible"]) else "")
    )
    for name, value in doc["split"].items():
        if name != "total":
            lines.append(f"    {name:14} {value:.6g}")
    lines.append(f"  wall {doc['wall_s']:.3f} s, forward evaluations {doc['n_evals']}")
    return "\n".join(lines)


def main(args) -> int:
    import json
    import math

    from bench.experiment.objective import assemble
    from bench.experiment.spec import DataSpec, RunSpec
    from problems.inverse.cases import get_case

    case = get_case(args.case)
    x = point(case, args.x)
    objective = assemble(RunSpec(case.name, "none", mesh=args.mesh, data=DataSpec(file=args.data)))
    doc = evaluate(objective, x)
    if args.json:
        doc["split"] = {
            k: (None if isinstance(v, float) and math.isnan(v) else v)
            for k, v in doc["split"].items()
        }
        print(json.dumps(doc, indent=1))
    else:
        print(f"{case.name} (mesh {args.mesh}):")
        print(format_evaluation(doc))
    return 0

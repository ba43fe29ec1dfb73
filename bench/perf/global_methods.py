"""Evaluations the global methods need to reach the optimum of the analytic problems (not a test).

    python -m bench.perf.global_methods [--methods cma,bo,ngopt,de,pso] [--seeds 5]
                                        [--problems smooth,multimodal]

A method may carry options after ``@``: ``ngopt@num_workers=4``, ``cma@popsize=16,restarts=0``
(values are parsed as Python literals when they are).

For each method, problem and seed ``0 .. seeds-1``: one run from the case's default start with the
method's default options; from the objective's log, the number of forward evaluations until the
first point that *reaches the optimum*:

* ``analytic-smooth`` (budget 2000): every parameter within 1 % of the reference;
* ``analytic-multimodal`` (budget 600): cost below 100, i.e. in the global basin (the local
  minima have costs of 1.7e4 and more).

Printed per method and problem: the median over the seeds (a seed that never gets there counts as
infinite, so the median is finite when more than half of the seeds succeed), how many succeeded,
the median best cost at the end, and the median wall time of a run in seconds (the optimiser's
own overhead: the analytic models cost microseconds). ``bo`` stops at its ``max_evals`` (200).
"""

from __future__ import annotations

import argparse
import ast
import math
import time
import warnings

import numpy as np

from problems.inverse.analytic import ANALYTIC_CASES, analytic_objective
from solvers import solve

#: problem -> (case, budget, criterion on (scaled point / reference, cost), criterion text)
PROBLEMS = {
    "smooth": (
        "analytic-smooth",
        2000,
        lambda xn, c: bool(np.max(np.abs(xn - 1.0)) < 0.01),
        "all |x/ref - 1| < 1 %",
    ),
    "multimodal": ("analytic-multimodal", 600, lambda xn, c: c < 100.0, "cost < 100"),
}


def evals_to_reach(obj, reached) -> float:
    """Forward evaluations until the first logged point satisfying ``reached`` (inf: never)."""
    for e in obj.log:
        if e["cached"] or not (e["ok"] and e["feasible"]):
            continue
        if reached(np.asarray(e["x"]) / obj.reference, e["cost"]):
            return float(e["n_evals"])
    return math.inf


def parse_method(spec: str) -> tuple[str, dict]:
    """``"ngopt@num_workers=4,optimizer=NGOpt"`` -> ``("ngopt", {"num_workers": 4, ...})``."""
    method, _, rest = spec.partition("@")
    options = {}
    for item in filter(None, rest.split(",")):
        key, _, value = item.partition("=")
        try:
            options[key] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            options[key] = value
    return method, options


def measure(spec: str, problem: str, seeds: int) -> dict:
    method, options = parse_method(spec)
    name, budget, reached, _ = PROBLEMS[problem]
    case = ANALYTIC_CASES[name]
    evals, costs, walls = [], [], []
    for seed in range(seeds):
        obj = analytic_objective(name)
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = solve(obj, method, budget=budget, seed=seed, x0=case.start, **options)
        walls.append(time.perf_counter() - t0)
        evals.append(evals_to_reach(obj, reached))
        costs.append(res.cost)
    return {
        "median_evals": float(np.median(evals)),
        "reached": sum(math.isfinite(e) for e in evals),
        "evals": evals,
        "median_cost": float(np.median(costs)),
        "median_wall_s": float(np.median(walls)),
    }


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--methods", default="cma,bo,ngopt,ngopt@num_workers=4,de,pso")
    ap.add_argument("--problems", default="smooth,multimodal")
    ap.add_argument("--seeds", type=int, default=5)
    args = ap.parse_args(argv)
    problems = args.problems.split(",")
    for p in problems:
        name, budget, _, text = PROBLEMS[p]
        print(f"# {p}: {name}, budget {budget}, reached = {text}")
    header = (
        "| method | "
        + " | ".join(f"{p}: median evals (reached) | best cost | wall s" for p in problems)
        + " |"
    )
    print(header)
    print("|---" * (1 + 3 * len(problems)) + "|")
    for method in args.methods.split(","):
        cells = []
        for p in problems:
            m = measure(method, p, args.seeds)
            med = "—" if not math.isfinite(m["median_evals"]) else f"{m['median_evals']:.0f}"
            reached = f"{m['reached']}/{args.seeds}"
            cells.append(f"{med} ({reached}) | {m['median_cost']:.2g} | {m['median_wall_s']:.1f}")
        print(f"| `{method}` | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()

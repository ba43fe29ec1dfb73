"""Wrapper fidelity: each global method through femubench against its library called directly (a
benchmark, not a test).

    nice python -m bench.perf.fidelity run [--out results/perf/fidelity] [--methods cma,de,...]
        [--functions 1,2,3,6,8,10,15,17,21] [--instances 1,2,3] [--seeds 0] [--budget 5000]
    python -m bench.perf.fidelity table [--out results/perf/fidelity]

BBOB in 5-D (``cocoex``): for every method, function, instance and seed, two runs with the same
budget, seed, start (COCO's initial solution, the origin) and the settings femubench documents
for the method (solvers/): *femubench* (``solvers.solve`` on the problem of
:mod:`problems.benchmarks.bbob`) and *direct* (the library's own entry point on the same function:
``cma.fmin2`` with IPOP restarts, pymoo's ``minimize`` with DE/GA, pyswarms' ``GlobalBestPSO``,
scipy's ``dual_annealing`` with its own local search, ``nlopt.opt``). The direct runs are cut at
the budget by a counting wrapper (its call that would exceed the budget raises).

Reported per method: targets reached (f - f_opt <= 10^k, k in :data:`TARGET_EXPONENTS`, within
the budget) by each side and the ratio femubench/direct (the fidelity target is >= 0.95), runs
that reached the final target 1e-8, and the real calls of the function against femubench's count
(``n_evals`` must equal the real calls plus the infeasible points, which are charged without a
call, plus the charged repeats, served from the cache: ``n_repeats``).

Every run is one JSON file ``OUT/rows/<method>__<side>__f<f>_i<i>_s<seed>.json`` written
atomically: an interrupted run resumes where it stopped; ``table`` prints and writes
``OUT/fidelity.md`` and ``OUT/fidelity.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

METHODS = (
    "cma",
    "de",
    "ga",
    "pso",
    "sa",
    "nlopt:CRS2_LM",
    "nlopt:DIRECT_L",
    "nlopt:ESCH",
    "nlopt:ISRES",
    "nlopt:MLSL",
)
FUNCTIONS = (1, 2, 3, 6, 8, 10, 15, 17, 21)
#: targets f - f_opt <= 10^k
TARGET_EXPONENTS = (1, -1, -3, -5, -8)
DIM = 5
LO, HI = -5.0, 5.0


class _Stop(Exception):
    """The direct run's call beyond the budget."""


class Counted:
    """A counting function with the best-so-far trace ``[(call, best gap)]``; beyond ``budget``
    calls it raises :class:`_Stop` (``budget=None``: never)."""

    def __init__(self, fn, f_opt: float, budget: int | None):
        self.fn, self.f_opt, self.budget = fn, f_opt, budget
        self.calls, self.best, self.trace = 0, math.inf, []

    def __call__(self, x) -> float:
        if self.budget is not None and self.calls >= self.budget:
            raise _Stop
        self.calls += 1
        f = float(self.fn(np.asarray(x, dtype=float)))
        if f - self.f_opt < self.best:
            self.best = f - self.f_opt
            self.trace.append((self.calls, self.best))
        return f

    def __getstate__(self):  # pragma: no cover - never shipped to another process
        raise TypeError("Counted is in-process only")


def targets_reached(trace, budget: int) -> int:
    """How many of the targets 10^k the trace reached within ``budget`` calls."""
    best = min((g for n, g in trace if n <= budget), default=math.inf)
    return sum(best <= 10.0**k for k in TARGET_EXPONENTS)


# --- the two sides ----------------------------------------------------------------------------


def run_femubench(method: str, function: int, instance: int, seed: int, budget: int) -> dict:
    """One run through femubench; the function's real calls counted beside its ``n_evals``."""
    from problems.benchmarks.bbob import problem
    from problems.inverse.evaluator import Evaluator
    from solvers import solve

    up = problem(function, instance, DIM)
    model = up.problem.model
    counted = Counted(model.fn, up.f_min, None)
    model.fn = counted
    ev = Evaluator(up.problem)
    t0 = time.perf_counter()
    res = solve(ev, method, budget=budget, seed=seed, x0=up.x0)
    trace = [(n, f - up.f_min) for n, f in res.trace]
    return {
        "trace": trace,
        "calls": counted.calls,
        "n_evals": res.n_evals,
        "n_infeasible": res.n_infeasible,
        "n_cache_hits": res.n_cache_hits,
        "n_repeats": res.n_repeats,
        "status": res.status,
        "wall_s": time.perf_counter() - t0,
    }


def _defaults(options: dict) -> dict:
    """``{name: default}`` of a method's declared options (solvers.options.Option)."""
    return {
        k: getattr(v, "default", v[0] if isinstance(v, tuple) else v) for k, v in options.items()
    }


def _cma(f, x0, seed, budget):
    import cma

    from solvers.cma_ import CMA_OPTIONS

    d = _defaults(CMA_OPTIONS)
    cma.fmin2(
        f,
        x0,
        d["sigma0"] * (HI - LO),
        {
            "bounds": [LO, HI],
            "seed": seed + 1,
            "tolfun": d["tolfun"],
            "tolx": d["tolx"] * (HI - LO),
            "verbose": -9,
            "verb_log": 0,
            "verb_disp": 0,
        },
        restarts=d["restarts"],
        incpopsize=d["incpopsize"],
    )


def _pymoo(kind):
    def run(f, x0, seed, budget):
        from pymoo.config import Config
        from pymoo.core.problem import ElementwiseProblem
        from pymoo.optimize import minimize

        from solvers.pymoo_ import DE_OPTIONS, GA_OPTIONS

        Config.warnings["not_compiled"] = False

        class P(ElementwiseProblem):
            def __init__(self):
                super().__init__(n_var=DIM, n_obj=1, xl=LO, xu=HI)

            def _evaluate(self, x, out, *args, **kwargs):
                out["F"] = f(x)

        if kind == "de":
            from pymoo.algorithms.soo.nonconvex.de import DE

            d = _defaults(DE_OPTIONS)
            alg = DE(pop_size=d["pop_size"], variant=d["variant"], CR=d["CR"], F=d["F"])
        else:
            from pymoo.algorithms.soo.nonconvex.ga import GA
            from pymoo.operators.crossover.sbx import SBX
            from pymoo.operators.mutation.pm import PM

            d = _defaults(GA_OPTIONS)
            alg = GA(
                pop_size=d["pop_size"],
                crossover=SBX(prob=d["crossover_prob"], eta=d["crossover_eta"]),
                mutation=PM(eta=d["mutation_eta"]),
                eliminate_duplicates=True,
            )
        minimize(P(), alg, ("n_evals", budget), seed=seed, verbose=False)

    return run


def _pso(f, x0, seed, budget):
    import logging.config
    from unittest import mock

    from solvers.pyswarms_ import PSO_OPTIONS

    with mock.patch.object(logging.config, "dictConfig", lambda config: None):
        from pyswarms.single import GlobalBestPSO

    d = _defaults(PSO_OPTIONS)
    np.random.seed(seed)  # pyswarms draws from NumPy's global generator
    clamp = d["velocity_clamp"] * (HI - LO)
    with mock.patch.object(logging.config, "dictConfig", lambda config: None):
        pso = GlobalBestPSO(
            n_particles=d["n_particles"],
            dimensions=DIM,
            options={"c1": d["c1"], "c2": d["c2"], "w": d["w"]},
            bounds=(np.full(DIM, LO), np.full(DIM, HI)),
            bh_strategy=d["bh_strategy"],
            velocity_clamp=(-clamp, clamp),
        )
    iters = math.ceil(budget / d["n_particles"]) + 1
    pso.optimize(lambda X: np.array([f(x) for x in X]), iters, verbose=False)


def _sa(f, x0, seed, budget):
    from scipy.optimize import dual_annealing

    dual_annealing(f, [(LO, HI)] * DIM, maxfun=budget, rng=seed, x0=x0)


def _nlopt(name):
    def run(f, x0, seed, budget):
        import nlopt

        from solvers.nlopt_ import MLSL_OPTIONS, algorithm_code

        code, full = algorithm_code(name)
        nlopt.srand(int(seed))
        opt = nlopt.opt(code, DIM)

        def objective(x, grad):
            try:
                return f(x)
            except _Stop:
                raise nlopt.ForcedStop from None

        opt.set_min_objective(objective)
        opt.set_lower_bounds(np.full(DIM, LO))
        opt.set_upper_bounds(np.full(DIM, HI))
        opt.set_maxeval(budget)
        if "MLSL" in full:
            d = _defaults(MLSL_OPTIONS)
            local = nlopt.opt(algorithm_code(d["local"])[0], DIM)
            local.set_xtol_rel(d["local_xtol_rel"])
            local.set_ftol_rel(d["local_ftol_rel"])
            opt.set_local_optimizer(local)
        try:
            opt.optimize(np.asarray(x0, float))
        except nlopt.ForcedStop:
            pass

    return run


DIRECT = {
    "cma": _cma,
    "de": _pymoo("de"),
    "ga": _pymoo("ga"),
    "pso": _pso,
    "sa": _sa,
    **{f"nlopt:{a}": _nlopt(a) for a in ("CRS2_LM", "DIRECT_L", "ESCH", "ISRES", "MLSL")},
}


def run_direct(method: str, function: int, instance: int, seed: int, budget: int) -> dict:
    """One run of the library called directly on the same function, cut at ``budget`` calls."""
    import warnings

    from problems.benchmarks.bbob import BBOBFunction

    fn = BBOBFunction(function, instance, DIM)
    counted = Counted(fn, float(fn.bare().best_value()), budget)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        state = np.random.get_state()
        try:
            DIRECT[method](counted, np.zeros(DIM), seed, budget)
        except _Stop:
            pass
        finally:
            np.random.set_state(state)
    return {
        "trace": counted.trace,
        "calls": counted.calls,
        "wall_s": time.perf_counter() - t0,
    }


# --- driver -----------------------------------------------------------------------------------


def _key(method, side, f, i, s) -> str:
    return f"{method.replace(':', '-')}__{side}__f{f}_i{i}_s{s}"


def _write(path: Path, text: str) -> None:
    from problems.io.atomic import atomic_write_text

    atomic_write_text(path, text)


def run_all(out: Path, methods, functions, instances, seeds, budget: int) -> None:
    """Run every missing (method, side, function, instance, seed) and write its row."""
    rows = out / "rows"
    rows.mkdir(parents=True, exist_ok=True)
    for method in methods:
        for f in functions:
            for i in instances:
                for s in seeds:
                    for side, fn in (("femubench", run_femubench), ("direct", run_direct)):
                        path = rows / f"{_key(method, side, f, i, s)}.json"
                        if path.is_file():
                            continue
                        doc = fn(method, f, i, s, budget)
                        doc.update(
                            method=method, side=side, function=f, instance=i, seed=s, budget=budget
                        )
                        _write(path, json.dumps(doc) + "\n")
            print(f"{method} f{f}: done", flush=True)


def summary(out: Path) -> list[dict]:
    """Per method: targets reached by each side, their ratio, runs to 1e-8, the count check."""
    docs = [json.loads(p.read_text()) for p in sorted((out / "rows").glob("*.json"))]
    by: dict = {}
    for d in docs:
        by.setdefault(d["method"], {}).setdefault(d["side"], {})[
            (d["function"], d["instance"], d["seed"])
        ] = d
    rows = []
    for method in [m for m in METHODS if m in by] + sorted(set(by) - set(METHODS)):
        sides = by[method]
        keys = sorted(set(sides.get("femubench", {})) & set(sides.get("direct", {})))
        if not keys:
            continue
        fb = [sides["femubench"][k] for k in keys]
        dr = [sides["direct"][k] for k in keys]
        tf = sum(targets_reached(d["trace"], d["budget"]) for d in fb)
        td = sum(targets_reached(d["trace"], d["budget"]) for d in dr)
        exact = sum(
            d["n_evals"] == d["calls"] + d["n_infeasible"] + d.get("n_repeats", 0) for d in fb
        )
        rows.append(
            {
                "method": method,
                "runs": len(keys),
                "targets": len(keys) * len(TARGET_EXPONENTS),
                "femubench": tf,
                "direct": td,
                "ratio": tf / td if td else math.nan,
                "final_femubench": sum(targets_reached(d["trace"], d["budget"]) == 5 for d in fb),
                "final_direct": sum(targets_reached(d["trace"], d["budget"]) == 5 for d in dr),
                "calls_femubench": sum(d["calls"] for d in fb),
                "n_evals_femubench": sum(d["n_evals"] for d in fb),
                "cache_hits_femubench": sum(d["n_cache_hits"] for d in fb),
                "calls_direct": sum(d["calls"] for d in dr),
                "counts_exact": f"{exact}/{len(fb)}",
                "wall_femubench_s": sum(d["wall_s"] for d in fb),
                "wall_direct_s": sum(d["wall_s"] for d in dr),
            }
        )
    return rows


def table(rows: list[dict]) -> str:
    """The summary as a Markdown table."""
    head = (
        "| method | runs | targets femubench | targets direct | ratio | runs to 1e-8 (fb/direct) "
        "| calls femubench (n_evals; cache hits) | calls direct | counts exact "
        "| wall fb/direct s |\n"
        "|:---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n"
    )
    body = "".join(
        f"| {r['method']} | {r['runs']} | {r['femubench']}/{r['targets']} | "
        f"{r['direct']}/{r['targets']} | {r['ratio']:.2f} | {r['final_femubench']}/"
        f"{r['final_direct']} | {r['calls_femubench']} ({r['n_evals_femubench']}; "
        f"{r['cache_hits_femubench']}) | {r['calls_direct']} | {r['counts_exact']} | "
        f"{r['wall_femubench_s']:.1f}/{r['wall_direct_s']:.1f} |\n"
        for r in rows
    )
    return head + body


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench.perf.fidelity", description=__doc__)
    p.add_argument("what", choices=["run", "table"])
    p.add_argument("--out", default="results/perf/fidelity", type=Path)
    p.add_argument("--methods", default=",".join(METHODS))
    p.add_argument("--functions", default=",".join(map(str, FUNCTIONS)))
    p.add_argument("--instances", default="1,2,3")
    p.add_argument("--seeds", default="0")
    p.add_argument("--budget", type=int, default=1000 * DIM)
    a = p.parse_args(argv)
    ints = lambda s: [int(v) for v in s.split(",") if v.strip()]  # noqa: E731
    methods = [m.strip() for m in a.methods.split(",") if m.strip()]
    bad = [m for m in methods if m not in DIRECT]
    if bad:
        p.error(f"--methods: {', '.join(bad)} unknown; allowed: {', '.join(DIRECT)}")
    if a.budget < 1:
        p.error(f"--budget {a.budget} is out of range: >= 1")
    if a.what == "run":
        run_all(a.out, methods, ints(a.functions), ints(a.instances), ints(a.seeds), a.budget)
    rows = summary(a.out)
    text = table(rows)
    print(text)
    a.out.mkdir(parents=True, exist_ok=True)
    _write(a.out / "fidelity.md", text)
    _write(a.out / "fidelity.json", json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

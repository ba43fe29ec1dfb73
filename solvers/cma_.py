"""cma adapter: ``cma`` (CMA-ES, Hansen's ``cma`` package, with IPOP restarts).

CMA-ES runs on the unit box ``u in [0, 1]^n`` mapped affinely onto the scaled box
``z = lower + u (upper - lower)``, so one step size ``sigma0`` (a fraction of each box width) fits
all parameters. The box is cma's ``bounds`` option with its default ``BoundTransform``: ``ask``
returns points inside the box (they are clipped to it as well, against rounding), and every
generation is one :meth:`Evaluator.costs` batch. Failed and infeasible points cost
``FAILURE_COST`` (1e12) and are simply ranked last.

Restarts: when cma's own termination criteria fire (``tolfun``, ``tolx``, stagnation, flat
fitness, ...) and evaluations are left, CMA-ES restarts from a seeded uniform point in the box
with the population multiplied by ``incpopsize`` (IPOP-CMA-ES), at most ``restarts`` times;
after the last one the run stops with status ``converged``. The run normally ends at the budget.

Seeding: cma draws from NumPy's *global* generator (its ``seed`` option reseeds it): the run is
wrapped in :func:`~solvers.base.isolated_global_rng` and each restart gets a seed derived from the
run's seed. cma writes no files (``verb_log=0``) and prints nothing (``verbose=-9``).
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from problems.inverse.evaluator import BudgetExhausted
from problems.io import jsonio
from solvers.base import Outcome, Run, isolated_global_rng, register
from solvers.options import count, nonnegative, positive

CMA_OPTIONS = {
    "sigma0": positive(0.3, "initial step size as a fraction of each box width (unit box)"),
    "popsize": count(
        None, "population size lambda of the first run (None: cma's 4 + floor(3 ln n))"
    ),
    "restarts": nonnegative(
        9, "IPOP restarts after cma's own termination (0: stop at the first termination)", "int"
    ),
    "incpopsize": count(2, "population factor at each restart (IPOP; 1: plain restarts)"),
    "tolfun": nonnegative(1e-11, "cma termination: range of the recent best costs below tolfun"),
    "tolx": nonnegative(1e-11, "cma termination: step sizes below tolx (unit box)"),
    "max_generations": count(
        None, "maximum number of generations over all restarts (None: until the budget)"
    ),
}


@register(
    "cma",
    library="cma",
    family="global",
    options=CMA_OPTIONS,
    stochastic=True,
    description="CMA-ES (covariance matrix adaptation evolution strategy) with bounds and IPOP "
    "restarts",
)
def run_cma(r: Run) -> Outcome:
    import cma

    obj, o = r.objective, r.options
    n = r.lower.size
    width = r.upper - r.lower
    rng = r.rng(1)
    popsize = int(o["popsize"]) if o["popsize"] else 4 + int(3 * math.log(n))
    max_gen = int(o["max_generations"]) if o["max_generations"] else None
    generations, restarts_done, terminations = 0, 0, []
    u0 = np.clip((r.z0 - r.lower) / width, 0.0, 1.0)
    with isolated_global_rng(r.seed), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        while True:
            es = cma.CMAEvolutionStrategy(
                u0,
                float(o["sigma0"]),
                {
                    "bounds": [0.0, 1.0],
                    "popsize": popsize,
                    "seed": int(rng.integers(1, 2**31 - 1)),
                    "tolfun": float(o["tolfun"]),
                    "tolx": float(o["tolx"]),
                    "verbose": -9,
                    "verb_log": 0,
                    "verb_disp": 0,
                },
            )
            while not es.stop():
                if obj.remaining == 0:
                    return Outcome(
                        "budget",
                        f"evaluation budget spent after {generations} generations",
                        generations,
                        {"restarts": restarts_done, "terminations": terminations},
                    )
                if max_gen is not None and generations >= max_gen:
                    return Outcome(
                        "max_iterations",
                        f"{max_gen} generations",
                        generations,
                        {"restarts": restarts_done, "terminations": terminations},
                    )
                U = np.asarray(es.ask(), dtype=float)
                Z = np.clip(r.lower + U * width, r.lower, r.upper)
                before = obj.n_evals
                try:
                    f = obj.costs(Z)
                except BudgetExhausted as exc:  # the points that fitted are evaluated and logged
                    if obj.best is not None and obj.n_evals > before:
                        # a row for the cut generation
                        r.record(
                            obj.best_z,
                            obj.best.cost,
                            generation=generations + 1,
                            restart=restarts_done,
                            popsize=popsize,
                            sigma=float(es.sigma),
                            partial=True,
                        )
                    return Outcome(
                        "budget",
                        str(exc),
                        generations,
                        {"restarts": restarts_done, "terminations": terminations},
                    )
                es.tell(list(U), [float(c) for c in f])
                generations += 1
                k = int(np.argmin(f))
                r.record(
                    Z[k],
                    f[k],
                    generation=generations,
                    restart=restarts_done,
                    popsize=popsize,
                    sigma=float(es.sigma),
                )
            terminations.append({k: jsonio.plain(v) for k, v in es.stop().items()})
            if restarts_done >= int(o["restarts"]) or obj.remaining == 0:
                break
            restarts_done += 1
            popsize = int(round(popsize * float(o["incpopsize"])))
            u0 = rng.uniform(0.0, 1.0, n)
    stops = ", ".join(sorted(terminations[-1]))
    return Outcome(
        "converged",
        f"cma terminated ({stops}) after {restarts_done} restart(s)",
        generations,
        {"restarts": restarts_done, "terminations": terminations},
    )

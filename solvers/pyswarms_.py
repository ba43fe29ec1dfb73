"""pyswarms adapter: ``pso`` (GlobalBestPSO, star topology, with bounds).

pyswarms has no seed argument and draws from NumPy's *global* generator: the run is wrapped in
:func:`~solvers.base.isolated_global_rng` (seeded, then restored). Its ``Reporter`` (created at
import and with every optimizer) reconfigures the *root* logger and creates ``report.log`` in the
working directory; here pyswarms is imported and built with ``logging.config.dictConfig``
disabled, so neither happens. The Pyramid and Random topologies are not offered (they break on
NumPy >= 1.24). Each iteration evaluates the swarm as one :meth:`Evaluator.costs` batch.
"""

from __future__ import annotations

import contextlib
import logging.config
import math
from unittest import mock

import numpy as np

from solvers.base import Outcome, Run, isolated_global_rng, lhs, register
from solvers.options import choice, count, flag, nonnegative, number, positive

PSO_OPTIONS = {
    "n_particles": count(30, "swarm size"),
    "w": number(0.729, "inertia weight"),
    "c1": nonnegative(1.49445, "cognitive coefficient"),
    "c2": number(1.49445, "social coefficient"),
    "max_iterations": count(None, "maximum number of iterations (None: until the budget)"),
    "bh_strategy": choice(
        "reflective",
        "pyswarms boundary handling: nearest | reflective | shrink | random | intermediate | "
        "periodic",
        ("nearest", "reflective", "shrink", "random", "intermediate", "periodic"),
    ),
    "velocity_clamp": positive(
        0.5, "maximum |velocity| per iteration as a fraction of each box width (None: no clamp)"
    ),
    "ftol": number(
        -math.inf,
        "stop when the best cost improves by less than ftol (relative) for ftol_iter iterations",
    ),
    "ftol_iter": count(1, "iterations over which ftol is checked"),
    "include_x0": flag(False, "put the start point into the initial swarm"),
}


@contextlib.contextmanager
def _no_logging_config():
    with mock.patch.object(logging.config, "dictConfig", lambda config: None):
        yield


def _make_optimizer(r: Run):
    with _no_logging_config():
        from pyswarms.single import GlobalBestPSO

    o = r.options
    init = lhs(int(o["n_particles"]), r.lower, r.upper, r.rng(1))
    if o["include_x0"]:
        init[0] = np.clip(r.z0, r.lower, r.upper)
    clamp = None
    if o["velocity_clamp"] is not None:
        # pyswarms clamps all dimensions alike: work on the unit box, z = lower + u (upper - lower)
        clamp = (-float(o["velocity_clamp"]), float(o["velocity_clamp"]))
    with _no_logging_config():
        return GlobalBestPSO(
            n_particles=int(o["n_particles"]),
            dimensions=r.lower.size,
            options={"c1": o["c1"], "c2": o["c2"], "w": o["w"]},
            bounds=(np.zeros(r.lower.size), np.ones(r.lower.size)),
            bh_strategy=o["bh_strategy"],
            velocity_clamp=clamp,
            ftol=o["ftol"],
            ftol_iter=int(o["ftol_iter"]),
            init_pos=(init - r.lower) / (r.upper - r.lower),
        )


@register(
    "pso",
    library="pyswarms",
    family="global",
    options=PSO_OPTIONS,
    stochastic=True,
    description="global-best particle swarm (pyswarms GlobalBestPSO, star topology, bounds)",
)
def run_pso(r: Run) -> Outcome:
    obj, o = r.objective, r.options
    width = r.upper - r.lower

    def cost(U):
        Z = np.clip(r.lower + U * width, r.lower, r.upper)
        c = obj.costs(Z)
        k = int(np.argmin(c))
        r.record(Z[k], c[k])
        return c

    n = int(o["n_particles"])
    iters = int(o["max_iterations"] or math.ceil(r.budget / n) + 1)
    with isolated_global_rng(r.seed):
        pso = _make_optimizer(r)
        pso.optimize(cost, iters, verbose=False)
    used = len(pso.cost_history)
    if obj.remaining == 0:
        return Outcome("budget", f"evaluation budget spent after {used} iterations", used)
    if used < iters:
        return Outcome("converged", "best cost stalled below ftol", used)
    return Outcome("max_iterations", f"{iters} iterations", used)

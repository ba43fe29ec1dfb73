"""Hybrids a practitioner would use: ``multistart-lm`` and ``pso+lm``.

``multistart-lm``: LM from ``n_starts`` starts (the start point first if ``include_x0``, then a
seeded Latin hypercube over the box); every start may use all that is left of the budget (a
start that converges leaves the rest to the next ones; the first is never handicapped against a
single ``lm`` run). Status and success are those of the best start (``converged`` only when its
point passes the first-order test, :mod:`solvers.optimality`).

``pso+lm``: a short particle-swarm phase (``global_fraction`` of the budget) hands its best point
to LM, which gets the rest.

Both run their phases through :meth:`~solvers.base.Run.sub`: one objective, one budget, one
history (rows carry a ``phase`` label).
"""

from __future__ import annotations

import numpy as np

from problems.inverse.evaluator import BudgetExhausted
from solvers.base import Outcome, Run, lhs, register
from solvers.optimality import data_cost
from solvers.options import count, flag, fraction
from solvers.pyswarms_ import PSO_OPTIONS
from solvers.scipy_ import LM_OPTIONS

_LM_KEYS = ("scheme", "rel_step", "ftol", "xtol", "gtol", "x_scale", "opt_tol")

MULTISTART_OPTIONS = {
    "n_starts": count(5, "number of LM starts"),
    "include_x0": flag(True, "use the start point as the first start"),
    **{k: LM_OPTIONS[k] for k in _LM_KEYS},
}


def _best_in_log(obj, start: int) -> tuple[float, list[float] | None]:
    best, x = np.inf, None
    for e in obj.log[start:]:
        if e["ok"] and e["feasible"] and e["cost"] < best:
            best, x = e["cost"], [float(v) for v in e["x"]]
    return float(best), x


@register(
    "multistart-lm",
    library="scipy",
    family="global",
    options=MULTISTART_OPTIONS,
    stochastic=True,
    description="LM from k seeded Latin-hypercube starts within the budget",
)
def run_multistart(r: Run) -> Outcome:
    obj, o = r.objective, r.options
    k = int(o["n_starts"])
    starts = lhs(k, r.lower, r.upper, r.rng(1))
    if o["include_x0"]:
        starts = np.vstack([np.clip(r.z0, r.lower, r.upper), starts[: k - 1]])
    lm_opts = {key: o[key] for key in _LM_KEYS}
    summary, statuses = [], []
    for i, z0 in enumerate(starts):
        share = int(r.budget - obj.spent)
        if share < 1:
            break
        log0, n0 = len(obj.log), obj.n_evals
        try:
            out = r.sub("lm", z0, share, lm_opts, phase=f"lm[{i}]")
        except BudgetExhausted as exc:  # the whole budget spent: this start ends, the run too
            out = Outcome("budget", str(exc))
        cost, x = _best_in_log(obj, log0)
        summary.append(
            {
                "x0": [float(v) for v in obj.to_physical(z0)],
                "x": x,
                "cost": cost,
                "status": out.status,
                "n_evals": obj.n_evals - n0,
            }
        )
        statuses.append(out.status)
    best = min(range(len(summary)), key=lambda j: summary[j]["cost"]) if summary else None
    status = "converged" if best is not None and statuses[best] == "converged" else "stalled"
    if status != "converged" and best is not None:
        # a converged start whose cost ties the best one's (the same optimum reached twice; the
        # costs differ by rounding) is the converged answer: its optimality test held there
        tie = float(o["ftol"]) * summary[best]["cost"] + 1e-15 * data_cost(obj)
        tied = [j for j in range(len(summary)) if summary[j]["cost"] <= summary[best]["cost"] + tie]
        if any(statuses[j] == "converged" for j in tied):
            status = "converged"
    if obj.remaining < 1 and status != "converged":
        status = "budget"
    return Outcome(
        status,
        f"{len(summary)} LM starts; best from start {best}",
        r.n_iterations,
        {"starts": summary},
    )


PSO_LM_OPTIONS = {
    "global_fraction": fraction(0.5, "share of the budget for the PSO phase"),
    "n_particles": count(20, "swarm size of the PSO phase"),
    **{k: PSO_OPTIONS[k] for k in ("w", "c1", "c2", "bh_strategy", "velocity_clamp")},
    **{k: LM_OPTIONS[k] for k in _LM_KEYS},
}


@register(
    "pso+lm",
    library="pyswarms+scipy",
    family="global",
    options=PSO_LM_OPTIONS,
    stochastic=True,
    description="short particle-swarm phase, then LM from its best point",
)
def run_pso_lm(r: Run) -> Outcome:
    obj, o = r.objective, r.options
    n_global = max(1, int(o["global_fraction"] * r.budget))
    pso_opts = {k: o[k] for k in ("n_particles", "w", "c1", "c2", "bh_strategy", "velocity_clamp")}
    pso_opts["include_x0"] = True
    out_g = r.sub("pso", r.z0, n_global, pso_opts, phase="pso")
    n_pso = obj.n_evals
    z_best = obj.best_z if obj.best is not None else r.z0
    out_l = r.sub("lm", z_best, r.budget - obj.spent, {k: o[k] for k in _LM_KEYS}, phase="lm")
    return Outcome(
        out_l.status,
        f"pso: {out_g.status}; lm: {out_l.message}",
        r.n_iterations,
        {"pso_evals": n_pso},
    )

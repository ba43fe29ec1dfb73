"""Identification with the iterated model-error correction: re-evaluate the correction at the
current solution and re-solve from there until the parameters settle.

Round k: ``eps_k = U_hifi(x_k) - U_inverse(x_k)`` (``correction_at(x_k)``), objective with data
``U_E - eps_k`` (``make_objective(eps_k)``), solve warm-started at ``x_k`` -> ``x_{k+1}``; stop when
``max_i |x_{k+1,i} / x_{k,i} - 1| < tol`` (default 0.1 %) or after ``max_rounds``. Every round's
evaluations count against one budget (in the objectives' budget unit: evaluations or nominal
forward-equivalents), and every high-fidelity run is charged.

The same loop makes the first-order consistent correction (treatment ``first-order``) when
``correction_at`` returns a :func:`~problems.inverse.model_error.first_order` correction (a shift
and a slope ``J_hifi(x_k) - J_inverse(x_k)``): the objective then fits
``U_E - eps_k - S_k (x - x_k)`` and the fixed point is the high-fidelity model's own optimum.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np

from solvers.base import solve
from solvers.result import RunResult


def solve_iterated(
    make_objective: Callable,
    correction_at: Callable,
    method: str,
    *,
    budget: int,
    x0,
    seed: int | None = 0,
    tol: float = 1e-3,
    max_rounds: int = 8,
    **options,
) -> RunResult:
    """Minimise with the iterated correction; returns the last round's result with totals.

    make_objective : ``correction -> Evaluator``, the objective with that correction applied and its
                     runs charged (as :func:`problems.inverse.build.build_objective` does)
    correction_at  : ``x (physical) -> Correction`` (high-fidelity and inverse runs at x, counted):
                     a one-point correction (treatment ``iterated``) or a first-order one
                     (treatment ``first-order``, recorded in the provenance)
    """
    if not 0 < tol < 1:
        raise ValueError(f"tol = {tol!r} is out of range: 0 < tol < 1")
    if int(max_rounds) < 1:
        raise ValueError(f"max_rounds = {max_rounds!r} is out of range: a whole number >= 1")
    x = np.asarray(x0, float)
    used, n_evals, fe, nominal, history, charges, rounds = 0.0, 0, 0.0, 0.0, [], {}, []
    result, treatment = None, "iterated"
    for k in range(int(max_rounds)):
        left = int(budget - used + 1e-9)  # in the objective's budget unit
        if left < 1:
            break
        corr = correction_at(x)
        if corr.treatment == "first-order":
            treatment = "first-order"
        objective = make_objective(corr)
        result = solve(objective, method, budget=left, seed=seed, x0=x, **options)
        n_evals += result.n_evals
        used += (
            result.n_evals
            if result.budget_unit == "evaluations"
            else result.forward_equivalents_nominal
        )
        fe += result.forward_equivalents
        nominal += result.forward_equivalents_nominal
        for kind, c in result.charges.items():
            total = charges.setdefault(kind, {"n": 0, "wall_s": 0.0, "forward_equivalents": 0.0})
            for key in total:
                total[key] += c[key]
        history += [{**row, "round": k} for row in result.history]
        x_new = np.asarray(result.x, float)
        move = float(np.max(np.abs(x_new / x - 1.0)))
        rounds.append(
            {
                "round": k,
                "x": x_new.tolist(),
                "cost": result.cost,
                "move": move,
                "n_evals": result.n_evals,
            }
        )
        x = x_new
        if move < tol:
            break
    if result is None:
        raise ValueError(f"budget = {budget!r} leaves no evaluation for the first round")
    converged = rounds[-1]["move"] < tol
    extra = {**result.extra, "correction_rounds": rounds, "correction_converged": converged}
    return replace(
        result,
        x0=[float(v) for v in np.asarray(x0, float)],
        n_evals=n_evals,
        budget=int(budget),
        forward_equivalents=fe,
        forward_equivalents_nominal=nominal,
        charges=charges,
        history=history,
        extra=extra,
        n_iterations=sum(r["n_evals"] > 0 for r in rounds),
        provenance={**result.provenance, "treatment": treatment, "tol": tol},
    )

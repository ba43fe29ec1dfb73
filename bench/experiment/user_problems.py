"""Running a user problem (an entry point, see :mod:`problems.user`): start, solve, judge.

A run of a user problem is the problem's factory called with the suite's arguments, an
:class:`~problems.inverse.evaluator.Evaluator` over it and :func:`solvers.solve`; the result's
``extra["problem"]`` holds what the report needs to judge it without importing the problem:

``name``, ``kind`` (``"scalar"`` or ``"least-squares"``), ``f_min``, ``x_ref``, the success rule
(``success_rule``, ``success_text``) and the verdict (``success``, ``f_gap``, ``digits``). The
fixed-target views and the COCO/IOH export read the result's exact per-call ``trace``.
"""

from __future__ import annotations

import functools

import numpy as np


@functools.lru_cache(maxsize=64)
def _cached(entry: str, args_json: str, name: str):
    import json

    from problems.user import load_problem

    return load_problem(entry, json.loads(args_json), name=name)


def problem_of(config):
    """The :class:`~problems.user.UserProblem` of a run configuration with a ``problem`` field
    (loaded once per process and entry point + arguments)."""
    from bench.experiment.spec import canonical_json

    spec = config.problem
    return _cached(spec["entry"], canonical_json(spec.get("args") or {}), config.case)


def start_of(up, config) -> np.ndarray:
    """The physical start of a run: the problem's ``x0`` (``start = "default"``), or the
    ``start_index``-th seeded random point: uniform in a finite box, else ``x0`` plus a normal
    step of scale ``max(|x0|, |reference|)`` per parameter (clipped to the box)."""
    if config.start == "default":
        return up.x0.copy()
    p = up.problem
    rng = np.random.default_rng([config.seed, 7919, config.start_index])
    u = rng.random(p.n_params)
    finite = np.isfinite(p.lower) & np.isfinite(p.upper)
    scale = np.maximum(np.abs(up.x0), np.abs(p.reference))
    lo = np.where(np.isfinite(p.lower), p.lower, 0.0)
    hi = np.where(np.isfinite(p.upper), p.upper, 0.0)
    step = up.x0 + scale * rng.standard_normal(p.n_params)
    x = np.where(finite, lo + u * (hi - lo), step)
    return np.clip(x, p.lower, p.upper)


def run_user(config, *, mapper=None, observers=()):
    """Run one configuration of a user problem; return its RunResult (``extra["problem"]`` as in
    the module docstring). Exceptions propagate (the runner turns them into failed records)."""
    from problems.inverse.evaluator import Evaluator
    from solvers import solve

    up = problem_of(config)
    ev = Evaluator(
        up.problem,
        mapper=mapper,
        budget_unit=config.budget_unit,
        free_repeats=getattr(config, "free_repeats", False),
    )
    ev.observers.extend(observers)
    result = solve(
        ev,
        config.method,
        budget=config.budget,
        seed=config.seed,
        x0=start_of(up, config),
        **dict(config.options),
    )
    verdict = up.judge(np.asarray(result.x), float(result.cost), bool(result.success))
    result.extra["problem"] = {**up.describe(), **verdict}
    result.provenance = {**result.provenance, "problem": config.problem}
    return result

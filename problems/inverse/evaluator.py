"""What is paid: the evaluator counts, caches, budgets and logs every evaluation of a problem.

The :class:`Evaluator` is what a solver sees as its objective. It wraps a
:class:`~problems.inverse.problem.LeastSquaresProblem` (which knows the data and the weights) the
way pymoo's ``core/evaluator.py`` and scipy's ``_differentiable_functions.py`` keep counting apart
from the problem. Every public method takes scaled points ``z = x / reference``.

Accounting (honest: what a user pays for; COCO's rule by default)
-----------------------------------------------------------------
* ``n_evals`` counts every call a method makes: finite-difference columns, runs with exact
  sensitivities, failed points (``ok=False``), infeasible points (``check`` returned a message,
  or the point lies outside the box; the model is *not* called, but the point still counts, and is
  also counted in ``n_infeasible``) and **repeats**: a point proposed again is served from the
  cache (no model run) but charged like a new evaluation. ``n_cache_hits`` counts every call
  served from the cache; ``n_repeats`` those of them that were charged (so the model ran
  ``n_evals - n_repeats`` times). ``n_failed`` counts the ``ok=False`` results.
* ``free_repeats=True`` restores the FE-economy rule: repeats are served free (not in
  ``n_evals``, not charged to the budget). :attr:`repeats_rule` (``"charged"`` or ``"free"``) says
  which rule applied; every result records it.
* A *reuse* is not a call of the method: the wrapper asking again for a value it already holds
  (``evaluate(..., reuse=True)``: the base point of a finite-difference Jacobian or gradient, the
  final point recorded in a history) is served free from the cache, as scipy reuses ``f(x0)``
  in its finite differences; a point not yet evaluated is charged as usual.
* Jacobian columns, one rule for every method: a finite-difference Jacobian or gradient costs
  one evaluation per column it runs (n forward, up to 2n central; a failed column's retry is
  one more), its base point being a reuse; a run with exact sensitivities is one evaluation (and
  ``jacobian_cost`` forward-equivalents in that unit, below). Libraries' own counts of
  "Jacobian evaluations" are never used for the budget.
* ``trace``: ``[[n_evals, best cost], ...]``, one pair at each charged evaluation that lowered
  the best usable cost: the best-so-far cost after *every* charged evaluation, exactly (it is
  the pair's cost up to the next pair's ``n_evals``), so evaluations-to-target need no rounding
  to an iteration's or a generation's end.
* :meth:`forward_equivalents` converts the evaluations into plain forward runs by measured wall
  time: a plain or infeasible evaluation is one, a run with sensitivities is its wall time over
  the median wall time of the plain runs of the same evaluator (without plain runs, the median
  plain part of its runs with sensitivities, which the FE model reports: the Newton run is bit
  for bit the plain run; without either, the nominal ``jacobian_cost``).
* :meth:`nominal_equivalents` does the same with a fixed, declared price: a run with
  sensitivities (response + exact Jacobian) counts ``jacobian_cost`` forward-equivalents (the
  model's declared ``jacobian_cost``, the measured ratio rounded up; see ``FEForwardModel``),
  every other evaluation one. It depends only on which evaluations were made, so it is the same
  on every machine and every run: the unit of budgets in forward-equivalents.
* :meth:`charge` records runs made on the identification's behalf outside the evaluator
  (high-fidelity runs of a model-error correction, surrogate training runs); they survive
  :meth:`reset` (they belong to how the objective was set up) and are converted to
  forward-equivalents the same way (:meth:`charged_equivalents`).
* ``log`` holds one dict per evaluation, cache hits included (``cached=True``):
  ``{"x", "cost", "ok", "feasible", "wall_s", "cached", "charged", "n_evals", "kind"}``,
  ``kind`` being ``"plain"`` or ``"jacobian"``, ``charged`` whether the call was paid.
* ``set_budget(n)``: an evaluation that would make the spent budget exceed ``n`` raises
  :class:`BudgetExhausted`; for a batch, the points that fit are evaluated and recorded first.
  ``best`` (the lowest-cost successful point so far) lets any solver return a result then. The
  spent budget (:attr:`spent`) is ``n_evals`` when ``budget_unit = "evaluations"`` (the default)
  and :meth:`nominal_equivalents` when ``budget_unit = "forward-equivalents"``: then an exact
  Jacobian costs ``jacobian_cost`` of the budget and a finite-difference Jacobian its n (forward)
  or 2n (central) runs, so that methods with and without exact Jacobians get the same budget. A
  charged repeat costs what the evaluation it repeats cost.

Failure policy (never raise into a solver)
------------------------------------------
A failed point (the model returned ``ok=False``, non-finite or wrongly shaped values, or raised)
and an infeasible point get ``cost = FAILURE_COST`` (1e12: finite, so that population methods can
rank it) and a residual vector whose squared norm equals ``FAILURE_COST`` (so that a trust-region
method rejects the step and shrinks its radius; a line search backtracks). Samplers treat these
points as ``log p = -inf``. Such points are never ``best``. A model that *raises* is treated as
failed with the exception text as message (a ``RuntimeWarning`` is issued once per evaluator).

Batches and parallelism
-----------------------
:meth:`costs`, :meth:`evaluate_many` and :meth:`jacobian` send all uncached feasible points of
one batch through a single ``mapper(fn, items)`` call (``fn`` is a picklable callable wrapping
the model, ``items`` the physical points); ``mapper=None`` is :func:`sequential_map`.

The cost path of a cheap model
------------------------------
A model offering ``misfit_of(problem)`` (the surrogate: it is affine in a few coefficients)
gives the costs of a batch of points without its measurement vectors
(:mod:`problems.surrogate.misfit`, :mod:`problems.inverse.reduced`): plain evaluations take
that path in-process (no mapper: a call costs microseconds), with the same counts, cache, budget
and failure policy; the residual vector of such an evaluation is made when a solver first asks
for it. Runs with sensitivities take the model's own call. ``cost_path=False`` turns it off (then
every evaluation is the model's call and the problem's residual, as for any model).
"""

from __future__ import annotations

import math
import time
import warnings
from collections import OrderedDict
from dataclasses import dataclass, replace
from functools import partial
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from problems.inverse.problem import FAILURE_COST, LeastSquaresProblem
from problems.inverse.protocol import ForwardResult, RunModel, provides_jacobian

Mapper = Callable[
    [Callable[[np.ndarray], ForwardResult], Sequence[np.ndarray]], Iterable[ForwardResult]
]


def sequential_map(fn, items) -> list:
    """The in-process mapper: ``[fn(x) for x in items]``."""
    return [fn(x) for x in items]


#: the units a budget can be given in (``Evaluator(budget_unit=...)``)
BUDGET_UNITS = ("evaluations", "forward-equivalents")

#: finite-difference steps relative to |z| by scheme, scipy's recommendation for a function
#: accurate to machine precision eps: sqrt(eps) (forward, error ~ h + eps/h) and eps^(1/3)
#: (central, error ~ h^2 + eps/h); a model whose values carry more noise declares its own
#: ``fd_rel_step = {"forward": ..., "central": ...}`` (the FE model: measured, see forward.py)
FD_REL_STEP = {
    "forward": float(np.sqrt(np.finfo(float).eps)),
    "central": float(np.cbrt(np.finfo(float).eps)),
}

#: nominal price, in forward-equivalents, of a response + exact Jacobian of a model that provides
#: Jacobians but declares no ``jacobian_cost``
DEFAULT_JACOBIAN_COST = 2.0


class BudgetExhausted(Exception):
    """Raised by the evaluator when an evaluation would exceed the budget."""

    def __init__(self, budget: float, n_evals: int, unit: str = "evaluations"):
        if unit == "evaluations":
            text = f"evaluation budget of {budget} exhausted ({n_evals} evaluations used)"
        else:
            text = (
                f"budget of {budget:g} forward-equivalents exhausted ({n_evals} evaluations used)"
            )
        super().__init__(text)
        self.budget = budget
        self.n_evals = n_evals
        self.unit = unit


@dataclass(frozen=True)
class Evaluation:
    """One evaluated point. ``x`` is physical; ``residual`` is the whitened residual (made on
    first use when the evaluation came from a model's cost path: ``_residual`` is then a
    callable).

    ``jacobian`` is dR/dz (m, n) when the point was run with exact sensitivities.
    """

    x: np.ndarray
    cost: float
    _residual: np.ndarray | Callable[[], np.ndarray] | None
    ok: bool
    feasible: bool
    message: str = ""
    cached: bool = False
    wall_s: float = 0.0
    jacobian: np.ndarray | None = None
    plain_wall_s: float | None = None

    @property
    def residual(self) -> np.ndarray | None:
        r = self._residual
        if callable(r):
            r = r()
            object.__setattr__(self, "_residual", r)
        return r

    @property
    def usable(self) -> bool:
        """Feasible and successfully evaluated (a sampler's ``log p`` is finite only then)."""
        return self.ok and self.feasible


class Evaluator:
    """Counting, caching, budgeted evaluation of a least-squares problem (a solver's objective).

    problem  : the :class:`LeastSquaresProblem`
    mapper   : ``mapper(fn, items) -> iterable`` used for every batch; ``None`` = sequential
    cache    : True (unbounded), False, or an int (keep the most recent ``cache`` points)
    exact_jacobian : use the model's exact Jacobian when it provides one (else finite differences)
    budget_unit : what :meth:`set_budget` caps: ``"evaluations"`` (``n_evals``) or
                  ``"forward-equivalents"`` (:meth:`nominal_equivalents`)
    jacobian_cost : nominal forward-equivalents of one response + exact Jacobian (default: the
                  model's declared ``jacobian_cost``, else DEFAULT_JACOBIAN_COST); >= 1
    cost_path : plain evaluations of a model offering ``misfit_of`` take its cost path (see the
                  module docstring)
    free_repeats : serve repeated points free (FE economy) instead of charging them (COCO's
                  rule, the default); see the module docstring

    ``observers`` (a list) holds callables ``observer(evaluator, evaluation)`` called after each
    recorded evaluation (progress bars, live logs); they must not raise.
    """

    def __init__(
        self,
        problem: LeastSquaresProblem,
        *,
        mapper: Mapper | None = None,
        cache: bool | int = True,
        exact_jacobian: bool = True,
        budget_unit: str = "evaluations",
        jacobian_cost: float | None = None,
        cost_path: bool = True,
        free_repeats: bool = False,
    ):
        if budget_unit not in BUDGET_UNITS:
            raise ValueError(
                f"budget_unit = {budget_unit!r} is unknown; allowed: {', '.join(BUDGET_UNITS)}"
            )
        if jacobian_cost is None:
            jacobian_cost = getattr(problem.model, "jacobian_cost", None) or DEFAULT_JACOBIAN_COST
        if not (math.isfinite(float(jacobian_cost)) and float(jacobian_cost) >= 1.0):
            raise ValueError(
                f"jacobian_cost = {jacobian_cost!r} is out of range: a number >= 1 "
                "(forward-equivalents of a response + Jacobian)"
            )
        self.problem = problem
        # a scalar objective (problems.user.ScalarProblem): the cost is the model's one value f
        # and the "residual" kept is [f] (what finite differences difference), not a residual
        self.scalar = bool(getattr(problem, "scalar", False))
        self.mapper = mapper
        self.cache = cache
        self.exact_jacobian = exact_jacobian and provides_jacobian(problem.model)
        self.budget_unit = budget_unit
        self.jacobian_cost = float(jacobian_cost)
        self.free_repeats = bool(free_repeats)
        self._warned = False
        self.charges: dict[str, dict[str, float]] = {}
        self.observers: list = []
        make = getattr(problem.model, "misfit_of", None) if cost_path else None
        self._misfit = make(problem) if make is not None else None
        self.reset()

    # --- the problem, as a solver sees it --------------------------------------------------------
    model = property(lambda self: self.problem.model)
    data = property(lambda self: self.problem.data)
    names = property(lambda self: self.problem.names)
    reference = property(lambda self: self.problem.reference)
    lower = property(lambda self: self.problem.lower)
    upper = property(lambda self: self.problem.upper)
    lower_z = property(lambda self: self.problem.lower_z)
    upper_z = property(lambda self: self.problem.upper_z)
    blocks = property(lambda self: self.problem.blocks)
    n_params = property(lambda self: self.problem.n_params)
    n_residuals = property(lambda self: self.problem.n_residuals)
    provenance = property(lambda self: self.problem.provenance)
    data_hash = property(lambda self: self.problem.provenance.get("data_hash"))

    def to_physical(self, z) -> np.ndarray:
        return self.problem.to_physical(z)

    def to_scaled(self, x) -> np.ndarray:
        return self.problem.to_scaled(x)

    def whiten(self, d) -> np.ndarray:
        return self.problem.whiten(d)

    # --- bookkeeping -----------------------------------------------------------------------------
    def reset(self) -> None:
        """Clear counters, log, cache, best point and budget."""
        self.n_evals = 0
        self.n_failed = 0
        self.n_infeasible = 0
        self.n_cache_hits = 0
        self.n_repeats = 0  # charged calls served from the cache (in n_evals)
        self.n_jacobian_failures = 0
        self.n_jacobian_runs = 0  # new evaluations run with exact sensitivities
        self._nominal = 0.0
        self.log: list[dict[str, Any]] = []
        self.trace: list[list[float]] = []
        self.best: Evaluation | None = None
        self._cache: OrderedDict[bytes, Evaluation] = OrderedDict()
        self.budget: float | None = None

    def set_budget(self, n: float | None) -> None:
        """Cap the spent budget (:attr:`spent`, in ``budget_unit``) at ``n`` (``None``: no cap).
        In evaluations the cap is a whole number; in forward-equivalents any number >= 0."""
        if n is not None and not float(n) >= 0:
            raise ValueError(f"budget = {n} is out of range: must be >= 0")
        if n is None:
            self.budget = None
        else:
            self.budget = int(n) if self.budget_unit == "evaluations" else float(n)

    @property
    def spent(self) -> float:
        """The budget used so far, in ``budget_unit``: ``n_evals`` or the nominal
        forward-equivalents."""
        return self.n_evals if self.budget_unit == "evaluations" else self._nominal

    @property
    def remaining(self) -> float:
        """Plain forward evaluations that still fit in the budget (``inf`` without budget); in
        forward-equivalents the whole number of them (a Jacobian run needs ``jacobian_cost``)."""
        if self.budget is None:
            return math.inf
        if self.budget_unit == "evaluations":
            return max(0, self.budget - self.n_evals)
        return max(0, math.floor(self.budget - self._nominal + 1e-9))

    @property
    def repeats_rule(self) -> str:
        """``"charged"`` (every call counts, the default) or ``"free"`` (``free_repeats``)."""
        return "free" if self.free_repeats else "charged"

    def charge_of(self, kind: str, feasible: bool = True) -> float:
        """Nominal forward-equivalents of one new evaluation: ``jacobian_cost`` for a feasible
        run with sensitivities (``kind = "jacobian"``), 1 for everything else."""
        return self.jacobian_cost if (kind == "jacobian" and feasible) else 1.0

    def counters(self) -> dict[str, float]:
        return {
            "n_evals": self.n_evals,
            "n_failed": self.n_failed,
            "n_infeasible": self.n_infeasible,
            "n_cache_hits": self.n_cache_hits,
            "n_repeats": self.n_repeats,
            "forward_equivalents": self.forward_equivalents(),
            "nominal_equivalents": self.nominal_equivalents(),
            "n_jacobian_runs": self.n_jacobian_runs,
        }

    def charge(self, kind: str, n: int, wall_s: float) -> None:
        """Record ``n`` runs of ``kind`` (e.g. ``"hifi"``, ``"training"``) taking ``wall_s`` s in
        all."""
        c = self.charges.setdefault(kind, {"n": 0, "wall_s": 0.0})
        c["n"] += int(n)
        c["wall_s"] += float(wall_s)

    def _unit_s(self) -> float | None:
        """Median wall time of this evaluator's successful plain runs, s (the forward-equivalent);
        without any, the median plain part of its runs with sensitivities (``plain_wall_s``, when
        the model reports it)."""
        new = [e for e in self.log if not e["cached"] and e["ok"] and e["feasible"]]
        plain = [e["wall_s"] for e in new if e["kind"] == "plain"]
        if not plain:
            plain = [e["plain_wall_s"] for e in new if e.get("plain_wall_s")]
        return float(np.median(plain)) if plain else None

    def charged_equivalents(self) -> dict[str, float]:
        """Each charged kind in forward-equivalents (its wall time over the plain-run median)."""
        unit = self._unit_s()
        return {k: (c["wall_s"] / unit if unit else float(c["n"])) for k, c in self.charges.items()}

    def forward_equivalents(self) -> float:
        """Evaluations in plain-forward-run units (runs with sensitivities weighted by wall
        time). Without a successful plain run to measure against (a method that only ever asks
        for Jacobians) the runs' own plain parts are the unit, and without those a run with
        sensitivities counts its nominal ``jacobian_cost``. A charged repeat counts what the
        evaluation it repeats counted."""
        paid = [e for e in self.log if e["charged"]]
        unit = self._unit_s()
        total = 0.0
        for e in paid:
            if e["kind"] == "jacobian" and e["ok"]:
                wall = e["source_wall_s"] if e["cached"] else e["wall_s"]
                total += wall / unit if unit else self.jacobian_cost
            else:
                total += 1.0
        return total

    def nominal_equivalents(self) -> float:
        """Evaluations in nominal forward-equivalents: ``jacobian_cost`` per feasible run with
        exact sensitivities, 1 per other evaluation (charged repeats included, free cache hits
        excluded). Deterministic."""
        return self._nominal

    @property
    def best_z(self) -> np.ndarray | None:
        return None if self.best is None else self.to_scaled(self.best.x)

    # --- evaluation ------------------------------------------------------------------------------
    def _finish(self, x: np.ndarray, res: ForwardResult) -> Evaluation:
        if not res.ok:
            return self._failure(x, res.message or "forward model failed", res.wall_s)
        r, why = self.problem.residual(res.values)
        if r is None:
            return self._failure(x, why, res.wall_s)
        J = None if res.jacobian is None else self.problem.residual_jacobian(res.jacobian)
        cost = float(r[0]) if self.scalar else float(r @ r)
        return Evaluation(
            x, cost, r, True, True, res.message, False, res.wall_s, J, res.plain_wall_s
        )

    def _failure(self, x, message, wall_s=0.0, feasible=True) -> Evaluation:
        if message.startswith("model raised") and not self._warned:
            self._warned = True
            warnings.warn(
                f"forward model raised an exception, treated as a failed point: {message}",
                RuntimeWarning,
                stacklevel=3,
            )
        return Evaluation(
            x,
            FAILURE_COST,
            self.problem.failure_residual.copy(),
            False,
            feasible,
            message,
            False,
            wall_s,
        )

    def _record(
        self, ev: Evaluation, key: bytes | None, kind: str, charged: bool = True, source_wall_s=0.0
    ) -> None:
        if ev.cached:
            self.n_cache_hits += 1
        if charged:
            self.n_evals += 1
            self._nominal += self.charge_of(kind, ev.feasible)
        if ev.cached:
            self.n_repeats += int(charged)
        else:
            if kind == "jacobian" and ev.feasible:
                self.n_jacobian_runs += 1
            if not ev.feasible:
                self.n_infeasible += 1
            elif not ev.ok:
                self.n_failed += 1
            if self.cache and key is not None:
                self._cache[key] = ev
                if not isinstance(self.cache, bool) and len(self._cache) > int(self.cache):
                    self._cache.popitem(last=False)
            if ev.ok and ev.feasible and (self.best is None or ev.cost < self.best.cost):
                self.best = ev
                self.trace.append([self.n_evals, ev.cost])
        self.log.append(
            {
                "x": ev.x,
                "cost": ev.cost,
                "ok": ev.ok,
                "feasible": ev.feasible,
                "wall_s": ev.wall_s,
                "cached": ev.cached,
                "charged": charged,
                "n_evals": self.n_evals,
                "kind": kind,
                "plain_wall_s": None if ev.cached else ev.plain_wall_s,
                **({"source_wall_s": source_wall_s} if ev.cached and charged else {}),
            }
        )
        for observe in self.observers:
            observe(self, ev)

    def evaluate_many(
        self, Z, *, with_jacobian: bool = False, reuse: bool = False
    ) -> list[Evaluation]:
        """Evaluate a batch of scaled points; the uncached feasible ones go through one mapper call.

        Order of the log = order of ``Z``. A point already evaluated (or earlier in ``Z``) is
        served from the cache, charged unless ``free_repeats`` or ``reuse`` (the wrapper asking
        again for a value it holds, not a call of the method). If the budget does not cover
        every charged point, the first ones that fit are evaluated and recorded, then
        :class:`BudgetExhausted` is raised. ``with_jacobian`` runs the model with exact
        sensitivities (only a cached evaluation that already has them is reused).
        """
        fast = self._misfit is not None and not with_jacobian
        prepared = self.problem.classify(Z, check=not fast)
        keys = [x.tobytes() for x, _ in prepared]
        kind = "jacobian" if with_jacobian else "plain"
        # per point: None (new), a cached Evaluation, or the index of its first copy in Z
        source: list[Evaluation | int | None] = []
        first: dict[bytes, int] = {}
        for i, key in enumerate(keys):
            cached = self._cache.get(key) if self.cache else None
            if cached is not None and (
                not with_jacobian or cached.jacobian is not None or not cached.usable
            ):
                source.append(cached)
                self._cache.move_to_end(key)
            elif self.cache and key in first:
                source.append(first[key])
            else:
                source.append(None)
                first[key] = i
        free = self.free_repeats or reuse

        def feasible(i: int) -> bool:
            src = source[i]
            if isinstance(src, Evaluation):
                return src.feasible
            return prepared[i if src is None else src][1] is None

        charged = [i for i in range(len(keys)) if source[i] is None or not free]
        fits = self._fitting([self.charge_of(kind, feasible(i)) for i in charged])
        allowed = set(charged[:fits])
        todo = [i for i in range(len(keys)) if source[i] is None and i in allowed]
        run_idx = [i for i in todo if prepared[i][1] is None]
        done: dict[int, Evaluation] = {}
        if run_idx:
            points = [prepared[i][0] for i in run_idx]
            run = self._cost_path if fast else partial(self._run, with_jacobian=with_jacobian)
            done.update(zip(run_idx, run(points)))
        for i in todo:
            if i not in done:
                done[i] = self._failure(prepared[i][0], prepared[i][1], feasible=False)
        out: list[Evaluation] = []
        for i, src in enumerate(source):
            pay = i in allowed
            if src is None:
                if not pay:
                    continue  # left out by the budget
                ev = done[i]
                self._record(ev, keys[i], kind)
            else:
                if isinstance(src, int):
                    if src not in done:
                        continue  # repeat of a point left out by the budget
                    src = done[src]
                if not (pay or free):
                    continue  # a charged repeat left out by the budget
                ev = replace(src, cached=True, wall_s=0.0)
                self._record(ev, None, kind, charged=pay, source_wall_s=src.wall_s)
            out.append(ev)
        if len(allowed) < len(charged):
            raise BudgetExhausted(self.budget, self.n_evals, self.budget_unit)
        return out

    def _run(self, points, with_jacobian: bool = False) -> list[Evaluation]:
        """Evaluations of feasible ``points`` by the model's call, in one mapper call."""
        mapper = self.mapper or sequential_map
        results = list(mapper(RunModel(self.model, with_jacobian), points))
        if len(results) != len(points):
            raise RuntimeError(f"mapper returned {len(results)} results for {len(points)} points")
        return [self._finish(x, res) for x, res in zip(points, results)]

    def _cost_path(self, points) -> list[Evaluation]:
        """Plain evaluations of in-box ``points`` by the model's cost path (the model's rule
        decides feasibility); on any exception the path is dropped for good (warned once) and
        the points are classified and run as for any model."""
        t0 = time.perf_counter()
        try:
            costs, A, reasons = self._misfit(np.array(points))
            notes = self._misfit.messages(points)
        except Exception as exc:  # never into the solver: the exact path decides
            warnings.warn(
                f"the model's cost path failed ({type(exc).__name__}: {exc}); using its call",
                RuntimeWarning,
                stacklevel=3,
            )
            self._misfit = None
            out: list[Evaluation | None] = [None] * len(points)
            feasible = []
            for k, x in enumerate(points):
                why = self.problem.check(x)
                if why is None:
                    feasible.append(k)
                else:
                    out[k] = self._failure(x, why, feasible=False)
            for k, ev in zip(feasible, self._run([points[k] for k in feasible])):
                out[k] = ev
            return out
        each = (time.perf_counter() - t0) / len(points)
        residual = self._misfit.residual
        out = []
        for x, cost, a, why, note in zip(points, costs, A, reasons, notes):
            if why is not None:
                out.append(self._failure(x, why, feasible=False))
            elif not math.isfinite(cost):
                out.append(self._failure(x, "non-finite cost", each))
            else:
                ev = Evaluation(x, float(cost), partial(residual, a), True, True, note, False, each)
                out.append(ev)
        return out

    def _fitting(self, charges: list[float]) -> int:
        """How many of the next new evaluations, with these nominal charges, fit in the budget."""
        if self.budget is None:
            return len(charges)
        if self.budget_unit == "evaluations":
            return min(len(charges), max(0, self.budget - self.n_evals))
        spent, k = self._nominal, 0
        for c in charges:
            if spent + c > self.budget + 1e-9:
                break
            spent += c
            k += 1
        return k

    def evaluate(self, z, *, with_jacobian: bool = False, reuse: bool = False) -> Evaluation:
        """Evaluate one scaled point (cache first; counts and budget as documented; ``reuse``:
        a cached point is served free, see :meth:`evaluate_many`)."""
        return self.evaluate_many(
            np.asarray(z, dtype=float).reshape(1, -1), with_jacobian=with_jacobian, reuse=reuse
        )[0]

    def cost(self, z) -> float:
        return self.evaluate(z).cost

    def residual(self, z) -> np.ndarray:
        return self.evaluate(z).residual.copy()

    def costs(self, Z) -> np.ndarray:
        """Costs of a batch of scaled points (one mapper call for the uncached ones)."""
        return np.array([ev.cost for ev in self.evaluate_many(Z)])

    def cost_split(self, z) -> dict[str, float]:
        """Cost per named block plus ``"total"``; blocks are ``nan`` for a failed/infeasible
        point (a reuse: free when ``z`` was evaluated)."""
        ev = self.evaluate(z, reuse=True)
        if not ev.usable:
            return {**{name: math.nan for name in self.blocks}, "total": ev.cost}
        return {**self.problem.split(ev.residual), "total": ev.cost}

    # --- derivatives -----------------------------------------------------------------------------
    def fd_rel_step(self, scheme: str = "forward", rel_step: float | None = None) -> float:
        """The relative finite-difference step of ``scheme``: ``rel_step`` when given (> 0), else
        the model's declared ``fd_rel_step[scheme]``, else :data:`FD_REL_STEP` (scipy's)."""
        if rel_step is not None:
            ok = isinstance(rel_step, (int, float)) and math.isfinite(rel_step) and rel_step > 0
            if not ok:
                raise ValueError(f"rel_step = {rel_step!r} is out of range: a number > 0 (or None)")
            return float(rel_step)
        declared = getattr(self.model, "fd_rel_step", None) or {}
        return float(declared.get(scheme, FD_REL_STEP[scheme]))

    def jacobian(
        self, z, *, scheme: str = "forward", rel_step: float | None = None, r0=None
    ) -> np.ndarray:
        """Jacobian ``dR/dz`` (m, n) of the whitened residual: exact when the model provides it
        (one run with sensitivities, ``scheme`` ignored), else by finite differences.

        Finite differences: step ``h_i = rel_step * |z_i|`` (``rel_step`` where ``z_i = 0``),
        relative as scipy and MINPACK make it, so that a parameter far from its reference scale
        loses no digits; ``rel_step`` defaults to :meth:`fd_rel_step`. A step that would leave the
        box is flipped inward (``central`` falls back to a one-sided inward difference there). All
        columns are one batch. A column whose point failed is retried once on the other side; if
        that fails too, the column is set to zero and ``n_jacobian_failures`` is incremented. If
        ``z`` itself failed, the Jacobian is zero (nothing sensible can be differenced).
        """
        if scheme not in ("forward", "central"):
            raise ValueError(f"scheme = {scheme!r} is unknown; allowed: forward, central")
        z = np.clip(np.asarray(z, dtype=float).ravel(), self.lower_z, self.upper_z)
        if self.exact_jacobian:  # the Jacobian at z: a reuse when z was run with it
            ev = self.evaluate(z, with_jacobian=True, reuse=True)
            if ev.usable and ev.jacobian is not None:
                return ev.jacobian.copy()
            if not ev.usable:
                return np.zeros((self.n_residuals, self.n_params))
        return self._fd_jacobian(z, scheme, rel_step, r0)

    def _fd_jacobian(self, z, scheme, rel_step, r0) -> np.ndarray:
        n, m = self.n_params, self.n_residuals
        if r0 is None:
            ev0 = self.evaluate(z, reuse=True)
            if not ev0.usable:
                return np.zeros((m, n))
            r0 = ev0.residual
        r0 = np.asarray(r0, dtype=float)
        rel_step = self.fd_rel_step(scheme, rel_step)
        h = rel_step * np.where(z != 0, np.abs(z), 1.0)
        up_room, down_room = self.upper_z - z, z - self.lower_z
        plus = np.where(
            h <= up_room, h, np.where(down_room >= up_room, -np.minimum(h, down_room), up_room)
        )
        central = scheme == "central"
        pts, cols = [], []
        for i in range(n):
            if central and h[i] <= up_room[i] and h[i] <= down_room[i]:
                pts += [_shift(z, i, h[i]), _shift(z, i, -h[i])]
                cols.append((i, "c"))
            else:
                pts.append(_shift(z, i, plus[i]))
                cols.append((i, "f"))
        evs = self.evaluate_many(np.array(pts))
        J = np.zeros((m, n))
        k, retry = 0, []
        for i, kind in cols:
            if kind == "c":
                ea, eb = evs[k], evs[k + 1]
                k += 2
                if ea.usable and eb.usable:
                    J[:, i] = (ea.residual - eb.residual) / (
                        self.to_scaled(ea.x)[i] - self.to_scaled(eb.x)[i]
                    )
                    continue
                good = ea if ea.usable else (eb if eb.usable else None)
                if good is not None:
                    J[:, i] = (good.residual - r0) / (self.to_scaled(good.x)[i] - z[i])
                else:
                    self.n_jacobian_failures += 1
                continue
            ev = evs[k]
            k += 1
            dz = self.to_scaled(ev.x)[i] - z[i]
            if ev.usable and dz != 0:
                J[:, i] = (ev.residual - r0) / dz
            else:
                retry.append((i, -plus[i]))
        todo = []
        for i, s in retry:
            if self.lower_z[i] <= z[i] + s <= self.upper_z[i]:
                todo.append((i, s))
            else:
                self.n_jacobian_failures += 1
        if todo:
            evs = self.evaluate_many(np.array([_shift(z, i, s) for i, s in todo]))
            for (i, _), ev in zip(todo, evs):
                dz = self.to_scaled(ev.x)[i] - z[i]
                if ev.usable and dz != 0:
                    J[:, i] = (ev.residual - r0) / dz
                else:
                    self.n_jacobian_failures += 1
        return J

    def gradient(self, z, *, reuse: bool = False, **kw) -> tuple[float, np.ndarray]:
        """``cost`` and its gradient ``2 J^T R`` in z (through :meth:`jacobian`); of a scalar
        problem, ``df/dz`` (the one row of the value's Jacobian). The point itself is a call of
        the method (charged, also when repeated) unless ``reuse`` (a library asking for the
        gradient at the point whose cost it just had); the columns are charged as in
        :meth:`jacobian`."""
        ev = self.evaluate(z, with_jacobian=self.exact_jacobian, reuse=reuse)
        if not ev.usable:
            return ev.cost, np.zeros(self.n_params)
        J = ev.jacobian if ev.jacobian is not None else self.jacobian(z, r0=ev.residual, **kw)
        if self.scalar:
            return ev.cost, J[0].copy()
        return ev.cost, 2.0 * J.T @ ev.residual


def _shift(z, i, s):
    p = z.copy()
    p[i] = z[i] + s
    return p

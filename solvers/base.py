"""One interface over every method: :func:`solve`, the registry :data:`METHODS`, the budget guard.

A method is a function ``run(r: Run) -> Outcome`` registered with :func:`register`. It works in
the objective's scaled space ``z = x / reference`` (``r.z0``, ``r.lower``, ``r.upper``), calls the
objective (its only source of evaluations), records one history row per iteration or generation
with :meth:`Run.record`, and returns an :class:`Outcome` (status, message, iterations, extra).

:func:`solve` does everything else, identically for all methods:

* resets the objective (counters, log, cache, best point) and sets its budget: the objective
  raises :class:`~problems.inverse.evaluator.BudgetExhausted` rather than exceed it; :func:`solve`
  catches it (status ``"budget"``) and returns the best point so far;
* the final point is the best (lowest-cost, successful, feasible) point the objective evaluated
  during the run; if there is none, the status is ``"failed"`` and ``x = x0``, ``cost = inf``;
* the counts come from the objective's own counters (never from the library), the wall time
  from a clock around the run;
* the seed: ``seed=None`` draws one from OS entropy and records it, so every run can be
  replayed; libraries that use NumPy's global generator are run inside :func:`isolated_global_rng`.

``x0`` is physical; ``None`` means the centre of the box (not the reference, which is the answer
on the analytic problems; where a bound is infinite, the reference clipped into the box). A start
outside the box raises ``ValueError``; a global or sampling method on a box with an infinite
bound is refused (:func:`finite_box_error`).

``success`` is true when the status is ``"converged"``, and also for global and sampling methods
when they stopped at their budget or generation limit (their normal end), except the
least-squares hybrids of :data:`OPTIMALITY_TESTED` (converged only).
"""

from __future__ import annotations

import contextlib
import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from problems.inverse.evaluator import BudgetExhausted, Evaluator
from problems.io import jsonio
from solvers.options import Option
from solvers.result import RunResult

FAMILIES = ("local", "global", "sampling")

#: Methods that need residuals (least squares) or a likelihood; they refuse a scalar objective
#: (problems.user.ScalarProblem), whose cost is f itself
LEAST_SQUARES_ONLY = ("lm", "lm-minpack", "trf", "gauss-newton", "multistart-lm", "pso+lm", "mcmc")
STATUSES = ("converged", "budget", "max_iterations", "failed", "stalled")

#: Methods whose status comes from the first-order test of :mod:`solvers.optimality`: their
#: success is ``converged`` only, whatever their family (a multistart that spent its budget
#: has not succeeded unless its best point passes the test)
OPTIMALITY_TESTED = ("lm", "lm-minpack", "trf", "gauss-newton", "multistart-lm", "pso+lm")


def finite_box_error(info: "MethodInfo", objective) -> str | None:
    """Why ``info``'s method cannot run on ``objective``'s box, or None: the global and sampling
    methods search or sample the box (uniform populations, Latin hypercubes, box-relative step
    sizes), so they need every bound finite; the local methods work with infinite bounds
    (``lm-minpack`` refuses finite ones itself)."""
    if info.family == "local":
        return None
    lo, hi = np.asarray(objective.lower, float), np.asarray(objective.upper, float)
    bad = ~(np.isfinite(lo) & np.isfinite(hi))
    if not bad.any():
        return None
    i = int(np.flatnonzero(bad)[0])
    return (
        f"method {info.name!r} searches the box and needs finite bounds; "
        f"{objective.names[i]} has [{lo[i]:g}, {hi[i]:g}] (use a local method: lm, trf, "
        "lm-minpack, gauss-newton, nlopt:BOBYQA, ...)"
    )


def default_start(objective) -> np.ndarray:
    """The physical start used when ``x0`` is None: the centre of the box where both bounds of a
    parameter are finite, else its reference clipped into the box."""
    lo, hi = objective.lower, objective.upper
    finite = np.isfinite(lo) & np.isfinite(hi)
    with np.errstate(invalid="ignore"):
        centre = 0.5 * (lo + hi)
    return np.where(finite, centre, np.clip(objective.reference, lo, hi))


@dataclass(frozen=True)
class MethodInfo:
    """A registered method: its library, family and declared options ``name ->``
    :class:`~solvers.options.Option`."""

    name: str
    library: str
    family: str
    options: dict[str, Option]
    run: Callable[["Run"], "Outcome"]
    stochastic: bool = False
    description: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "library": self.library,
            "family": self.family,
            "stochastic": self.stochastic,
            "description": self.description,
            "options": {k: opt.to_dict() for k, opt in self.options.items()},
        }


@dataclass
class Outcome:
    """What a method reports back to :func:`solve` (counts and final point come from the
    objective)."""

    status: str = "converged"
    message: str = ""
    n_iterations: int | None = None
    extra: dict[str, Any] = field(default_factory=dict)


METHODS: dict[str, MethodInfo] = {}
_RESOLVERS: list[Callable[[str], MethodInfo | None]] = []  # dynamic names, e.g. nlopt:<ANY>


def register(
    name: str,
    *,
    library: str,
    family: str,
    options: dict[str, Option] | None = None,
    stochastic: bool = False,
    description: str = "",
):
    """Decorator adding ``run`` to :data:`METHODS` under ``name``; ``options`` declared with
    :mod:`solvers.options`."""
    if family not in FAMILIES:
        raise ValueError(f"family {family!r} is unknown; allowed: {', '.join(FAMILIES)}")
    bad = [k for k, v in (options or {}).items() if not isinstance(v, Option)]
    if bad:
        raise TypeError(f"{name}: options {bad} are not declared as solvers.options.Option")

    def deco(run):
        METHODS[name] = MethodInfo(
            name, library, family, dict(options or {}), run, stochastic, description
        )
        return run

    return deco


def register_resolver(resolve: Callable[[str], MethodInfo | None]) -> None:
    """Add a resolver of dynamic method names (e.g. any ``nlopt:<ALGORITHM>``) to
    :func:`get_method`."""
    _RESOLVERS.append(resolve)


def find_method(name: str) -> MethodInfo | None:
    """The method ``name`` (registered or resolved), or None when it is unknown."""
    try:
        return get_method(name)
    except ValueError:
        return None


def get_method(name: str) -> MethodInfo:
    """The registered method ``name`` (or one resolved dynamically, e.g. any
    ``nlopt:<ALGORITHM>``)."""
    if name in METHODS:
        return METHODS[name]
    for resolve in _RESOLVERS:
        info = resolve(name)
        if info is not None:
            return info
    raise ValueError(
        f"solver {name!r} is unknown; allowed: {', '.join(sorted(METHODS))} "
        "(and any nlopt:<ALGORITHM>)"
    )


@dataclass
class Run:
    """The context a method runs in: objective, start, seed, budget, options and the history."""

    objective: Evaluator
    method: str
    z0: np.ndarray
    seed: int
    budget: int
    options: dict[str, Any]
    history: list[dict[str, Any]] = field(default_factory=list)
    phase: str | None = None
    _iteration: list[int] = field(default_factory=lambda: [0])  # shared with sub-runs

    @property
    def lower(self) -> np.ndarray:
        return self.objective.lower_z

    @property
    def upper(self) -> np.ndarray:
        return self.objective.upper_z

    @property
    def n_iterations(self) -> int:
        return self._iteration[0]

    def rng(self, stream: int = 0) -> np.random.Generator:
        """A generator derived from the run's seed (``stream`` separates independent uses)."""
        return np.random.default_rng([self.seed, stream])

    def record(self, z=None, cost: float | None = None, **more) -> None:
        """Append one history row (one per iteration/generation); ``z`` is the current point."""
        obj = self.objective
        self._iteration[0] += 1
        best = obj.best
        row = {
            "iteration": self._iteration[0],
            "n_evals": obj.n_evals,
            "best_cost": best.cost if best is not None else math.inf,
            "cost": math.inf if cost is None else float(cost),
            "x": [] if z is None else [float(v) for v in obj.to_physical(z)],
        }
        if self.phase:
            row["phase"] = self.phase
        row.update({k: jsonio.plain(v) for k, v in more.items()})
        self.history.append(row)

    def record_log(self, start: int = 0) -> None:
        """One history row per new (uncached) evaluation in ``objective.log[start:]``."""
        obj = self.objective
        best = math.inf
        for row in self.history:
            best = min(best, row["best_cost"])
        for entry in obj.log[start:]:
            if entry["cached"]:
                continue
            if entry["ok"] and entry["feasible"]:
                best = min(best, entry["cost"])
            self._iteration[0] += 1
            row = {
                "iteration": self._iteration[0],
                "n_evals": entry["n_evals"],
                "best_cost": best,
                "cost": entry["cost"],
                "x": [float(v) for v in entry["x"]],
            }
            if self.phase:
                row["phase"] = self.phase
            self.history.append(row)

    def sub(
        self,
        method: str,
        z0,
        budget: int,
        options: dict[str, Any] | None = None,
        phase: str | None = None,
    ) -> Outcome:
        """Run another registered method as a phase, capped at ``budget`` more evaluations (in the
        objective's ``budget_unit``: evaluations or nominal forward-equivalents).

        The phase shares the objective, the history and the iteration counter. If the phase uses
        up its share, it ends with status ``"budget"``; if the *whole* budget is spent,
        :class:`BudgetExhausted` propagates to :func:`solve`.
        """
        info = get_method(method)
        opts = resolve_options(info, options or {}, strict=False)
        obj = self.objective
        outer = obj.budget
        share = max(0, int(budget)) if obj.budget_unit == "evaluations" else max(0.0, budget)
        cap = obj.spent + share  # in the objective's budget unit
        obj.set_budget(cap if outer is None else min(outer, cap))
        child = Run(
            obj,
            method,
            np.asarray(z0, float),
            self.seed,
            int(budget),
            opts,
            self.history,
            phase or method,
            self._iteration,
        )
        try:
            out = info.run(child)
        except BudgetExhausted as exc:
            if outer is not None and outer - obj.spent < 1.0 - 1e-9:  # not one more run fits
                raise
            out = Outcome("budget", str(exc))
        finally:
            obj.set_budget(outer)
        return out


def resolve_options(
    info: MethodInfo, options: dict[str, Any], strict: bool = True
) -> dict[str, Any]:
    """Defaults overridden by ``options``; unknown names and values the method's declaration does
    not allow (:meth:`solvers.options.Option.error`) raise ``ValueError`` (unknown names are
    dropped when not ``strict``)."""
    unknown = set(options) - set(info.options)
    if unknown and strict:
        raise ValueError(
            f"{info.name}: unknown option(s) {sorted(unknown)}; allowed: {sorted(info.options)}"
        )
    if strict:
        for k, v in options.items():
            opt = info.options[k]
            why = opt.error(v)
            if why:
                raise ValueError(
                    f"{info.name}: option {k} = {why}; allowed: {opt.range_text()} "
                    f"(default {opt.default!r}: {opt.help})"
                )
    out = {k: opt.default for k, opt in info.options.items()}
    out.update({k: v for k, v in options.items() if k in info.options})
    return out


@contextlib.contextmanager
def isolated_global_rng(seed: int):
    """Seed NumPy's *global* generator for a library that uses it, and restore it afterwards."""
    state = np.random.get_state()
    np.random.seed(seed % 2**32)
    try:
        yield
    finally:
        np.random.set_state(state)


def solve(
    objective: Evaluator, method: str, *, budget: int, seed: int | None = 0, x0=None, **options
) -> RunResult:
    """Minimise ``objective`` with ``method`` within ``budget`` forward evaluations.

    ``x0`` is physical (``None``: centre of the box). Options are the method's (see
    ``METHODS[method].options``); unknown options raise ``ValueError``. See the module docstring.
    """
    info = get_method(method)
    if getattr(objective, "scalar", False) and info.name in LEAST_SQUARES_ONLY:
        raise ValueError(
            f"method {info.name!r} needs a least-squares problem (residuals); this problem is a "
            "scalar objective f(x): use a global or derivative-free method"
        )
    opts = resolve_options(info, options)
    why = finite_box_error(info, objective)
    if why:
        raise ValueError(why)
    budget = int(budget)
    if budget < 1:
        raise ValueError(f"budget must be at least 1 forward evaluation, got {budget}")
    if seed is None:
        seed = int(np.random.SeedSequence().entropy % 2**32)
    seed = int(seed)
    obj = objective
    if x0 is None:
        x0 = default_start(obj)
    x0 = np.asarray(x0, dtype=float).ravel()
    if x0.size != obj.n_params:
        raise ValueError(
            f"x0 has {x0.size} values, expected {obj.n_params} ({', '.join(obj.names)})"
        )
    if not np.all(np.isfinite(x0)):
        raise ValueError(f"x0 must be finite, got {x0.tolist()}")
    span = obj.upper - obj.lower
    if np.any(x0 < obj.lower - 1e-9 * span) or np.any(x0 > obj.upper + 1e-9 * span):
        raise ValueError(
            "x0 lies outside the bounds: "
            + "; ".join(
                f"{n} = {v:g} is outside [{lo:g}, {hi:g}]"
                for n, v, lo, hi, w in zip(obj.names, x0, obj.lower, obj.upper, span)
                if not lo - 1e-9 * w <= v <= hi + 1e-9 * w
            )
        )
    x0 = np.clip(x0, obj.lower, obj.upper)

    obj.reset()
    obj.set_budget(budget)
    run = Run(
        obj, info.name if method == info.name else method, obj.to_scaled(x0), seed, budget, opts
    )
    t0 = time.perf_counter()
    try:
        out = info.run(run)
    except BudgetExhausted as exc:
        out = Outcome("budget", str(exc))
    finally:
        obj.set_budget(None)
    wall = time.perf_counter() - t0

    status, message = out.status, out.message
    if status not in STATUSES:
        raise RuntimeError(f"{method}: invalid status {status!r}")
    best = obj.best
    if best is None:
        x, cost = x0.copy(), math.inf
        last = next((e for e in reversed(obj.log) if not e["ok"] or not e["feasible"]), None)
        status = "failed"
        message = (
            "no successful evaluation"
            + (f"; {message}" if message else "")
            + (f" (last failure at x = {np.asarray(last['x']).tolist()})" if last else "")
        )
    else:
        x, cost = best.x.copy(), best.cost
    success = status == "converged" or (
        info.family != "local"
        and info.name not in OPTIMALITY_TESTED
        and status in ("budget", "max_iterations")
    )
    extra = {k: jsonio.plain(v) for k, v in out.extra.items()}
    if obj.n_jacobian_failures:
        extra["n_jacobian_failures"] = obj.n_jacobian_failures
    if obj.n_jacobian_runs:
        extra["n_jacobian_runs"] = obj.n_jacobian_runs
        extra["jacobian_cost"] = obj.jacobian_cost
    return RunResult(
        method=run.method,
        options={k: jsonio.plain(v) for k, v in opts.items()},
        seed=seed,
        budget=budget,
        parameter_names=list(obj.names),
        reference=[float(v) for v in obj.reference],
        x0=[float(v) for v in x0],
        x=[float(v) for v in x],
        x_normalised=[float(v) for v in obj.to_scaled(x)],
        cost=float(cost),
        status=status,
        success=bool(success),
        message=message,
        n_evals=obj.n_evals,
        n_failed=obj.n_failed,
        n_infeasible=obj.n_infeasible,
        n_cache_hits=obj.n_cache_hits,
        n_repeats=obj.n_repeats,
        repeats=obj.repeats_rule,
        n_iterations=int(out.n_iterations if out.n_iterations is not None else run.n_iterations),
        wall_s=wall,
        forward_equivalents=obj.forward_equivalents(),
        forward_equivalents_nominal=obj.nominal_equivalents(),
        budget_unit=obj.budget_unit,
        charges={
            k: {**c, "forward_equivalents": obj.charged_equivalents()[k]}
            for k, c in obj.charges.items()
        },
        provenance=jsonio.plain(dict(obj.provenance)),
        history=run.history,
        trace=[[int(n), float(c)] for n, c in obj.trace],
        extra=extra,
    )


def lhs(n: int, lower, upper, rng: np.random.Generator) -> np.ndarray:
    """``n`` Latin-hypercube points in the box, shape (n, d)."""
    from scipy.stats import qmc

    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    unit = qmc.LatinHypercube(d=lower.size, seed=rng).random(n)
    return lower + unit * (upper - lower)

"""The pluggable weighted least-squares objective (it knows nothing of FE).

A :class:`ForwardModel` maps physical parameters ``x`` to a predicted measurement vector
``U_N(x)``; the :class:`Objective` compares it with the data ``U_E``::

    R(x) = C^(-1/2) (U_E - U_N(x)),     cost(x) = R^T R

with ``C`` diagonal (``sigma``: scalar or vector of standard deviations) or full
(``covariance``; its lower Cholesky factor ``L`` is used, ``R = L^-1 (U_E - U_N)``, so that
``R^T R = d^T C^-1 d``). ``blocks`` names slices of the measurement vector so that the cost can be
split (:meth:`Objective.cost_split`); with a full covariance the split is that of the
Cholesky-whitened residual (it still sums to the total).

Solvers work in the *scaled* space ``z = x / reference`` (the reference is ``z = 1``); every
public method of :class:`Objective` takes ``z``.

Accounting (honest: what a user pays for)
-----------------------------------------
* ``n_evals`` counts every forward evaluation: finite-difference columns, failed points
  (``ok=False``) and infeasible points (``check`` returned a message, or the point lies outside
  the box; the model is *not* called, but the point still counts, and is also counted in
  ``n_infeasible``). ``n_failed`` counts the ``ok=False`` results.
* Exact repeats of a point already evaluated are served from a cache; they are counted apart in
  ``n_cache_hits`` and are *not* in ``n_evals``, nor charged to the budget.
* ``log`` holds one dict per evaluation, cache hits included (``cached=True``):
  ``{"x", "cost", "ok", "feasible", "wall_s", "cached", "n_evals"}`` (``n_evals`` = the counter
  after that entry).
* ``set_budget(n)``: an evaluation that would make ``n_evals`` exceed ``n`` raises
  :class:`BudgetExhausted`; for a batch, the points that fit are evaluated and recorded first.
  ``best`` (the lowest-cost successful point so far) lets any solver return a result then.

Failure policy (never raise into a solver)
------------------------------------------
A failed point (the model returned ``ok=False``, non-finite or wrongly shaped values, or raised)
and an infeasible point get ``cost = FAILURE_COST`` (1e12: finite, so that population methods can
rank it) and a residual vector whose squared norm equals ``FAILURE_COST`` (so that a trust-region
method rejects the step and shrinks its radius; a line search backtracks). Samplers treat these
points as ``log p = -inf`` (see ``Evaluation.ok`` / ``feasible``). Such points are never ``best``.
A model that *raises* is treated as failed with the exception text as message (and a
``RuntimeWarning`` is issued once per objective), because an exception inside a solver loop would
lose the whole run.

Batches and parallelism
-----------------------
:meth:`Objective.costs`, :meth:`Objective.evaluate_many` and :meth:`Objective.jacobian` send all
uncached feasible points of one batch through a single ``mapper(fn, items)`` call (``fn`` is a
picklable callable wrapping the model, ``items`` the physical points); ``mapper=None`` is the
built-in sequential ``map``. A Dask mapper is e.g.
``lambda fn, items: client.gather(client.map(fn, items, pure=False))``. ``check`` always runs in
the calling process.
"""
from __future__ import annotations

import math
import time
import warnings
from collections import OrderedDict
from dataclasses import dataclass, replace
from typing import Any, Callable, Iterable, Protocol, Sequence, runtime_checkable

import numpy as np
from scipy.linalg import cholesky, solve_triangular

FAILURE_COST = 1e12
"""Cost given to failed and infeasible points (finite, far above any sensible cost)."""

BOX_TOL = 1e-9
"""Points outside the box by less than ``BOX_TOL * (upper - lower)`` are clipped, not rejected."""

Mapper = Callable[[Callable[[np.ndarray], "ForwardResult"], Sequence[np.ndarray]], Iterable["ForwardResult"]]


@dataclass(frozen=True)
class ForwardResult:
    """What a forward model returns for one point."""

    ok: bool
    values: np.ndarray | None  # predicted measurement vector U_N(x), same layout as the data
    message: str = ""
    wall_s: float = 0.0


@runtime_checkable
class ForwardModel(Protocol):
    """Anything picklable with ``names``, ``check`` and ``__call__`` (it is shipped to workers)."""

    names: tuple[str, ...]

    def check(self, x: np.ndarray) -> str | None:
        """``None`` if the physical point ``x`` is feasible, else the reason (cheap, no FE)."""
        ...

    def __call__(self, x: np.ndarray) -> ForwardResult:
        """Evaluate at physical ``x``; never raises for non-convergence (``ok=False`` instead)."""
        ...


class BudgetExhausted(Exception):
    """Raised by the objective when an evaluation would exceed the budget."""

    def __init__(self, budget: int, n_evals: int):
        super().__init__(f"evaluation budget of {budget} forward evaluations exhausted ({n_evals} used)")
        self.budget = budget
        self.n_evals = n_evals


@dataclass(frozen=True)
class Evaluation:
    """One evaluated point. ``x`` is physical; ``residual`` is the whitened residual."""

    x: np.ndarray
    cost: float
    residual: np.ndarray | None
    ok: bool
    feasible: bool
    message: str = ""
    cached: bool = False
    wall_s: float = 0.0

    @property
    def usable(self) -> bool:
        """Feasible and successfully evaluated (a sampler's ``log p`` is finite only then)."""
        return self.ok and self.feasible


class RunModel:
    """Picklable wrapper shipped through the mapper: times the call, turns exceptions into failures."""

    def __init__(self, model: ForwardModel):
        self.model = model

    def __call__(self, x: np.ndarray) -> ForwardResult:
        t0 = time.perf_counter()
        try:
            res = self.model(np.array(x, dtype=float))
        except Exception as exc:  # a crash inside the model must not kill the solver loop
            return ForwardResult(False, None, f"model raised {type(exc).__name__}: {exc}",
                                 time.perf_counter() - t0)
        if not isinstance(res, ForwardResult):
            return ForwardResult(False, None, f"model returned {type(res).__name__}, not ForwardResult",
                                 time.perf_counter() - t0)
        if not res.wall_s:
            res = replace(res, wall_s=time.perf_counter() - t0)
        return res


def _sequential_map(fn, items):
    return [fn(x) for x in items]


class Objective:
    """Weighted least-squares objective over a forward model, in the scaled space ``z = x / reference``.

    Parameters
    ----------
    model : ForwardModel
    data : (m,) measured vector ``U_E`` (same layout as the model's values)
    lower, upper, reference : (n,) physical bounds and reference values (reference != 0)
    sigma : scalar or (m,) standard deviations (diagonal covariance); default 1
    covariance : (m, m) full covariance (exclusive with ``sigma``)
    blocks : names of slices of the measurement vector, for :meth:`cost_split`
    mapper : ``mapper(fn, items) -> iterable`` used for every batch; ``None`` = sequential
    cache : True (unbounded), False, or an int (keep the most recent ``cache`` points)
    """

    def __init__(self, model: ForwardModel, data, *, lower, upper, reference, sigma=None,
                 covariance=None, blocks: dict[str, slice] | None = None, mapper: Mapper | None = None,
                 cache: bool | int = True):
        self.model = model
        self.data = np.asarray(data, dtype=float).ravel()
        m = self.data.size
        if m == 0:
            raise ValueError("Objective: the data vector is empty")
        self.names = tuple(getattr(model, "names", ()))
        self.reference = np.asarray(reference, dtype=float).ravel().copy()
        self.lower = np.asarray(lower, dtype=float).ravel().copy()
        self.upper = np.asarray(upper, dtype=float).ravel().copy()
        n = self.reference.size
        if not self.names:
            self.names = tuple(f"x{i}" for i in range(n))
        if not (len(self.names) == self.lower.size == self.upper.size == n):
            raise ValueError(f"Objective: names {self.names}, lower, upper and reference must have the same "
                             f"length (got {len(self.names)}, {self.lower.size}, {self.upper.size}, {n})")
        if np.any(self.reference == 0) or not np.all(np.isfinite(self.reference)):
            raise ValueError("Objective: reference values must be finite and non-zero (z = x / reference)")
        if np.any(self.lower > self.upper):
            raise ValueError("Objective: lower bound above upper bound")
        zl, zu = self.lower / self.reference, self.upper / self.reference
        self.lower_z, self.upper_z = np.minimum(zl, zu), np.maximum(zl, zu)

        if sigma is not None and covariance is not None:
            raise ValueError("Objective: give sigma or covariance, not both")
        self._chol = None
        self._sigma = None
        if covariance is not None:
            cov = np.asarray(covariance, dtype=float)
            if cov.shape != (m, m):
                raise ValueError(f"Objective: covariance must be ({m}, {m}), got {cov.shape}")
            try:
                self._chol = cholesky(cov, lower=True)
            except np.linalg.LinAlgError as exc:
                raise ValueError(f"Objective: covariance is not positive definite ({exc})") from None
        else:
            s = np.ones(m) if sigma is None else np.broadcast_to(np.asarray(sigma, dtype=float), (m,)).copy()
            if np.any(s <= 0) or not np.all(np.isfinite(s)):
                raise ValueError("Objective: sigma must be positive and finite")
            self._sigma = s

        self.blocks = dict(blocks) if blocks else {"all": slice(0, m)}
        for name, sl in self.blocks.items():
            if not isinstance(sl, slice) or len(range(m)[sl]) == 0:
                raise ValueError(f"Objective: block {name!r} must be a non-empty slice of the {m} measurements")
        self.mapper = mapper
        self.cache = cache
        self._runner = RunModel(model)
        self._failure_residual = np.full(m, math.sqrt(FAILURE_COST / m))
        self._warned = False
        self.budget: int | None = None
        self.reset()

    # --- shape and scaling -----------------------------------------------------------------
    @property
    def n_params(self) -> int:
        return self.reference.size

    @property
    def n_residuals(self) -> int:
        return self.data.size

    def to_physical(self, z) -> np.ndarray:
        return np.asarray(z, dtype=float) * self.reference

    def to_scaled(self, x) -> np.ndarray:
        return np.asarray(x, dtype=float) / self.reference

    def whiten(self, d: np.ndarray) -> np.ndarray:
        """``C^(-1/2) d`` (``L^-1 d`` for a full covariance); ``d`` is (m,) or (m, k)."""
        d = np.asarray(d, dtype=float)
        if self._chol is not None:
            return solve_triangular(self._chol, d, lower=True)
        return d / (self._sigma[:, None] if d.ndim == 2 else self._sigma)

    # --- bookkeeping -----------------------------------------------------------------------
    def reset(self) -> None:
        """Clear counters, log, cache, best point and budget."""
        self.n_evals = 0
        self.n_failed = 0
        self.n_infeasible = 0
        self.n_cache_hits = 0
        self.n_jacobian_failures = 0
        self.log: list[dict[str, Any]] = []
        self.best: Evaluation | None = None
        self._cache: OrderedDict[bytes, Evaluation] = OrderedDict()
        self.budget = None

    def set_budget(self, n: int | None) -> None:
        """Cap ``n_evals`` at ``n`` (``None``: no cap)."""
        if n is not None and int(n) < 0:
            raise ValueError(f"budget must be >= 0, got {n}")
        self.budget = None if n is None else int(n)

    @property
    def remaining(self) -> float:
        """Forward evaluations left in the budget (``inf`` without budget)."""
        return math.inf if self.budget is None else max(0, self.budget - self.n_evals)

    def counters(self) -> dict[str, int]:
        return {"n_evals": self.n_evals, "n_failed": self.n_failed, "n_infeasible": self.n_infeasible,
                "n_cache_hits": self.n_cache_hits}

    @property
    def best_z(self) -> np.ndarray | None:
        return None if self.best is None else self.to_scaled(self.best.x)

    # --- evaluation ------------------------------------------------------------------------
    def _prepare_many(self, Z: np.ndarray) -> list[tuple[np.ndarray, str | None]]:
        """Physical points (clipped within tolerance) and why each is infeasible, if it is."""
        if Z.ndim != 2 or Z.shape[1] != self.n_params:
            raise ValueError(f"expected {self.n_params} parameters {self.names}, got shape {Z.shape[1:]}")
        X = Z * self.reference
        tol = BOX_TOL * np.maximum(self.upper - self.lower, np.abs(self.reference) * 1e-12)
        finite = np.all(np.isfinite(X), axis=1)
        out = (X < self.lower - tol) | (X > self.upper + tol)
        Xc = np.clip(X, self.lower, self.upper)
        prepared = []
        for k in range(len(X)):
            if not finite[k]:
                prepared.append((X[k].copy(), "non-finite parameters"))
            elif out[k].any():
                bad = ", ".join(f"{self.names[i]}={X[k, i]:.6g}" for i in np.flatnonzero(out[k]))
                prepared.append((X[k].copy(), f"outside the bounds: {bad}"))
            else:
                x = Xc[k].copy()
                try:
                    msg = self.model.check(x)
                except Exception as exc:
                    msg = f"check raised {type(exc).__name__}: {exc}"
                prepared.append((x, msg))
        return prepared

    def _finish(self, x: np.ndarray, res: ForwardResult) -> Evaluation:
        if not res.ok or res.values is None:
            return self._failure(x, res.message or "forward model failed", res.wall_s)
        values = np.asarray(res.values, dtype=float).ravel()
        if values.shape != self.data.shape:
            return self._failure(x, f"model returned {values.size} values, data has {self.data.size}", res.wall_s)
        if not np.all(np.isfinite(values)):
            return self._failure(x, "model returned non-finite values", res.wall_s)
        r = self.whiten(self.data - values)
        cost = float(r @ r)
        if not math.isfinite(cost):
            return self._failure(x, "non-finite cost", res.wall_s)
        return Evaluation(x, cost, r, True, True, res.message, False, res.wall_s)

    def _failure(self, x, message, wall_s=0.0, feasible=True) -> Evaluation:
        if message.startswith("model raised") and not self._warned:
            self._warned = True
            warnings.warn(f"forward model raised an exception, treated as a failed point: {message}",
                          RuntimeWarning, stacklevel=3)
        return Evaluation(x, FAILURE_COST, self._failure_residual.copy(), False, feasible, message, False, wall_s)

    def _record(self, ev: Evaluation, key: bytes | None) -> None:
        if ev.cached:
            self.n_cache_hits += 1
        else:
            self.n_evals += 1
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
        self.log.append({"x": ev.x, "cost": ev.cost, "ok": ev.ok, "feasible": ev.feasible,
                         "wall_s": ev.wall_s, "cached": ev.cached, "n_evals": self.n_evals})

    def evaluate_many(self, Z) -> list[Evaluation]:
        """Evaluate a batch of scaled points; the uncached feasible ones go through one mapper call.

        Order of the log = order of ``Z``. If the budget does not cover every new point, the first
        ones that fit are evaluated and recorded, then :class:`BudgetExhausted` is raised.
        """
        Z = np.atleast_2d(np.asarray(Z, dtype=float))
        prepared = self._prepare_many(Z)
        keys = [x.tobytes() for x, _ in prepared]
        hits: dict[int, Evaluation | int] = {}  # index -> cached Evaluation, or index of its first copy
        new: list[int] = []  # indices that need a new evaluation
        first: dict[bytes, int] = {}
        for i, key in enumerate(keys):
            if self.cache and key in self._cache:
                hits[i] = self._cache[key]
                self._cache.move_to_end(key)
            elif self.cache and key in first:
                hits[i] = first[key]
            else:
                new.append(i)
                first[key] = i
        allowed = len(new) if self.budget is None else max(0, self.budget - self.n_evals)
        todo = new[:allowed]
        run_idx = [i for i in todo if prepared[i][1] is None]
        done: dict[int, Evaluation] = {}
        if run_idx:
            mapper = self.mapper or _sequential_map
            results = list(mapper(self._runner, [prepared[i][0] for i in run_idx]))
            if len(results) != len(run_idx):
                raise RuntimeError(f"mapper returned {len(results)} results for {len(run_idx)} points")
            for i, res in zip(run_idx, results):
                done[i] = self._finish(prepared[i][0], res)
        for i in todo:
            if i not in done:
                done[i] = self._failure(prepared[i][0], prepared[i][1], feasible=False)
        out: list[Evaluation] = []
        for i in range(len(prepared)):
            if i in done:
                ev = done[i]
                self._record(ev, keys[i])
            elif i in hits:
                src = hits[i]
                if isinstance(src, int):
                    if src not in done:
                        continue  # repeat of a point left out by the budget
                    src = done[src]
                ev = replace(src, cached=True, wall_s=0.0)
                self._record(ev, None)
            else:
                continue  # left out by the budget
            out.append(ev)
        if len(new) > allowed:
            raise BudgetExhausted(self.budget, self.n_evals)
        return out

    def evaluate(self, z) -> Evaluation:
        """Evaluate one scaled point (cache first; counts and budget as documented)."""
        return self.evaluate_many(np.asarray(z, dtype=float).reshape(1, -1))[0]

    def cost(self, z) -> float:
        return self.evaluate(z).cost

    def residual(self, z) -> np.ndarray:
        return self.evaluate(z).residual.copy()

    def costs(self, Z) -> np.ndarray:
        """Costs of a batch of scaled points (one mapper call for the uncached ones)."""
        return np.array([ev.cost for ev in self.evaluate_many(Z)])

    def cost_split(self, z) -> dict[str, float]:
        """Cost per named block plus ``"total"``; blocks are ``nan`` for a failed/infeasible point."""
        ev = self.evaluate(z)
        if not ev.usable:
            return {**{name: math.nan for name in self.blocks}, "total": ev.cost}
        return {**{name: float(ev.residual[sl] @ ev.residual[sl]) for name, sl in self.blocks.items()},
                "total": ev.cost}

    # --- derivatives -----------------------------------------------------------------------
    def jacobian(self, z, *, scheme: str = "forward", rel_step: float = 1e-6, r0=None) -> np.ndarray:
        """Finite-difference Jacobian ``dR/dz`` of the whitened residual, shape (m, n).

        Step ``h_i = rel_step * max(|z_i|, 1)``; a step that would leave the box is flipped inward
        (``central`` falls back to a one-sided inward difference there). All columns are one batch.
        A column whose point failed is retried once on the other side (another batch); if that
        fails too, the column is set to zero and ``n_jacobian_failures`` is incremented. If ``z``
        itself failed, the Jacobian is zero (nothing sensible can be differenced).
        """
        if scheme not in ("forward", "central"):
            raise ValueError(f"scheme must be 'forward' or 'central', got {scheme!r}")
        z = np.clip(np.asarray(z, dtype=float).ravel(), self.lower_z, self.upper_z)
        n, m = self.n_params, self.n_residuals
        if r0 is None:
            ev0 = self.evaluate(z)
            if not ev0.usable:
                return np.zeros((m, n))
            r0 = ev0.residual
        r0 = np.asarray(r0, dtype=float)
        h = rel_step * np.maximum(np.abs(z), 1.0)
        up_room, down_room = self.upper_z - z, z - self.lower_z
        # columns: list of (index, +step, -step or None); -step None means one-sided
        plus = np.where(h <= up_room, h, np.where(down_room >= up_room, -np.minimum(h, down_room), up_room))
        central = scheme == "central"
        pts, cols = [], []
        for i in range(n):
            if central and h[i] <= up_room[i] and h[i] <= down_room[i]:
                pts += [self._shift(z, i, h[i]), self._shift(z, i, -h[i])]
                cols.append((i, "c"))
            else:
                pts.append(self._shift(z, i, plus[i]))
                cols.append((i, "f"))
        evs = self.evaluate_many(np.array(pts))
        J = np.zeros((m, n))
        k, retry = 0, []
        for i, kind in cols:
            if kind == "c":
                ea, eb = evs[k], evs[k + 1]
                k += 2
                if ea.usable and eb.usable:
                    J[:, i] = (ea.residual - eb.residual) / (self.to_scaled(ea.x)[i] - self.to_scaled(eb.x)[i])
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
            evs = self.evaluate_many(np.array([self._shift(z, i, s) for i, s in todo]))
            for (i, _), ev in zip(todo, evs):
                dz = self.to_scaled(ev.x)[i] - z[i]
                if ev.usable and dz != 0:
                    J[:, i] = (ev.residual - r0) / dz
                else:
                    self.n_jacobian_failures += 1
        return J

    @staticmethod
    def _shift(z, i, s):
        p = z.copy()
        p[i] = z[i] + s
        return p

    def gradient(self, z, **kw) -> tuple[float, np.ndarray]:
        """``cost`` and its gradient ``2 J^T R`` in z (through :meth:`jacobian`)."""
        ev = self.evaluate(z)
        if not ev.usable:
            return ev.cost, np.zeros(self.n_params)
        J = self.jacobian(z, r0=ev.residual, **kw)
        return ev.cost, 2.0 * J.T @ ev.residual

"""nevergrad adapter: ``ngopt`` (Nevergrad's ``NGOpt`` portfolio optimiser).

``NGOpt`` picks an algorithm (or a chain of them) from the dimension, the budget, the number of
workers and the kind of parametrization (see below). It is a reference "what would a generic
black-box optimiser do" method rather than a tuned one.

The parametrization is ``ng.p.Array`` on the unit box ``u in [0, 1]^n`` mapped affinely onto the
scaled box ``z = lower + u (upper - lower)`` (one step scale for all parameters); it is seeded
through ``parametrization.random_state``. Its initial value is a seeded uniform point of the box
(the start point with ``include_x0``, like the other population methods). NGOpt 1.0's choice for a
few bounded continuous parameters: with one worker, ``Cobyla`` (a deterministic local method, whose
trajectory then depends on the seed only through that point) up to a budget of ``50 n``, above it
a quadratic-surrogate-assisted CMA (``MetaModel`` over ``CmaFmin2``); with more workers,
``MetaModel`` (CMA-ES) at any budget. ``extra["optimizer"]`` records the choice. Candidates are
asked in batches of ``num_workers``: each batch is one :meth:`Evaluator.costs` call
(one history row per batch), then told. Points are clipped to the box (a no-op for nevergrad's
bounded arrays, kept against rounding). Failed and infeasible points are told ``FAILURE_COST``
(1e12).

Nevergrad's own ``budget`` is set to the run's budget; cache hits (repeated points) are free, so
asking goes on until the objective's budget is spent, up to ``max_asks_factor`` times the budget
(then status ``stalled``).

Seeding: besides ``parametrization.random_state``, the run is wrapped in
:func:`~solvers.base.isolated_global_rng`, because some of NGOpt's members draw from NumPy's global
generator. One of them, ``CmaFmin2`` (NGOpt's choice for a few hundred evaluations in 2-5
dimensions with one worker), calls ``cma.fmin`` on a background thread without a seed, which
seeds cma from the clock: during the run ``cma.fmin`` is wrapped to pass a seed drawn from the run's
seed when none is given. The thread (cma's sampling, nevergrad's restart points) and the main thread
(NGOpt's quadratic surrogate, whose inner Powell/DE optimisers seed themselves from NumPy's global
generator) both draw from that global generator; nevergrad lets the thread compute its next point
while the main thread goes on, so the order of the draws depended on thread scheduling and a loaded
machine gave a different trajectory for the same seed. During the run a ``tell`` to such a
thread therefore waits until the thread has posted its next point (or ended), see
:func:`_synchronous_recast`: the thread and the main thread never run at the same time.
"""

from __future__ import annotations

import contextlib
import warnings

import numpy as np

from problems.inverse.evaluator import BudgetExhausted
from solvers.base import Outcome, Run, isolated_global_rng, register
from solvers.options import choice, count, flag, nonnegative

NGOPT_OPTIONS = {
    "num_workers": count(
        1,
        "candidates asked per batch (one objective.costs call each; NGOpt adapts its choice to it)",
    ),
    "optimizer": choice(
        "NGOpt", "nevergrad optimizer name from ng.optimizers.registry (NGOpt: the portfolio)"
    ),
    "include_x0": flag(
        False, "start nevergrad at the start point (False: at a seeded uniform point of the box)"
    ),
    "max_asks_factor": nonnegative(
        3, "stop (stalled) after max_asks_factor * budget asks (repeated points are free)", "int"
    ),
}


@register(
    "ngopt",
    library="nevergrad",
    family="global",
    options=NGOPT_OPTIONS,
    stochastic=True,
    description="Nevergrad's NGOpt portfolio (chooses e.g. surrogate-assisted CMA, DE, Cobyla "
    "from dimension, budget and workers)",
)
def run_ngopt(r: Run) -> Outcome:
    o = r.options
    width = r.upper - r.lower
    workers = max(1, int(o["num_workers"]))
    if o["include_x0"]:
        u0 = np.clip((r.z0 - r.lower) / width, 0.0, 1.0)
    else:
        u0 = r.rng(2).uniform(0.0, 1.0, r.lower.size)
    with (
        isolated_global_rng(r.seed),
        _seeded_cma_fmin(r.rng(3)),
        _synchronous_recast(),
        warnings.catch_warnings(),
    ):
        warnings.simplefilter("ignore")  # nevergrad warns about settings and bad tells
        import nevergrad as ng

        if o["optimizer"] not in ng.optimizers.registry:
            raise ValueError(f"ngopt: optimizer {o['optimizer']!r} is not in nevergrad's registry")
        param = ng.p.Array(init=u0, lower=0.0, upper=1.0)
        param.random_state = np.random.RandomState(int(r.rng(1).integers(2**31 - 1)))
        opt = ng.optimizers.registry[o["optimizer"]](
            parametrization=param, budget=r.budget, num_workers=workers
        )
        try:
            return _ask_and_tell(r, opt, workers, width, o)
        finally:
            _stop_threads(opt)  # no recast thread may outlive the run (see _stop_threads)


def _ask_and_tell(r: Run, opt, workers: int, width, o) -> Outcome:
    obj = r.objective
    chosen = _chosen(opt)
    extra = {"optimizer": chosen}
    max_asks = int(o["max_asks_factor"]) * r.budget
    asks, batches = 0, 0
    while obj.remaining > 0:
        if asks >= max_asks:
            return Outcome(
                "stalled", f"{asks} asks gave only {obj.n_evals} new points", batches, extra
            )
        k = int(min(workers, obj.remaining))
        cands = [opt.ask() for _ in range(k)]
        asks += k
        Z = np.clip(r.lower + np.array([c.value for c in cands]) * width, r.lower, r.upper)
        try:
            f = obj.costs(Z)
        except BudgetExhausted as exc:  # cannot happen (k <= remaining) unless the budget moved
            return Outcome("budget", str(exc), batches, extra)
        for c, fc in zip(cands, f):
            opt.tell(c, float(fc))
        batches += 1
        j = int(np.argmin(f))
        r.record(Z[j], f[j], batch=batches)
    extra["optimizer"] = _chosen(opt)
    return Outcome(
        "budget",
        f"evaluation budget spent after {batches} batches of up to {workers}",
        batches,
        extra,
    )


def _stop_threads(opt, depth: int = 4) -> None:
    """Stop and join the background threads of the recast optimizers inside ``opt`` (NGOpt's
    CmaFmin2 runs ``cma.fmin`` on one). Left alive, a thread waits for its next ``tell`` until the
    optimizer is garbage-collected, at some later moment, when it wakes and runs on inside cma,
    drawing from NumPy's global generator while another run uses it: the same seed then gave
    different results."""
    from nevergrad.optimization import base

    seen, todo = set(), [(opt, 0)]
    while todo:
        obj, d = todo.pop()
        if id(obj) in seen or d > depth:
            continue
        seen.add(id(obj))
        thread = getattr(obj, "_messaging_thread", None)
        if thread is not None:
            thread.stop()
            inner = getattr(thread, "_thread", None)
            if inner is not None:
                inner.join(timeout=10.0)
        for value in vars(obj).values():
            items = value if isinstance(value, (list, tuple)) else [value]
            todo.extend((v, d + 1) for v in items if isinstance(v, base.Optimizer))


@contextlib.contextmanager
def _seeded_cma_fmin(rng: np.random.Generator):
    """Within the block, ``cma.fmin`` without a ``seed`` option gets one drawn from ``rng``."""
    import cma

    original = cma.fmin

    def fmin(*args, **kwargs):
        if len(args) < 4:  # options passed by keyword (as nevergrad does), or not at all
            options = dict(kwargs.get("options") or {})
            if options.get("seed") in (None, 0, "time"):
                options["seed"] = int(rng.integers(1, 2**31 - 1))
            kwargs["options"] = options
        return original(*args, **kwargs)

    cma.fmin = fmin
    try:
        yield
    finally:
        cma.fmin = original


@contextlib.contextmanager
def _synchronous_recast():
    """Within the block, a ``tell`` to a nevergrad optimizer that runs a library on a background
    thread (``SequentialRecastOptimizer``: CmaFmin2, Powell, Cobyla, ...) returns only once that
    thread has posted its next point, its end or its error: the thread's computation (and its draws
    from NumPy's global generator) happens while the main thread waits, never alongside it.

    Safe: ``_internal_tell_candidate`` is called only for a point the thread asked for, so a living
    thread is blocked on that answer and posts exactly one message after it; the message is taken
    and put back on the (otherwise empty) queue, where the next ``ask`` reads it."""
    from nevergrad.optimization.recaster import SequentialRecastOptimizer

    original = SequentialRecastOptimizer._internal_tell_candidate

    def tell(self, candidate, loss):
        thread = self._messaging_thread
        alive = thread is not None and thread.is_alive()
        original(self, candidate, loss)
        if alive:
            queue = thread.messages_ask
            queue.put(queue.get())

    SequentialRecastOptimizer._internal_tell_candidate = tell
    try:
        yield
    finally:
        SequentialRecastOptimizer._internal_tell_candidate = original


def _chosen(opt) -> str:
    """The algorithm NGOpt delegated to (its own name for other optimizers)."""
    info = getattr(opt, "_info", None)
    if callable(info):
        try:
            sub = info().get("sub-optim")
            if sub:
                return str(sub)
        except Exception:  # private API: best effort, for the record only
            pass
    return type(opt).__name__

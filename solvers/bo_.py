"""scikit-optimize adapter: ``bo`` (Bayesian optimisation: GP surrogate + expected improvement).

For expensive objectives with small budgets (tens to ~200 forward evaluations): every new point
is chosen by maximising an acquisition function (expected improvement by default) of a Gaussian
process fitted to *all* points evaluated so far.

* Space: the unit box ``u in [0, 1]^n`` mapped affinely onto the scaled box
  ``z = lower + u (upper - lower)``; suggestions are clipped to it (a no-op, against rounding).
* Initial design: a seeded Latin hypercube of ``n_initial`` points (default ``4 n``), evaluated as
  one :meth:`Evaluator.costs` batch (``include_x0`` puts the start point in it). Then one point per
  iteration, one history row each.
* Surrogate: scikit-optimize's default GP — constant x Matern-5/2 kernel with one length scale per
  parameter, a learned white-noise term, ``normalize_y`` — on the cost itself (``transform=none``)
  or on ``log1p``: ``ln(1 + cost / cost_scale)`` (logarithmic far above ``cost_scale``, linear
  below it, so that the zero-cost optimum of noise-free data is no ``-inf`` spike; ``cost_scale``
  is the number of residuals — the expected cost at the truth for consistent noise — or the
  running ``median`` cost) or ``log``: ``ln(cost)``. The costs span three decades and more over
  the box, yet on the analytic problems the untransformed cost found better points in 100
  evaluations than either logarithm (docs/solvers.md): a stationary GP smooths the deep, narrow
  funnel of a log-cost and the learned noise term absorbs it. Hence the default ``none``.
* Failed and infeasible points (cost ``FAILURE_COST``) are given the worst transformed value of
  the successful points plus ``failure_penalty`` (recomputed at every iteration): a large but
  finite value that keeps the GP well scaled while steering away from the failing region.
* A suggestion that repeats an evaluated point (a free cache hit, which would not advance the
  run) is replaced by a seeded uniform point in the box.
* The GP hyperparameters are re-optimised every ``refit_every`` iterations and kept in between
  (a refit with fixed hyperparameters is one Cholesky factorisation); the acquisition search scores
  ``n_points`` random points and polishes the ``n_restarts`` best with L-BFGS-B.
* The surrogate costs O(k^3) in the number k of points (the acquisition search O(k^2) per
  prediction), about 0.1-0.5 s per iteration up to k ~ 100 on one core: the run stops after
  ``max_evals`` evaluations (status ``max_iterations``) even if the budget is larger. The GP runs
  with BLAS limited to one thread (tiny matrices: threads only contend, 3x slower on two busy
  cores).

Seeding: the design from the run's seed, and every scikit-optimize ``Optimizer`` (a fresh one per
iteration, fitted on all points, so that failure substitutes can follow the worst cost) gets a
``random_state`` drawn from a seeded generator; the GP and acquisition steps run inside
:func:`~solvers.base.isolated_global_rng` (scikit-learn/scikit-optimize draw from NumPy's global
generator in places: without it, equal seeds gave different points).
"""

from __future__ import annotations

import warnings

import numpy as np

from solvers.base import Outcome, Run, isolated_global_rng, lhs, register
from solvers.options import Option, choice, count, flag, nonnegative, number

BO_OPTIONS = {
    "n_initial": count(
        None, "Latin-hypercube points of the initial design (None: 4 n, n = number of parameters)"
    ),
    "include_x0": flag(False, "put the start point into the initial design"),
    "acq_func": choice(
        "EI",
        "acquisition: EI (expected improvement) | PI | LCB | gp_hedge",
        ("EI", "PI", "LCB", "gp_hedge"),
    ),
    "xi": nonnegative(0.01, "EI/PI exploration margin, in units of the transformed cost"),
    "kappa": nonnegative(1.96, "LCB exploration weight"),
    "transform": choice(
        "none",
        "surrogate target: none = cost | log1p = ln(1 + cost/cost_scale) | log = ln(cost)",
        ("none", "log1p", "log"),
    ),
    "cost_scale": Option(
        "float",
        None,
        "cost_scale of log1p: a cost | median (running median cost) | None (number of residuals)",
        low=0.0,
        low_open=True,
        strings=("median",),
    ),
    "failure_penalty": number(
        1.0, "failed points: worst transformed cost so far + failure_penalty"
    ),
    "acq_optimizer": choice(
        "lbfgs",
        "acquisition search: lbfgs (random points + L-BFGS-B polish) | sampling",
        ("lbfgs", "sampling"),
    ),
    "n_points": count(2000, "random points scored per acquisition search"),
    "n_restarts": count(2, "L-BFGS-B starts of the acquisition search (lbfgs; at least 1)"),
    "gp_restarts": nonnegative(
        1, "random restarts of the GP hyperparameter (marginal likelihood) fit", "int"
    ),
    "refit_every": count(
        5,
        "fit the GP hyperparameters at every refit_every-th iteration; in between keep them",
    ),
    "noise": Option(
        "float",
        "gaussian",
        "GP noise: gaussian (a learned white-noise level) | a fixed variance (of the normalised "
        "target)",
        low=0.0,
        strings=("gaussian",),
    ),
    "max_evals": count(
        200, "stop after this many evaluations (the GP costs O(k^3)); None: the budget"
    ),
}


def _transform(cost: np.ndarray, how: str, scale: float) -> np.ndarray:
    if how == "log1p":
        return np.log1p(cost / scale)
    if how == "log":
        return np.log(cost + 1e-300)
    if how == "none":
        return cost.copy()
    raise ValueError(f"bo: transform {how!r} is unknown; allowed: log1p, log, none")


@register(
    "bo",
    library="scikit-optimize",
    family="global",
    options=BO_OPTIONS,
    stochastic=True,
    description="Bayesian optimisation: GP (Matern 5/2) surrogate, expected improvement, "
    "Latin-hypercube start; for small budgets (<= ~200 evaluations)",
)
def run_bo(r: Run) -> Outcome:
    obj, o = r.objective, r.options
    n = r.lower.size
    width = r.upper - r.lower
    how = str(o["transform"])
    scale = "median" if o["cost_scale"] == "median" else float(o["cost_scale"] or obj.n_residuals)
    _transform(np.ones(1), how, 1.0)  # unknown transform: ValueError before any evaluation
    cap = r.budget if o["max_evals"] is None else min(r.budget, int(o["max_evals"]))
    n_init = max(1, min(int(o["n_initial"] or 4 * n), cap))
    rng = r.rng(2)

    U0 = (lhs(n_init, r.lower, r.upper, r.rng(1)) - r.lower) / width
    if o["include_x0"]:
        U0[0] = np.clip((r.z0 - r.lower) / width, 0.0, 1.0)
    U: list[np.ndarray] = []  # every point told to the surrogate (unit box)
    C: list[float] = []  # its cost
    ok: list[bool] = []  # successful and feasible

    def evaluate(Ub: np.ndarray) -> None:
        Z = np.clip(r.lower + Ub * width, r.lower, r.upper)
        evs = obj.evaluate_many(Z)  # BudgetExhausted (budget < n_initial) ends the run in solve()
        U.extend(np.clip((Z - r.lower) / width, 0.0, 1.0))
        C.extend(ev.cost for ev in evs)
        ok.extend(ev.usable for ev in evs)
        c = np.array([ev.cost for ev in evs])
        j = int(np.argmin(c))
        r.record(Z[j], c[j], n_points=len(C))

    evaluate(U0)
    iterations, hyper = 0, None
    while obj.n_evals < cap:
        seed = int(rng.integers(2**31 - 1))
        if iterations % max(1, int(o["refit_every"])) == 0:
            hyper = None  # fit the hyperparameters afresh
        u, hyper = _suggest(np.array(U), np.array(C), np.array(ok), o, how, scale, seed, hyper)
        u = np.clip(u, 0.0, 1.0)
        if _is_cached(obj, np.clip(r.lower + u * width, r.lower, r.upper)):
            u = rng.uniform(0.0, 1.0, n)  # a repeat is charged for nothing new: explore instead
        before = obj.n_evals
        evaluate(u[None, :])
        iterations += 1
        if obj.n_evals == before and iterations > 10 * cap:  # guard; repeats are replaced above
            return Outcome("stalled", "suggestions only repeat evaluated points", iterations)
    if cap < r.budget:
        return Outcome(
            "max_iterations",
            f"max_evals = {cap} evaluations (the surrogate grows as k^3)",
            iterations,
        )
    return Outcome(
        "budget", f"evaluation budget spent after {iterations} surrogate iterations", iterations
    )


def _is_cached(obj, z) -> bool:
    """Whether the scaled point ``z`` was evaluated already (it would be a cache hit)."""
    x = obj.to_physical(z)
    return any(np.array_equal(x, e["x"]) for e in obj.log)


def _suggest(
    U: np.ndarray, C: np.ndarray, ok: np.ndarray, o: dict, how: str, scale, seed: int, hyper=None
):
    """Next point (unit box) from a GP fitted to all points ``U`` with costs ``C`` (``ok``: usable).

    ``hyper``: ``(kernel, noise)`` of an earlier fit to keep (no hyperparameter optimisation), or
    ``None`` to fit them. Returns the point and the ``hyper`` of this GP.
    """
    from sklearn.gaussian_process.kernels import Sum, WhiteKernel
    from skopt import Optimizer
    from threadpoolctl import threadpool_limits

    y = np.empty_like(C)
    if ok.any():
        if scale == "median":
            scale = float(np.median(C[ok])) or 1.0
        y[ok] = _transform(C[ok], how, scale)
        y[~ok] = y[ok].max() + float(o["failure_penalty"])
    else:  # nothing succeeded yet: a flat surrogate, EI then explores at random
        y[:] = 0.0
    acq_kwargs = {"xi": float(o["xi"]), "kappa": float(o["kappa"])}
    opt_kwargs = {
        "n_points": int(o["n_points"]),
        "n_restarts_optimizer": max(1, int(o["n_restarts"])),
        "n_jobs": 1,
    }
    gp = _gp(U.shape[1], o["noise"], int(o["gp_restarts"]), hyper)
    with threadpool_limits(1), isolated_global_rng(seed), warnings.catch_warnings():
        # sklearn's GP convergence warnings, skopt's repeat warnings
        warnings.simplefilter("ignore")
        opt = Optimizer(
            [(0.0, 1.0)] * U.shape[1],
            base_estimator=gp,
            n_initial_points=0,
            acq_func=str(o["acq_func"]),
            acq_optimizer=str(o["acq_optimizer"]),
            acq_func_kwargs=acq_kwargs,
            acq_optimizer_kwargs=opt_kwargs,
            random_state=seed,
        )
        opt.tell([list(map(float, u)) for u in U], [float(v) for v in y])
        model = opt.models[-1]
        kernel = model.kernel_
        if isinstance(kernel, Sum) and isinstance(kernel.k2, WhiteKernel):
            # skopt adds the noise term at every fit (and zeroes it for predictions)
            kernel = kernel.k1
        return np.asarray(opt.ask(), dtype=float), (kernel, model.noise_)


def _gp(n: int, noise, restarts: int, hyper=None):
    """scikit-optimize's default GP for ``n`` continuous parameters (noise model and restarts as
    given); with ``hyper = (kernel, noise level)``, a GP with these hyperparameters kept fixed."""
    from skopt.learning import GaussianProcessRegressor
    from skopt.learning.gaussian_process.kernels import ConstantKernel, Matern

    if hyper is not None:
        kernel, level = hyper
        return GaussianProcessRegressor(
            kernel=kernel, normalize_y=True, optimizer=None, noise=float(level) if level else None
        )

    kernel = ConstantKernel(1.0, (0.01, 1000.0)) * Matern(
        length_scale=np.ones(n), length_scale_bounds=[(0.01, 100)] * n, nu=2.5
    )
    return GaussianProcessRegressor(
        kernel=kernel,
        normalize_y=True,
        n_restarts_optimizer=restarts,
        noise=noise if noise == "gaussian" else float(noise),
    )

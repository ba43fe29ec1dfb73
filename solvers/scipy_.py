"""scipy adapters: the least-squares trust regions ``lm`` (dogbox), ``trf``, MINPACK's
Levenberg-Marquardt ``lm-minpack`` (all ``scipy.optimize.least_squares``), and ``sa``
(``dual_annealing``).

Names say what runs: ``lm`` is scipy's *dogbox* (a rectangular trust region with bounds; a
Levenberg-Marquardt-type method, not MINPACK's LM; kept under its historical name), ``trf`` the
trust-region reflective method, ``lm-minpack`` MINPACK's ``lmder`` (Levenberg-Marquardt with
Moré's scaling; unbounded: a problem with a finite bound is refused). Their statuses come from the
first-order test of :mod:`solvers.optimality` at the returned point, not from the library's stop.

Defaults next to the library's: ``trf`` and ``lm-minpack`` use least_squares' own (ftol = xtol =
gtol = 1e-8, x_scale 1); ``lm`` keeps 1e-10 (tighter than scipy's, as its records were made).
``sa`` equals ``dual_annealing``'s defaults, local search included (L-BFGS-B *with the box*,
``maxiter = min(max(6 n, 100), 1000)``, what scipy sets when its ``minimizer_kwargs`` are empty),
its gradient from the parallel finite-difference Jacobian.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import dual_annealing, least_squares

from solvers.base import Outcome, Run, register
from solvers.optimality import STEP_TOL, data_cost, first_order
from solvers.options import choice, count, flag, nonnegative, number, positive

JAC_OPTIONS = {
    "scheme": choice(
        "forward",
        "finite-difference scheme of the parallel Jacobian: forward | central",
        ("forward", "central"),
    ),
    "rel_step": positive(
        None,
        "finite-difference step relative to |z| (z = x / reference; where z = 0, the reference "
        "scale); None: the model's declared step, else scipy's sqrt(eps) = 1.5e-8 (forward) or "
        "eps^(1/3) = 6.1e-6 (central)",
    ),
}

#: the optimality test's tolerance, an option of every least-squares method
OPT_OPTION = {
    "opt_tol": positive(
        STEP_TOL,
        "status converged only when the relative Gauss-Newton step at the returned point is "
        "below opt_tol (about that many correct digits; solvers/optimality.py)",
    ),
}


def _ls_options(tol: float, scipy_note: str) -> dict:
    return {
        **JAC_OPTIONS,
        "ftol": number(
            tol, f"stop when the relative cost decrease of a step is below ftol{scipy_note}"
        ),
        "xtol": nonnegative(tol, f"stop when the relative step size is below xtol{scipy_note}"),
        "gtol": nonnegative(tol, f"stop when the scaled gradient is below gtol{scipy_note}"),
        "x_scale": number(
            1.0,
            "least_squares x_scale in z (1.0 or 'jac'; scipy's default 1.0)",
            low=0.0,
            low_open=True,
            strings=("jac",),
        ),
        "max_nfev": count(
            None, "least_squares max_nfev (its own count, Jacobians excluded); None = budget"
        ),
        **OPT_OPTION,
    }


LM_OPTIONS = {
    **_ls_options(1e-10, " (scipy's default 1e-8)"),
    "ls_method": choice(
        "dogbox",
        "least_squares method with bounds: dogbox (rectangular trust region, variables at a "
        "bound leave the step) or trf (reflective trust region)",
        ("dogbox", "trf"),
    ),
}
TRF_OPTIONS = _ls_options(1e-8, " (scipy's default)")
MINPACK_OPTIONS = {
    k: v for k, v in _ls_options(1e-8, " (scipy's default)").items() if k != "max_nfev"
}


def strictly_inside(z, lo, hi, rstep: float = 1e-10) -> np.ndarray:
    """``z`` moved strictly inside the box, so that least_squares (whose
    ``make_strictly_feasible`` moves only points *on* a bound) starts at the point the wrapper
    checked. A parameter with both bounds finite is clipped to ``[lo + d, hi - d]``,
    ``d = rstep * (hi - lo)`` (the box-relative margin lm's shipped records were made with); one
    with a single finite bound it sits on is moved off it by ``rstep * max(1, |bound|)`` (scipy's
    rule); infinite bounds are left alone. All in the scaled coordinates z (dimensionless)."""
    z = np.array(z, float)
    box = np.isfinite(lo) & np.isfinite(hi)
    d = rstep * (hi[box] - lo[box])
    z[box] = np.clip(z[box], lo[box] + d, hi[box] - d)
    at_lo = ~box & np.isfinite(lo) & (z <= lo)
    at_hi = ~box & np.isfinite(hi) & (z >= hi)
    z[at_lo] = lo[at_lo] + rstep * np.maximum(1.0, np.abs(lo[at_lo]))
    z[at_hi] = hi[at_hi] - rstep * np.maximum(1.0, np.abs(hi[at_hi]))
    # a box too narrow for the margin (or one where lo + d rounds to lo): its centre
    tight = (z <= lo) | (z >= hi)
    z[tight] = 0.5 * (lo[tight] + hi[tight])
    return z


def dogbox_start(z, lo, hi, rstep: float = 1e-10) -> np.ndarray:
    """Where dogbox continues after an ``xtol`` stop in its first step: ``z`` in the box, a
    parameter within ``rstep * (hi - lo)`` (``rstep * max(1, |bound|)`` for a single finite
    bound) of a bound put exactly *on* it.

    dogbox keeps a variable exactly on a bound whose gradient points outward out of its step (its
    active set; every accepted iterate that reaches a bound is put exactly on it). A start a hair
    *inside* the box (least_squares' and :func:`strictly_inside`'s 1e-10) defeats that when the
    Gauss-Newton step also points out: the variable is free, the dogleg step is cut where it meets
    the bound, every other component shrinks with it, and the whole first step (~1e-10) trips the
    ``xtol`` test, ending the run at its start (hyperbolic-tension's default start, pt0 on its
    lower bound, stopped after 2 evaluations 25 % from the reference). Dimensionless, in z."""
    z = np.clip(np.array(z, float), lo, hi)
    box = np.isfinite(lo) & np.isfinite(hi)
    span = np.where(box, hi - lo, 1.0)
    with np.errstate(invalid="ignore"):
        near_lo = np.isfinite(lo) & (z - lo <= rstep * np.where(box, span, np.maximum(1, abs(lo))))
        near_hi = np.isfinite(hi) & (hi - z <= rstep * np.where(box, span, np.maximum(1, abs(hi))))
    z[near_lo] = lo[near_lo]
    z[near_hi & ~near_lo] = hi[near_hi & ~near_lo]
    return z


def verdict(r: Run, z, residual, J, library_status: int, message: str) -> Outcome:
    """The Outcome of a least-squares run that stopped at ``z`` (residual, Jacobian ``J`` there)
    with least_squares ``library_status``: budget/iterations/failed from the library, else
    ``converged`` or ``stalled`` by the first-order test (:mod:`solvers.optimality`)."""
    obj = r.objective
    if library_status == -1:
        return Outcome("failed", message)
    opt = first_order(
        z, residual, J, r.lower, r.upper, data_cost(obj), tol=float(r.options["opt_tol"])
    )
    extra = {"optimality_step": opt.step, "flat": opt.flat}
    if opt.converged:
        return Outcome("converged", f"{message}; {opt.message}", extra=extra)
    if library_status == 0:
        status = "budget" if obj.remaining < 1 else "max_iterations"
        return Outcome(status, f"{message}; {opt.message}", extra=extra)
    return Outcome("stalled", f"{message}; {opt.message}", extra=extra)


def _least_squares(r: Run, method: str) -> Outcome:
    """least_squares (``method``: dogbox, trf or lm) on the whitened residual in z. With exact
    Jacobians every trial point is evaluated with its Jacobian (one run with sensitivities,
    ``jacobian_cost`` forward-equivalents nominal): an accepted point then needs no second run
    for its Jacobian, and most points are accepted. Iterations = Jacobian evaluations.

    A dogbox run that stops on ``xtol`` within its first step at a point that is not first-order
    continues once from where it stopped (:func:`dogbox_start`): the start, nudged 1e-10 inside
    the box, let a variable whose gradient points out of it cut the first step to ~1e-10, which
    dogbox's xtol test (run on every trial step) took for convergence."""
    obj, o = r.objective, r.options
    lo, hi = r.lower, r.upper
    # least_squares starts trf strictly inside the box; every method starts there, so that its
    # first call is the point checked here (and records keep their trajectories)
    z0 = strictly_inside(r.z0, lo, hi)
    eager = obj.exact_jacobian
    ev0 = obj.evaluate(z0, with_jacobian=eager)
    if not ev0.usable:
        return Outcome("failed", f"start point failed: {ev0.message}")
    n_jac = [0]
    start = [z0]  # the start of the least_squares call under way, until its first call

    def fun(z):
        # least_squares' first call is at its start, which was evaluated on its behalf
        reuse = start[0] is not None and np.array_equal(z, start[0])
        start[0] = None
        return obj.evaluate(z, with_jacobian=eager, reuse=reuse).residual.copy()

    last: dict[bytes, np.ndarray] = {}

    def jac(z, *_):
        # least_squares asks for J(z0) once to check it and once more in its first iteration
        # (MINPACK's lmder also at its answer): the same Jacobian again is a reuse
        key = np.asarray(z, float).tobytes()
        if key in last:
            return last[key].copy()
        ev = obj.evaluate(z, with_jacobian=eager, reuse=True)  # the point just evaluated
        r.record(z, ev.cost)
        n_jac[0] += 1
        J = obj.jacobian(z, scheme=o["scheme"], rel_step=o["rel_step"], r0=ev.residual)
        last.clear()
        last[key] = J
        return J.copy()

    # MINPACK's maxfev counts residual calls only: the objective caps the Jacobian columns
    kw = (
        {"max_nfev": r.budget}
        if method == "lm"
        else {"bounds": (lo, hi), "max_nfev": o["max_nfev"] or r.budget}
    )
    tols = {k: o[k] for k in ("ftol", "xtol", "gtol", "x_scale")}
    res = least_squares(fun, z0, jac=jac, method=method, **tols, **kw)
    nfev, njev, note = int(res.nfev), int(res.njev or 0), ""
    ev = obj.evaluate(res.x, reuse=True)
    first_step = n_jac[0] <= 2  # the start's Jacobian and at most one accepted step's
    if method == "dogbox" and res.status in (3, 4) and first_step and obj.remaining >= 1:
        opt = first_order(res.x, ev.residual, res.jac, lo, hi, data_cost(obj), o["opt_tol"])
        z1 = dogbox_start(res.x, lo, hi)
        if not opt.converged and obj.evaluate(z1, with_jacobian=eager, reuse=True).usable:
            start[0] = z1
            if "max_nfev" in kw and o["max_nfev"]:
                kw["max_nfev"] = max(1, o["max_nfev"] - nfev)
            res = least_squares(fun, z1, jac=jac, method=method, **tols, **kw)
            nfev, njev = nfev + int(res.nfev), njev + int(res.njev or 0)
            note = "continued once after an xtol stop in the first step; "
            ev = obj.evaluate(res.x, reuse=True)
    r.record(res.x, ev.cost)
    out = verdict(r, res.x, ev.residual, res.jac, res.status, note + res.message)
    out.n_iterations = n_jac[0]
    out.extra.update({"library_nfev": nfev, "library_njev": njev})
    return out


@register(
    "lm",
    library="scipy",
    family="local",
    options=LM_OPTIONS,
    description="scipy least_squares 'dogbox' (rectangular trust region with bounds, a "
    "Levenberg-Marquardt-type method; not MINPACK's LM, see lm-minpack) or 'trf', the model's "
    "exact Jacobian or a parallel finite-difference one",
)
def run_lm(r: Run) -> Outcome:
    method = r.options["ls_method"]
    if method not in ("dogbox", "trf"):
        raise ValueError(f"ls_method = {method!r} is unknown; allowed: dogbox, trf")
    return _least_squares(r, method)


@register(
    "trf",
    library="scipy",
    family="local",
    options=TRF_OPTIONS,
    description="scipy least_squares 'trf' (trust-region reflective with bounds), the model's "
    "exact Jacobian or a parallel finite-difference one",
)
def run_trf(r: Run) -> Outcome:
    return _least_squares(r, "trf")


@register(
    "lm-minpack",
    library="scipy",
    family="local",
    options=MINPACK_OPTIONS,
    description="MINPACK's Levenberg-Marquardt (scipy least_squares 'lm', lmder) with the "
    "model's exact Jacobian or a parallel finite-difference one; unbounded: refuses a finite box",
)
def run_lm_minpack(r: Run) -> Outcome:
    obj = r.objective
    bounded = np.isfinite(obj.lower) | np.isfinite(obj.upper)
    if bounded.any():
        i = int(np.flatnonzero(bounded)[0])
        raise ValueError(
            f"lm-minpack: MINPACK's Levenberg-Marquardt cannot honour bounds, and {obj.names[i]} "
            f"has [{obj.lower[i]:g}, {obj.upper[i]:g}]; allowed: a problem with infinite bounds "
            "(use lm or trf on a box)"
        )
    return _least_squares(r, "lm")


SA_OPTIONS = {
    "maxiter": count(1000, "maximum number of annealing iterations (scipy's default)"),
    "initial_temp": number(
        5230.0, "initial temperature (scipy's default)", low=0.01, low_open=True, high=5e4
    ),
    "restart_temp_ratio": number(
        2e-5,
        "reannealing starts when the temperature falls to initial_temp * ratio (scipy's default)",
        low=0.0,
        low_open=True,
        high=1.0,
        high_open=True,
    ),
    "visit": number(
        2.62, "visiting distribution parameter (scipy's default)", low=1.0, low_open=True, high=3.0
    ),
    "accept": number(
        -5.0,
        "acceptance distribution parameter (scipy's default)",
        low=-1e4,
        low_open=True,
        high=-5.0,
    ),
    "no_local_search": flag(False, "pure generalised simulated annealing (no L-BFGS-B polishing)"),
    **JAC_OPTIONS,
}


@register(
    "sa",
    library="scipy",
    family="global",
    options=SA_OPTIONS,
    stochastic=True,
    description="dual annealing (generalised simulated annealing + L-BFGS-B local search in the "
    "box, gradients from the parallel Jacobian)",
)
def run_sa(r: Run) -> Outcome:
    obj, o = r.objective, r.options
    start = len(obj.log)
    n = r.lower.size

    def grad(z):
        # L-BFGS-B asks for the gradient at the point whose cost it just had: a reuse
        return obj.gradient(z, reuse=True, scheme=o["scheme"], rel_step=o["rel_step"])[1]

    bounds = list(zip(r.lower, r.upper))
    local = {  # what dual_annealing sets when minimizer_kwargs are empty, plus our gradient
        "method": "L-BFGS-B",
        "jac": grad,
        "bounds": bounds,
        "options": {"maxiter": min(max(6 * n, 100), 1000)},
    }
    try:
        res = dual_annealing(
            obj.cost,
            bounds,
            maxiter=o["maxiter"],
            minimizer_kwargs=local,
            initial_temp=o["initial_temp"],
            restart_temp_ratio=o["restart_temp_ratio"],
            visit=o["visit"],
            accept=o["accept"],
            maxfun=r.budget,
            rng=r.seed,
            no_local_search=o["no_local_search"],
            x0=r.z0,
        )
    finally:  # the callback fires only on improvement: the history comes from the objective's log
        r.record_log(start)
    message = "; ".join(res.message) if isinstance(res.message, list) else str(res.message)
    status = "max_iterations"
    if obj.remaining == 0 or "function call" in message:
        # its maxfun (cache hits included) = budget
        status = "budget"
    return Outcome(status, message, int(res.nit), {"library_nfev": int(res.nfev)})

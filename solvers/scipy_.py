"""scipy adapters: ``lm`` (least_squares, dogbox or trf) and ``sa`` (dual_annealing)."""

from __future__ import annotations

import numpy as np
from scipy.optimize import dual_annealing, least_squares

from solvers.base import Outcome, Run, register
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

LM_OPTIONS = {
    **JAC_OPTIONS,
    "ftol": number(1e-10, "stop when the relative cost decrease of a step is below ftol"),
    "xtol": nonnegative(1e-10, "stop when the relative step size is below xtol"),
    "gtol": nonnegative(1e-10, "stop when the scaled gradient is below gtol"),
    "x_scale": number(
        1.0, "least_squares x_scale in z (1.0 or 'jac')", low=0.0, low_open=True, strings=("jac",)
    ),
    "ls_method": choice(
        "dogbox",
        "least_squares method with bounds: dogbox (rectangular trust region, variables at a "
        "bound leave the step) or trf (reflective trust region)",
        ("dogbox", "trf"),
    ),
    "max_nfev": count(
        None, "least_squares max_nfev (its own count, Jacobians excluded); None = budget"
    ),
}

_LS_STATUS = {
    -1: "failed",
    0: "max_iterations",
    1: "converged",
    2: "converged",
    3: "converged",
    4: "converged",
}


@register(
    "lm",
    library="scipy",
    family="local",
    options=LM_OPTIONS,
    description="Levenberg-Marquardt-type trust region with bounds (least_squares 'dogbox' or "
    "'trf'), the model's exact Jacobian or a parallel finite-difference one",
)
def run_lm(r: Run) -> Outcome:
    """least_squares on the whitened residual in z. With exact Jacobians every trial point is
    evaluated with its Jacobian (one run with sensitivities, ``jacobian_cost`` forward-equivalents
    nominal): an accepted point then needs no second run for its Jacobian, and most points are
    accepted. Iterations = Jacobian evaluations."""
    obj, o = r.objective, r.options
    lo, hi = r.lower, r.upper
    # least_squares starts strictly inside the box; do the same here so its first call is a
    # cache hit
    z0 = np.clip(r.z0, lo + 1e-10 * (hi - lo), hi - 1e-10 * (hi - lo))
    eager = obj.exact_jacobian
    ev0 = obj.evaluate(z0, with_jacobian=eager)
    if not ev0.usable:
        return Outcome("failed", f"start point failed: {ev0.message}")
    n_jac = [0]

    first = [True]

    def fun(z):
        # least_squares' first call is at z0, which was evaluated above on its behalf
        reuse = first[0] and np.array_equal(z, z0)
        first[0] = False
        return obj.evaluate(z, with_jacobian=eager, reuse=reuse).residual.copy()

    def jac(z):
        ev = obj.evaluate(z, with_jacobian=eager, reuse=True)  # the point just evaluated
        r.record(z, ev.cost)
        n_jac[0] += 1
        return obj.jacobian(z, scheme=o["scheme"], rel_step=o["rel_step"], r0=ev.residual)

    res = least_squares(
        fun,
        z0,
        jac=jac,
        bounds=(lo, hi),
        method=o["ls_method"],
        ftol=o["ftol"],
        xtol=o["xtol"],
        gtol=o["gtol"],
        x_scale=o["x_scale"],
        max_nfev=o["max_nfev"] or r.budget,
    )
    r.record(res.x, obj.evaluate(res.x, reuse=True).cost)
    return Outcome(
        _LS_STATUS.get(res.status, "failed"),
        res.message,
        n_jac[0],
        {"library_nfev": int(res.nfev), "library_njev": int(res.njev or 0)},
    )


SA_OPTIONS = {
    "maxiter": count(1000, "maximum number of annealing iterations"),
    "initial_temp": number(5230.0, "initial temperature", low=0.01, low_open=True, high=5e4),
    "restart_temp_ratio": number(
        2e-5,
        "reannealing starts when the temperature falls to initial_temp * ratio",
        low=0.0,
        low_open=True,
        high=1.0,
        high_open=True,
    ),
    "visit": number(2.62, "visiting distribution parameter", low=1.0, low_open=True, high=3.0),
    "accept": number(-5.0, "acceptance distribution parameter", low=-1e4, low_open=True, high=-5.0),
    "no_local_search": flag(False, "pure generalised simulated annealing (no L-BFGS-B polishing)"),
    **JAC_OPTIONS,
}


@register(
    "sa",
    library="scipy",
    family="global",
    options=SA_OPTIONS,
    stochastic=True,
    description="dual annealing (generalised simulated annealing + L-BFGS-B local search, "
    "gradients from the parallel Jacobian)",
)
def run_sa(r: Run) -> Outcome:
    obj, o = r.objective, r.options
    start = len(obj.log)

    def grad(z):
        # L-BFGS-B asks for the gradient at the point whose cost it just had: a reuse
        return obj.gradient(z, reuse=True, scheme=o["scheme"], rel_step=o["rel_step"])[1]

    try:
        res = dual_annealing(
            obj.cost,
            list(zip(r.lower, r.upper)),
            maxiter=o["maxiter"],
            minimizer_kwargs={"method": "L-BFGS-B", "jac": grad},
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

"""``gauss-newton``: bounded Gauss-Newton with a projected Armijo line search (H = J^T J).

Each iteration, at the current point z with whitened residual r and Jacobian J (the model's
exact one, or one parallel batch of finite differences):

1. gradient ``g = 2 J^T r``; variables at a bound whose gradient pushes outward are *active*
   and held fixed (projected Gauss-Newton);
2. Gauss-Newton step on the free variables, ``J_f p_f = -r`` in the least-squares sense (``lstsq``:
   the minimum-norm step when ``J^T J`` is singular);
3. projected Armijo backtracking: ``z(a) = P(z + a p)``, accept the first ``a = 1, 1/2, 1/4, ...``
   with ``cost(z(a)) <= cost(z) + c1 g.(z(a) - z)``. A failed point has cost FAILURE_COST and is
   rejected like any other bad step.

With exact Jacobians the trial points of the line search are run with their Jacobians (the
accepted point's is then at hand: one run per iteration when the full step is taken).

Stops: relative cost decrease < ftol, predicted by the linear model before the line search
(``|r|^2 - |r + J p|^2 <= ftol |r|^2``, MINPACK's test: at the optimum the trial points' costs
differ from the start's by rounding only, and the line search would spend evaluations comparing
them) or achieved by the accepted step; relative step < xtol, projected gradient < gtol, no
acceptable step after ``max_backtracks`` halvings, ``max_iterations``. At every stop but the
last the first-order test of :mod:`solvers.optimality` gives the status: ``"converged"`` when it
passes at the returned point (the line search failing *at* the optimum, where no decrease is
left to find, is convergence), else ``"stalled"``. After an accepted step the test uses the new
residual with the last Jacobian (no extra evaluation; the step is small when the test matters).
"""

from __future__ import annotations

import numpy as np

from solvers.base import Outcome, Run, register
from solvers.optimality import data_cost, first_order
from solvers.options import count, nonnegative, number
from solvers.scipy_ import JAC_OPTIONS, OPT_OPTION

GN_OPTIONS = {
    **JAC_OPTIONS,
    "max_iterations": count(100, "maximum number of Gauss-Newton iterations"),
    "ftol": number(1e-10, "stop when the relative cost decrease of an accepted step is below ftol"),
    "xtol": nonnegative(1e-10, "stop when |dz| <= xtol (xtol + |z|)"),
    "gtol": nonnegative(1e-12, "stop when the projected gradient's infinity norm is below gtol"),
    "c1": nonnegative(1e-4, "Armijo sufficient-decrease constant"),
    "max_backtracks": count(30, "maximum number of step halvings in the line search"),
    **OPT_OPTION,
}


@register(
    "gauss-newton",
    library="femubench",
    family="local",
    options=GN_OPTIONS,
    description="own bounded Gauss-Newton: H = J^T J, projected step, Armijo backtracking",
)
def run_gauss_newton(r: Run) -> Outcome:
    obj, o = r.objective, r.options
    lo, hi = r.lower, r.upper
    z = np.clip(r.z0, lo, hi)
    # with exact Jacobians every trial point is run with its Jacobian: the accepted one (usually
    # the first, a = 1) then needs no second run
    eager = obj.exact_jacobian
    ev = obj.evaluate(z, with_jacobian=eager)
    if not ev.usable:
        return Outcome("failed", f"start point failed: {ev.message}")
    f, res = ev.cost, ev.residual
    r.record(z, f)
    scale, tol = data_cost(obj), float(o["opt_tol"])

    def verdict(why: str, z, res, J, it: int) -> Outcome:
        opt = first_order(z, res, J, lo, hi, scale, tol)
        extra = {"optimality_step": opt.step, "flat": opt.flat}
        status = "converged" if opt.converged else "stalled"
        return Outcome(status, f"{why}; {opt.message}", it, extra)

    for it in range(1, int(o["max_iterations"]) + 1):
        J = obj.jacobian(z, scheme=o["scheme"], rel_step=o["rel_step"], r0=res)
        g = 2.0 * J.T @ res
        pg = z - np.clip(z - g, lo, hi)
        if np.max(np.abs(pg)) <= o["gtol"]:
            return verdict("projected gradient below gtol", z, res, J, it - 1)
        active = ((z <= lo) & (g > 0)) | ((z >= hi) & (g < 0))
        free = ~active
        p = np.zeros_like(z)
        if free.any():
            p[free] = np.linalg.lstsq(J[:, free], -res, rcond=None)[0]
        predicted = f - float(np.sum((res + J @ p) ** 2))  # the linear model's decrease
        if predicted <= o["ftol"] * f:  # no step can decrease the cost measurably (MINPACK's test)
            return verdict("predicted relative cost decrease below ftol", z, res, J, it)
        alpha, accepted = 1.0, None
        for _ in range(int(o["max_backtracks"]) + 1):
            zt = np.clip(z + alpha * p, lo, hi)
            dz = zt - z
            if not np.any(dz):
                break
            evt = obj.evaluate(zt, with_jacobian=eager)
            if evt.usable and evt.cost <= f + o["c1"] * float(g @ dz):
                accepted = (zt, evt)
                break
            alpha *= 0.5
        if accepted is None:
            return verdict("line search found no sufficient decrease", z, res, J, it)
        zt, evt = accepted
        decrease, step = f - evt.cost, np.linalg.norm(zt - z)
        z, f, res = zt, evt.cost, evt.residual
        r.record(z, f, step_length=alpha)
        if decrease <= o["ftol"] * f:
            return verdict("relative cost decrease below ftol", z, res, J, it)
        if step <= o["xtol"] * (o["xtol"] + np.linalg.norm(z)):
            return verdict("relative step below xtol", z, res, J, it)
    return Outcome("max_iterations", f"{o['max_iterations']} iterations", int(o["max_iterations"]))

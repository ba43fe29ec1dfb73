"""nlopt adapters: ``nlopt:<ALGORITHM>``.

The name after ``nlopt:`` is an nlopt algorithm, with or without its prefix: ``BOBYQA`` resolves
to ``LN_BOBYQA``, ``DIRECT_L`` to ``GN_DIRECT_L``, ``MLSL`` to ``G_MLSL_LDS`` (low-discrepancy
starts) with a local optimizer (option ``local``, default BOBYQA) set by ``set_local_optimizer``.
The registered names are listed in :data:`REGISTERED`; any other nlopt algorithm also works
(``nlopt:LN_PRAXIS``, ``nlopt:GN_DIRECT_L_RAND`` ...). Gradient-based ones (``LD_*``, ``GD_*``) get
``2 J^T r`` from the objective's parallel Jacobian.

nlopt's random generator is seeded with ``nlopt.srand(seed)`` before each run (CRS2, ESCH, ISRES,
*_RAND and G_MLSL are stochastic; ``nlopt:MLSL`` = G_MLSL_LDS draws its starts from a Sobol
sequence and is deterministic). nlopt evaluates one point per call: one history row per call.
Local algorithms stop on ``xtol_rel`` / ``ftol_rel``; global ones run until ``maxeval`` (default:
the budget) unless tolerances are given.
"""

from __future__ import annotations

import nlopt
import numpy as np

from solvers.base import METHODS, MethodInfo, Outcome, Run, register_resolver
from solvers.options import choice, count, nonnegative, positive
from solvers.scipy_ import JAC_OPTIONS

LOCAL = ("BOBYQA", "SBPLX", "NELDERMEAD", "COBYLA", "LBFGS")
GLOBAL = ("CRS2_LM", "DIRECT_L", "ESCH", "ISRES", "MLSL")
REGISTERED = tuple(f"nlopt:{a}" for a in LOCAL + GLOBAL)
_STOCHASTIC = ("CRS2", "ESCH", "ISRES", "RAND")  # and MLSL with pseudo-random starts (not *_LDS)

LOCAL_OPTIONS = {
    "xtol_rel": nonnegative(1e-8, "relative tolerance on z"),
    "ftol_rel": nonnegative(1e-12, "relative tolerance on the cost"),
    "ftol_abs": nonnegative(0.0, "absolute tolerance on the cost (0: off)"),
    "initial_step": positive(None, "initial step in z (None: nlopt's default from the bounds)"),
    "maxeval": count(
        None, "nlopt maxeval (its own count, cache hits included); None = 10 x budget"
    ),
}
GLOBAL_OPTIONS = {
    "xtol_rel": nonnegative(0.0, "relative tolerance on z (0: off; global methods run to maxeval)"),
    "ftol_rel": nonnegative(0.0, "relative tolerance on the cost (0: off)"),
    "ftol_abs": nonnegative(0.0, "absolute tolerance on the cost (0: off)"),
    "population": nonnegative(0, "population / points per iteration (0: nlopt's default)", "int"),
    "maxeval": count(
        None, "nlopt maxeval (its own count, cache hits included); None = 10 x budget"
    ),
}
MLSL_OPTIONS = {
    **GLOBAL_OPTIONS,
    "local": choice(
        "BOBYQA", "local optimizer of MLSL (an LN_ algorithm; LD_ ones get the Jacobian gradient)"
    ),
    "local_xtol_rel": nonnegative(1e-6, "relative z tolerance of each local search"),
    "local_ftol_rel": nonnegative(1e-10, "relative cost tolerance of each local search"),
}

_RESULT = {
    nlopt.SUCCESS: "converged",
    nlopt.STOPVAL_REACHED: "converged",
    nlopt.FTOL_REACHED: "converged",
    nlopt.XTOL_REACHED: "converged",
    nlopt.MAXEVAL_REACHED: "max_iterations",
    nlopt.MAXTIME_REACHED: "max_iterations",
}


def algorithm_code(name: str) -> tuple[int, str]:
    """nlopt constant and full name for ``BOBYQA``, ``LN_BOBYQA``, ``MLSL``...
    (ValueError if unknown)."""
    key = name.upper()
    if key == "MLSL":
        key = "G_MLSL_LDS"
    candidates = [key] + [p + key for p in ("LN_", "GN_", "LD_", "GD_", "G_")]
    for c in candidates:
        if (
            hasattr(nlopt, c)
            and isinstance(getattr(nlopt, c), int)
            and c[:2] in ("LN", "GN", "LD", "GD", "G_")
        ):
            return getattr(nlopt, c), c
    raise ValueError(f"nlopt algorithm {name!r} is unknown (e.g. {', '.join(LOCAL + GLOBAL)})")


def _is_global(full: str) -> bool:
    return full.startswith("G")


def _needs_grad(full: str) -> bool:
    return full[1] == "D"


def _apply(opt, o):
    opt.set_xtol_rel(float(o["xtol_rel"]))
    opt.set_ftol_rel(float(o["ftol_rel"]))
    opt.set_ftol_abs(float(o["ftol_abs"]))


def _make_run(full: str):
    def run(r: Run) -> Outcome:
        obj, o = r.objective, r.options
        code = getattr(nlopt, full)
        n = r.lower.size
        calls = [0]

        pending: list[BaseException] = []  # an exception raised in the callback, re-raised after

        def f(z, grad):
            calls[0] += 1
            try:
                if grad.size > 0:
                    c, g = obj.gradient(
                        z, scheme=o.get("scheme", "forward"), rel_step=o.get("rel_step")
                    )
                    grad[:] = g
                else:
                    c = obj.cost(z)
            except BaseException as exc:  # nlopt does not propagate Python exceptions reliably
                pending.append(exc)
                raise nlopt.ForcedStop() from None
            r.record(z, c)
            return float(c)

        nlopt.srand(int(r.seed))
        opt = nlopt.opt(code, n)
        opt.set_min_objective(f)
        opt.set_lower_bounds(r.lower)
        opt.set_upper_bounds(r.upper)
        _apply(opt, o)
        opt.set_maxeval(int(o["maxeval"] or 10 * r.budget))  # the objective enforces the budget
        if o.get("initial_step"):
            opt.set_initial_step(float(o["initial_step"]))
        if o.get("population"):
            opt.set_population(int(o["population"]))
        if "MLSL" in full:
            lcode, lfull = algorithm_code(o["local"])
            if _is_global(lfull):
                raise ValueError(f"MLSL needs a local optimizer, got {lfull}")
            local = nlopt.opt(lcode, n)
            local.set_xtol_rel(float(o["local_xtol_rel"]))
            local.set_ftol_rel(float(o["local_ftol_rel"]))
            opt.set_local_optimizer(local)
        z0 = np.clip(r.z0, r.lower, r.upper)
        try:
            opt.optimize(z0)
            code_out = opt.last_optimize_result()
        except BaseException as exc:
            if pending:
                raise pending[0] from None  # e.g. BudgetExhausted, handled by solve()
            if isinstance(exc, nlopt.RoundoffLimited):
                return Outcome("stalled", "nlopt: roundoff limited", calls[0])
            if not isinstance(exc, (RuntimeError, ValueError, SystemError, nlopt.exception)):
                raise
            status = "failed" if obj.best is None else "stalled"
            return Outcome(status, f"nlopt: {type(exc).__name__} {exc}", calls[0])
        if pending:
            raise pending[0]
        status = _RESULT.get(code_out, "failed")
        if status == "max_iterations" and obj.remaining == 0:
            status = "budget"
        return Outcome(status, f"nlopt result {code_out}", calls[0], {"algorithm": full})

    return run


def _options(full: str) -> dict:
    if "MLSL" in full:
        return MLSL_OPTIONS
    opts = dict(GLOBAL_OPTIONS if _is_global(full) else LOCAL_OPTIONS)
    if not _is_global(full):
        opts.pop("population", None)
    if _needs_grad(full):
        opts.update(JAC_OPTIONS)
    return opts


def _info(name: str, short: str) -> MethodInfo:
    _, full = algorithm_code(short)
    family = "global" if _is_global(full) else "local"
    stochastic = any(s in full for s in _STOCHASTIC) or (full.endswith("MLSL"))
    return MethodInfo(
        name, "nlopt", family, _options(full), _make_run(full), stochastic, f"nlopt {full}"
    )


for _short in LOCAL + GLOBAL:
    METHODS[f"nlopt:{_short}"] = _info(f"nlopt:{_short}", _short)


def _resolve(name: str) -> MethodInfo | None:
    if not name.lower().startswith("nlopt:"):
        return None
    return _info(name, name.split(":", 1)[1])


register_resolver(_resolve)

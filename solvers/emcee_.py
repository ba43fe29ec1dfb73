"""emcee adapter: ``mcmc`` (affine-invariant ensemble sampler).

Posterior ``p(z | data) ~ exp(-cost(z) / 2)`` (Gaussian likelihood of the whitened residuals) with
a uniform prior on the box; points outside the box are rejected without a forward evaluation;
failed and infeasible points have ``log p = -inf``. The sampler is vectorised: each half-ensemble
move is one :meth:`Objective.evaluate_many` batch.

Budget: a step costs at most ``n_walkers`` evaluations; the sampler stops before a step that might
not fit (``n_steps=None``: as many steps as the budget allows). Walkers start in a small Gaussian
ball around the start point (``init="ball"``, standard deviation ``ball_size`` in z) or spread over
the box by Latin hypercube (``init="lhs"``). Seeded: walker start from ``seed``, emcee's own
``RandomState`` from ``seed``.

Reported in ``extra``: posterior ``mean``, ``median``, ``std``, ``q2.5``/``q97.5`` (95 % interval) per
parameter (physical, after discarding ``burn_fraction`` of the steps), ``map`` (best sample) and
its cost, ``acceptance_fraction``, ``autocorr_time`` (integrated, in steps), ``n_steps``, ``n_walkers``,
``warnings`` (e.g. a chain shorter than 50 autocorrelation times), and the chain itself (physical,
``chain[step][walker][param]`` and ``log_prob[step][walker]``), or, with ``chain_path``, an ``.npz``
file holding them. The RunResult's ``x`` is the best point evaluated (at least as good as the MAP
sample). Status: ``"converged"`` when the kept chain is at least 50 autocorrelation times long,
else ``"budget"`` or ``"max_iterations"``.
"""
from __future__ import annotations

import math
import warnings

import numpy as np

from solvers.base import Outcome, Run, lhs, register

MCMC_OPTIONS = {
    "n_walkers": (None, "number of walkers (None: max(16, 4 n), made even)"),
    "n_steps": (None, "number of steps (None: as many as the budget allows)"),
    "init": ("ball", "walker start: ball (around x0) | lhs (Latin hypercube over the box)"),
    "ball_size": (1e-2, "standard deviation of the start ball, in z = x / reference"),
    "burn_fraction": (0.3, "fraction of the steps discarded as burn-in"),
    "moves": ("de-mix", "emcee moves: de-mix (80 % DE + 20 % DE-snooker) | stretch | de | de-snooker | walk"),
    "keep_chain": (True, "store the chain in extra (ignored when chain_path is given)"),
    "chain_path": (None, "write chain and log_prob to this .npz file instead of extra"),
    "min_tau_multiple": (50.0, "warn when the kept chain is shorter than this many autocorrelation times"),
}


def _moves(name: str):
    import emcee

    table = {"stretch": emcee.moves.StretchMove, "de": emcee.moves.DEMove,
             "de-snooker": emcee.moves.DESnookerMove, "walk": emcee.moves.WalkMove}
    if name == "de-mix":
        return [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]
    if name not in table:
        raise ValueError(f"mcmc: moves {name!r} is unknown; allowed: de-mix, {', '.join(table)}")
    return table[name]()


@register("mcmc", library="emcee", family="sampling", options=MCMC_OPTIONS, stochastic=True,
          description="posterior sampling (emcee ensemble sampler), Gaussian likelihood, uniform prior on the box")
def run_mcmc(r: Run) -> Outcome:
    import emcee

    obj, o = r.objective, r.options
    n = r.lower.size
    nw = int(o["n_walkers"] or max(16, 4 * n))
    nw += nw % 2
    lo, hi = r.lower, r.upper
    rng = r.rng(1)
    if o["init"] == "ball":
        p0 = r.z0 + o["ball_size"] * rng.standard_normal((nw, n))
        p0 = np.where(p0 < lo, 2 * lo - p0, p0)  # reflect into the box
        p0 = np.clip(np.where(p0 > hi, 2 * hi - p0, p0), lo, hi)
    elif o["init"] == "lhs":
        p0 = lhs(nw, lo, hi, rng)
    else:
        raise ValueError(f"mcmc: init {o['init']!r} is unknown; allowed: ball, lhs")

    def log_prob(Z):
        Z = np.atleast_2d(Z)
        lp = np.full(len(Z), -np.inf)
        inside = np.all((Z >= lo) & (Z <= hi), axis=1)
        if inside.any():
            evs = obj.evaluate_many(Z[inside])
            lp[inside] = [-0.5 * ev.cost if ev.usable else -np.inf for ev in evs]
        return lp

    sampler = emcee.EnsembleSampler(nw, n, log_prob, vectorize=True, moves=_moves(o["moves"]))
    sampler.random_state = np.random.RandomState(r.seed % 2**32).get_state()
    if obj.remaining < nw:
        return Outcome("budget", f"budget below the {nw} evaluations of the initial ensemble", 0)
    planned = int(o["n_steps"]) if o["n_steps"] else math.inf
    state, steps, stopped_by_budget = p0, 0, False
    while steps < planned:
        # every step costs at most nw evaluations (+ nw for the initial ensemble): chunks that surely fit
        chunk = min(planned - steps, (obj.remaining - (nw if steps == 0 else 0)) // nw)
        if chunk < 1:
            stopped_by_budget = True
            break
        for state in sampler.sample(state, iterations=int(chunk), skip_initial_state_check=True):
            steps += 1
            k = int(np.argmax(state.log_prob))
            r.record(state.coords[k], -2.0 * state.log_prob[k] if np.isfinite(state.log_prob[k]) else None)
    if steps == 0:
        return Outcome("budget", "budget too small for one step", 0)

    chain_z = sampler.get_chain()  # (steps, walkers, n)
    logp = sampler.get_log_prob()
    burn = min(int(o["burn_fraction"] * steps), steps - 1)
    kept = chain_z[burn:]
    flat = obj.to_physical(kept.reshape(-1, n))
    from emcee.autocorr import integrated_time

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tau = integrated_time(kept, tol=0) if kept.shape[0] > 1 else np.full(n, np.inf)
    tau = np.where(np.isfinite(tau), tau, np.inf)  # a too-short chain gives nan
    tau_max = float(np.max(tau))
    k = np.unravel_index(np.argmax(logp), logp.shape)
    extra = {
        "n_walkers": nw, "n_steps": steps, "burn": burn,
        "mean": dict(zip(obj.names, flat.mean(axis=0))),
        "median": dict(zip(obj.names, np.median(flat, axis=0))),
        "std": dict(zip(obj.names, flat.std(axis=0, ddof=1) if len(flat) > 1 else np.zeros(n))),
        "q2.5": dict(zip(obj.names, np.percentile(flat, 2.5, axis=0))),
        "q97.5": dict(zip(obj.names, np.percentile(flat, 97.5, axis=0))),
        "map": dict(zip(obj.names, obj.to_physical(chain_z[k]))),
        "map_cost": float(-2.0 * logp[k]) if np.isfinite(logp[k]) else math.inf,
        "acceptance_fraction": float(np.mean(sampler.acceptance_fraction)),
        "autocorr_time": dict(zip(obj.names, tau)),
        "warnings": [],
    }
    long_enough = (steps - burn) >= o["min_tau_multiple"] * tau_max
    if not long_enough:
        msg = (f"chain of {steps - burn} kept steps is shorter than {o['min_tau_multiple']:g} "
               f"autocorrelation times (tau = {tau_max:.3g} steps): the estimates are unreliable")
        extra["warnings"].append(msg)
        warnings.warn(f"mcmc: {msg}", RuntimeWarning, stacklevel=2)
    chain_x = obj.to_physical(chain_z)
    if o["chain_path"]:
        np.savez(o["chain_path"], chain=chain_x, log_prob=logp, names=np.array(obj.names))
        extra["chain_path"] = str(o["chain_path"])
    elif o["keep_chain"]:
        extra["chain"] = chain_x
        extra["log_prob"] = np.where(np.isfinite(logp), logp, -np.inf)
    if long_enough:
        status = "converged"
    else:
        status = "budget" if stopped_by_budget else "max_iterations"
    message = f"{steps} steps x {nw} walkers, acceptance {extra['acceptance_fraction']:.2f}, tau_max {tau_max:.3g}"
    return Outcome(status, message, steps, extra)

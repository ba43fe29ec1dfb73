"""emcee adapter: ``mcmc`` (affine-invariant ensemble sampler).

Posterior ``p(z | data) ~ exp(-cost(z) / 2)`` (Gaussian likelihood of the whitened residuals) with
a uniform prior on the box; points outside the box are rejected without a forward evaluation;
failed and infeasible points have ``log p = -inf``. The sampler is vectorised: each half-ensemble
move is one :meth:`Evaluator.evaluate_many` batch.

Budget: a step costs at most ``n_walkers`` evaluations; the sampler stops before a step that might
not fit (``n_steps=None``: as many steps as the budget allows). Walkers start in a small Gaussian
ball around the start point (``init="ball"``, standard deviation ``ball_size`` in z) or spread over
the box by Latin hypercube (``init="lhs"``). Seeded: walker start from ``seed``, emcee's own
``RandomState`` from ``seed``.

Reported in ``extra``: posterior ``mean``, ``median``, ``std``, ``q2.5``/``q97.5`` (95 % interval)
per parameter (physical, after discarding ``burn_fraction`` of the steps), ``map`` (best sample) and
its cost, ``acceptance_fraction``, ``autocorr_time`` (integrated, in steps), ``n_steps``,
``n_walkers``, ``warnings`` (e.g. a chain shorter than 50 autocorrelation times),
``stopped_converged`` (the run stopped by the convergence rule, before its budget), and the chain
itself (physical, ``chain[step][walker][param]`` and ``log_prob[step][walker]``), or, with
``chain_path``, the path of the ``.npz`` file holding them (see below). The RunResult's ``x`` is the
best point evaluated (at least as good as the MAP sample). Status: ``"converged"`` when the kept
chain is at least 50 autocorrelation times long, else ``"budget"`` or ``"max_iterations"``.

Length: with ``stop_converged`` (the default) the chain stops at the first check (every
``check_every`` steps) where :func:`converged_at` holds - the kept chain is at least
``min_tau_multiple`` (50) autocorrelation times long and the estimate of tau moved by less than
``tau_rtol`` since the previous check (emcee's documented rule) - so the budget is a cap, and a
chain that mixes well costs what it needs, not the whole budget. Every check is made on the chain
so far only: the stop is as reproducible as the chain.

Structure: :func:`run_mcmc` is a thin loop over :func:`ensemble_steps` (emcee's
``EnsembleSampler.sample()`` generator, iterated as emcee's own ``run_mcmc`` does, in chunks the
budget surely allows), recording the best walker of each step. The chain lives in an emcee backend:
the in-memory :class:`emcee.backends.Backend`, or, with ``chain_path``,
:class:`solvers.npz_backend.NpzBackend`, which persists it to that file while sampling (chain in
z = x / reference, with ``names`` and ``scale`` = reference: x = chain x scale).
:func:`chain_summary` turns a backend into the numbers of ``extra``.
"""

from __future__ import annotations

import math
import warnings
from typing import Callable, Iterator

import numpy as np

from solvers.base import Outcome, Run, lhs, register
from solvers.options import Option, choice, count, flag, fraction, nonnegative, positive

MCMC_OPTIONS = {
    "n_walkers": count(None, "number of walkers (None: max(16, 4 n), made even)"),
    "n_steps": count(None, "number of steps (None: as many as the budget allows)"),
    "init": choice(
        "ball",
        "walker start: ball (around x0) | lhs (Latin hypercube over the box)",
        ("ball", "lhs"),
    ),
    "ball_size": positive(1e-2, "standard deviation of the start ball, in z = x / reference"),
    "burn_fraction": fraction(0.3, "fraction of the steps discarded as burn-in", high_open=True),
    "moves": choice(
        "de-mix",
        "emcee moves: de-mix (80 % DE + 20 % DE-snooker) | stretch | de | de-snooker | walk",
        ("de-mix", "stretch", "de", "de-snooker", "walk"),
    ),
    "keep_chain": flag(True, "store the chain in extra (ignored when chain_path is given)"),
    "chain_path": Option(
        "str",
        None,
        "keep the chain in this .npz file (solvers.npz_backend.NpzBackend) instead of extra",
    ),
    "min_tau_multiple": positive(
        50.0, "warn when the kept chain is shorter than this many autocorrelation times"
    ),
    "stop_converged": flag(
        True, "stop as soon as the chain is converged (see converged_at); the budget is then a cap"
    ),
    "check_every": count(250, "steps between two convergence checks (stop_converged)"),
    "tau_rtol": nonnegative(
        0.05,
        "convergence also needs tau_max to have changed by less than this since the last check",
    ),
}


def _moves(name: str):
    import emcee

    table = {
        "stretch": emcee.moves.StretchMove,
        "de": emcee.moves.DEMove,
        "de-snooker": emcee.moves.DESnookerMove,
        "walk": emcee.moves.WalkMove,
    }
    if name == "de-mix":
        return [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]
    if name not in table:
        raise ValueError(f"mcmc: moves {name!r} is unknown; allowed: de-mix, {', '.join(table)}")
    return table[name]()


def initial_ensemble(r: Run, n_walkers: int) -> np.ndarray:
    """Walker start positions (n_walkers, n) in z: a ball about ``r.z0`` reflected into the box, or
    LHS."""
    o, lo, hi = r.options, r.lower, r.upper
    rng = r.rng(1)
    if o["init"] == "ball":
        p0 = r.z0 + o["ball_size"] * rng.standard_normal((n_walkers, lo.size))
        p0 = np.where(p0 < lo, 2 * lo - p0, p0)  # reflect into the box
        return np.clip(np.where(p0 > hi, 2 * hi - p0, p0), lo, hi)
    if o["init"] == "lhs":
        return lhs(n_walkers, lo, hi, rng)
    raise ValueError(f"mcmc: init {o['init']!r} is unknown; allowed: ball, lhs")


def log_posterior(objective, lower, upper) -> Callable[[np.ndarray], np.ndarray]:
    """Vectorised ``log p(Z) = -cost / 2`` inside the box (one evaluation batch), ``-inf`` outside
    the box (not evaluated) and at failed or infeasible points."""

    def log_prob(Z):
        Z = np.atleast_2d(Z)
        lp = np.full(len(Z), -np.inf)
        inside = np.all((Z >= lower) & (Z <= upper), axis=1)
        if inside.any():
            evs = objective.evaluate_many(Z[inside])
            lp[inside] = [-0.5 * ev.cost if ev.usable else -np.inf for ev in evs]
        return lp

    return log_prob


def ensemble_steps(
    sampler, p0, remaining: Callable[[], float], max_steps: float = math.inf
) -> Iterator:
    """Iterate emcee's ``sampler.sample()`` generator from ``p0`` and yield the ensemble state after
    each step, for at most ``max_steps`` steps and only while the budget surely allows them: a step
    costs at most one evaluation per walker, the first one also the initial ensemble's.
    ``remaining()`` is the number of evaluations left."""
    nw = sampler.nwalkers
    state, done = p0, 0
    while done < max_steps:
        chunk = min(max_steps - done, (remaining() - (nw if done == 0 else 0)) // nw)
        if chunk < 1:
            return
        # the last state of a chunk is where the next chunk starts
        for state in sampler.sample(state, iterations=int(chunk), skip_initial_state_check=True):  # noqa: B020
            done += 1
            yield state


def kept_tau(chain_z: np.ndarray, burn_fraction: float) -> tuple[int, np.ndarray]:
    """Burn-in (steps) and the integrated autocorrelation time (steps) of each parameter over the
    kept part of ``chain_z`` (steps, walkers, n); ``inf`` where the chain is too short to tell."""
    from emcee.autocorr import integrated_time

    steps, n = chain_z.shape[0], chain_z.shape[2]
    burn = min(int(burn_fraction * steps), steps - 1)
    kept = chain_z[burn:]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tau = integrated_time(kept, tol=0) if kept.shape[0] > 1 else np.full(n, np.inf)
    return burn, np.where(np.isfinite(tau), tau, np.inf)  # a too-short chain gives nan


def converged_at(
    chain_z: np.ndarray,
    burn_fraction: float,
    min_tau_multiple: float,
    tau_rtol: float,
    previous_tau: float,
) -> tuple[bool, float]:
    """The stopping rule of emcee's documentation: the kept chain (after discarding
    ``burn_fraction`` of the steps) is at least ``min_tau_multiple`` times its largest integrated
    autocorrelation time long, and that time changed by less than ``tau_rtol`` (relative) since the
    previous check (``previous_tau``). Returns (converged, tau_max)."""
    burn, tau = kept_tau(chain_z, burn_fraction)
    tau_max = float(np.max(tau))
    long_enough = chain_z.shape[0] - burn >= min_tau_multiple * tau_max
    steady = math.isfinite(previous_tau) and abs(tau_max - previous_tau) <= tau_rtol * tau_max
    return bool(long_enough and steady), tau_max


def chain_summary(
    backend, names, to_physical, burn_fraction: float, min_tau_multiple: float
) -> dict:
    """Posterior numbers of ``extra`` from an emcee backend (chain in z; ``to_physical`` maps z to
    x):
    burn-in, mean/median/std/percentiles of the kept chain, MAP sample and cost, acceptance,
    integrated autocorrelation times (steps) and the short-chain warning."""
    steps, n = backend.iteration, len(names)
    chain_z, logp = backend.get_chain(), backend.get_log_prob()
    burn, tau = kept_tau(chain_z, burn_fraction)
    flat = to_physical(chain_z[burn:].reshape(-1, n))
    tau_max = float(np.max(tau))
    k = np.unravel_index(np.argmax(logp), logp.shape)
    extra = {
        "n_walkers": backend.nwalkers,
        "n_steps": steps,
        "burn": burn,
        "mean": dict(zip(names, flat.mean(axis=0))),
        "median": dict(zip(names, np.median(flat, axis=0))),
        "std": dict(zip(names, flat.std(axis=0, ddof=1) if len(flat) > 1 else np.zeros(n))),
        "q2.5": dict(zip(names, np.percentile(flat, 2.5, axis=0))),
        "q97.5": dict(zip(names, np.percentile(flat, 97.5, axis=0))),
        "map": dict(zip(names, to_physical(chain_z[k]))),
        "map_cost": float(-2.0 * logp[k]) if np.isfinite(logp[k]) else math.inf,
        "acceptance_fraction": float(np.mean(backend.accepted / steps)),
        "autocorr_time": dict(zip(names, tau)),
        "tau_max": tau_max,
        "warnings": [],
    }
    if (steps - burn) < min_tau_multiple * tau_max:
        extra["warnings"].append(
            f"chain of {steps - burn} kept steps is shorter than {min_tau_multiple:g} "
            f"autocorrelation times (tau = {tau_max:.3g} steps): the estimates are unreliable"
        )
    return extra


@register(
    "mcmc",
    library="emcee",
    family="sampling",
    options=MCMC_OPTIONS,
    stochastic=True,
    description="posterior sampling (emcee ensemble sampler), Gaussian likelihood, uniform prior "
    "on the box",
)
def run_mcmc(r: Run) -> Outcome:
    import emcee

    from solvers.npz_backend import NpzBackend

    obj, o = r.objective, r.options
    n = r.lower.size
    nw = int(o["n_walkers"] or max(16, 4 * n))
    nw += nw % 2
    if nw < 2 * n:  # emcee's ensemble moves need it
        raise ValueError(
            f"mcmc: n_walkers = {o['n_walkers']} is out of range: at least twice the {n} "
            f"parameters ({2 * n})"
        )
    p0 = initial_ensemble(r, nw)
    if obj.remaining < nw:
        return Outcome("budget", f"budget below the {nw} evaluations of the initial ensemble", 0)
    if o["chain_path"]:
        backend = NpzBackend(
            o["chain_path"],
            metadata={"names": np.array(obj.names), "scale": obj.to_physical(np.ones(n))},
        )
    else:
        backend = emcee.backends.Backend()
    sampler = emcee.EnsembleSampler(
        nw,
        n,
        log_posterior(obj, r.lower, r.upper),
        vectorize=True,
        moves=_moves(o["moves"]),
        backend=backend,
    )
    sampler.random_state = np.random.RandomState(r.seed % 2**32).get_state()
    planned = int(o["n_steps"]) if o["n_steps"] else math.inf
    check_every = int(o["check_every"])
    stopped, tau_seen = False, math.inf
    # a chain never comes back to a point it evaluated: caching its 10^5 evaluations (each with its
    # residual, m floats) would only fill the memory (10 GB for 150 000 points of m = 8 130)
    cache, obj.cache = obj.cache, False
    try:
        for state in ensemble_steps(sampler, p0, lambda: obj.remaining, planned):
            k = int(np.argmax(state.log_prob))
            lp = state.log_prob[k]
            r.record(state.coords[k], -2.0 * lp if np.isfinite(lp) else None)
            if o["stop_converged"] and backend.iteration % check_every == 0:
                stopped, tau_seen = converged_at(
                    backend.get_chain(),
                    o["burn_fraction"],
                    o["min_tau_multiple"],
                    o["tau_rtol"],
                    tau_seen,
                )
                if stopped:
                    break
    finally:
        obj.cache = cache
    steps = backend.iteration
    if steps == 0:
        return Outcome("budget", "budget too small for one step", 0)

    extra = chain_summary(
        backend, obj.names, obj.to_physical, o["burn_fraction"], o["min_tau_multiple"]
    )
    tau_max = extra.pop("tau_max")
    for msg in extra["warnings"]:
        warnings.warn(f"mcmc: {msg}", RuntimeWarning, stacklevel=2)
    if o["chain_path"]:
        extra["chain_path"] = str(backend.flush())
    elif o["keep_chain"]:
        logp = backend.get_log_prob()
        extra["chain"] = obj.to_physical(backend.get_chain())
        extra["log_prob"] = np.where(np.isfinite(logp), logp, -np.inf)
    extra["stopped_converged"] = stopped
    if not extra["warnings"]:
        status = "converged"
    else:
        status = "budget" if steps < planned else "max_iterations"
    message = (
        f"{steps} steps x {nw} walkers, acceptance {extra['acceptance_fraction']:.2f}, tau_max "
        f"{tau_max:.3g}"
    )
    return Outcome(status, message, steps, extra)

"""Evidence of a calibrated variant: Laplace from the exact Jacobian, and MCMC with bridge sampling.

Convention (docs/calibrating.md, "Evidence"): with the noise model known, the likelihood of the
data D under variant M at parameters x is ``L(x) = c exp(-chi2(x) / 2)`` with a constant c (the
noise normalisation ``(2 pi)^(-n/2) prod 1/sigma_i``) common to every variant fitted to the same
data; the prior is uniform on the variant's box B of volume V (physical units). Every log evidence
here is ``log Z = log (1/V) int_B exp(-chi2(x)/2) dx``, i.e. ``log p(D|M) - log c``: differences
between variants are the log Bayes factors.

* :func:`laplace_log_evidence`: chi2 expanded to second order at the optimum x* with the
  Gauss-Newton Hessian ``F = J^T C^-1 J`` (the Fisher information of the exact Jacobian,
  physical units), integrated over the box::

      log Z = -chi2*/2 + k/2 log 2 pi - 1/2 log det F - log V + log P_B

  ``P_B`` the mass of N(x*, F^-1) inside the box (Genz's algorithm, scipy): 1 for an optimum deep
  inside a box much wider than the posterior, 1/2 per parameter on a bound, and for a direction
  the data do not see (a tiny eigenvalue of F) it cancels the Gaussian's width so that the prior
  width is what counts. Without ``P_B`` this is the textbook Laplace evidence.
* :func:`model_probabilities`: posterior probabilities of the variants from their log evidences
  with equal prior probabilities.
* :func:`bridge_log_evidence`: Meng & Wong's (1996) iterative bridge sampling estimate from
  posterior draws (MCMC) and draws of a Gaussian proposal fitted to them, with the relative
  error estimate of Fruehwirth-Schnatter (2004). Chosen over the harmonic mean (infinite
  variance in general) and thermodynamic integration (a chain per temperature: tens of chains
  of the model): with a proposal close to the posterior its error is small and itself
  estimated, for one extra batch of model evaluations.
"""

from __future__ import annotations

import math
import time

import numpy as np

#: eigenvalues of F below this fraction of the largest are raised to it (directions the data do
#: not see: the box mass P_B then carries the prior width)
EIGEN_FLOOR = 1e-14


def laplace_log_evidence(chi2: float, fisher_x, x, lower, upper) -> dict:
    """Laplace log evidence of one variant (module docstring) and its terms.

    chi2     : chi-square at the optimum (whitened residual's squared norm)
    fisher_x : (k, k) ``J^T C^-1 J`` in physical units (1 / unit_i unit_j)
    x, lower, upper : (k,) the optimum and the prior box, physical units
    Returns ``log_evidence`` and the terms ``log_likelihood`` (-chi2/2), ``log_occam``
    (``k/2 log 2 pi - 1/2 log det F - log V``: the posterior volume over the prior's),
    ``log_box_mass`` (log P_B) and ``log_prior_volume`` (log V).
    """
    from scipy.stats import multivariate_normal

    F = np.asarray(fisher_x, float)
    F = 0.5 * (F + F.T)
    x, lo, hi = (np.asarray(a, float) for a in (x, lower, upper))
    k = x.size
    lam, V = np.linalg.eigh(F)
    lam = np.maximum(lam, EIGEN_FLOOR * max(float(lam.max()), 1e-300))
    cov = (V / lam) @ V.T
    sd = np.sqrt(np.diag(cov))
    R = cov / np.outer(sd, sd)
    R = 0.5 * (R + R.T)
    mass = float(
        multivariate_normal.cdf(
            (hi - x) / sd, np.zeros(k), R, lower_limit=(lo - x) / sd, abseps=1e-14, releps=1e-4
        )
    )
    log_mass = math.log(mass) if mass > 0 else -math.inf
    log_volume = float(np.sum(np.log(hi - lo)))
    log_occam = 0.5 * k * math.log(2 * math.pi) - 0.5 * float(np.sum(np.log(lam))) - log_volume
    return {
        "log_evidence": -0.5 * chi2 + log_occam + log_mass,
        "log_likelihood": -0.5 * chi2,
        "log_occam": log_occam,
        "log_box_mass": log_mass,
        "log_prior_volume": log_volume,
    }


def model_probabilities(log_evidence: dict[str, float]) -> dict[str, float]:
    """Posterior probability of each variant from its log evidence, equal prior probabilities."""
    finite = {k: v for k, v in log_evidence.items() if math.isfinite(v)}
    if not finite:
        return {k: math.nan for k in log_evidence}
    top = max(finite.values())
    w = {k: math.exp(v - top) if math.isfinite(v) else 0.0 for k, v in log_evidence.items()}
    total = sum(w.values())
    return {k: v / total for k, v in w.items()}


def bridge_log_evidence(log_post_samples, samples, log_post, rng, *, n_proposal=None) -> dict:
    """Bridge sampling estimate of ``log int exp(log_post)`` (Meng & Wong 1996, iterative
    optimal bridge; Gronau et al. 2017's recipe).

    log_post_samples : (N1,) unnormalised log posterior at the posterior draws ``samples``
                       (N1, k) (physical units); their first half fits the Gaussian proposal, the
                       second half enters the estimate
    log_post         : callable (M, k) -> (M,) unnormalised log posterior (``-inf`` outside the
                       prior's support), evaluated once on ``n_proposal`` proposal draws
                       (default: as many as the second half)
    Returns ``log_evidence``, ``relative_error`` (Fruehwirth-Schnatter 2004's estimate, ignoring
    the draws' autocorrelation), ``n_proposal`` evaluations and ``iterations``.
    """
    from scipy.special import logsumexp

    lp = np.asarray(log_post_samples, float)
    X = np.asarray(samples, float)
    half = len(X) // 2
    fit, X1, l1 = X[:half], X[half:], lp[half:]
    # the Gaussian proposal in standardised coordinates (parameters differ by orders of
    # magnitude: E in MPa, K near 1), its correlation's eigenvalues floored
    k = X.shape[1]
    mean = fit.mean(axis=0)
    sd = fit.std(axis=0, ddof=1)
    sd = np.where(sd > 0, sd, 1e-9 * np.maximum(np.abs(mean), 1e-300))
    lam, V = np.linalg.eigh(np.atleast_2d(np.cov((fit - mean) / sd, rowvar=False)))
    lam = np.maximum(lam, 1e-10 * max(float(lam.max()), 1e-300))
    log_norm = -0.5 * k * math.log(2 * math.pi) - 0.5 * float(np.sum(np.log(lam)))
    log_norm -= float(np.sum(np.log(sd)))

    def log_q(Y):
        W = ((Y - mean) / sd) @ V / np.sqrt(lam)
        return log_norm - 0.5 * np.sum(W * W, axis=1)

    n2 = int(n_proposal or len(X1))
    X2 = mean + sd * ((rng.standard_normal((n2, k)) * np.sqrt(lam)) @ V.T)
    l2 = np.asarray(log_post(X2), float)
    q1, q2 = log_q(X1), log_q(X2)
    n1 = len(X1)
    s1, s2 = n1 / (n1 + n2), n2 / (n1 + n2)
    # log ratios posterior/proposal, shifted for stability
    a1, a2 = l1 - q1, l2 - q2
    shift = float(np.median(a1))
    a1, a2 = a1 - shift, a2 - shift
    log_r, iterations = 0.0, 0
    while iterations < 1000:
        iterations += 1
        # r = [1/n2 sum l2/(s1 l2 + s2 r)] / [1/n1 sum 1/(s1 l1 + s2 r)]  (l = exp(a))
        num = logsumexp(a2 - np.logaddexp(math.log(s1) + a2, math.log(s2) + log_r)) - math.log(n2)
        den = logsumexp(-np.logaddexp(math.log(s1) + a1, math.log(s2) + log_r)) - math.log(n1)
        new = num - den
        done = abs(new - log_r) < 1e-10
        log_r = new
        if done:
            break
    # Fruehwirth-Schnatter's relative mean-squared error, with p/Z over q at each draw:
    # f_prop at the proposal draws, f_post at the posterior draws
    w2, w1 = np.exp(a2 - log_r), np.exp(a1 - log_r)
    f_prop = w2 / (s1 * w2 + s2)
    f_post = 1.0 / (s1 * w1 + s2)
    re2 = np.var(f_prop) / np.mean(f_prop) ** 2 / n2 + np.var(f_post) / np.mean(f_post) ** 2 / n1
    return {
        "log_evidence": log_r + shift,
        "relative_error": float(math.sqrt(re2)) if math.isfinite(re2) else math.nan,
        "n_proposal": n2,
        "proposal_outside_support": int(np.sum(~np.isfinite(l2))),
        "iterations": iterations,
    }


def sample_posterior(
    log_post,
    x0,
    cov0,
    lower,
    upper,
    *,
    n_walkers: int = 0,
    n_steps: int = 300,
    seed: int = 0,
    burn_fraction: float = 0.5,
) -> dict:
    """emcee on ``log_post`` (vectorised: (M, k) physical rows -> (M,), ``-inf`` off the
    support) with differential-evolution moves (80 % DE + 20 % DE-snooker, as
    bench/studies/posterior.py), walkers started in N(x0, cov0) (each sd kept within
    [1e-3, 0.25] of the box's width) clipped into the box.

    n_walkers : walkers (0: max(16, 2 k + 2), even); n_steps: steps of every walker, the first
    ``burn_fraction`` discarded. Returns ``samples`` (kept, flat, physical), ``log_prob``,
    ``tau`` (integrated autocorrelation time per parameter, steps; emcee's estimator),
    ``tau_multiple`` (kept steps / largest tau: >= 50 for a converged chain), ``acceptance``,
    ``n_evals`` and ``wall_s``.
    """
    import warnings

    import emcee
    from emcee.autocorr import integrated_time

    t0 = time.perf_counter()
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    x0 = np.asarray(x0, float)
    k = x0.size
    nw = max(int(n_walkers) or 16, 2 * k + 2)
    nw += nw % 2
    rng = np.random.default_rng(seed)
    span = hi - lo
    # the start's spread per parameter within [1e-3, 0.25] of the box: a direction the Laplace
    # covariance leaves at zero (a pseudo-inverse) would keep the DE moves out of it for good
    cov0 = np.asarray(cov0, float)
    sd = np.sqrt(np.maximum(np.diag(cov0), 0.0))
    R = np.where(np.outer(sd, sd) > 0, cov0 / np.where(sd > 0, sd, 1.0)[:, None], 0.0)
    R = R / np.where(sd > 0, sd, 1.0)[None, :]
    np.fill_diagonal(R, 1.0)
    lam, V = np.linalg.eigh(0.5 * (R + R.T))
    R = (V * np.maximum(lam, 1e-6)) @ V.T
    sd = np.clip(sd, 1e-3 * span, 0.25 * span)
    L = np.linalg.cholesky(R * np.outer(sd, sd))
    p0 = np.clip(x0 + rng.standard_normal((nw, k)) @ L.T, lo + 1e-9 * span, hi - 1e-9 * span)
    calls = [0]

    def counted(X):
        calls[0] += len(X)
        return log_post(X)

    moves = [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]
    sampler = emcee.EnsembleSampler(nw, k, counted, vectorize=True, moves=moves)
    sampler.random_state = np.random.RandomState(seed).get_state()
    sampler.run_mcmc(p0, n_steps, progress=False, skip_initial_state_check=True)
    burn = int(burn_fraction * n_steps)
    chain = sampler.get_chain()[burn:]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tau = integrated_time(chain, tol=0)
    return {
        "samples": chain.reshape(-1, k),
        "log_prob": sampler.get_log_prob()[burn:].reshape(-1),
        "tau": tau.tolist(),
        "tau_multiple": float(len(chain) / np.max(tau)),
        "acceptance": float(np.mean(sampler.acceptance_fraction)),
        "n_walkers": nw,
        "n_steps": int(n_steps),
        "burn": burn,
        "n_evals": calls[0],
        "wall_s": time.perf_counter() - t0,
    }


def posterior_summary(names, samples) -> dict:
    """Mean, sd and the 2.5 / 97.5 % quantiles of each parameter's draws."""
    X = np.asarray(samples, float)
    return {
        "names": list(names),
        "mean": X.mean(axis=0).tolist(),
        "sd": X.std(axis=0, ddof=1).tolist(),
        "q025": np.percentile(X, 2.5, axis=0).tolist(),
        "q975": np.percentile(X, 97.5, axis=0).tolist(),
    }

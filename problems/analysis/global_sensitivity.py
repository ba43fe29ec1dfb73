"""Global sensitivity analysis over a parameter box: Sobol indices (Saltelli) and Morris screening.

Thin, testable layer over SALib 1.5 for any *vectorised* evaluator ``f(X) -> Y`` (``X`` (n, d)
physical points, ``Y`` (n, k) outputs; NaN marks a failed point):

* **Sobol** first-order ``S1`` and total ``ST`` indices with Saltelli's cross-sampling
  (``SALib.sample.sobol``, scrambled Sobol' sequence, ``calc_second_order=False``): ``N`` base
  samples cost ``N (d + 2)`` evaluations; confidence intervals by bootstrap (``num_resamples``).
* **Morris** elementary effects (``SALib.sample.morris``, ``num_levels`` grid levels): ``r``
  trajectories cost ``r (d + 1)`` evaluations; ``mu_star`` (mean |EE|) ranks the influence and
  ``sigma`` flags non-linearity/interaction. SALib computes EE with the step measured in the unit
  cube, so ``mu_star`` has the output's unit per *full parameter range*.

Failed points (NaN rows) cannot be fed to the estimators: the Saltelli groups (``d + 2`` rows) or
Morris trajectories (``d + 1`` rows) containing one are dropped and the count is reported. Indices
are then conditional on success -- biased if failures are not rare. Infeasible regions of the box
(e.g. exponent-compression: ``a sigma0^b <= sigma0 / 3``) are better avoided altogether by a
smaller box: :func:`feasible_scale` finds the largest box, scaled about the reference, whose
sample points are all feasible.

:class:`FESummaries` evaluates the FE summary outputs (objective cost, peak plate force in kN,
lateral bulge = largest front-face u_h at the last snapshot in mm) through any mapper.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

FE_OUTPUTS = ("cost", "peak_force_kN", "bulge_mm")
FE_OUTPUT_LABELS = {
    "cost": "cost (chi-square, -)",
    "peak_force_kN": "peak force (kN)",
    "bulge_mm": "lateral bulge u_h (mm)",
}


def salib_problem(names: Sequence[str], lower, upper) -> dict:
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    if lower.shape != upper.shape or lower.size != len(names):
        raise ValueError("names, lower and upper must have the same length")
    if np.any(upper <= lower):
        raise ValueError("every upper bound must exceed its lower bound")
    return {
        "num_vars": len(names),
        "names": list(names),
        "bounds": np.column_stack([lower, upper]).tolist(),
    }


def scaled_box(lower, upper, reference, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """The box shrunk about ``reference``: ``ref - s (ref - lower)``, ``ref + s (upper - ref)``."""
    if not 0 < scale <= 1:
        raise ValueError(f"box scale = {scale!r} is out of range: 0 < scale <= 1")
    lower, upper, ref = (np.asarray(a, float) for a in (lower, upper, reference))
    return ref - scale * (ref - lower), ref + scale * (upper - ref)


def feasible_scale(
    check: Callable[[np.ndarray], str | None],
    lower,
    upper,
    reference,
    unit_points,
    *,
    iterations: int = 30,
) -> tuple[float, int]:
    """Largest box scale s in (0, 1] (bisection) for which every ``unit_points`` row is feasible.

    ``unit_points`` (n, d) in [0, 1]^d are mapped into :func:`scaled_box`; ``check(x)`` returns None
    when ``x`` is feasible. Returns ``(scale, n_infeasible_at_full_box)``. Cheap (no FE).
    """
    U = np.asarray(unit_points, float)

    def bad(s):
        lo, hi = scaled_box(lower, upper, reference, s)
        return sum(check(lo + u * (hi - lo)) is not None for u in U)

    n_full = bad(1.0)
    if n_full == 0:
        return 1.0, 0
    a, b = 0.0, 1.0
    for _ in range(iterations):
        m = 0.5 * (a + b)
        if bad(m) == 0:
            a = m
        else:
            b = m
    if a == 0.0:
        raise ValueError("no box about the reference is feasible at every sample point")
    return a, n_full


def evaluate(
    f: Callable[[np.ndarray], np.ndarray], X, *, mapper=None, chunk_size: int | None = None
) -> np.ndarray:
    """``f(X)`` as a 2-D array; with a ``mapper``, ``f`` is applied to chunks of rows in
    parallel."""
    X = np.atleast_2d(np.asarray(X, float))
    if mapper is None:
        Y = np.asarray(f(X), float)
    else:
        size = chunk_size or max(1, math.ceil(len(X) / 16))
        chunks = [X[i : i + size] for i in range(0, len(X), size)]
        parts = mapper(f, chunks)
        Y = np.concatenate(
            [np.asarray(p, float).reshape(len(c), -1) for p, c in zip(parts, chunks)]
        )
    if Y.ndim == 1:
        Y = Y[:, None]
    if len(Y) != len(X):
        raise ValueError(f"evaluator returned {len(Y)} rows for {len(X)} points")
    return Y


def _keep_groups(Y: np.ndarray, group: int) -> np.ndarray:
    """Boolean mask over groups of ``group`` consecutive rows that are all finite."""
    ok = np.all(np.isfinite(Y), axis=1).reshape(-1, group)
    return ok.all(axis=1)


@dataclass
class SobolResult:
    names: tuple[str, ...]
    outputs: tuple[str, ...]
    S1: np.ndarray  # (k outputs, d)
    S1_conf: np.ndarray
    ST: np.ndarray
    ST_conf: np.ndarray
    n_base: int
    n_used: int  # base samples kept (groups without failures)
    n_evals: int
    conf_level: float
    lower: np.ndarray
    upper: np.ndarray
    wall_s: float = 0.0
    warnings: list[str] = field(default_factory=list)

    def rows(self) -> list[dict]:
        return [
            {
                "output": o,
                "parameter": n,
                "S1": float(self.S1[j, i]),
                "S1_conf": float(self.S1_conf[j, i]),
                "ST": float(self.ST[j, i]),
                "ST_conf": float(self.ST_conf[j, i]),
            }
            for j, o in enumerate(self.outputs)
            for i, n in enumerate(self.names)
        ]


@dataclass
class MorrisResult:
    names: tuple[str, ...]
    outputs: tuple[str, ...]
    mu: np.ndarray  # (k, d)
    mu_star: np.ndarray
    mu_star_conf: np.ndarray
    sigma: np.ndarray
    n_trajectories: int
    n_used: int
    n_evals: int
    num_levels: int
    lower: np.ndarray
    upper: np.ndarray
    wall_s: float = 0.0
    warnings: list[str] = field(default_factory=list)

    def rows(self) -> list[dict]:
        return [
            {
                "output": o,
                "parameter": n,
                "mu": float(self.mu[j, i]),
                "mu_star": float(self.mu_star[j, i]),
                "mu_star_conf": float(self.mu_star_conf[j, i]),
                "sigma": float(self.sigma[j, i]),
            }
            for j, o in enumerate(self.outputs)
            for i, n in enumerate(self.names)
        ]


def sobol_sample(names, lower, upper, n_base: int, *, seed: int = 0) -> np.ndarray:
    """Saltelli cross-sample, ``n_base (d + 2)`` rows (``n_base`` should be a power of 2)."""
    from SALib.sample import sobol as sobol_sampler

    if n_base < 2:
        raise ValueError(f"n_base = {n_base} is out of range: need at least 2 base samples")
    with warnings.catch_warnings():
        # SALib warns for a non-power-of-2 n_base; we say so ourselves
        warnings.simplefilter("ignore")
        return sobol_sampler.sample(
            salib_problem(names, lower, upper),
            int(n_base),
            calc_second_order=False,
            scramble=True,
            seed=seed,
        )


def sobol_analyze(
    names,
    lower,
    upper,
    Y,
    *,
    outputs: Sequence[str] | None = None,
    seed: int = 0,
    conf_level: float = 0.95,
    num_resamples: int = 200,
    n_evals: int | None = None,
) -> SobolResult:
    """S1 and ST per output from the outputs ``Y`` (n_base (d + 2), k) of :func:`sobol_sample`."""
    from SALib.analyze import sobol as sobol_analyzer

    d = len(names)
    Y = np.asarray(Y, float)
    Y = Y[:, None] if Y.ndim == 1 else Y
    if len(Y) % (d + 2):
        raise ValueError(f"{len(Y)} outputs is not a multiple of d + 2 = {d + 2}")
    n_base = len(Y) // (d + 2)
    outputs = (
        tuple(outputs) if outputs is not None else tuple(f"y{j + 1}" for j in range(Y.shape[1]))
    )
    keep = _keep_groups(Y, d + 2)
    warns = []
    if not keep.all():
        warns.append(
            f"{int((~keep).sum())} of {n_base} Saltelli groups contain failed points and were "
            "dropped: the indices are conditional on success"
        )
    if keep.sum() < 2:
        raise ValueError(f"only {int(keep.sum())} complete Saltelli groups: too many failed points")
    if n_base & (n_base - 1):
        warns.append(
            f"n_base = {n_base} is not a power of 2: the Sobol' sequence loses its balance"
        )
    Yk = Y.reshape(n_base, d + 2, -1)[keep].reshape(-1, Y.shape[1])
    problem = salib_problem(names, lower, upper)
    k = Y.shape[1]
    S1, S1c, ST, STc = (np.full((k, d), np.nan) for _ in range(4))
    for j in range(k):
        y = Yk[:, j]
        if np.ptp(y) == 0:
            warns.append(f"output {outputs[j]!r} is constant over the sample: indices undefined")
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = sobol_analyzer.analyze(
                problem,
                y,
                calc_second_order=False,
                num_resamples=num_resamples,
                conf_level=conf_level,
                seed=seed,
            )
        S1[j], S1c[j], ST[j], STc[j] = res["S1"], res["S1_conf"], res["ST"], res["ST_conf"]
    return SobolResult(
        tuple(names),
        outputs,
        S1,
        S1c,
        ST,
        STc,
        n_base,
        int(keep.sum()),
        len(Y) if n_evals is None else n_evals,
        conf_level,
        np.asarray(lower, float),
        np.asarray(upper, float),
        warnings=warns,
    )


def sobol_indices(
    f,
    names,
    lower,
    upper,
    n_base: int,
    *,
    outputs=None,
    seed: int = 0,
    mapper=None,
    chunk_size: int | None = None,
    conf_level: float = 0.95,
    num_resamples: int = 200,
) -> SobolResult:
    """Sample, evaluate (``f`` vectorised, optionally through ``mapper``) and analyse
    (see module doc)."""
    t0 = time.perf_counter()
    X = sobol_sample(names, lower, upper, n_base, seed=seed)
    Y = evaluate(f, X, mapper=mapper, chunk_size=chunk_size)
    res = sobol_analyze(
        names,
        lower,
        upper,
        Y,
        outputs=outputs,
        seed=seed,
        conf_level=conf_level,
        num_resamples=num_resamples,
    )
    res.wall_s = time.perf_counter() - t0
    return res


def morris_sample(
    names, lower, upper, n_trajectories: int, *, num_levels: int = 4, seed: int = 0
) -> np.ndarray:
    """``n_trajectories (d + 1)`` rows of Morris one-at-a-time trajectories."""
    from SALib.sample import morris as morris_sampler

    if n_trajectories < 2:
        raise ValueError(f"n_trajectories = {n_trajectories} is out of range: need at least 2")
    return morris_sampler.sample(
        salib_problem(names, lower, upper), int(n_trajectories), num_levels=num_levels, seed=seed
    )


def morris_analyze(
    names,
    lower,
    upper,
    X,
    Y,
    *,
    outputs=None,
    num_levels: int = 4,
    seed: int = 0,
    conf_level: float = 0.95,
    num_resamples: int = 200,
    n_evals: int | None = None,
) -> MorrisResult:
    from SALib.analyze import morris as morris_analyzer

    d = len(names)
    X, Y = np.asarray(X, float), np.asarray(Y, float)
    Y = Y[:, None] if Y.ndim == 1 else Y
    if len(Y) % (d + 1) or len(X) != len(Y):
        raise ValueError(
            f"X ({len(X)} rows) and Y ({len(Y)} rows) must hold whole trajectories of d + 1 = "
            f"{d + 1}"
        )
    r = len(Y) // (d + 1)
    outputs = (
        tuple(outputs) if outputs is not None else tuple(f"y{j + 1}" for j in range(Y.shape[1]))
    )
    keep = _keep_groups(Y, d + 1)
    warns = []
    if not keep.all():
        warns.append(
            f"{int((~keep).sum())} of {r} Morris trajectories contain failed points and were "
            "dropped"
        )
    if keep.sum() < 2:
        raise ValueError(
            f"only {int(keep.sum())} complete Morris trajectories: too many failed points"
        )
    rows = np.repeat(keep, d + 1)
    Xk, Yk = X[rows], Y[rows]
    problem = salib_problem(names, lower, upper)
    k = Y.shape[1]
    mu, mus, musc, sig = (np.full((k, d), np.nan) for _ in range(4))
    for j in range(k):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = morris_analyzer.analyze(
                problem,
                Xk,
                Yk[:, j],
                num_resamples=num_resamples,
                conf_level=conf_level,
                num_levels=num_levels,
                seed=seed,
            )
        mu[j], mus[j], musc[j], sig[j] = (
            res["mu"],
            res["mu_star"],
            res["mu_star_conf"],
            res["sigma"],
        )
    return MorrisResult(
        tuple(names),
        outputs,
        mu,
        mus,
        musc,
        sig,
        r,
        int(keep.sum()),
        len(Y) if n_evals is None else n_evals,
        num_levels,
        np.asarray(lower, float),
        np.asarray(upper, float),
        warnings=warns,
    )


def morris_screening(
    f,
    names,
    lower,
    upper,
    n_trajectories: int,
    *,
    outputs=None,
    num_levels: int = 4,
    seed: int = 0,
    mapper=None,
    chunk_size: int | None = None,
    conf_level: float = 0.95,
    num_resamples: int = 200,
) -> MorrisResult:
    t0 = time.perf_counter()
    X = morris_sample(names, lower, upper, n_trajectories, num_levels=num_levels, seed=seed)
    Y = evaluate(f, X, mapper=mapper, chunk_size=chunk_size)
    res = morris_analyze(
        names,
        lower,
        upper,
        X,
        Y,
        outputs=outputs,
        num_levels=num_levels,
        seed=seed,
        conf_level=conf_level,
        num_resamples=num_resamples,
    )
    res.wall_s = time.perf_counter() - t0
    return res


# --- FE summary outputs -----------------------------------------------------------------------


def summary_outputs(values, n_snapshots: int, n_points: int) -> tuple[float, float]:
    """``(peak force kN, lateral bulge mm)`` of one measurement vector ``[u_h, u_v, r]``.

    Bulge: the largest front-face horizontal displacement at the last snapshot.
    """
    from problems.inverse import layout

    u_h, _, r = layout.unstack(values, n_snapshots, n_points)
    return float(np.max(r)), float(np.max(u_h[-1]))


class FESummaries:
    """Vectorised evaluator ``X (n, d) physical -> Y (n, 3) = [cost, peak force, bulge]`` of an
    objective.

    The forward runs of one call go through ``mapper`` as one batch (``bench.parallel.mapper``, the
    suites' evaluator); infeasible points (box or ``check``) and failed runs give NaN rows.
    ``n_evals`` counts the forward runs attempted, ``n_failed``/``n_infeasible`` the NaN rows.
    """

    outputs = FE_OUTPUTS

    def __init__(self, objective, n_snapshots: int, n_points: int, mapper=None):
        self.objective = objective
        self.n_snapshots, self.n_points = int(n_snapshots), int(n_points)
        self.mapper = mapper
        self.n_evals = self.n_failed = self.n_infeasible = 0
        self.fe_wall_s = 0.0

    def __call__(self, X) -> np.ndarray:
        from problems.inverse.evaluator import sequential_map
        from problems.inverse.protocol import RunModel

        obj = self.objective
        X = np.atleast_2d(np.asarray(X, float))
        Y = np.full((len(X), 3), np.nan)
        feasible = []
        for i, x in enumerate(X):
            if (
                np.any(x < obj.lower - 1e-9 * np.abs(obj.lower))
                or np.any(x > obj.upper + 1e-9 * np.abs(obj.upper))
                or obj.model.check(x) is not None
            ):
                self.n_infeasible += 1
            else:
                feasible.append(i)
        mapper = self.mapper or sequential_map
        results = list(mapper(RunModel(obj.model), [X[i] for i in feasible]))
        self.n_evals += len(feasible)
        for i, res in zip(feasible, results):
            self.fe_wall_s += res.wall_s
            if not res.ok or res.values is None or not np.all(np.isfinite(res.values)):
                self.n_failed += 1
                continue
            v = np.asarray(res.values, float)
            r = obj.whiten(obj.data - v)
            Y[i] = (float(r @ r), *summary_outputs(v, self.n_snapshots, self.n_points))
        return Y

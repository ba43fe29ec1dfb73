"""Model-error treatments: what the inverse model's discretisation gets wrong, and how the
objective accounts for it.

With data ``U_E`` made on a fine discretisation and an inverse model ``U_N`` on a coarser one,
the misfit ``U_E - U_N(x)`` holds the measurement noise *and* the discretisation error
``eps(x) = U_hifi(x) - U_N(x)``. The treatments, all behind the objective:

* ``none``      : the plain residual.
* ``one-point`` : ``eps`` evaluated once at the start ``x0`` with a high-fidelity model and
  subtracted from the data: ``U_E - eps(x0) - U_N(x)``.
* ``iterated``  : the one-point correction re-evaluated at the current solution, the problem
  re-solved from there, until the parameters move less than a tolerance (see
  :func:`solvers.corrected.solve_iterated`).
* ``first-order`` : the iterated correction made first-order consistent (Alexandrov et al. 1998;
  manifold mapping, Echeverria & Hemker 2005): round k also takes the exact (DDM) Jacobians of
  both models at ``x_k`` and minimises ``||U_E - eps_k - S_k (x - x_k) - U_N(x)||_W`` with
  ``S_k = J_hifi(x_k) - J_N(x_k)``, so that the corrected model matches the high-fidelity model's
  response *and* Jacobian at ``x_k``. Its fixed point solves
  ``J_hifi(x*)^T W (U_E - U_hifi(x*)) = 0``: the high-fidelity model's own optimum, where the
  zero-order ``iterated`` stops at ``J_N(x*)^T W (U_E - U_hifi(x*)) = 0`` (:func:`first_order`).
* ``bae``       : the Bayesian approximation error approach (Kaipio & Somersalo): ``eps`` over K
  prior samples (Latin hypercube in the bounds); the data are shifted by its mean and its
  covariance is added to that of the noise, ``C + C_eps``, kept as low rank plus diagonal.

The honesty rule: the discretisation that made a model-error data set is never used inside the
inverse loop (forward model, high-fidelity model of a correction, BAE statistics, surrogate
training); :func:`check_honest` enforces it. Every high-fidelity run is counted apart
(:class:`Correction` ``n_hifi``, ``hifi_wall_s``) so that it can be charged.
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass, field, replace

import numpy as np

from problems.inverse.evaluator import sequential_map
from problems.inverse.protocol import RunModel, provides_jacobian

#: the treatments a correction can be; see :data:`TREATMENTS` for what a caller may ask for
CORRECTIONS = ("none", "one-point", "iterated", "first-order", "bae")
#: the treatments that re-evaluate their correction at a solver's solutions
#: (:func:`solvers.corrected.solve_iterated`): they exist for identifications only
ITERATED = ("iterated", "first-order")
#: what ``--correction``, a suite's ``treatments`` and ``Identification.treatment`` accept:
#: a correction, or ``default`` = the case's default treatment with its region, high-fidelity
#: mesh and samples (:func:`problems.inverse.cases.default_treatment`)
TREATMENTS = (*CORRECTIONS, "default")


class HonestyError(ValueError):
    """A model inside the inverse loop uses the discretisation that made the data."""


def check_honest(data_discretisation: str | None, tier: str, **models_in_loop: str | None) -> None:
    """Refuse a model-error data set whose discretisation is used by any model in the loop.

    data_discretisation : canonical key of the discretisation that made the data (None: unknown)
    tier                : ``consistent`` (the data were made with the inverse model itself: allowed,
                          labelled) or ``model-error``
    models_in_loop      : role -> canonical discretisation key (e.g. ``forward="coarse/eighth"``,
                          ``hifi="fine/eighth"``); None entries are ignored
    """
    if tier == "consistent" or data_discretisation is None:
        return
    for role, key in models_in_loop.items():
        if key is not None and key == data_discretisation:
            raise HonestyError(
                f"the {role} model uses discretisation {key}, which made the model-error data: the "
                "discretisation that makes pseudo-experimental data is never used inside the "
                "inverse loop (use the consistent tier, or data made on another discretisation)"
            )


@dataclass
class Correction:
    """A model-error treatment's effect on the objective.

    treatment  : one of :data:`CORRECTIONS`
    shift      : (m,) subtracted from the data (mean model error), same units as the data
    factor     : (m, K) low-rank factor V of the added covariance ``C_eps = V V^T`` (or None)
    n_hifi     : high-fidelity runs it took; ``hifi_wall_s`` their total wall time, s
    n_inverse  : inverse-model runs it took (beyond the identification's own); ``inverse_wall_s``
    n_failed   : sample points whose high-fidelity or inverse run failed (left out)
    points     : (k, n) physical parameter points where eps was evaluated
    provenance : hifi and inverse discretisations, sample seed, content hash
    slope      : (m, n) ``S = J_hifi - J_inverse`` at ``anchor``, data units per physical
                 parameter unit (first-order correction; None: zero-order)
    anchor     : (n,) the physical point ``x_k`` of the slope: the objective's data are
                 ``U_E - shift - slope (x - anchor)`` (:class:`AffineCorrected`)
    """

    treatment: str
    shift: np.ndarray | None = None
    factor: np.ndarray | None = None
    n_hifi: int = 0
    hifi_wall_s: float = 0.0
    n_inverse: int = 0
    inverse_wall_s: float = 0.0
    n_failed: int = 0
    points: np.ndarray | None = None
    provenance: dict = field(default_factory=dict)
    slope: np.ndarray | None = None
    anchor: np.ndarray | None = None

    @property
    def hash(self) -> str:
        """Content hash of the statistics (shift, factor, points; slope and anchor when present,
        so that a zero-order correction's hash is what it always was)."""
        h = hashlib.sha256(self.treatment.encode())
        for a in (self.shift, self.factor, self.points, self.slope, self.anchor):
            if a is not None:
                h.update(np.ascontiguousarray(a, dtype=float).tobytes())
        return h.hexdigest()

    def save(self, path) -> None:
        """Write the statistics to ``path`` (npz, with the hash and provenance)."""
        import json

        from problems.io.atomic import atomic_savez

        atomic_savez(
            path,
            treatment=self.treatment,
            shift=_or_empty(self.shift),
            factor=_or_empty(self.factor),
            points=_or_empty(self.points),
            counts=np.array(
                [self.n_hifi, self.hifi_wall_s, self.n_inverse, self.inverse_wall_s, self.n_failed]
            ),
            provenance=json.dumps(self.provenance, sort_keys=True),
            slope=_or_empty(self.slope),
            anchor=_or_empty(self.anchor),
            hash=self.hash,
        )

    @classmethod
    def load(cls, path) -> "Correction":
        """Read statistics written by :meth:`save`; the content hash is verified. A torn file
        (truncated zip, missing array, hash mismatch) raises ValueError naming ``path``; a missing
        one FileNotFoundError."""
        import json
        import zipfile

        try:
            with np.load(path, allow_pickle=False) as f:
                counts = f["counts"]
                c = cls(
                    str(f["treatment"]),
                    _or_none(f["shift"]),
                    _or_none(f["factor"]),
                    int(counts[0]),
                    float(counts[1]),
                    int(counts[2]),
                    float(counts[3]),
                    int(counts[4]),
                    _or_none(f["points"]),
                    json.loads(str(f["provenance"])),
                    *(_or_none(f[k]) if k in f.files else None for k in ("slope", "anchor")),
                )
                stored = str(f["hash"])
        except FileNotFoundError:
            raise
        except (zipfile.BadZipFile, EOFError, KeyError, OSError, ValueError, IndexError) as exc:
            raise ValueError(
                f"BAE statistics {path} are torn ({type(exc).__name__}: {exc})"
            ) from None
        if stored != c.hash:
            raise ValueError(f"BAE statistics {path} are torn (content hash mismatch)")
        return c


def _or_empty(a):
    return np.zeros(0) if a is None else np.asarray(a, float)


def _or_none(a):
    return None if a.size == 0 else np.array(a)


def _run_pair(hifi, inverse, X, mapper, with_jacobian: bool = False):
    """Results of both models at the points X; per point (hifi, inverse) ForwardResults (their
    exact Jacobians too with ``with_jacobian``) or None if either failed."""
    mapper = mapper or sequential_map
    t0 = time.perf_counter()
    hi = list(mapper(RunModel(hifi, with_jacobian), list(X)))
    t1 = time.perf_counter()
    lo = list(mapper(RunModel(inverse, with_jacobian), list(X)))
    t2 = time.perf_counter()
    pairs = [(h, lo_) if (h.ok and lo_.ok) else None for h, lo_ in zip(hi, lo)]
    # wall times: the models' own timings (summed over workers), not the elapsed time of the batch
    hifi_s = sum(r.wall_s for r in hi) or (t1 - t0)
    inv_s = sum(r.wall_s for r in lo) or (t2 - t1)
    return pairs, hifi_s, inv_s


def one_point(hifi, inverse, x0, *, mapper=None, provenance: dict | None = None) -> Correction:
    """The one-point additive correction ``eps(x0) = U_hifi(x0) - U_inverse(x0)``
    (physical ``x0``)."""
    x0 = np.asarray(x0, float)
    pairs, hifi_s, inv_s = _run_pair(hifi, inverse, [x0], mapper)
    if pairs[0] is None:
        raise RuntimeError(f"model-error correction: a model failed at x0 = {x0.tolist()}")
    return _at_point("one-point", pairs[0], x0, hifi_s, inv_s, dict(provenance or {}))


def _at_point(treatment: str, pair, x, hifi_s, inv_s, provenance: dict, **fields) -> Correction:
    """The correction of one high-fidelity / inverse run ``pair`` at the physical ``x``: the
    shift ``U_hifi(x) - U_inverse(x)``, the two runs counted with their wall times, ``fields``
    (e.g. a first-order slope) as given."""
    hi, lo = pair
    return Correction(
        treatment,
        shift=np.asarray(hi.values) - np.asarray(lo.values),
        n_hifi=1,
        hifi_wall_s=hifi_s,
        n_inverse=1,
        inverse_wall_s=inv_s,
        points=np.asarray(x, float)[None, :],
        provenance=provenance,
        **fields,
    )


def first_order(hifi, inverse, x, *, mapper=None, provenance: dict | None = None) -> Correction:
    """The first-order consistent correction at the physical ``x`` (the point ``x_k`` of a round
    of :func:`solvers.corrected.solve_iterated`): ``shift = U_hifi(x) - U_inverse(x)`` and
    ``slope = J_hifi(x) - J_inverse(x)`` (m, n; data units per physical parameter unit), from
    one run with exact (DDM) sensitivities of each model. The two runs are counted (``n_hifi``,
    ``n_inverse``) with their wall times, which hold the sensitivities' price, so that the
    charged forward-equivalents are their real cost."""
    x = np.asarray(x, float)
    for name, model in (("high-fidelity", hifi), ("inverse", inverse)):
        if not provides_jacobian(model):
            raise ValueError(
                f"the first-order correction needs exact Jacobians: the {name} model "
                f"{type(model).__name__} provides none; allowed: models with exact Jacobians "
                "(the FE models), or the iterated correction"
            )
    pairs, hifi_s, inv_s = _run_pair(hifi, inverse, [x], mapper, with_jacobian=True)
    if pairs[0] is None or pairs[0][0].jacobian is None or pairs[0][1].jacobian is None:
        raise RuntimeError(f"first-order correction: a model failed at x = {x.tolist()}")
    hi, lo = pairs[0]
    return _at_point(
        "first-order",
        pairs[0],
        x,
        hifi_s,
        inv_s,
        {**(provenance or {}), "with_jacobian": True},
        slope=np.asarray(hi.jacobian, float) - np.asarray(lo.jacobian, float),
        anchor=x.copy(),
    )


class AffineCorrected:
    """The inverse model ``model`` plus the affine part of a first-order correction:
    ``U(x) = U_N(x) + slope (x - anchor)`` and ``dU/dx = J_N(x) + slope`` (physical units), so
    that the objective's residual is ``U_E - shift - slope (x - anchor) - U_N(x)`` (the shift is
    taken off the data). Picklable (it is shipped to workers); ``names``, ``check`` and the
    Jacobian's declared price are the model's."""

    def __init__(self, model, slope, anchor):
        self.model = model
        self.slope = np.asarray(slope, float)
        self.anchor = np.asarray(anchor, float)
        self.names = model.names
        self.provides_jacobian = provides_jacobian(model)
        self.jacobian_cost = getattr(model, "jacobian_cost", None)

    def check(self, x):
        return self.model.check(x)

    def __call__(self, x, jacobian: bool = False):
        x = np.asarray(x, float)
        res = self.model(x, jacobian=True) if jacobian else self.model(x)
        if not res.ok or res.values is None:
            return res
        values = np.asarray(res.values, float) + self.slope @ (x - self.anchor)
        J = None if res.jacobian is None else np.asarray(res.jacobian, float) + self.slope
        return replace(res, values=values, jacobian=J)


def corrected_model(model, correction: Correction | None):
    """``model`` with the affine part of ``correction`` (:class:`AffineCorrected`) when it has a
    slope (first-order), else ``model`` itself (the shift goes off the data)."""
    if correction is None or correction.slope is None:
        return model
    return AffineCorrected(model, correction.slope, correction.anchor)


def bae_statistics(
    hifi,
    inverse,
    lower,
    upper,
    *,
    samples: int = 32,
    seed: int = 0,
    mapper=None,
    rank: int | None = None,
    provenance: dict | None = None,
) -> Correction:
    """Bayesian approximation error: mean and low-rank covariance of ``eps`` over a seeded Latin
    hypercube of ``samples`` points in the box [lower, upper] (physical units).

    The covariance factor keeps the leading ``rank`` (default: all) principal directions of the
    centred errors, ``C_eps = V V^T`` with ``V = E_c Q S / sqrt(K - 1)``.
    """
    from scipy.stats import qmc

    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    X = qmc.scale(
        qmc.LatinHypercube(d=lower.size, seed=np.random.default_rng(seed)).random(samples),
        lower,
        upper,
    )
    X = np.array([x for x in X if hifi.check(x) is None and inverse.check(x) is None])
    pairs, hifi_s, inv_s = _run_pair(hifi, inverse, X, mapper)
    good = [i for i, p in enumerate(pairs) if p is not None]
    if len(good) < 2:
        raise RuntimeError(
            f"BAE statistics: only {len(good)} of {len(X)} sample points ran on both models"
        )
    E = np.array([pairs[i][0].values - pairs[i][1].values for i in good])  # (K, m)
    mean = E.mean(axis=0)
    U, S, _ = np.linalg.svd((E - mean).T, full_matrices=False)  # (m, K)
    k = len(S) if rank is None else min(rank, len(S))
    factor = U[:, :k] * (S[:k] / np.sqrt(len(good) - 1))
    return Correction(
        "bae",
        shift=mean,
        factor=factor,
        n_hifi=len(X),
        hifi_wall_s=hifi_s,
        n_inverse=len(X),
        inverse_wall_s=inv_s,
        n_failed=len(X) - len(good),
        points=X[good],
        provenance={**(provenance or {}), "samples": samples, "seed": seed, "rank": k},
    )

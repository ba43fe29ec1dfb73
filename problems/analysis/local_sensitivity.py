"""Local sensitivities of the measurements to each parameter (the paper's eqs. 16-18, Fig. 5).

For a parameter ``x_i`` perturbed by the relative step ``delta`` about its reference value
(``x_i -> x_i (1 + delta)``, all other parameters at their reference), and for each snapshot ``n``
of the ``N`` snapshots::

    s_ux,n(x_i) = (1 - ||u^x_n(x_i)|| / ||u^x_n(x^REF)||) / delta      horizontal field (eq. 16)
    s_uy,n(x_i) = (1 - ||u^y_n(x_i)|| / ||u^y_n(x^REF)||) / delta      vertical field   (eq. 17)
    s_r,n(x_i)  = (1 -     r_n(x_i)  /     r_n(x^REF)   ) / delta      reaction force   (eq. 18)

``||.||`` is the Euclidean norm over the ``m`` measurement points of one snapshot. The paper's
sensitivity is the sum over the snapshots, ``s = sum_n s_n``; both are returned. The values are
dimensionless: ``s_n ~ -d ln||u_n|| / d ln x_i`` (minus the elasticity of the snapshot norm), so a
parameter whose increase enlarges a field has a *negative* sensitivity.

If the model cannot be evaluated at ``x_i (1 + delta)`` (infeasible parameters, or no
convergence), the step is taken to the other side, ``x_i (1 - delta)``; the signed step used is
recorded (``deltas``) and the formulas above are applied with it, so the result still estimates
the same quantity. If both sides fail the sensitivities of that parameter are NaN.

Everything here is pure: it works for any function ``x -> (u_h (N, m), u_v (N, m), r (N,))``,
e.g. :class:`ModelFields` around any forward model whose measurement vector has the layout
``[u_h (N x m, snapshot-major), u_v (N x m), r (N)]``.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from problems.inverse import layout
from problems.inverse.evaluator import sequential_map

MEASURES = ("ux", "uy", "r")
"""Keys of the three sensitivity measures: horizontal field, vertical field, reaction force."""

MEASURE_LABELS = {
    "ux": "horizontal displacement $u^x$",
    "uy": "vertical displacement $u^y$",
    "r": "reaction force $r$",
}

Fields = tuple[np.ndarray, np.ndarray, np.ndarray]


class ModelFields:
    """Picklable ``x -> (u_h, u_v, r)`` around a forward model (``model(x).values`` in the layout).

    Returns ``None`` when the model reports a failure (``ok=False``) or ``check(x)`` rejects ``x``.
    """

    def __init__(self, model, n_snapshots: int, n_points: int):
        self.model = model
        self.n_snapshots = int(n_snapshots)
        self.n_points = int(n_points)

    def __call__(self, x) -> Fields | None:
        x = np.asarray(x, dtype=float)
        check = getattr(self.model, "check", None)
        if check is not None and check(x) is not None:
            return None
        res = self.model(x)
        if not res.ok or res.values is None:
            return None
        return layout.unstack(res.values, self.n_snapshots, self.n_points)


def snapshot_sensitivities(
    reference: Fields, perturbed: Fields, delta: float
) -> dict[str, np.ndarray]:
    """Eqs. 16-18 per snapshot: ``{"ux": (N,), "uy": (N,), "r": (N,)}`` for one signed ``delta``.

    A snapshot whose reference norm (or force) is zero gives NaN (the ratio is undefined).
    """
    if not delta:
        raise ValueError("delta must be non-zero")
    ref_h, ref_v, ref_r = (np.asarray(a, dtype=float) for a in reference)
    per_h, per_v, per_r = (np.asarray(a, dtype=float) for a in perturbed)
    if ref_h.shape != per_h.shape or ref_v.shape != per_v.shape or ref_r.shape != per_r.shape:
        raise ValueError("reference and perturbed fields have different shapes")

    def ratio(num, den):
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(den != 0, num / np.where(den != 0, den, 1.0), np.nan)

    nh = ratio(np.linalg.norm(per_h, axis=1), np.linalg.norm(ref_h, axis=1))
    nv = ratio(np.linalg.norm(per_v, axis=1), np.linalg.norm(ref_v, axis=1))
    nr = ratio(per_r, ref_r)
    return {"ux": (1.0 - nh) / delta, "uy": (1.0 - nv) / delta, "r": (1.0 - nr) / delta}


@dataclass
class LocalSensitivities:
    """Result of :func:`local_sensitivities` (arrays are indexed [parameter] or [parameter,
    snapshot])."""

    names: tuple[str, ...]
    x_ref: np.ndarray
    delta: float
    # (n,) signed relative step used per parameter (nan: failed)
    deltas: np.ndarray
    per_snapshot: dict[str, np.ndarray]  # measure -> (n, N)
    n_evals: int
    messages: list[str] = field(default_factory=list)

    @property
    def summed(self) -> dict[str, np.ndarray]:
        """The paper's sensitivities: sum over the snapshots, measure -> (n,)."""
        return {k: v.sum(axis=1) for k, v in self.per_snapshot.items()}

    @property
    def total_abs(self) -> np.ndarray:
        """``|s_ux| + |s_uy| + |s_r|`` per parameter (one number to rank parameters by)."""
        s = self.summed
        return np.abs(s["ux"]) + np.abs(s["uy"]) + np.abs(s["r"])

    @property
    def n_snapshots(self) -> int:
        return self.per_snapshot["ux"].shape[1]

    def ranking(self) -> list[str]:
        """Parameter names from the least to the most sensitive (by :attr:`total_abs`; NaN last)."""
        t = np.where(np.isfinite(self.total_abs), self.total_abs, np.inf)
        return [self.names[i] for i in np.argsort(t, kind="stable")]

    def smallest(self, measure: str | None = None) -> str:
        """Name of the least sensitive parameter, overall or for one measure (by |s|)."""
        if measure is None:
            return self.ranking()[0]
        s = np.abs(self.summed[measure])
        return self.names[int(np.nanargmin(s))]

    def rows(self) -> list[dict]:
        """One row per parameter: summed s_ux, s_uy, s_r, the sum of magnitudes and the step
        used."""
        s, t = self.summed, self.total_abs
        return [
            {
                "parameter": n,
                "reference": float(self.x_ref[i]),
                "delta": float(self.deltas[i]),
                "s_ux": float(s["ux"][i]),
                "s_uy": float(s["uy"][i]),
                "s_r": float(s["r"][i]),
                "sum_abs": float(t[i]),
            }
            for i, n in enumerate(self.names)
        ]

    def snapshot_rows(self) -> list[dict]:
        """One row per (parameter, snapshot): the per-snapshot terms of eqs. 16-18."""
        out = []
        for i, n in enumerate(self.names):
            for k in range(self.n_snapshots):
                out.append(
                    {
                        "parameter": n,
                        "snapshot": k + 1,
                        **{f"s_{m}": float(self.per_snapshot[m][i, k]) for m in MEASURES},
                    }
                )
        return out


def local_sensitivities(
    fields: Callable[[np.ndarray], Fields | None],
    x_ref,
    *,
    delta: float = 0.01,
    names: Sequence[str] | None = None,
    mapper=None,
    active: Sequence[int] | None = None,
) -> LocalSensitivities:
    """Eqs. 16-18 for every parameter (or the indices ``active``) of ``x_ref``.

    fields : ``x -> (u_h (N, m), u_v (N, m), r (N,))`` or ``None`` on failure (it may also raise);
             picklable if a parallel ``mapper`` is used
    x_ref  : (n,) reference point, physical units (no zero entries: the step is relative)
    delta  : relative perturbation (the paper: 0.01)
    mapper : ``mapper(fn, items) -> list`` for the 1 + n evaluations (one batch), None: sequential

    Raises RuntimeError if the reference itself cannot be evaluated.
    """
    x_ref = np.asarray(x_ref, dtype=float).ravel()
    n = x_ref.size
    names = tuple(names) if names is not None else tuple(f"x{i + 1}" for i in range(n))
    if len(names) != n:
        raise ValueError(f"{len(names)} names for {n} parameters")
    if not (math.isfinite(delta) and delta != 0 and abs(delta) < 1):
        raise ValueError(f"delta = {delta!r} is out of range: 0 < |delta| < 1")
    if np.any(x_ref == 0):
        raise ValueError("x_ref has zero entries: a relative perturbation is undefined there")
    idx = list(range(n)) if active is None else [int(i) for i in active]
    mapper = mapper or sequential_map
    safe = _Safe(fields)

    def shifted(i, d):
        x = x_ref.copy()
        x[i] = x_ref[i] * (1.0 + d)
        return x

    outs = mapper(safe, [x_ref] + [shifted(i, delta) for i in idx])
    n_evals = len(outs)
    ref = outs[0]
    if ref is None:
        raise RuntimeError("the model cannot be evaluated at the reference point")
    results = dict(zip(idx, outs[1:]))
    deltas = np.full(n, np.nan)
    for i in idx:
        if results[i] is not None:
            deltas[i] = delta
    retry = [i for i in idx if results[i] is None]
    messages = []
    if retry:
        again = mapper(safe, [shifted(i, -delta) for i in retry])
        n_evals += len(again)
        for i, out in zip(retry, again):
            if out is not None:
                results[i], deltas[i] = out, -delta
                messages.append(f"{names[i]}: x(1 + {delta:g}) failed, used x(1 - {delta:g})")
            else:
                messages.append(f"{names[i]}: both x(1 +- {delta:g}) failed, sensitivities are NaN")
    N = np.asarray(ref[2]).size
    per = {k: np.full((n, N), np.nan) for k in MEASURES}
    for i in idx:
        if results[i] is None:
            continue
        s = snapshot_sensitivities(ref, results[i], deltas[i])
        for k in MEASURES:
            per[k][i] = s[k]
    for msg in messages:
        warnings.warn(f"local_sensitivities: {msg}", RuntimeWarning, stacklevel=2)
    return LocalSensitivities(names, x_ref, float(delta), deltas, per, n_evals, messages)


class _Safe:
    """Picklable wrapper: an exception inside ``fields`` is a failure (None), not a crash."""

    def __init__(self, fn):
        self.fn = fn

    def __call__(self, x):
        try:
            out = self.fn(np.asarray(x, dtype=float))
        except Exception:  # noqa: BLE001 - a failed point is reported, never raised into the batch
            return None
        if out is None:
            return None
        u_h, u_v, r = (np.asarray(a, dtype=float) for a in out)
        if not (np.all(np.isfinite(u_h)) and np.all(np.isfinite(u_v)) and np.all(np.isfinite(r))):
            return None
        return u_h, u_v, r

r"""The surrogate forward model: POD basis + regression of its coefficients, behind the
forward-model protocol.

``U(x) = ybar + sigma * (Phi a(z))``,  ``z = (x - lower) / (upper - lower)``, and its Jacobian
``dU/dx = diag(sigma) Phi (da/dz) diag(1 / (upper - lower))`` in physical units, exact for the
surrogate (the regressions differentiate their kernels).

Validity: ``check`` rejects what the model the surrogate stands for rejects (its own ``check``,
for the FE model the case's material rule) and points outside the case's box. Extrapolation: a
point inside the box but outside the box the training design covered gets a result whose
``message`` starts with ``extrapolation:``; :meth:`SurrogateModel.extrapolation` also gives the
distance to the nearest training point and, on request, whether the point lies in the convex hull
of the training points (a linear programme; in 6 dimensions the hull of a few hundred points
fills only a small part of the box, so it is a diagnostic, not the flag).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from problems.inverse.protocol import ForwardResult
from problems.surrogate.pod import POD


@dataclass(frozen=True, eq=False)
class SurrogateModel:
    """A picklable forward model approximating another one (see the module docstring).

    names      : parameter names
    lower, upper : (d,) the case's box, physical units (also the scaling of z)
    pod        : the POD basis (mean, scale = the data's sigma, modes)
    regression : :class:`~problems.surrogate.regression.RBFFit` or ``GPFit`` of the coefficients
    train_z    : (n, d) scaled successful training points
    design_box : (lower, upper) of the training design, physical units
    checker    : object whose ``check(x)`` is the validity rule (the FE model; never run), or None
    hold_out_variance : (m,) mean squared hold-out error of each measurement, units of the
                 measurement squared (mm^2, kN^2), or None before validation; the likelihood adds it
                 to the noise variance: ``C = diag(sigma^2 + hold_out_variance)``
    info       : settings, cost, selection, validation and hashes (JSON-ready)
    """

    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    pod: POD
    regression: object
    train_z: np.ndarray
    design_box: tuple[np.ndarray, np.ndarray]
    checker: object = None
    hold_out_variance: np.ndarray | None = None
    info: dict = field(default_factory=dict)

    provides_jacobian = True

    @property
    def n_values(self) -> int:
        return self.pod.mean.size

    @property
    def n_modes(self) -> int:
        return self.pod.n_modes

    @property
    def kind(self) -> str:
        return self.regression.kind

    @property
    def hash(self) -> str | None:
        """Content hash of the stored model (set by
        :func:`problems.surrogate.store.save` / ``load``)."""
        return self.info.get("hash")

    def to_scaled(self, x) -> np.ndarray:
        return (np.asarray(x, float) - self.lower) / (self.upper - self.lower)

    @cached_property
    def _weights(self) -> np.ndarray:
        """(m, r) ``diag(scale) Phi``: one matrix-vector product per evaluation."""
        return np.ascontiguousarray(self.pod.scale[:, None] * self.pod.modes)

    @cached_property
    def _packed_gp(self):
        """The compiled GP mean's arrays (:class:`~problems.surrogate._kernels.PackedGP`), or None
        when the regression is not a Matern 5/2 GP of shared training points (then numpy)."""
        from problems.surrogate._kernels import PackedGP

        return PackedGP.of(self.regression)

    def coefficients(self, Z) -> np.ndarray:
        """(q, r) POD coefficients at scaled points ``Z`` (q, d): the compiled GP mean where it
        applies, else the regression's own (numpy) prediction."""
        gp = self._packed_gp
        return self.regression.predict(Z) if gp is None else gp.mean(Z)

    def affine_form(self) -> tuple[np.ndarray, np.ndarray]:
        """``(offset (m,), basis (m, r))`` of ``U = offset + basis a``: the model is affine in its
        POD coefficients ``a``."""
        return self.pod.mean, self._weights

    def misfit_of(self, problem):
        """The compiled cost path of ``problem`` on this surrogate
        (:class:`~problems.surrogate.misfit.SurrogateMisfit`): what the evaluator uses for plain
        evaluations."""
        from problems.surrogate.misfit import SurrogateMisfit

        return SurrogateMisfit(self, problem)

    @cached_property
    def _covers_box(self) -> bool:
        """True when the training design box is the whole box (no extrapolation possible)."""
        lo, hi = self.design_box
        return bool(np.all(lo <= self.lower) and np.all(hi >= self.upper))

    def check(self, x) -> str | None:
        """None when ``x`` (physical) is valid: right shape, finite, in the box, accepted by the
        checker."""
        x = np.asarray(x, float)
        if x.shape != self.lower.shape:
            return f"expected {self.lower.size} parameters {self.names}, got shape {x.shape}"
        if np.all((x >= self.lower) & (x <= self.upper)):  # fast path (NaN fails it)
            return None if self.checker is None else self.checker.check(x)
        if not np.all(np.isfinite(x)):
            return "non-finite parameters"
        out = [
            f"{n} = {v:.6g} not in [{lo:.6g}, {hi:.6g}]"
            for n, v, lo, hi in zip(self.names, x, self.lower, self.upper)
            if not lo <= v <= hi
        ]
        if out:
            return "outside the box: " + "; ".join(out)
        return None if self.checker is None else self.checker.check(x)

    def __call__(self, x, jacobian: bool = False) -> ForwardResult:
        """Predicted measurement vector at physical ``x`` (and ``dU/dx`` (m, d) with
        ``jacobian=True``).
        Invalid points give ``ok=False`` with the reason; extrapolation is said in ``message``."""
        t0 = time.perf_counter()
        x = np.asarray(x, float)
        reason = self.check(x)
        if reason is not None:
            return ForwardResult(False, None, reason, time.perf_counter() - t0)
        z = self.to_scaled(x)
        a = self.coefficients(z[None])[0]
        W = self._weights
        values = self.pod.mean + W @ a
        J = None
        if jacobian:
            G = self.regression.gradient(z) / (self.upper - self.lower)  # (r, d)
            # one matrix-vector product per parameter: a threaded (m, r) x (r, d) GEMM is far slower
            # on a busy machine
            J = np.column_stack([W @ G[:, i] for i in range(G.shape[1])])
        message = "" if self._covers_box else self.extrapolation_message(x)
        return ForwardResult(True, values, message, time.perf_counter() - t0, J)

    def predict(self, X) -> np.ndarray:
        """(q, m) predictions at the rows of ``X`` (physical), no checks (vectorised)."""
        Z = self.to_scaled(np.atleast_2d(X))
        return self.pod.mean + self.coefficients(Z) @ self._weights.T

    def evaluate_batch(self, X, jacobian: bool = False) -> list[ForwardResult]:
        """``[self(x, jacobian) for x in X]``, with the values of the valid points computed in one
        vectorised prediction (checks stay per point); each result's ``wall_s`` is the batch's
        wall time divided among its points."""
        t0 = time.perf_counter()
        X = np.atleast_2d(np.asarray(X, float))
        reasons = [self.check(x) for x in X]
        ok = [i for i, r in enumerate(reasons) if r is None]
        values = self.predict(X[ok]) if ok else np.empty((0, self.n_values))
        jac = {i: self(X[i], jacobian=True).jacobian for i in ok} if jacobian else {}
        each = (time.perf_counter() - t0) / max(1, len(X))
        out, k = [], 0
        for i, r in enumerate(reasons):
            if r is not None:
                out.append(ForwardResult(False, None, r, each))
                continue
            msg = "" if self._covers_box else self.extrapolation_message(X[i])
            out.append(ForwardResult(True, values[k], msg, each, jac.get(i)))
            k += 1
        return out

    # --- extrapolation -------------------------------------------------------------------------

    def box_excess(self, x) -> np.ndarray:
        """(d,) how far ``x`` lies outside the training design box, in fractions of the case's
        box width per parameter (0 inside)."""
        lo, hi = self.design_box
        x = np.asarray(x, float)
        return np.maximum(np.maximum(lo - x, x - hi), 0.0) / (self.upper - self.lower)

    def extrapolation_message(self, x) -> str:
        """``""`` inside the training design box, else ``"extrapolation: ..."`` naming the
        parameters."""
        ex = self.box_excess(x)
        if not np.any(ex > 0):
            return ""
        parts = [f"{n} by {e:.3g}" for n, e in zip(self.names, ex) if e > 0]
        return (
            "extrapolation: outside the training design box ("
            + ", ".join(parts)
            + " of the box width)"
        )

    def extrapolation(self, x, *, hull: bool = False) -> dict:
        """Where ``x`` lies relative to the training points (scaled units): ``outside_box``,
        ``box_excess`` (d,), ``nn_distance`` to the nearest training point, ``nn_ratio`` (that over
        the median nearest-neighbour distance within the design) and, with ``hull=True``,
        ``in_hull``."""
        z = self.to_scaled(x)
        d = np.sqrt(np.sum((self.train_z - z) ** 2, axis=1))
        D = np.sqrt(np.sum((self.train_z[:, None] - self.train_z[None]) ** 2, axis=2))
        np.fill_diagonal(D, np.inf)
        typical = float(np.median(D.min(axis=1))) if len(D) > 1 else float("nan")
        ex = self.box_excess(x)
        out = {
            "outside_box": bool(np.any(ex > 0)),
            "box_excess": ex,
            "nn_distance": float(d.min()),
            "nn_ratio": float(d.min() / typical) if typical > 0 else float("nan"),
        }
        if hull:
            out["in_hull"] = in_hull(self.train_z, z)
        return out

    def inflated_sigma(self, sigma) -> np.ndarray:
        """``sqrt(sigma^2 + hold_out_variance)``: the standard deviations a likelihood on this
        surrogate should use (``sigma`` the data's, same units)."""
        s = np.broadcast_to(np.asarray(sigma, float), (self.n_values,))
        if self.hold_out_variance is None:
            return s.copy()
        return np.sqrt(s**2 + self.hold_out_variance)


def in_hull(points: np.ndarray, z: np.ndarray) -> bool:
    """True when ``z`` is a convex combination of the rows of ``points``
    (linear feasibility problem)."""
    from scipy.optimize import linprog

    n = len(points)
    A_eq = np.vstack([points.T, np.ones((1, n))])
    b_eq = np.concatenate([z, [1.0]])
    res = linprog(np.zeros(n), A_eq=A_eq, b_eq=b_eq, bounds=(0, None), method="highs")
    return bool(res.status == 0)


# --- use inside an identification -------------------------------------------------------------


def discretisation_of(model) -> str | None:
    """Canonical discretisation key (``"NX,NY,NZ"``) of the FE model a surrogate was trained on,
    or None when it is not known."""
    info = getattr(model, "info", None) or {}
    key = (info.get("description") or {}).get("discretisation")
    if key:
        return str(key)
    mesh = getattr(getattr(model, "checker", None), "mesh", None)
    if mesh is None:
        return None
    from problems.fe.mesh import discretisation_key

    return discretisation_key(mesh)


def restricted(model: SurrogateModel, case, points, loading) -> SurrogateModel:
    """The surrogate restricted to the measurement points ``points`` (a subset of its own, e.g. a
    measurement region) for ``case`` and ``loading``; refuses a surrogate of another case, loading
    or measurement grid. The result is a :class:`SurrogateModel` whose POD rows are those of the
    kept points (same regression, same cost per evaluation)."""
    import dataclasses

    from problems.inverse import layout

    checker = model.checker
    if tuple(model.names) != tuple(case.names):
        raise ValueError(
            f"surrogate parameters {tuple(model.names)} are not those of case {case.name} "
            f"{tuple(case.names)}"
        )
    desc = (model.info.get("description") or {}) if model.info else {}
    if desc.get("case") not in (None, case.name):
        raise ValueError(f"surrogate is of case {desc.get('case')!r}, not {case.name!r}")
    own = getattr(checker, "points", None)
    if own is None:
        raise ValueError("surrogate has no measurement points (no FE checker): cannot match data")
    own_loading = getattr(checker, "loading", None)
    if own_loading is not None and own_loading != loading:
        raise ValueError(f"surrogate was trained for loading {own_loading}, the data use {loading}")
    own, points = np.asarray(own, float), np.asarray(points, float)
    N = int(desc.get("n_snapshots") or (model.n_values // (2 * len(own) + 1)))
    if layout.size(N, len(own)) != model.n_values:
        raise ValueError("surrogate size does not match its measurement grid")
    match = [np.flatnonzero(np.all(np.abs(own - p) < 1e-9, axis=1)) for p in points]
    if any(len(k) != 1 for k in match):
        raise ValueError("the data's measurement points are not among the surrogate's")
    keep = np.array([k[0] for k in match])
    if len(keep) == len(own) and np.array_equal(keep, np.arange(len(own))):
        return model
    m = len(own)
    idx = np.arange(model.n_values)
    rows = layout.stack(
        idx[: N * m].reshape(N, m)[:, keep],
        idx[N * m : 2 * N * m].reshape(N, m)[:, keep],
        idx[2 * N * m :],
    ).astype(int)
    pod = dataclasses.replace(
        model.pod,
        mean=model.pod.mean[rows],
        scale=model.pod.scale[rows],
        modes=np.ascontiguousarray(model.pod.modes[rows]),
    )
    hv = None if model.hold_out_variance is None else model.hold_out_variance[rows]
    new_checker = checker
    if hasattr(checker, "points"):
        try:
            new_checker = dataclasses.replace(checker, points=points)
        except TypeError:
            new_checker = checker
    info = dict(model.info, restricted_rows=len(rows))
    return dataclasses.replace(model, pod=pod, hold_out_variance=hv, checker=new_checker, info=info)


class VectorisedMapper:
    """A mapper (``mapper(fn, items) -> list``) that evaluates a whole batch of a model offering
    ``evaluate_batch`` (the surrogate) in one vectorised call; any other callable goes to
    ``fallback`` (default: in-process). Population methods and emcee's vectorised moves send
    their batches through :meth:`Evaluator.evaluate_many`, so they profit without change."""

    def __init__(self, fallback=None):
        self.fallback = fallback

    def __call__(self, fn, items):
        from problems.inverse.evaluator import sequential_map
        from problems.inverse.protocol import RunModel

        items = list(items)
        model = getattr(fn, "model", None)
        if isinstance(fn, RunModel) and hasattr(model, "evaluate_batch") and items:
            try:
                return model.evaluate_batch(np.array(items, float), jacobian=fn.with_jacobian)
            except Exception:  # fall back to one call per point (each failure said by RunModel)
                pass
        return (self.fallback or sequential_map)(fn, items)

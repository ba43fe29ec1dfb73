"""The weighted least-squares problem: data, whitening, scaling, bounds and the residual.

It knows nothing of FE and nothing of counting (that is the evaluator's job)::

    R(x) = C^(-1/2) (U_E - U_N(x)),     cost(x) = R^T R

with ``C`` diagonal (``sigma``: scalar or vector of standard deviations), diagonal plus low rank
(``sigma`` and ``covariance_factor`` V: ``C = diag(sigma^2) + V V^T``, e.g. a model-error
covariance; whitened with the symmetric square root of the Woodbury form, O(m k)) or full
(``covariance``; its lower Cholesky factor ``L`` is used, ``R = L^-1 (U_E - U_N)``), or
diagonal with equicorrelated groups (``sigma``, ``groups`` and ``group_rho``: within each group of
values, e.g. one DIC point across the snapshots all correlated against one reference image,
``C_g = D_g R D_g`` with ``R = (1 - rho) I + rho 1 1^T``; whitened group by group with the closed
form of ``R^(-1/2)``, O(m)). In every case ``R^T R = d^T C^-1 d``. ``blocks`` names slices of
the measurement vector so that the cost can be split; with a full covariance (or correlated
groups) the split is that of the whitened residual (it still sums to the total). Solvers work
in the *scaled* space ``z = x / reference`` (the reference is z = 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import cholesky, solve_triangular

from problems.inverse.protocol import ForwardModel

FAILURE_COST = 1e12
"""Cost given to failed and infeasible points (finite, far above any sensible cost)."""

BOX_TOL = 1e-9
"""Points outside the box by less than ``BOX_TOL * (upper - lower)`` are clipped, not rejected."""


def outer_box(lower, upper, reference) -> tuple[np.ndarray, np.ndarray]:
    """The box widened by ``BOX_TOL`` of its width (of ``1e-12 |reference|`` where the width is
    zero or infinite: a half-infinite bound gets no tolerance from its infinite side); beyond it
    a point is outside the box, within it clipped."""
    width = np.asarray(upper, float) - np.asarray(lower, float)
    width = np.where(np.isfinite(width), width, 0.0)
    tol = BOX_TOL * np.maximum(width, np.abs(reference) * 1e-12)
    return lower - tol, upper + tol


@dataclass(eq=False)
class LeastSquaresProblem:
    """Data, weights, box and scaling of one identification problem over a forward model.

    model      : the forward model (see :mod:`problems.inverse.protocol`)
    data       : (m,) measured vector ``U_E`` (same layout as the model's values)
    lower, upper, reference : (n,) physical bounds and reference values (reference != 0)
    sigma      : scalar or (m,) standard deviations (diagonal covariance); default 1; an
                 infinite one gives its value no weight (a point not measured, e.g. a failed DIC
                 subset)
    covariance : (m, m) full covariance (exclusive with ``sigma``)
    covariance_factor : (m, k) V of an added low-rank covariance ``V V^T`` (with ``sigma``)
    groups     : (g, n) indices of g disjoint groups of n values each whose errors are correlated
                 with coefficient ``group_rho`` (with ``sigma``, finite on them)
    group_rho  : the correlation within a group, -1/(n-1) < rho < 1 (0: independent, the
                 diagonal covariance exactly)
    blocks     : names of slices of the measurement vector, for :meth:`split`
    provenance : where the data and the model come from (case, tier, hashes, meshes), reported
    """

    model: ForwardModel
    data: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    reference: np.ndarray
    sigma: np.ndarray | float | None = None
    covariance: np.ndarray | None = None
    covariance_factor: np.ndarray | None = None
    groups: np.ndarray | None = None
    group_rho: float = 0.0
    blocks: dict[str, slice] | None = None
    provenance: dict = field(default_factory=dict)

    def __post_init__(self):
        self.data = np.asarray(self.data, dtype=float).ravel()
        m = self.data.size
        if m == 0:
            raise ValueError("the data vector is empty")
        self.reference = np.asarray(self.reference, dtype=float).ravel().copy()
        self.lower = np.asarray(self.lower, dtype=float).ravel().copy()
        self.upper = np.asarray(self.upper, dtype=float).ravel().copy()
        n = self.reference.size
        self.names = tuple(getattr(self.model, "names", ())) or tuple(f"x{i}" for i in range(n))
        if not (len(self.names) == self.lower.size == self.upper.size == n):
            raise ValueError(
                f"names {self.names}, lower, upper and reference must have the same length "
                f"(got {len(self.names)}, {self.lower.size}, {self.upper.size}, {n})"
            )
        if np.any(self.reference == 0) or not np.all(np.isfinite(self.reference)):
            raise ValueError("reference values must be finite and non-zero (z = x / reference)")
        if np.any(self.lower > self.upper):
            raise ValueError("a lower bound is above its upper bound")
        self._outer = outer_box(self.lower, self.upper, self.reference)
        zl, zu = self.lower / self.reference, self.upper / self.reference
        self.lower_z, self.upper_z = np.minimum(zl, zu), np.maximum(zl, zu)
        self._chol = self._sigma = None
        if self.sigma is not None and self.covariance is not None:
            raise ValueError("give sigma or covariance, not both")
        if self.covariance is not None:
            cov = np.asarray(self.covariance, dtype=float)
            if cov.shape != (m, m):
                raise ValueError(f"covariance must be ({m}, {m}), got {cov.shape}")
            try:
                self._chol = cholesky(cov, lower=True)
            except np.linalg.LinAlgError as exc:
                raise ValueError(f"covariance is not positive definite ({exc})") from None
        else:
            s = (
                np.ones(m)
                if self.sigma is None
                else np.broadcast_to(np.asarray(self.sigma, float), (m,)).copy()
            )
            if np.any(np.isnan(s) | (s <= 0)) or not np.isfinite(s).any():
                bad = int(np.sum(np.isnan(s) | (s <= 0))) or m
                raise ValueError(
                    f"sigma: {bad} of {m} standard deviations are NaN, <= 0 or all infinite; "
                    "allowed: > 0 (infinite: a value not measured, no weight), some finite"
                )
            self._sigma = s
        self._lowrank = None
        if self.covariance_factor is not None:
            if self.covariance is not None:
                raise ValueError("covariance_factor goes with sigma, not with a full covariance")
            V = np.asarray(self.covariance_factor, dtype=float).reshape(m, -1)
            Q, S, _ = np.linalg.svd(V / self._sigma[:, None], full_matrices=False)
            # (I + U U^T)^(-1/2) = I - Q c Q^T
            self._lowrank = (Q, 1.0 - 1.0 / np.sqrt(1.0 + S * S))
        self._groups = None
        if self.groups is not None and self.group_rho != 0.0:
            self._groups = self._equicorrelation(m)
        self.blocks = dict(self.blocks) if self.blocks else {"all": slice(0, m)}
        for name, sl in self.blocks.items():
            if not isinstance(sl, slice) or len(range(m)[sl]) == 0:
                raise ValueError(
                    f"block {name!r} must be a non-empty slice of the {m} measurements"
                )
        self.failure_residual = np.full(m, math.sqrt(FAILURE_COST / m))

    def _equicorrelation(self, m: int):
        """Checked ``groups`` and the coefficients ``(a, b)`` of ``R^(-1/2) = a I + (b - a) P``
        (P the mean over a group): ``a = (1 - rho)^-1/2``, ``b = (1 + (n - 1) rho)^-1/2``."""
        if self.covariance is not None or self.covariance_factor is not None:
            raise ValueError("groups go with a diagonal sigma, not with a (low-rank) covariance")
        G = np.asarray(self.groups)
        rho = float(self.group_rho)
        if G.ndim != 2 or G.shape[1] < 2 or not np.issubdtype(G.dtype, np.integer):
            raise ValueError(f"groups must be (g, n) integer indices with n >= 2, got {G.shape}")
        n = G.shape[1]
        if not (-1.0 / (n - 1) < rho < 1.0):
            raise ValueError(
                f"group correlation rho = {rho!r} is out of range: allowed "
                f"{-1.0 / (n - 1):.6g} < rho < 1 for groups of n = {n} (-1/(n-1) < rho < 1)"
            )
        if G.min() < 0 or G.max() >= m or len(np.unique(G)) != G.size:
            raise ValueError(f"groups must be disjoint indices in [0, {m})")
        if not np.all(np.isfinite(self._sigma[G])):
            raise ValueError("groups: a value of a correlated group has an infinite sigma")
        return G, 1.0 / math.sqrt(1.0 - rho), 1.0 / math.sqrt(1.0 + (n - 1) * rho)

    # --- shape and scaling ---------------------------------------------------------------------
    @property
    def n_params(self) -> int:
        return self.reference.size

    @property
    def n_residuals(self) -> int:
        return self.data.size

    def to_physical(self, z) -> np.ndarray:
        return np.asarray(z, dtype=float) * self.reference

    def to_scaled(self, x) -> np.ndarray:
        return np.asarray(x, dtype=float) / self.reference

    def whiten(self, d) -> np.ndarray:
        """``C^(-1/2) d`` (``L^-1 d`` for a full covariance; ``R^(-1/2) D^-1 d`` on correlated
        groups, the symmetric root: no snapshot is singled out); ``d`` is (m,) or (m, k)."""
        d = np.asarray(d, dtype=float)
        if self._chol is not None:
            return solve_triangular(self._chol, d, lower=True)
        w = d / (self._sigma[:, None] if d.ndim == 2 else self._sigma)
        if self._groups is not None:
            G, a, b = self._groups
            wg = w[G]  # (g, n) or (g, n, k); w is already a new array (d / sigma)
            w[G] = a * wg + (b - a) * wg.mean(axis=1, keepdims=True)
        if self._lowrank is not None:
            Q, c = self._lowrank
            w = w - Q @ ((c[:, None] if d.ndim == 2 else c) * (Q.T @ w))
        return w

    # --- points and residuals ------------------------------------------------------------------
    def classify(self, Z, check: bool = True) -> list[tuple[np.ndarray, str | None]]:
        """For scaled points Z (k, n): the physical point (clipped within tolerance) and why it is
        infeasible (non-finite, outside the box, or the model's ``check``; ``check=False``: the
        caller asks the model later), or None if feasible."""
        Z = np.atleast_2d(np.asarray(Z, dtype=float))
        if Z.ndim != 2 or Z.shape[1] != self.n_params:
            raise ValueError(
                f"expected {self.n_params} parameters {self.names}, got shape {Z.shape[1:]}"
            )
        X = Z * self.reference
        finite = np.all(np.isfinite(X), axis=1)
        out = (X < self._outer[0]) | (X > self._outer[1])
        Xc = np.minimum(np.maximum(X, self.lower), self.upper)  # np.clip: same values, 10x slower
        prepared = []
        for k in range(len(X)):
            if not finite[k]:
                prepared.append((X[k].copy(), "non-finite parameters"))
            elif out[k].any():
                bad = ", ".join(
                    f"{self.names[i]} = {X[k, i]:.6g} is outside [{self.lower[i]:.6g}, "
                    f"{self.upper[i]:.6g}]"
                    for i in np.flatnonzero(out[k])
                )
                prepared.append((X[k].copy(), f"outside the bounds: {bad}"))
            else:
                x = Xc[k].copy()
                prepared.append((x, self.check(x) if check else None))
        return prepared

    def check(self, x) -> str | None:
        """The model's ``check`` of the physical point ``x`` (an exception is a reason too)."""
        try:
            return self.model.check(x)
        except Exception as exc:
            return f"check raised {type(exc).__name__}: {exc}"

    def residual(self, values) -> tuple[np.ndarray | None, str]:
        """Whitened residual of predicted ``values`` (m,), or (None, why) when they are unusable."""
        if values is None:
            return None, "model returned no values"
        values = np.asarray(values, dtype=float).ravel()
        if values.shape != self.data.shape:
            return None, f"model returned {values.size} values, data has {self.data.size}"
        if not np.all(np.isfinite(values)):
            return None, "model returned non-finite values"
        r = self.whiten(self.data - values)
        if not math.isfinite(float(r @ r)):
            return None, "non-finite cost"
        return r, ""

    def residual_jacobian(self, jacobian_x) -> np.ndarray:
        """dR/dz (m, n) of the whitened residual from the model's dU_N/dx (m, n) in physical
        units."""
        return -self.whiten(np.asarray(jacobian_x, float)) * self.reference[None, :]

    def split(self, r) -> dict[str, float]:
        """Cost per named block of the whitened residual ``r``."""
        return {name: float(r[sl] @ r[sl]) for name, sl in self.blocks.items()}

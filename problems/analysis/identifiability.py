"""Practical identifiability from the whitened Jacobian: Fisher information and Laplace covariance.

The objective is ``cost(z) = R(z)^T R(z)`` with the whitened residual ``R = C^(-1/2) (U_E - U_N)``
and the scaled parameters ``z = x / reference``. With ``J = dR/dz`` (m x n):

* Fisher information (Gaussian measurement noise of covariance C): ``F_z = J^T J``;
  in physical units ``F_x = S^-1 F_z S^-1`` with ``S = diag(reference)`` (columns of J divided
  by the reference, since ``dR/dx_i = dR/dz_i / ref_i``).
* Its eigenvalues ``lambda_1 >= ... >= lambda_n`` and condition number ``lambda_1 / lambda_n``
  (in z, i.e. dimensionless; the physical-units condition number depends on the units and is not
  reported). The eigenvector of the smallest eigenvalue is the least identifiable combination.
* Laplace (Gauss-Newton) approximation of the posterior ``p(z) ~ exp(-cost(z) / 2)`` (flat prior):
  ``Cov_z = F_z^-1``, ``Cov_x = S Cov_z S``. Standard deviations ``sd_x = sqrt(diag Cov_x)`` and
  ``sd_% = 100 sqrt(diag Cov_z)`` (percent of the reference value), correlation
  ``rho_ij = Cov_ij / (sd_i sd_j)``.

A singular or numerically ill-conditioned ``F_z`` (``lambda_n <= rcond lambda_1``) is inverted
with the Moore-Penrose pseudo-inverse (eigenvalues below the cut-off dropped): the standard
deviations are then those *within the identifiable subspace* and are flagged in ``warnings``;
the unidentifiable directions have unbounded variance.

:func:`refine_mode` polishes a point to the local minimum by Gauss-Newton steps (for a Laplace
approximation at the MAP rather than at an arbitrary point).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

DEFAULT_RCOND = 1e-12
"""Relative eigenvalue cut-off below which F_z counts as singular (pseudo-inverse)."""


def fisher_information(J) -> np.ndarray:
    """``J^T J`` of a whitened Jacobian (m, n) -> (n, n), symmetrised."""
    J = np.asarray(J, dtype=float)
    if J.ndim != 2:
        raise ValueError(f"Jacobian must be 2-D (m, n), got shape {J.shape}")
    F = J.T @ J
    return 0.5 * (F + F.T)


def laplace_covariance(F, rcond: float = DEFAULT_RCOND) -> tuple[np.ndarray, int, bool]:
    """``(F^-1, rank, used_pinv)`` of a symmetric positive semi-definite F (eigen-decomposition).

    Eigenvalues ``<= rcond * lambda_max`` (or non-positive) are dropped, giving the pseudo-inverse.
    """
    F = np.asarray(F, dtype=float)
    lam, V = np.linalg.eigh(0.5 * (F + F.T))
    lam_max = float(lam.max()) if lam.size else 0.0
    keep = lam > max(rcond * lam_max, 0.0) if lam_max > 0 else np.zeros_like(lam, bool)
    inv = np.where(keep, 1.0 / np.where(keep, lam, 1.0), 0.0)
    cov = (V * inv) @ V.T
    return 0.5 * (cov + cov.T), int(keep.sum()), bool(not keep.all())


def correlation_matrix(cov) -> np.ndarray:
    """``cov_ij / (sd_i sd_j)``; rows/columns of zero variance are NaN (1 on the diagonal)."""
    cov = np.asarray(cov, dtype=float)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = cov / np.outer(sd, sd)
    rho[~np.isfinite(rho)] = np.nan
    np.fill_diagonal(rho, np.where(sd > 0, 1.0, np.nan))
    return np.clip(rho, -1.0, 1.0)


@dataclass
class Identifiability:
    """Fisher information and Laplace covariance at one point (see the module docstring)."""

    names: tuple[str, ...]
    reference: np.ndarray  # (n,) the scaling (z = x / reference)
    x: np.ndarray  # (n,) physical point where J was taken
    jacobian_z: np.ndarray  # (m, n) whitened dR/dz
    fisher_z: np.ndarray  # (n, n) J^T J
    eigenvalues: np.ndarray  # (n,) of fisher_z, descending
    eigenvectors: np.ndarray  # (n, n) columns, same order
    condition: float  # lambda_max / lambda_min (inf if singular)
    rank: int
    pinv: bool  # the covariance is a pseudo-inverse
    cov_z: np.ndarray  # (n, n) Laplace covariance in z
    rcond: float = DEFAULT_RCOND
    warnings: list[str] = field(default_factory=list)
    n_evals: int = 0

    @property
    def fisher_x(self) -> np.ndarray:
        """Fisher information in physical units (1 / unit_i unit_j)."""
        s = 1.0 / self.reference
        return self.fisher_z * np.outer(s, s)

    @property
    def cov_x(self) -> np.ndarray:
        """Laplace covariance in physical units."""
        return self.cov_z * np.outer(self.reference, self.reference)

    @property
    def std_x(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.cov_x), 0.0, None))

    @property
    def std_percent(self) -> np.ndarray:
        """Standard deviation in percent of the reference value."""
        return 100.0 * np.sqrt(np.clip(np.diag(self.cov_z), 0.0, None))

    @property
    def correlation(self) -> np.ndarray:
        return correlation_matrix(self.cov_z)

    @property
    def weakest(self) -> dict[str, float]:
        """The least identifiable direction: eigenvector of the smallest eigenvalue (z units)."""
        v = self.eigenvectors[:, -1]
        v = v * np.sign(v[np.argmax(np.abs(v))])
        return dict(zip(self.names, map(float, v)))

    def rows(self) -> list[dict]:
        """One row per parameter: point, Laplace standard deviation (physical and %)."""
        return [
            {
                "parameter": n,
                "x": float(self.x[i]),
                "reference": float(self.reference[i]),
                "std": float(self.std_x[i]),
                "std_percent": float(self.std_percent[i]),
            }
            for i, n in enumerate(self.names)
        ]

    def summary(self) -> dict:
        return {
            "names": list(self.names),
            "condition": self.condition,
            "rank": self.rank,
            "pinv": self.pinv,
            "eigenvalues": self.eigenvalues.tolist(),
            "std_percent": self.std_percent.tolist(),
            "weakest_direction": self.weakest,
            "warnings": list(self.warnings),
            "n_evals": self.n_evals,
        }


def analyse_jacobian(
    J_z, reference, *, x=None, names: Sequence[str] | None = None, rcond: float = DEFAULT_RCOND
) -> Identifiability:
    """Fisher information, eigen-decomposition, condition number and Laplace covariance.

    J_z       : (m, n) Jacobian of the *whitened* residual w.r.t. z = x / reference
    reference : (n,) physical reference values (the scaling)
    x         : (n,) physical point where J_z was taken (default: the reference)
    """
    J = np.asarray(J_z, dtype=float)
    ref = np.asarray(reference, dtype=float).ravel()
    if J.ndim != 2 or J.shape[1] != ref.size:
        raise ValueError(f"Jacobian shape {J.shape} does not match {ref.size} parameters")
    if not np.all(np.isfinite(J)):
        raise ValueError("Jacobian has non-finite entries")
    n = ref.size
    names = tuple(names) if names is not None else tuple(f"x{i + 1}" for i in range(n))
    x = ref.copy() if x is None else np.asarray(x, dtype=float).ravel()
    F = fisher_information(J)
    lam, V = np.linalg.eigh(F)
    order = np.argsort(lam)[::-1]
    lam, V = lam[order], V[:, order]
    cov, rank, used_pinv = laplace_covariance(F, rcond)
    lam_min = float(lam[-1])
    cond = float(lam[0] / lam_min) if lam_min > 0 else math.inf
    warns = []
    zero_cols = [names[i] for i in range(n) if not np.any(J[:, i])]
    if zero_cols:
        warns.append(
            f"the measurements do not depend on {', '.join(zero_cols)} (zero Jacobian column)"
        )
    if used_pinv:
        v = V[:, -1]
        lead = ", ".join(f"{names[i]} {v[i]:+.2f}" for i in np.argsort(-np.abs(v))[:3])
        warns.append(
            f"J^T J is singular or ill-conditioned (rank {rank} of {n}, cut-off {rcond:g} "
            "lambda_max): the Laplace covariance is a pseudo-inverse; its standard deviations hold "
            f"within the identifiable subspace only, the direction [{lead}] is not identifiable"
        )
    return Identifiability(names, ref, x, J, F, lam, V, cond, rank, used_pinv, cov, rcond, warns)


def identifiability(
    objective,
    z=None,
    *,
    scheme: str = "forward",
    rel_step: float = 1e-6,
    rcond: float = DEFAULT_RCOND,
    r0=None,
) -> Identifiability:
    """:func:`analyse_jacobian` of ``objective.jacobian(z)`` (z default: 1, the reference).

    Costs ``n + 1`` (forward) or ``2 n + 1`` (central) forward evaluations, fewer if cached; the
    number actually spent is stored in ``n_evals``.
    """
    z = np.ones(objective.n_params) if z is None else np.asarray(z, dtype=float).ravel()
    before, failures = objective.n_evals, getattr(objective, "n_jacobian_failures", 0)
    J = objective.jacobian(z, scheme=scheme, rel_step=rel_step, r0=r0)
    out = analyse_jacobian(
        J, objective.reference, x=objective.to_physical(z), names=objective.names, rcond=rcond
    )
    out.n_evals = objective.n_evals - before
    failed = getattr(objective, "n_jacobian_failures", 0) - failures
    if failed:
        out.warnings.append(f"{failed} Jacobian column(s) failed and were set to zero")
    return out


@dataclass
class Refined:
    """Result of :func:`refine_mode`."""

    z: np.ndarray
    cost: float
    jacobian: np.ndarray
    steps: int
    n_evals: int
    converged: bool
    message: str


def refine_mode(
    objective,
    z0,
    *,
    max_steps: int = 5,
    tol: float = 1e-6,
    scheme: str = "forward",
    rel_step: float = 1e-6,
    rcond: float = DEFAULT_RCOND,
) -> Refined:
    """Gauss-Newton polishing of ``z0`` toward the nearest minimum of ``objective`` (in the box).

    Each step solves ``(J^T J) dz = -J^T R`` (pseudo-inverse if singular), projects onto the box
    and halves the step until the cost decreases (at most 8 halvings). Stops when the cost
    decreases by less than ``tol`` (absolute; the cost is a chi-square, so 1e-6 is far below one
    unit of log-likelihood) or after ``max_steps``. Returns the Jacobian at the final point, so that
    :func:`analyse_jacobian` gives the Laplace approximation there without another Jacobian.
    """
    before = objective.n_evals
    z = np.clip(np.asarray(z0, dtype=float).ravel(), objective.lower_z, objective.upper_z)
    ev = objective.evaluate(z)
    if not ev.usable:
        raise ValueError(f"refine_mode: the start point cannot be evaluated ({ev.message})")
    cost, r = ev.cost, ev.residual
    J = objective.jacobian(z, scheme=scheme, rel_step=rel_step, r0=r)
    steps, converged, message = 0, False, "max_steps reached"
    for steps in range(1, max_steps + 1):
        F = fisher_information(J)
        cov, _, _ = laplace_covariance(F, rcond)
        dz = -cov @ (J.T @ r)
        t, accepted = 1.0, None
        for _ in range(9):
            zt = np.clip(z + t * dz, objective.lower_z, objective.upper_z)
            et = objective.evaluate(zt)
            if et.usable and et.cost < cost:
                accepted = (zt, et)
                break
            t *= 0.5
        if accepted is None:
            converged, message = True, "no decrease along the Gauss-Newton direction (at a minimum)"
            steps -= 1
            break
        gain = cost - accepted[1].cost
        z, cost, r = accepted[0], accepted[1].cost, accepted[1].residual
        J = objective.jacobian(z, scheme=scheme, rel_step=rel_step, r0=r)
        if gain < tol:
            converged, message = True, f"cost decrease {gain:.3g} < tol {tol:g}"
            break
    return Refined(z, float(cost), J, steps, objective.n_evals - before, converged, message)

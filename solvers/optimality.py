"""The first-order optimality test behind every least-squares method's status.

A library's own stop ("xtol reached", "line search failed") says why it stopped, not whether the
point is a minimum: ``gauss-newton`` stopped "stalled" at the optimum, and scipy's trust regions
stop "converged" on a small step far from it. So the least-squares methods (``lm``, ``trf``,
``lm-minpack``, ``gauss-newton``, ``multistart-lm``, ``pso+lm``) report ``"converged"`` only when
this test passes at the point they return, and ``"stalled"`` (or their budget/iteration status)
otherwise.

The test, at scaled point ``z`` with whitened residual ``r`` and Jacobian ``J = dr/dz``:

1. *active bounds*: a variable at a bound, or within ``tol`` (relative, the step's measure
   below) of it, whose cost gradient ``g = J^T r`` pushes outward is held (the projected
   gradient's rule on an epsilon-active set, as in Bertsekas' projected Newton methods: ``trf``
   returns a bounded minimum a hair inside the box, and a start nudged 1e-10 off a bound is not
   a free variable either); its part of the step is its distance to the bound; the others are
   free;
2. *Gauss-Newton step*: ``d`` solves ``J_free d = -r`` in the least-squares sense (minimum
   norm), projected onto the box. At a first-order point of a least-squares problem
   (``J_free^T r = 0``, zero or non-zero residual alike) ``d = 0``; near one, ``|d_i|`` estimates
   the distance to it. The measure is the largest relative step ``max_i |d_i| / |z_i|`` (``|d_i|``
   where ``z_i = 0``): scale-free, read as correct digits (``1e-6``: about six);
3. *not flat*: a point where the cost is no lower than that of a zero prediction
   (``cost >= |C^(-1/2) U_E|^2``, the data's own size) is not a minimum even when the step
   vanishes there (an exponential that underflowed: zero Jacobian columns, d = 0);
4. *determined*: ``J_free`` has full numerical rank (singular values above
   ``max(m, n) eps sigma_max``, numpy's rule); at a rank-deficient point the minimum-norm step
   ignores the directions the model has lost (a saturated sigmoid, two merged exponentials), so
   a vanishing ``d`` proves nothing there.

``converged`` iff the relative step is at most ``tol`` (:data:`STEP_TOL` unless a method's
``opt_tol`` option says otherwise), the point is not flat and the free parameters are
determined. The test costs no evaluation: it uses the Jacobian the method already has at its
final point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: default tolerance of the relative Gauss-Newton step: about 4 correct digits of every parameter
#: from the local minimum. Measured on NIST StRD at the certified points: with forward-difference
#: Jacobians (sqrt(eps) steps) the step is at most 1.4e-5 (Lanczos3), with central ones 4e-8, so
#: a true minimum passes; 1e-3 perturbations give steps of 1e-3 and more (the step estimates the
#: distance to the minimum).
STEP_TOL = 1e-4


@dataclass(frozen=True)
class Optimality:
    """The verdict: ``converged``, the relative Gauss-Newton step ``step`` (inf when unusable),
    ``flat`` (cost no lower than a zero prediction's) and a one-line ``message``."""

    converged: bool
    step: float
    flat: bool
    message: str


def first_order(z, r, J, lower, upper, data_cost: float, tol: float = STEP_TOL) -> Optimality:
    """The first-order test of the module docstring at ``z`` (scaled, (n,)), residual ``r``
    (m,), Jacobian ``J`` (m, n) in z, box ``lower``/``upper`` (scaled, may be infinite) and
    ``data_cost`` (the cost of a zero prediction)."""
    z, r, J = np.asarray(z, float), np.asarray(r, float), np.asarray(J, float)
    cost = float(r @ r)
    if not (np.all(np.isfinite(J)) and math.isfinite(cost)):
        return Optimality(False, math.inf, False, "non-finite residual or Jacobian")
    if cost == 0.0:
        return Optimality(True, 0.0, False, "zero residual")
    g = J.T @ r
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    scale = np.where(z != 0, np.abs(z), 1.0)
    near_lo, near_hi = z - lo <= tol * scale, hi - z <= tol * scale
    held_lo, held_hi = near_lo & (g > 0), near_hi & (g < 0)
    free = ~(held_lo | held_hi)
    d = np.zeros_like(z)
    rank = n_free = int(free.sum())
    if n_free:
        d[free], _, rank, _ = np.linalg.lstsq(J[:, free], -r, rcond=None)
    d = np.clip(z + d, lo, hi) - z
    d[held_lo] = lo[held_lo] - z[held_lo]
    d[held_hi] = hi[held_hi] - z[held_hi]
    step = float(np.max(np.abs(d) / scale)) if d.size else 0.0
    flat = data_cost > 0 and cost >= data_cost
    if step > tol:
        why = f"not a first-order point: Gauss-Newton step {step:.1e}"
        return Optimality(False, step, flat, why)
    if flat:
        return Optimality(
            False, step, True, f"flat: cost {cost:.3g} is no lower than the data's {data_cost:.3g}"
        )
    if rank < n_free:
        return Optimality(
            False,
            step,
            False,
            f"undetermined: Jacobian of rank {rank} for {n_free} free parameters "
            "(the model lost a direction here)",
        )
    return Optimality(True, step, False, f"first-order point: Gauss-Newton step {step:.1e}")


def data_cost(objective) -> float:
    """The cost of a zero prediction, ``|C^(-1/2) U_E|^2``, of a least-squares objective."""
    w = objective.whiten(objective.data)
    return float(w @ w)

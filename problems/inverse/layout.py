"""The measurement vector, defined once: ``[u_h, u_v, force]``.

``u_h`` and ``u_v`` are the front-face horizontal and vertical displacements (mm) at the m grid
points for each of the N snapshots (snapshot-major: all points of snapshot 1, then snapshot 2,
...), ``force`` the plate force (kN) at each snapshot. Data files, forward models, objectives,
sensitivities and Jacobians (rows) all use this order.
"""

from __future__ import annotations

import numpy as np

BLOCK_NAMES = ("u_h", "u_v", "force")


def size(n_snapshots: int, n_points: int) -> int:
    """Length of the measurement vector: 2 N m + N."""
    return 2 * n_snapshots * n_points + n_snapshots


def blocks(n_snapshots: int, n_points: int) -> dict[str, slice]:
    """Named slices: ``u_h``, ``u_v``, ``displacement`` (both) and ``force``."""
    nm = n_snapshots * n_points
    return {
        "u_h": slice(0, nm),
        "u_v": slice(nm, 2 * nm),
        "displacement": slice(0, 2 * nm),
        "force": slice(2 * nm, 2 * nm + n_snapshots),
    }


def point_groups(n_snapshots: int, n_points: int) -> np.ndarray:
    """(2 m, N) indices into the measurement vector: each point's ``u_h`` across the N
    snapshots (rows 0 .. m-1), then its ``u_v`` (rows m .. 2m-1)."""
    nm = n_snapshots * n_points
    k = np.arange(n_snapshots)[None, :] * n_points
    p = np.arange(n_points)[:, None]
    return np.concatenate([p + k, nm + p + k])


def point_rows(keep, n_snapshots: int) -> np.ndarray:
    """Boolean mask (2 N m + N,) over the measurement vector of the front-face points ``keep``
    (m,) bool: their ``u_h`` and ``u_v`` in each of the N snapshots, and every force (a
    measurement region never drops the force)."""
    kept = np.tile(np.asarray(keep, dtype=bool), (n_snapshots, 1))
    return stack(kept, kept, np.ones(n_snapshots, dtype=bool)).astype(bool)


def stack(u_h, u_v, force_kN) -> np.ndarray:
    """The measurement vector from ``u_h`` (N, m) mm, ``u_v`` (N, m) mm and ``force_kN`` (N,)."""
    return np.concatenate([np.ravel(u_h), np.ravel(u_v), np.ravel(force_kN)])


def unstack(values, n_snapshots: int, n_points: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(u_h (N, m), u_v (N, m), force (N,))`` from a measurement vector (or the rows of a
    Jacobian, ``values`` of shape (2 N m + N, k): then each part keeps the trailing axis)."""
    v = np.asarray(values, dtype=float)
    expected = size(n_snapshots, n_points)
    if v.shape[0] != expected:
        raise ValueError(
            f"measurement vector has {v.shape[0]} values; N = {n_snapshots} snapshots and "
            f"m = {n_points} points need 2 N m + N = {expected}"
        )
    b, tail = blocks(n_snapshots, n_points), v.shape[1:]
    return (
        v[b["u_h"]].reshape((n_snapshots, n_points) + tail),
        v[b["u_v"]].reshape((n_snapshots, n_points) + tail),
        v[b["force"]].reshape((n_snapshots,) + tail),
    )

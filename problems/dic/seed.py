"""Initial guesses: FFT cross-correlation at seed points and the neighbour graph for propagation.

``integer_guess`` finds the integer-pixel displacement of one (large) reference subset by the
zero-normalised cross-correlation (ZNCC) over a search window of the deformed image, all
shifts at once: the numerator is an FFT correlation of the window with the zero-mean template,
the window's local means and energies come from integral images, so the map is the exact ZNCC
at every integer shift.

``neighbour_graph`` links each point to its (up to 8) nearest neighbours within 1.5 times the
typical spacing: the 8-neighbourhood on a regular grid, and a sensible graph for any point set.
Reliability-guided propagation (in :mod:`problems.dic.correlate`) walks this graph.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import fftconvolve
from scipy.spatial import cKDTree


def _box_sums(a: np.ndarray, h: int, w: int) -> np.ndarray:
    """Sums of ``a`` over every ``h x w`` window ('valid' placements), via an integral image."""
    s = np.zeros((a.shape[0] + 1, a.shape[1] + 1))
    s[1:, 1:] = a.cumsum(0).cumsum(1)
    return s[h:, w:] - s[:-h, w:] - s[h:, :-w] + s[:-h, :-w]


def integer_guess(
    reference: np.ndarray, deformed: np.ndarray, cx: int, cy: int, half: int, radius: int
) -> tuple[int, int, float]:
    """Integer displacement ``(du, dv)`` of the ``(2 half + 1)^2`` subset centred at ``(cx, cy)``.

    The search covers shifts up to ``radius`` px in each direction (less where the deformed
    image ends). Returns ``(du, dv, zncc_peak)``; ``zncc_peak`` is -1 if nothing could be searched.
    """
    rows, cols = reference.shape
    half = int(min(half, cx, cy, cols - 1 - cx, rows - 1 - cy))
    if half < 2:
        return 0, 0, -1.0
    t = reference[cy - half : cy + half + 1, cx - half : cx + half + 1].astype(float)
    t0 = t - t.mean()
    tn = np.sqrt(np.sum(t0 * t0))
    r0, r1 = max(0, cy - half - radius), min(deformed.shape[0], cy + half + radius + 1)
    c0, c1 = max(0, cx - half - radius), min(deformed.shape[1], cx + half + radius + 1)
    win = deformed[r0:r1, c0:c1].astype(float)
    n = t.size
    if tn == 0 or win.shape[0] < t.shape[0] or win.shape[1] < t.shape[1]:
        return 0, 0, -1.0
    num = fftconvolve(win, t0[::-1, ::-1], mode="valid")
    s1 = _box_sums(win, *t.shape)
    s2 = _box_sums(win * win, *t.shape)
    den = np.sqrt(np.maximum(s2 - s1 * s1 / n, 0.0)) * tn
    zncc = np.where(den > 1e-12 * tn * tn, num / np.where(den > 0, den, 1.0), -1.0)
    k = int(np.argmax(zncc))
    i, j = np.unravel_index(k, zncc.shape)
    # placement (i, j) puts the template's top-left at (r0 + i, c0 + j)
    dv = r0 + i - (cy - half)
    du = c0 + j - (cx - half)
    return int(du), int(dv), float(zncc[i, j])


def neighbour_graph(points: np.ndarray, max_neighbours: int = 8) -> np.ndarray:
    """(n, max_neighbours) indices of each point's neighbours, -1 where there are fewer.

    Neighbours are the nearest points within 1.5 times the median nearest-neighbour distance.
    """
    n = len(points)
    if n < 2:
        return -np.ones((n, max_neighbours), dtype=np.int64)
    k = min(n, max_neighbours + 1)
    d, j = cKDTree(points).query(points, k=k)
    spacing = np.median(d[:, 1])
    j = np.where(d <= 1.5 * spacing * (1 + 1e-9), j, -1)[:, 1:]
    out = -np.ones((n, max_neighbours), dtype=np.int64)
    out[:, : j.shape[1]] = j
    return out


def seed_candidates(points: np.ndarray, valid: np.ndarray, n_seeds: int) -> list[int]:
    """Indices of up to ``n_seeds`` valid points: nearest to the centre of the point cloud, then
    to the centres of its four quadrants (robust seeds away from the borders)."""
    idx = np.flatnonzero(valid)
    if idx.size == 0:
        return []
    p = points[idx]
    lo, hi = p.min(0), p.max(0)
    c = (lo + hi) / 2
    q = (hi - lo) / 4
    targets = [c, c + [-q[0], -q[1]], c + [q[0], -q[1]], c + [-q[0], q[1]], c + [q[0], q[1]]]
    out: list[int] = []
    for t in targets[: max(1, n_seeds)]:
        k = int(idx[np.argmin(np.sum((p - t) ** 2, axis=1))])
        if k not in out:
            out.append(k)
    return out

"""Figure in the spirit of the paper's Fig. 2: reference subset, converged warped subset and
deformed-image subset for a few points (matplotlib, Agg back-end, PNG)."""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from problems.dic.correlate import DICResult
from problems.dic.interpolate import BSplineImage


def subset_panels(
    reference: np.ndarray, deformed: np.ndarray, result: DICResult, index: int, subset: int, order: int = 3
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(reference subset, warped subset g(W(xi; p)), deformed crop, warped corners in the crop).

    The deformed crop is the subset-sized window of the deformed image at the rounded
    displaced centre; the corners (5, 2) outline the converged warped subset in it.
    """
    h = subset // 2
    cx, cy = int(result.x[index]), int(result.y[index])
    p = result.params[index]
    if not np.all(np.isfinite(p)):
        raise ValueError(f"point {index} did not converge: nothing to show")
    ref = np.asarray(reference, float)[cy - h : cy + h + 1, cx - h : cx + h + 1]
    r = np.arange(-h, h + 1, dtype=float)
    dy, dx = np.meshgrid(r, r, indexing="ij")
    X = cx + p[0] + (1 + p[1]) * dx + p[2] * dy
    Y = cy + p[3] + p[4] * dx + (1 + p[5]) * dy
    warped = BSplineImage(deformed, order).values(X, Y)
    ox, oy = int(round(cx + p[0])), int(round(cy + p[3]))
    g = np.asarray(deformed, float)
    crop = np.full((subset, subset), np.nan)
    r0, c0 = oy - h, ox - h
    rs, cs = slice(max(r0, 0), min(r0 + subset, g.shape[0])), slice(max(c0, 0), min(c0 + subset, g.shape[1]))
    crop[rs.start - r0 : rs.stop - r0, cs.start - c0 : cs.stop - c0] = g[rs, cs]
    cor = np.array([(-h, -h), (h, -h), (h, h), (-h, h), (-h, -h)], dtype=float)
    cxw = cx + p[0] + (1 + p[1]) * cor[:, 0] + p[2] * cor[:, 1] - c0
    cyw = cy + p[3] + p[4] * cor[:, 0] + (1 + p[5]) * cor[:, 1] - r0
    return ref, warped, crop, np.column_stack([cxw, cyw])


def plot_subsets(
    reference: np.ndarray,
    deformed: np.ndarray,
    result: DICResult,
    indices: Sequence[int],
    path: str | Path,
    subset: int,
    order: int = 3,
    labels: Sequence[str] | None = None,
    title: str | None = None,
) -> Path:
    """Write the figure: one row per point, columns reference / warped / deformed subset."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    keep = [j for j, i in enumerate(indices) if bool(result.converged[int(i)])]
    labels = [labels[j] for j in keep] if labels is not None else None
    indices = [int(indices[j]) for j in keep]
    if not indices:
        raise ValueError("none of the requested points converged: nothing to plot")
    n = len(indices)
    fig, axes = plt.subplots(n, 3, figsize=(7.2, 2.4 * n + 0.4), squeeze=False)
    for row, i in enumerate(indices):
        ref, warped, crop, quad = subset_panels(reference, deformed, result, i, subset, order)
        lo, hi = np.nanmin(ref), np.nanmax(ref)
        name = labels[row] if labels is not None else f"({result.x[i]:.0f}, {result.y[i]:.0f}) px"
        for col, (img, t) in enumerate(
            (
                (ref, f"reference subset\n{name}"),
                (warped, f"warped subset g(W(ξ; p))\nZNCC = {result.zncc[i]:.5f}"),
                (crop, f"deformed image\nu = {result.u[i]:+.3f}, v = {result.v[i]:+.3f} px"),
            )
        ):
            ax = axes[row, col]
            ax.imshow(img, cmap="gray", vmin=lo, vmax=hi, interpolation="nearest")
            ax.set_title(t, fontsize=8)
            ax.set_xticks([])
            ax.set_yticks([])
        axes[row, 2].plot(quad[:, 0], quad[:, 1], "-", color="tab:orange", lw=1.0)
        axes[row, 2].set_xlim(-0.5, subset - 0.5)
        axes[row, 2].set_ylim(subset - 0.5, -0.5)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path

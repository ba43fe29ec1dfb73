"""The data of a Fig.-2-like figure (the paper's Fig. 2): reference subset, converged warped subset
and deformed-image subset for a few points, as arrays (:class:`SubsetPanels`, saved as ``.npz``).

Drawing it is post-processing and lives with the other figures: :mod:`bench.dic_figures`.
Grey levels as in the images; coordinates in pixels.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from problems.dic.correlate import DICResult
from problems.dic.interpolate import BSplineImage


@dataclass
class SubsetPanels:
    """The panels of ``n`` points, ``s`` x ``s`` px subsets.

    reference : (n, s, s) reference subsets
    warped    : (n, s, s) deformed image sampled at the converged warp, g(W(xi; p))
    deformed  : (n, s, s) deformed-image window at the rounded displaced centre (NaN off the image)
    outline   : (n, 5, 2) the warped subset's corners (x, y) in the window, closed polygon
    labels    : one name per point
    zncc      : (n,) final ZNCC (-)
    u, v      : (n,) displacements (px, x right, y down)
    title     : figure title ("" for none)
    """

    reference: np.ndarray
    warped: np.ndarray
    deformed: np.ndarray
    outline: np.ndarray
    labels: list[str]
    zncc: np.ndarray
    u: np.ndarray
    v: np.ndarray
    title: str = ""

    def save(self, path) -> Path:
        """Write the panels to ``path`` (.npz)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(
            path,
            reference=self.reference,
            warped=self.warped,
            deformed=self.deformed,
            outline=self.outline,
            labels=np.array(self.labels),
            zncc=self.zncc,
            u=self.u,
            v=self.v,
            title=np.array(self.title),
        )
        return path

    @classmethod
    def load(cls, path) -> SubsetPanels:
        with np.load(Path(path), allow_pickle=False) as f:
            return cls(
                f["reference"],
                f["warped"],
                f["deformed"],
                f["outline"],
                [str(t) for t in f["labels"]],
                f["zncc"],
                f["u"],
                f["v"],
                str(f["title"]),
            )


def subset_panels(
    reference: np.ndarray,
    deformed: np.ndarray,
    result: DICResult,
    index: int,
    subset: int,
    order: int = 3,
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
    rs, cs = (
        slice(max(r0, 0), min(r0 + subset, g.shape[0])),
        slice(max(c0, 0), min(c0 + subset, g.shape[1])),
    )
    crop[rs.start - r0 : rs.stop - r0, cs.start - c0 : cs.stop - c0] = g[rs, cs]
    cor = np.array([(-h, -h), (h, -h), (h, h), (-h, h), (-h, -h)], dtype=float)
    cxw = cx + p[0] + (1 + p[1]) * cor[:, 0] + p[2] * cor[:, 1] - c0
    cyw = cy + p[3] + p[4] * cor[:, 0] + (1 + p[5]) * cor[:, 1] - r0
    return ref, warped, crop, np.column_stack([cxw, cyw])


def subset_figure_data(
    reference: np.ndarray,
    deformed: np.ndarray,
    result: DICResult,
    indices: Sequence[int],
    subset: int,
    order: int = 3,
    labels: Sequence[str] | None = None,
    title: str | None = None,
) -> SubsetPanels:
    """The panels of the converged points among ``indices`` (labels default to their pixel
    position).

    Raises ValueError when none of them converged."""
    keep = [j for j, i in enumerate(indices) if bool(result.converged[int(i)])]
    labels = [labels[j] for j in keep] if labels is not None else None
    indices = [int(indices[j]) for j in keep]
    if not indices:
        raise ValueError("none of the requested points converged: nothing to plot")
    panels = [subset_panels(reference, deformed, result, i, subset, order) for i in indices]
    names = (
        list(labels)
        if labels is not None
        else [f"({result.x[i]:.0f}, {result.y[i]:.0f}) px" for i in indices]
    )
    return SubsetPanels(
        *(np.array([p[k] for p in panels]) for k in range(4)),
        names,
        np.asarray(result.zncc)[indices],
        np.asarray(result.u)[indices],
        np.asarray(result.v)[indices],
        title or "",
    )

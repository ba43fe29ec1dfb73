"""The DIC subset figure in the spirit of the paper's Fig. 2: one row per point, columns reference
subset / converged warped subset / deformed-image window with the warped outline. The panels are
computed by :func:`problems.dic.subsets.subset_figure_data` (saved by the DIC route as
``dic_subsets.npz`` beside its images); style and saving: :mod:`bench.plotting`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bench.plotting import COLOURS, pyplot, save

PANELS_FILE = "dic_subsets.npz"
FIGURE_FILE = "dic_subsets.png"


def subsets_figure(panels, path) -> Path:
    """Draw :class:`problems.dic.subsets.SubsetPanels` to ``path`` (grey levels shared per row)."""
    plt = pyplot()
    n, s = len(panels.labels), panels.reference.shape[-1]
    fig, axes = plt.subplots(n, 3, figsize=(7.2, 2.4 * n + 0.4), squeeze=False)
    for r in range(n):
        ref = panels.reference[r]
        lo, hi = np.nanmin(ref), np.nanmax(ref)
        cells = (
            (ref, f"reference subset\n{panels.labels[r]}"),
            (panels.warped[r], f"warped subset g(W(ξ; p))\nZNCC = {panels.zncc[r]:.5f}"),
            (
                panels.deformed[r],
                f"deformed image\nu = {panels.u[r]:+.3f}, v = {panels.v[r]:+.3f} px",
            ),
        )
        for c, (img, text) in enumerate(cells):
            ax = axes[r, c]
            ax.imshow(img, cmap="gray", vmin=lo, vmax=hi, interpolation="nearest")
            ax.set_title(text, fontsize=8)
            ax.set_xticks([])
            ax.set_yticks([])
            ax.grid(False)
        quad = panels.outline[r]
        axes[r, 2].plot(quad[:, 0], quad[:, 1], "-", color=COLOURS[4], lw=1.0)
        axes[r, 2].set_xlim(-0.5, s - 0.5)
        axes[r, 2].set_ylim(s - 0.5, -0.5)
    if panels.title:
        fig.suptitle(panels.title)
    fig.tight_layout()
    return save(fig, path)


def render_subsets(folder, path=None) -> Path:
    """Draw ``folder/dic_subsets.png`` (or ``path``) from ``folder/dic_subsets.npz``."""
    from problems.dic.subsets import SubsetPanels

    folder = Path(folder)
    source = folder / PANELS_FILE
    if not source.is_file():
        raise FileNotFoundError(
            f"{source} does not exist: run the DIC route with an image folder first"
        )
    return subsets_figure(SubsetPanels.load(source), path or folder / FIGURE_FILE)

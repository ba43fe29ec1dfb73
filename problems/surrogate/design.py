"""Training designs: seeded space-filling points in a box, optionally enriched near a point.

All designs are drawn in the unit cube and scaled to the box (physical units of the case's
parameters). The *global* design covers the box; the optional *local* design is a second,
narrower design around a given point (for example the parameters of the data set, or an optimum
found earlier) where the surrogate has to be most accurate. Its box is the given point plus or
minus ``local_scale`` times the width of the global box, clipped to the global box.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import qmc

METHODS = ("lhs", "sobol")


def unit_design(n: int, d: int, seed: int | np.random.Generator, method: str = "lhs") -> np.ndarray:
    """``n`` seeded points in the unit cube ``[0, 1]^d``, shape (n, d).

    method : ``lhs`` (Latin hypercube, optimised by random CD) or ``sobol`` (scrambled Sobol;
             ``n`` need not be a power of 2, the first ``n`` points of the sequence are taken)
    """
    if n < 0:
        raise ValueError(f"n = {n} is out of range: must be >= 0")
    if method not in METHODS:
        raise ValueError(f"design method {method!r} is unknown; allowed: {', '.join(METHODS)}")
    if n == 0:
        return np.empty((0, d))
    rng = np.random.default_rng(seed)
    if method == "lhs":
        return qmc.LatinHypercube(d=d, seed=rng).random(n)
    m = int(np.ceil(np.log2(max(n, 1))))
    return qmc.Sobol(d=d, scramble=True, seed=rng).random_base2(m)[:n]


@dataclass(frozen=True)
class Design:
    """The points of a design and where each came from.

    X      : (n, d) points, physical units
    origin : (n,) ``"global"`` or ``"local"``
    box    : (lower (d,), upper (d,)) the box the design covers (the global box), physical units
    local_box : (lower, upper) of the local design, or None
    """

    X: np.ndarray
    origin: np.ndarray
    box: tuple[np.ndarray, np.ndarray]
    local_box: tuple[np.ndarray, np.ndarray] | None = None

    def __len__(self) -> int:
        return len(self.X)


def local_box(lower, upper, center, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """``center +- scale (upper - lower)``, clipped to ``[lower, upper]`` (physical units)."""
    lower, upper, center = (np.asarray(a, float) for a in (lower, upper, center))
    if not 0 < scale <= 0.5:
        raise ValueError(
            f"local scale = {scale} is out of range: 0 < scale <= 0.5 (fraction of the box width)"
        )
    if center.shape != lower.shape or np.any(center < lower) or np.any(center > upper):
        raise ValueError(
            f"local centre {center.tolist()} must lie in the box [{lower.tolist()}, "
            f"{upper.tolist()}]"
        )
    half = scale * (upper - lower)
    return np.maximum(center - half, lower), np.minimum(center + half, upper)


def make_design(
    lower,
    upper,
    n: int,
    *,
    seed: int | list[int] = 0,
    method: str = "lhs",
    center=None,
    n_local: int = 0,
    local_scale: float = 0.1,
) -> Design:
    """A global design of ``n`` points in ``[lower, upper]``, plus ``n_local`` points in the local
    box around ``center`` (see :func:`local_box`). The two designs use independent streams of
    ``seed`` (an int or a list of ints: ``[seed, 1]`` gives a design independent of ``seed``'s)."""
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    if lower.shape != upper.shape or lower.ndim != 1 or np.any(~(upper > lower)):
        raise ValueError("bounds must be 1-D arrays of equal length with upper > lower")
    if n_local and center is None:
        raise ValueError("a local design needs a centre")
    g_seed, l_seed = np.random.SeedSequence(seed).spawn(2)
    X = (
        qmc.scale(unit_design(n, lower.size, np.random.default_rng(g_seed), method), lower, upper)
        if n
        else np.empty((0, lower.size))
    )
    origin = ["global"] * n
    lbox = None
    if n_local:
        lbox = local_box(lower, upper, center, local_scale)
        XL = qmc.scale(
            unit_design(n_local, lower.size, np.random.default_rng(l_seed), method), *lbox
        )
        X = np.vstack([X, XL])
        origin += ["local"] * n_local
    return Design(X, np.array(origin), (lower, upper), lbox)

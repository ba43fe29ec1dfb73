"""Mapping a deformed image back to the reference configuration.

A material point at ``X`` (reference) is seen at ``x = X + u(X)`` in the deformed image.
To render the deformed image we need, for every deformed (sub-)pixel ``x``, the reference
point ``X`` that lands there: the solution of ``X = x - u(X)``. It is found by fixed-point
iteration ``X_{k+1} = x - u(X_k)`` (a contraction while ``|grad u| < 1``, which holds by many
orders of magnitude for a compression test), vectorised over all pixel centres.

Sub-pixel sample points then use the local affine expansion of the converged map around
their pixel centre, ``X(x + d) = X(x) + (dX/dx) d``, with ``dX/dx`` from central differences
of the pixel-centre map: the neglected term is ``u'' d^2 <= 0.25 px^2 |u''|``, far below
1e-4 px for any smooth field.

This module also turns the quarter-model field (y >= 0) into a full-face field by symmetry
(u_y odd, u_z even about y = 0) and a field in mm into one in image pixels.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from scipy import ndimage

Field = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


def mirror_quarter_field(field: Field, half_width: float, height: float) -> Field:
    """Full-face field from a quarter field ``field(y, z) -> (u_y, u_z)`` defined for ``y >= 0``.

    ``u_y(-y, z) = -u_y(y, z)`` and ``u_z(-y, z) = u_z(y, z)``. Points outside the face are
    clamped onto it (constant extension), so the field can be evaluated anywhere.
    """

    def full(y: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        y = np.asarray(y, dtype=float)
        z = np.asarray(z, dtype=float)
        yq = np.clip(np.abs(y), 0.0, half_width)
        zq = np.clip(z, 0.0, height)
        uy, uz = field(yq, zq)
        uy = np.broadcast_to(np.asarray(uy, dtype=float), y.shape)
        uz = np.broadcast_to(np.asarray(uz, dtype=float), y.shape)
        if not (np.all(np.isfinite(uy)) and np.all(np.isfinite(uz))):
            raise ValueError("the displacement field returned non-finite values on the front face")
        return np.where(y < 0, -uy, uy), uz

    return full


def inverse_map(
    displacement: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
    shape: tuple[int, int],
    *,
    map_step: int = 1,
    tol: float = 1e-7,
    max_iter: int = 50,
) -> tuple[np.ndarray, np.ndarray]:
    """Displacement ``u(X(x))`` (px) at every pixel centre ``x`` of a deformed image.

    displacement : ``u(X, Y) -> (u_x, u_y)`` in pixels, reference image coordinates
    shape        : (rows, cols) of the image
    map_step     : solve on every ``map_step``-th pixel and interpolate (cubic spline) in between
                   (1 = every pixel; larger values save field evaluations for slow fields)

    Returns ``(ux, uy)`` of shape ``shape``: the reference point of pixel ``x`` is ``x - u``.
    """
    rows, cols = shape
    step = max(1, int(map_step))
    # coarse grid overhangs the image: no spline edge effects inside
    pad = 0 if step == 1 else 3 * step
    ys = np.arange(-pad, rows - 1 + step + pad, step, dtype=float)
    xs = np.arange(-pad, cols - 1 + step + pad, step, dtype=float)
    x, y = np.meshgrid(xs, ys)
    X, Y = x.copy(), y.copy()
    for _ in range(max_iter):
        ux, uy = displacement(X, Y)
        Xn, Yn = x - ux, y - uy
        change = max(np.max(np.abs(Xn - X)), np.max(np.abs(Yn - Y)))
        X, Y = Xn, Yn
        if change < tol:
            break
    else:
        raise ValueError(
            f"the inverse mapping X = x - u(X) did not converge in {max_iter} iterations "
            f"(last change {change:.3g} px): is the displacement gradient close to or above 1?"
        )
    ux, uy = x - X, y - Y
    if step > 1:
        r, c = np.mgrid[0:rows, 0:cols].astype(float)
        coords = np.array([(r.ravel() + pad) / step, (c.ravel() + pad) / step])
        ux = ndimage.map_coordinates(ux, coords, order=3, mode="nearest").reshape(shape)
        uy = ndimage.map_coordinates(uy, coords, order=3, mode="nearest").reshape(shape)
    return ux, uy


def supersample_displacement(
    ux: np.ndarray, uy: np.ndarray, n: int
) -> tuple[np.ndarray, np.ndarray]:
    """Displacements ``(Ux, Uy)`` at the ``n x n`` sub-samples of every pixel (float32).

    Sub-sample ``(a, b)`` of pixel ``(r, c)`` sits at ``x = c + d_b``, ``y = r + d_a`` with
    ``d = (k + 1/2)/n - 1/2`` and is stored at super-grid index ``(r n + a, c n + b)``; its
    reference point is ``X = x - Ux``, ``Y = y - Uy``. ``ux, uy`` are the pixel-centre
    displacements from :func:`inverse_map`, expanded by the local affine map.
    """
    rows, cols = ux.shape
    d = (np.arange(n) + 0.5) / n - 0.5
    out = []
    for comp in (ux, uy):
        gy, gx = np.gradient(comp)  # d/drow, d/dcol at pixel centres
        val = (
            comp[:, None, :, None]
            + gx[:, None, :, None] * d[None, None, None, :]
            + gy[:, None, :, None] * d[None, :, None, None]
        ).reshape(rows * n, cols * n)
        out.append(val.astype(np.float32))
    return out[0], out[1]

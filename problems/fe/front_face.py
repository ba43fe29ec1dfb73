"""What a camera and a load cell see of a forward run: front-face displacements and plate force."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from problems.fe.mesh import Mesh


def measurement_grid(
    spacing_mm: float = 5.0,
    margin_mm: float = 5.0,
    width_mm: float = 75.0,
    height_mm: float = 150.0,
) -> np.ndarray:
    """Points (m, 2) = (y, z) mm on the front face, every ``spacing_mm`` with a ``margin_mm``
    margin.

    The default gives y = 5...70, z = 5...145: 14 x 29 = 406 points (z fastest).
    """
    if spacing_mm <= 0 or margin_mm < 0:
        raise ValueError(
            f"grid spacing_mm = {spacing_mm} must be > 0 and margin_mm = {margin_mm} >= 0"
        )
    y = np.arange(margin_mm, width_mm - margin_mm + 1e-9, spacing_mm)
    z = np.arange(margin_mm, height_mm - margin_mm + 1e-9, spacing_mm)
    Y, Z = np.meshgrid(y, z, indexing="ij")
    return np.column_stack([Y.ravel(), Z.ravel()])


def front_face_stencil(mesh: Mesh, points_mm) -> tuple[np.ndarray, np.ndarray]:
    """Node indices and weights (m, k) of the elements' own shape functions on the front face at
    points (y, z) mm: k = 4, bilinear (8-node), or k = 9, biquadratic (27-node); a nodal field
    ``u`` (n_nodes,) is ``(w * u[cols]).sum(axis=1)`` there.

    Uses the structured grid of the front face x = max x (node coordinates of the undeformed mesh;
    the elements' faces are flat with straight edges, so the face map is affine per direction).
    Points must lie on the face (within 1e-9 mm).
    """
    pts = np.atleast_2d(np.asarray(points_mm, float))
    g = mesh.grid_index()[-1]  # (gy+1, gz+1) node indices on x = 75 mm
    p = mesh.grid_shape[1] // mesh.shape[1]  # nodes per element edge - 1: 1 or 2
    ys, zs = mesh.nodes[g[::p, 0], 1], mesh.nodes[g[0, ::p], 2]  # element corners
    y, z = pts[:, 0], pts[:, 1]
    if np.any((y < ys[0] - 1e-9) | (y > ys[-1] + 1e-9) | (z < zs[0] - 1e-9) | (z > zs[-1] + 1e-9)):
        raise ValueError(
            f"front-face points must lie in y in [{ys[0]}, {ys[-1]}] mm, z in [{zs[0]}, {zs[-1]}] "
            "mm"
        )
    j = np.clip(np.searchsorted(ys, y, side="right") - 1, 0, len(ys) - 2)
    k = np.clip(np.searchsorted(zs, z, side="right") - 1, 0, len(zs) - 2)
    s = (y - ys[j]) / (ys[j + 1] - ys[j])
    t = (z - zs[k]) / (zs[k + 1] - zs[k])
    if p == 1:
        cols = np.stack([g[j, k], g[j + 1, k], g[j + 1, k + 1], g[j, k + 1]], axis=1)
        w = np.stack([(1 - s) * (1 - t), s * (1 - t), s * t, (1 - s) * t], axis=1)
    else:  # quadratic Lagrange through the corners and the mid-node in each direction
        ls = np.stack([(1 - s) * (1 - 2 * s), 4 * s * (1 - s), s * (2 * s - 1)], axis=1)
        lt = np.stack([(1 - t) * (1 - 2 * t), 4 * t * (1 - t), t * (2 * t - 1)], axis=1)
        a, b = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
        cols = g[2 * j[:, None] + a.ravel(), 2 * k[:, None] + b.ravel()]
        w = ls[:, a.ravel()] * lt[:, b.ravel()]
    return cols, w


def front_face_operator(mesh: Mesh, points_mm) -> sp.csr_matrix:
    """Sparse (m, n_nodes) interpolation from node values to front-face points (y, z) mm: the
    elements' own shape functions on the face (:func:`front_face_stencil`)."""
    cols, w = front_face_stencil(mesh, points_mm)
    pts = np.atleast_2d(np.asarray(points_mm, float))
    rows = np.repeat(np.arange(len(pts)), w.shape[1])
    return sp.csr_matrix((w.ravel(), (rows, cols.ravel())), shape=(len(pts), mesh.n_nodes))

"""The 8-node hexahedron with the mean-dilatation B-bar strain operator, vectorised over elements.

Why B-bar: with full 2x2x2 integration a trilinear hexahedron locks when the flow is (nearly)
isochoric, as in pressure-insensitive plasticity; replacing the volumetric part of B at each
Gauss point by its element average (Hughes' mean dilatation) removes the volumetric constraint
count while keeping full integration, so no hourglass modes appear (see docs/fe_model.md).

Strain uses the Voigt order ``[xx, yy, zz, yz, xz, xy]`` with engineering shears.
"""

from __future__ import annotations

import numpy as np

from problems.fe.mesh import HEX_CORNERS

_SIGNS = 2.0 * HEX_CORNERS - 1.0  # natural coordinates of the corners, (8, 3)
GAUSS_POINTS = _SIGNS / np.sqrt(3.0)  # 2x2x2 Gauss rule, (8, 3)
GAUSS_WEIGHTS = np.ones(8)


def shape_functions(xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Trilinear shape functions N (g, 8) and their natural derivatives dN/dxi (g, 8, 3) at xi
    (g, 3)."""
    t = 1.0 + xi[:, None, :] * _SIGNS[None]  # (g, 8, 3): 1 + xi_a s_a
    N = t.prod(axis=2) / 8.0
    dN = np.empty(t.shape)
    for d in range(3):
        others = [e for e in range(3) if e != d]
        dN[..., d] = _SIGNS[None, :, d] * t[..., others[0]] * t[..., others[1]] / 8.0
    return N, dN


def gradients(coords: np.ndarray, xi: np.ndarray = GAUSS_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """Physical shape-function gradients dN/dx (ne, g, 8, 3) and det J (ne, g) of elements
    (ne, 8, 3) mm."""
    _, dN = shape_functions(xi)
    J = np.einsum("gai,eaj->egij", dN, coords)  # J_ij = d x_j / d xi_i
    detJ = np.linalg.det(J)
    if np.any(detJ <= 0):
        bad = np.unique(np.nonzero(detJ <= 0)[0])
        raise ValueError(
            f"mesh has {len(bad)} inverted or degenerate elements (first: {bad[0]}): det J <= 0"
        )
    dNdx = np.einsum("egij,gaj->egai", np.linalg.inv(J), dN)
    return dNdx, detJ


def strain_operator(dNdx: np.ndarray) -> np.ndarray:
    """Standard small-strain operator B (ne, g, 6, 24) from gradients (ne, g, 8, 3)."""
    ne, g = dNdx.shape[:2]
    B = np.zeros((ne, g, 6, 8, 3))
    dx, dy, dz = dNdx[..., 0], dNdx[..., 1], dNdx[..., 2]
    B[:, :, 0, :, 0] = dx
    B[:, :, 1, :, 1] = dy
    B[:, :, 2, :, 2] = dz
    B[:, :, 3, :, 1], B[:, :, 3, :, 2] = dz, dy
    B[:, :, 4, :, 0], B[:, :, 4, :, 2] = dz, dx
    B[:, :, 5, :, 0], B[:, :, 5, :, 1] = dy, dx
    return B.reshape(ne, g, 6, 24)


def b_bar(dNdx: np.ndarray, detJ: np.ndarray, weights: np.ndarray = GAUSS_WEIGHTS) -> np.ndarray:
    """Mean-dilatation operator B-bar (ne, g, 6, 24): the volumetric part of B is replaced by its
    element mean."""
    B = strain_operator(dNdx)
    ne, g = dNdx.shape[:2]
    b = dNdx.reshape(ne, g, 24)  # volumetric row: div u = b . u_e
    dV = detJ * weights
    b_mean = np.einsum("eg,egk->ek", dV, b) / dV.sum(axis=1)[:, None]
    B[:, :, :3, :] += ((b_mean[:, None, :] - b) / 3.0)[:, :, None, :]
    return B

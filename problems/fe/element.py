"""The hexahedra of the model and their B-bar strain operators, vectorised over elements.

* 8-node trilinear hexahedron, 2x2x2 Gauss points, mean-dilatation B-bar. Why B-bar: with full
  integration a trilinear hexahedron locks when the flow is (nearly) isochoric, as in
  pressure-insensitive plasticity; replacing the volumetric part of B at each Gauss point by its
  element average (Hughes' mean dilatation) removes the volumetric constraint count while keeping
  full integration, so no hourglass modes appear (see docs/fe_model.md).
* 27-node triquadratic (Lagrange) hexahedron, 3x3x3 Gauss points, Q2-P1 B-bar: the volumetric
  strain at each Gauss point is the L2 projection of div u onto {1, x, y, z} over the element
  (the mixed Q2-P1 element with its discontinuous linear pressure condensed out, written as a
  B-bar; for elasticity the two are the same discrete problem). Mean dilatation is its
  projection onto {1}; four volumetric constraints per element against 81 dofs do not lock.

:func:`strain_operators` gives either element's B-bar and integration weights.

Strain uses the Voigt order ``[xx, yy, zz, yz, xz, xy]`` with engineering shears.
"""

from __future__ import annotations

import numpy as np

from problems.fe.mesh import HEX_CORNERS
from problems.fe.mesh_quadratic import HEX27_OFFSETS

_SIGNS = 2.0 * HEX_CORNERS - 1.0  # natural coordinates of the corners, (8, 3)
GAUSS_POINTS = _SIGNS / np.sqrt(3.0)  # 2x2x2 Gauss rule, (8, 3)
GAUSS_WEIGHTS = np.ones(8)

_NATURAL27 = HEX27_OFFSETS - 1.0  # natural coordinates of the 27 nodes, (27, 3) in {-1, 0, 1}
_G3, _W3 = np.array([-np.sqrt(0.6), 0.0, np.sqrt(0.6)]), np.array([5.0, 8.0, 5.0]) / 9.0
#: 3x3x3 Gauss rule (exact for the tensor-product quintics), x fastest, (27, 3) and (27,)
GAUSS27_POINTS = np.stack(np.meshgrid(_G3, _G3, _G3, indexing="ij")[::-1], axis=-1).reshape(-1, 3)
GAUSS27_WEIGHTS = np.einsum("k,j,i->kji", _W3, _W3, _W3).ravel()


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


def shape_functions_27(xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triquadratic Lagrange shape functions N (g, 27) and dN/dxi (g, 27, 3) at xi (g, 3), nodes in
    :data:`problems.fe.mesh_quadratic.HEX27_OFFSETS` order."""
    t = xi[:, None, :]  # (g, 1, 3)
    a = _NATURAL27[None]  # (1, 27, 3): node coordinate -1, 0 or 1 per direction
    # 1-D quadratic Lagrange polynomials through -1, 0, 1 and their derivatives
    L = np.where(a == 0, 1.0 - t * t, 0.5 * t * (t + a))
    dL = np.where(a == 0, -2.0 * t, t + 0.5 * a)
    N = L.prod(axis=2)
    dN = np.stack(
        [
            dL[..., 0] * L[..., 1] * L[..., 2],
            L[..., 0] * dL[..., 1] * L[..., 2],
            L[..., 0] * L[..., 1] * dL[..., 2],
        ],
        axis=-1,
    )
    return N, dN


def gradients(coords: np.ndarray, xi: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Physical shape-function gradients dN/dx (ne, g, n, 3) and det J (ne, g) of elements
    (ne, n, 3) mm with n = 8 or 27 nodes, at xi (g, 3) (default: the element's Gauss points)."""
    if coords.shape[1] == 27:
        _, dN = shape_functions_27(GAUSS27_POINTS if xi is None else xi)
    else:
        _, dN = shape_functions(GAUSS_POINTS if xi is None else xi)
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
    """Standard small-strain operator B (ne, g, 6, 3 n) from gradients (ne, g, n, 3)."""
    ne, g, n = dNdx.shape[:3]
    B = np.zeros((ne, g, 6, n, 3))
    dx, dy, dz = dNdx[..., 0], dNdx[..., 1], dNdx[..., 2]
    B[:, :, 0, :, 0] = dx
    B[:, :, 1, :, 1] = dy
    B[:, :, 2, :, 2] = dz
    B[:, :, 3, :, 1], B[:, :, 3, :, 2] = dz, dy
    B[:, :, 4, :, 0], B[:, :, 4, :, 2] = dz, dx
    B[:, :, 5, :, 0], B[:, :, 5, :, 1] = dy, dx
    return B.reshape(ne, g, 6, 3 * n)


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


def b_bar_p1(
    dNdx: np.ndarray,
    detJ: np.ndarray,
    coords: np.ndarray,
    weights: np.ndarray = GAUSS27_WEIGHTS,
    xi: np.ndarray = GAUSS27_POINTS,
) -> np.ndarray:
    """Q2-P1 operator B-bar (ne, g, 6, 81) of 27-node elements (ne, 27, 3) mm: the volumetric
    part of B at each Gauss point is replaced by the L2 projection of div u onto
    {1, x, y, z} over the element, ``c_g = phi_g^T M^-1 sum_h phi_h b_h dV_h`` with
    ``M = sum_h phi_h phi_h^T dV_h`` (phi centred and scaled by the element size)."""
    B = strain_operator(dNdx)
    ne, g, n = dNdx.shape[:3]
    b = dNdx.reshape(ne, g, 3 * n)  # volumetric row: div u = b . u_e
    dV = detJ * weights
    N, _ = shape_functions_27(xi)
    x = np.einsum("ga,eai->egi", N, coords)  # Gauss points, mm
    V = dV.sum(axis=1)
    centre = np.einsum("eg,egi->ei", dV, x) / V[:, None]
    phi = np.concatenate(
        [np.ones((ne, g, 1)), (x - centre[:, None]) / np.cbrt(V)[:, None, None]], axis=2
    )
    M = np.einsum("eg,egk,egl->ekl", dV, phi, phi)
    C = np.linalg.solve(M, np.einsum("eg,egk,ega->eka", dV, phi, b))  # (ne, 4, 3 n)
    c = np.einsum("egk,eka->ega", phi, C)
    B[:, :, :3, :] += ((c - b) / 3.0)[:, :, None, :]
    return B


def strain_operators(coords: np.ndarray, use_b_bar: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Strain operator B (ne, g, 6, 3 n) 1/mm and integration weights dV (ne, g) mm^3 of elements
    (ne, n, 3) mm: 8-node with mean dilatation or 27-node with Q2-P1 B-bar (``use_b_bar=False``:
    the standard, fully integrated element, which locks when nearly incompressible)."""
    dNdx, detJ = gradients(coords)
    if coords.shape[1] == 27:
        B = b_bar_p1(dNdx, detJ, coords) if use_b_bar else strain_operator(dNdx)
        return B, detJ * GAUSS27_WEIGHTS
    B = b_bar(dNdx, detJ) if use_b_bar else strain_operator(dNdx)
    return B, detJ * GAUSS_WEIGHTS


def element_mean(values: np.ndarray) -> np.ndarray:
    """Mean over the reference element of Gauss-point values (ne, g, ...) -> (ne, ...): the plain
    mean of the 8 points, the Gauss-weighted mean of the 27."""
    if values.shape[1] == 27:
        return np.einsum("g,eg...->e...", GAUSS27_WEIGHTS / 8.0, values)
    return values.mean(axis=1)

"""The 27-node (triquadratic) hexahedral mesh of a structured 8-node mesh.

Every 8-node element becomes one 27-node element with the same corners: its mid-edge, mid-face and
centre nodes are the images of the natural points (0 or +-1 in each direction) under the element's
trilinear map, so the elements keep straight edges and flat faces, and a graded or distorted
8-node mesh keeps its geometry. The nodes form the structured grid of twice the element counts
(:attr:`problems.fe.mesh.Mesh.grid_shape`), numbered x fastest, so faces, the mid-height mirror,
the lower half and the nested-dissection order of :mod:`problems.fe.mesh` apply unchanged.
"""

from __future__ import annotations

import numpy as np

from problems.fe.mesh import HEX_CORNERS, Mesh

#: grid offsets (0, 1, 2 per direction) of the 27 nodes in VTK order (VTK_TRIQUADRATIC_HEXAHEDRON,
#: type 29; meshio ``hexahedron27``): 8 corners, 12 mid-edge nodes (bottom, top, vertical edges),
#: 6 face centres (x0, x1, y0, y1, z0, z1) and the centre
HEX27_OFFSETS = np.array(
    [*(2 * HEX_CORNERS)]
    + [[1, 0, 0], [2, 1, 0], [1, 2, 0], [0, 1, 0]]
    + [[1, 0, 2], [2, 1, 2], [1, 2, 2], [0, 1, 2]]
    + [[0, 0, 1], [2, 0, 1], [2, 2, 1], [0, 2, 1]]
    + [[0, 1, 1], [2, 1, 1], [1, 0, 1], [1, 2, 1], [1, 1, 0], [1, 1, 2], [1, 1, 1]]
)


def quadratic_mesh(mesh: Mesh) -> Mesh:
    """The 27-node mesh with the elements of the structured 8-node ``mesh`` (same shape, corners and
    geometry; nodes on the (2 nx + 1) x (2 ny + 1) x (2 nz + 1) grid)."""
    if mesh.elements.shape[1] != 8:
        raise ValueError(
            f"quadratic_mesh needs an 8-node mesh, got {mesh.elements.shape[1]} nodes per element"
        )
    nx, ny, nz = mesh.shape
    gx, gy = 2 * nx + 1, 2 * ny + 1
    i, j, k = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    base = np.stack([i, j, k], axis=-1).reshape(-1, 3)
    order = np.lexsort((base[:, 0], base[:, 1], base[:, 2]))  # the element order of box_mesh
    base = base[order]
    corners = mesh.elements[base[:, 0] + nx * (base[:, 1] + ny * base[:, 2])]
    if not np.array_equal(corners, mesh.elements):
        raise ValueError("quadratic_mesh needs the structured element order of box_mesh")
    sub = 2 * base[:, None, :] + HEX27_OFFSETS[None]  # (ne, 27, 3) fine-grid indices
    elements = sub[..., 0] + gx * (sub[..., 1] + gy * sub[..., 2])
    # trilinear map of each element at the natural points t = offset / 2 in [0, 1]^3
    t = HEX27_OFFSETS / 2.0
    w = np.prod(np.where(HEX_CORNERS[None] == 1, t[:, None], 1.0 - t[:, None]), axis=2)  # (27, 8)
    xyz = np.einsum("ga,eai->egi", w, mesh.nodes[mesh.elements])
    nodes = np.empty((gx * gy * (2 * nz + 1), 3))
    nodes[elements.ravel()] = xyz.reshape(-1, 3)  # shared nodes: the same point from both sides
    return Mesh(nodes, elements, mesh.shape)

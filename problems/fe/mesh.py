"""Structured 8-node hexahedral mesh of the quarter cube and its named node sets.

The quarter model spans x, y in [0, 75] mm and z in [0, 150] mm; x = 0 and y = 0 are symmetry
planes, z = 0 and z = 150 mm the plates, x = 75 mm the front face the camera sees.
Node (i, j, k) of the (nx+1) x (ny+1) x (nz+1) grid has index ``i + (nx+1) (j + (ny+1) k)``.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

SIZE_MM = (75.0, 75.0, 150.0)
#: named presets: ``coarse`` ~ 400-600, ``paper`` ~ 5 000 (paper: 4 960), ``fine`` 15 000-20 000 elements
MESH_PRESETS: dict[str, tuple[int, int, int]] = {
    "coarse": (6, 6, 12),   # 432 elements, 12.5 mm cubes
    "paper": (14, 14, 25),  # 4 900 elements
    "fine": (20, 20, 40),   # 16 000 elements, 3.75 mm cubes (pseudo-experimental data only)
}

# Corner order of the 8-node hexahedron (VTK / Abaqus C3D8 order) in the (i, j, k) offsets.
HEX_CORNERS = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                        [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]])


@dataclass(frozen=True, eq=False)
class Mesh:
    """A structured hexahedral mesh.

    nodes    : (n_nodes, 3) coordinates, mm
    elements : (n_elements, 8) node indices in :data:`HEX_CORNERS` order
    shape    : (nx, ny, nz) element counts
    """

    nodes: np.ndarray
    elements: np.ndarray
    shape: tuple[int, int, int]

    @property
    def n_nodes(self) -> int:
        return len(self.nodes)

    @property
    def n_elements(self) -> int:
        return len(self.elements)

    @property
    def n_dofs(self) -> int:
        return 3 * len(self.nodes)

    def grid_index(self) -> np.ndarray:
        """Node indices arranged as the structured grid, shape (nx+1, ny+1, nz+1)."""
        nx, ny, nz = self.shape
        return np.arange(self.n_nodes).reshape(nz + 1, ny + 1, nx + 1).transpose(2, 1, 0)

    def face(self, name: str) -> np.ndarray:
        """Node indices of a boundary face: ``x0, x1, y0, y1, z0, z1`` (x1 = front, z1 = top)."""
        g = self.grid_index()
        faces = {"x0": g[0], "x1": g[-1], "y0": g[:, 0], "y1": g[:, -1], "z0": g[:, :, 0], "z1": g[:, :, -1]}
        if name not in faces:
            raise ValueError(f"face {name!r} is unknown; allowed: {', '.join(faces)}")
        return faces[name].ravel()

    def info(self) -> dict:
        """Summary for reports: nx, ny, nz, elements, nodes, dofs."""
        nx, ny, nz = self.shape
        return {"nx": nx, "ny": ny, "nz": nz, "elements": self.n_elements, "nodes": self.n_nodes, "dofs": self.n_dofs}


def box_mesh(nx: int, ny: int, nz: int, size_mm: tuple[float, float, float] = SIZE_MM) -> Mesh:
    """Uniform structured mesh of the box [0, lx] x [0, ly] x [0, lz] mm with nx x ny x nz hexahedra."""
    for name, n in zip("xyz", (nx, ny, nz)):
        if int(n) != n or n < 1:
            raise ValueError(f"mesh n{name} = {n!r} is out of range: a whole number >= 1")
    nx, ny, nz = int(nx), int(ny), int(nz)
    x, y, z = (np.linspace(0.0, L, n + 1) for L, n in zip(size_mm, (nx, ny, nz)))
    Z, Y, X = np.meshgrid(z, y, x, indexing="ij")
    nodes = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    i, j, k = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    base = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1)  # (ne, 3)
    corners = base[:, None, :] + HEX_CORNERS[None]             # (ne, 8, 3)
    elements = corners[..., 0] + (nx + 1) * (corners[..., 1] + (ny + 1) * corners[..., 2])
    order = np.lexsort((base[:, 0], base[:, 1], base[:, 2]))   # x fastest
    return Mesh(nodes, elements[order], (nx, ny, nz))


def parse_mesh(spec: str | tuple[int, int, int]) -> Mesh:
    """Mesh from a preset name (``coarse``, ``paper``, ``fine``), ``"NX,NY,NZ"`` or a tuple."""
    if isinstance(spec, tuple):
        return box_mesh(*spec)
    if spec in MESH_PRESETS:
        return box_mesh(*MESH_PRESETS[spec])
    if re.fullmatch(r"\s*\d+\s*,\s*\d+\s*,\s*\d+\s*", spec):
        return box_mesh(*(int(s) for s in spec.split(",")))
    raise ValueError(f"mesh {spec!r} is unknown; allowed: {', '.join(MESH_PRESETS)} or NX,NY,NZ (whole numbers >= 1)")


def distort(mesh: Mesh, amount: float, seed: int = 0) -> Mesh:
    """Copy of ``mesh`` with interior nodes moved randomly by up to ``amount`` x the smallest spacing.

    Boundary nodes stay on their faces so that boundary conditions keep their meaning.
    """
    rng = np.random.default_rng(seed)
    h = min(L / n for L, n in zip(np.ptp(mesh.nodes, axis=0), mesh.shape))
    g = mesh.grid_index()
    interior = g[1:-1, 1:-1, 1:-1].ravel()
    nodes = mesh.nodes.copy()
    nodes[interior] += rng.uniform(-amount * h, amount * h, size=(len(interior), 3))
    return Mesh(nodes, mesh.elements, mesh.shape)


def nested_dissection_order(mesh: Mesh, leaf: int = 8) -> np.ndarray:
    """Fill-reducing order of the nodes by geometric nested dissection of the structured grid.

    The grid is split recursively across its longest side by a one-node-thick separator plane
    that is numbered after both halves. On the 3-D cube this gives SuperLU ~2-4x less work than
    its own MMD orderings (measured in bench/perf/forward.py).
    """
    out: list[np.ndarray] = []

    def split(block: np.ndarray) -> None:
        axis = int(np.argmax(block.shape))
        n = block.shape[axis]
        if block.size <= leaf or n < 3:
            out.append(block.ravel())
            return
        m = n // 2
        split(np.take(block, np.arange(m), axis=axis))
        split(np.take(block, np.arange(m + 1, n), axis=axis))
        out.append(np.take(block, [m], axis=axis).ravel())

    split(mesh.grid_index())
    return np.concatenate(out)

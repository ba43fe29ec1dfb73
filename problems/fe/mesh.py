"""Structured 8-node hexahedral mesh of the quarter cube, its named node sets and its mid-height
symmetry.

The quarter model spans x, y in [0, 75] mm and z in [0, 150] mm; x = 0 and y = 0 are symmetry
planes, z = 0 and z = 150 mm the plates, x = 75 mm the front face the camera sees.
Node (i, j, k) of the (nx+1) x (ny+1) x (nz+1) grid has index ``i + (nx+1) (j + (ny+1) k)``.

With identical plates top and bottom the test is also symmetric about the mid-height plane
z = 75 mm, so the FE model may solve only the *eighth* z in [0, 75] mm (the lower half of the
quarter mesh: a prefix of its node and element arrays) and unfold the answer onto the quarter
mesh. A mesh spec names the quarter mesh and, optionally, the model that solves it:
``"coarse"``, ``"coarse:quarter"``, ``"6,6,12:eighth"`` (see :func:`parse_mesh_spec`). The eighth
is the default wherever it is exact, i.e. whenever nz is even (a node plane at mid-height).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

#: the whole specimen of the default test, (x, y, z) extents in mm: the 150 mm cube
SPECIMEN_MM = (150.0, 150.0, 150.0)


def quarter_size(specimen_mm=SPECIMEN_MM) -> tuple[float, float, float]:
    """Extents (mm) of the quarter model [0, lx/2] x [0, ly/2] x [0, lz] of a rectangular
    specimen of (x, y, z) extents ``specimen_mm``; ValueError unless all three are finite and
    > 0."""
    dims = tuple(float(v) for v in specimen_mm)
    if len(dims) != 3 or not all(np.isfinite(v) and v > 0 for v in dims):
        raise ValueError(
            f"specimen_mm = {tuple(specimen_mm)!r} is out of range: three finite lengths > 0 mm"
        )
    return (dims[0] / 2.0, dims[1] / 2.0, dims[2])


#: the quarter model of the default specimen
SIZE_MM = quarter_size(SPECIMEN_MM)
#: named presets: ``coarse`` ~ 400-600, ``paper`` ~ 5 000 (paper: 4 960), ``fine`` 15 000-20 000
#: elements
MESH_PRESETS: dict[str, tuple[int, int, int]] = {
    "coarse": (6, 6, 12),  # 432 elements, 12.5 mm cubes
    # 5 096 elements (was 14 x 14 x 25: nz even gives the exact eighth model)
    "paper": (14, 14, 26),
    "fine": (20, 20, 40),  # 16 000 elements, 3.75 mm cubes
    "xfine": (24, 24, 48),  # 27 648 elements, 3.125 mm cubes: the model-error data only
}

#: models of the quarter mesh: ``eighth`` solves z in [0, 75] mm and unfolds it (nz even only),
#: ``quarter`` all of it
SYMMETRIES = ("eighth", "quarter")

# Corner order of the 8-node hexahedron (VTK / Abaqus C3D8 order) in the (i, j, k) offsets.
HEX_CORNERS = np.array(
    [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]
)


@dataclass(frozen=True, eq=False)
class Mesh:
    """A structured hexahedral mesh.

    nodes    : (n_nodes, 3) coordinates, mm
    elements : (n_elements, 8) node indices in :data:`HEX_CORNERS` order, or (n_elements, 27)
               for the 27-node hexahedron (problems/fe/mesh_quadratic.py), whose nodes form the
               structured grid of twice the element counts
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

    @property
    def grid_shape(self) -> tuple[int, int, int]:
        """Node intervals of the structured node grid along x, y, z: ``shape`` for 8-node
        elements, twice it for 27-node elements (mid-edge, mid-face and centre nodes)."""
        p = 2 if self.elements.shape[1] == 27 else 1
        return tuple(p * n for n in self.shape)

    def grid_index(self) -> np.ndarray:
        """Node indices arranged as the structured grid, shape (gx+1, gy+1, gz+1) with
        :attr:`grid_shape` (gx, gy, gz) (= (nx, ny, nz) for 8-node elements)."""
        gx, gy, gz = self.grid_shape
        return np.arange(self.n_nodes).reshape(gz + 1, gy + 1, gx + 1).transpose(2, 1, 0)

    def face(self, name: str) -> np.ndarray:
        """Node indices of a boundary face: ``x0, x1, y0, y1, z0, z1`` (x1 = front, z1 = top)."""
        g = self.grid_index()
        faces = {
            "x0": g[0],
            "x1": g[-1],
            "y0": g[:, 0],
            "y1": g[:, -1],
            "z0": g[:, :, 0],
            "z1": g[:, :, -1],
        }
        if name not in faces:
            raise ValueError(f"face {name!r} is unknown; allowed: {', '.join(faces)}")
        return faces[name].ravel()

    def info(self) -> dict:
        """Summary for reports: nx, ny, nz, elements, nodes, dofs."""
        nx, ny, nz = self.shape
        return {
            "nx": nx,
            "ny": ny,
            "nz": nz,
            "elements": self.n_elements,
            "nodes": self.n_nodes,
            "dofs": self.n_dofs,
        }


def box_mesh(nx: int, ny: int, nz: int, size_mm: tuple[float, float, float] = SIZE_MM) -> Mesh:
    """Uniform structured mesh of the box [0, lx] x [0, ly] x [0, lz] mm with nx x ny x nz
    hexahedra."""
    for name, n in zip("xyz", (nx, ny, nz)):
        if int(n) != n or n < 1:
            raise ValueError(f"mesh n{name} = {n!r} is out of range: a whole number >= 1")
    nx, ny, nz = int(nx), int(ny), int(nz)
    x, y, z = (np.linspace(0.0, L, n + 1) for L, n in zip(size_mm, (nx, ny, nz)))
    Z, Y, X = np.meshgrid(z, y, x, indexing="ij")
    nodes = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    i, j, k = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    base = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1)  # (ne, 3)
    corners = base[:, None, :] + HEX_CORNERS[None]  # (ne, 8, 3)
    elements = corners[..., 0] + (nx + 1) * (corners[..., 1] + (ny + 1) * corners[..., 2])
    order = np.lexsort((base[:, 0], base[:, 1], base[:, 2]))  # x fastest
    return Mesh(nodes, elements[order], (nx, ny, nz))


@dataclass(frozen=True)
class MeshSpec:
    """A parsed mesh spec: the quarter mesh (nx, ny, nz over the full height) and the model that
    solves it.

    symmetry : ``eighth`` (solve the lower half z <= 75 mm, unfold the answer; needs nz even) or
               ``quarter`` (solve the whole height)
    """

    shape: tuple[int, int, int]
    symmetry: str

    @property
    def mesh(self) -> Mesh:
        """The quarter mesh of the whole height of the default specimen (what responses are
        reported on)."""
        return self.build()

    def build(self, size_mm: tuple[float, float, float] = SIZE_MM) -> Mesh:
        """The quarter mesh of the whole height of a quarter model of extents ``size_mm`` (mm;
        :func:`quarter_size` of the specimen)."""
        return box_mesh(*self.shape, size_mm=size_mm)

    def __str__(self) -> str:
        return f"{','.join(map(str, self.shape))}:{self.symmetry}"


def default_symmetry(shape: tuple[int, int, int]) -> str:
    """``eighth`` where it is exact (nz even: a node plane at mid-height), else ``quarter``."""
    return "eighth" if shape[2] % 2 == 0 else "quarter"


def check_symmetry(symmetry: str, shape: tuple[int, int, int], what: str = "symmetry") -> str:
    """``symmetry`` if it is known and exact on a mesh of ``shape``; ValueError naming ``what``
    otherwise."""
    if symmetry not in SYMMETRIES:
        raise ValueError(f"{what} {symmetry!r} is unknown; allowed: {', '.join(SYMMETRIES)}")
    if symmetry == "eighth" and shape[2] % 2:
        raise ValueError(
            f"{what} 'eighth' needs an even NZ (a node plane at mid-height), got NZ = {shape[2]}; "
            f"use NZ = {shape[2] + 1} or 'quarter'"
        )
    return symmetry


def parse_mesh_spec(spec: str | tuple[int, int, int] | MeshSpec) -> MeshSpec:
    """Parse ``MESH[:SYMMETRY]``: MESH a preset (``coarse``, ``paper``, ``fine``), ``NX,NY,NZ`` or a
    tuple; SYMMETRY ``eighth`` or ``quarter``, by default ``eighth`` where it is exact (NZ even).
    ValueError for NZ < 2 (every node on a plate: nothing to solve)."""
    if isinstance(spec, MeshSpec):
        return spec
    symmetry = None
    if isinstance(spec, tuple):
        for name, n in zip("xyz", spec):
            if int(n) != n or n < 1:
                raise ValueError(f"mesh n{name} = {n!r} is out of range: a whole number >= 1")
        shape = tuple(int(n) for n in spec)
    else:
        base, sep, symmetry = str(spec).partition(":")
        base, symmetry = base.strip(), (symmetry.strip() if sep else None)
        if base in MESH_PRESETS:
            shape = MESH_PRESETS[base]
        elif re.fullmatch(r"\s*\d+\s*,\s*\d+\s*,\s*\d+\s*", base):
            shape = tuple(int(t) for t in base.split(","))
            for name, n in zip("xyz", shape):
                if n < 1:
                    raise ValueError(f"mesh n{name} = {n!r} is out of range: a whole number >= 1")
        else:
            raise ValueError(
                f"mesh {spec!r} is unknown; allowed: {', '.join(MESH_PRESETS)} or NX,NY,NZ "
                f"(whole numbers >= 1), optionally followed by :{'|:'.join(SYMMETRIES)}"
            )
    if shape[2] < 2:
        raise ValueError(
            f"mesh {spec!r}: NZ = {shape[2]} leaves no node between the plates (no free dof); "
            "allowed: NZ >= 2"
        )
    if symmetry is None:
        return MeshSpec(shape, default_symmetry(shape))
    return MeshSpec(shape, check_symmetry(symmetry, shape, f"mesh {spec!r}: symmetry"))


def discretisation_key(spec: str | tuple[int, int, int] | MeshSpec) -> str:
    """``"NX,NY,NZ"`` of a spec: two specs with the same key give the same answer (the eighth and
    the quarter model of one mesh agree to round-off), whatever their names."""
    return ",".join(map(str, parse_mesh_spec(spec).shape))


def parse_mesh(spec: str | tuple[int, int, int] | MeshSpec) -> Mesh:
    """The quarter mesh of a spec (see :func:`parse_mesh_spec`; the symmetry suffix does not change
    it)."""
    return parse_mesh_spec(spec).mesh


def mid_height_mirror(mesh: Mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Source of every node and element of a mesh symmetric about mid-height in its lower half.

    Returns ``node_src, node_upper, elem_src, elem_upper``: for each node (element) of ``mesh`` the
    index of its mirror image in the lower half z <= z_mid (itself when it lies there), and whether
    it lies strictly above the mid-plane. The lower half is a prefix of the node and element arrays,
    so the indices are also those of :func:`lower_half`.
    """
    nx, ny, nz = mesh.shape
    if nz % 2:
        raise ValueError(
            f"the mid-height mirror needs an even nz (a node plane at mid-height), got nz = {nz}"
        )
    gx, gy, gz = mesh.grid_shape
    layer_n, layer_e = (gx + 1) * (gy + 1), nx * ny
    k = np.arange(mesh.n_nodes) // layer_n
    node_src = np.arange(mesh.n_nodes) - (k - np.minimum(k, gz - k)) * layer_n
    ke = np.arange(mesh.n_elements) // layer_e
    elem_src = np.arange(mesh.n_elements) - (ke - np.minimum(ke, nz - 1 - ke)) * layer_e
    z = mesh.nodes[:, 2]
    z0, z1 = z[0], z[-1]
    if not (
        np.allclose(mesh.nodes[:, :2], mesh.nodes[node_src, :2], rtol=0, atol=1e-9 * (z1 - z0))
        and np.allclose(
            np.where(k > gz // 2, z0 + z1 - z, z), z[node_src], rtol=0, atol=1e-9 * (z1 - z0)
        )
    ):
        raise ValueError("the mesh is not symmetric about its mid-height plane")
    return node_src, k > gz // 2, elem_src, ke >= nz // 2


def lower_half(mesh: Mesh) -> Mesh:
    """The part z <= z_mid of a mesh symmetric about mid-height (nz even): nz / 2 layers, same
    element size."""
    mid_height_mirror(mesh)  # checks nz even and the symmetry of the nodes
    nx, ny, nz = mesh.shape
    gx, gy, gz = mesh.grid_shape
    n_nodes, n_elements = (gx + 1) * (gy + 1) * (gz // 2 + 1), nx * ny * (nz // 2)
    return Mesh(mesh.nodes[:n_nodes].copy(), mesh.elements[:n_elements].copy(), (nx, ny, nz // 2))


#: Voigt order of the stress (xx, yy, zz, yz, xz, xy); the mirror z -> -z flips yz and xz
Z_MIRROR_VOIGT = np.array([1.0, 1.0, 1.0, -1.0, -1.0, 1.0])


def z_mirror_signs(names) -> np.ndarray:
    """Sign of each named history variable under z -> -z: -1 for the ``*_yz`` and ``*_xz`` tensor
    components."""
    return np.array([-1.0 if n.endswith(("_yz", "_xz", "_zy", "_zx")) else 1.0 for n in names])


def unfold_mid_height(
    mesh: Mesh,
    top_mm: np.ndarray,
    displacements: np.ndarray,
    stress: np.ndarray,
    state: np.ndarray,
    state_names,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fields of the eighth model (lower half of ``mesh``) unfolded onto the whole of ``mesh``.

    top_mm        : (N,) top-plate displacement per snapshot, mm (compression positive)
    displacements : (N, n_half_nodes, 3) mm
    stress        : (N, n_half_elements, 6) MPa
    state         : (N, n_half_elements, s)

    Mirror image of the point (x, y, z) is (x, y, L - z): u_x, u_y are even,
    u_z(L - z) = -delta - u_z(z) (the top moves by -delta, the bottom is fixed); stress and tensor
    history variables keep their components except yz and xz, which change sign.
    """
    node_src, node_up, elem_src, elem_up = mid_height_mirror(mesh)
    u = displacements[:, node_src].copy()
    top = np.asarray(top_mm, float).reshape(-1, 1)
    u[:, node_up, 2] = -top - u[:, node_up, 2]
    s = stress[:, elem_src].copy()
    s[:, elem_up] *= Z_MIRROR_VOIGT
    h = state[:, elem_src].copy()
    h[:, elem_up] *= z_mirror_signs(state_names)
    return u, s, h


def distort(mesh: Mesh, amount: float, seed: int = 0) -> Mesh:
    """Copy of ``mesh`` with interior nodes moved randomly by up to ``amount`` x the smallest
    spacing.

    Boundary nodes stay on their faces so that boundary conditions keep their meaning.
    """
    rng = np.random.default_rng(seed)
    h = min(L / n for L, n in zip(np.ptp(mesh.nodes, axis=0), mesh.grid_shape))
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

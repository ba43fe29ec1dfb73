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

from problems.fe.presets import MESH_PRESETS, SPEC_PRESETS  # noqa: F401 (this module's API)

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
#: models of the quarter mesh: ``eighth`` solves z in [0, 75] mm and unfolds it (nz even only),
#: ``quarter`` all of it
SYMMETRIES = ("eighth", "quarter")

#: elements of a mesh spec: the 8-node B-bar hexahedron (default) and the 27-node Q2-P1
#: hexahedron (problems/fe/mesh_quadratic.py)
ELEMENTS = ("hex8", "hex27")

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


def graded_coordinates(n: int, length_mm: float, ratio: float, toward: str) -> np.ndarray:
    """Node coordinates (n + 1,) in mm on [0, length_mm] of ``n`` elements whose lengths grow
    geometrically, the largest ``ratio`` times the smallest (ratio >= 1; 1 gives
    ``np.linspace``).

    toward : ``end`` (smallest element at ``length_mm``: a free face, largest at 0: a symmetry
             plane) or ``both`` (smallest at both ends: the plates, largest at mid-length; the
             coordinates are exactly symmetric, z_k + z_(n-k) = length_mm, so the lower half of an
             even ``n`` is the eighth model of the whole)
    """
    if not (np.isfinite(ratio) and ratio >= 1.0):
        raise ValueError(f"grading ratio = {ratio!r} is out of range: a number >= 1")
    if toward not in ("end", "both"):
        raise ValueError(f"toward = {toward!r} is unknown; allowed: end, both")
    if ratio == 1.0:
        return np.linspace(0.0, length_mm, n + 1)
    k = np.arange(n)
    level = (n - 1 - k) if toward == "end" else np.minimum(k, n - 1 - k)  # 0 = smallest
    top = level.max()
    sizes = ratio ** (level / top) if top > 0 else np.ones(n)
    x = np.concatenate([[0.0], np.cumsum(sizes)]) * (length_mm / sizes.sum())
    if toward == "both":
        x = 0.5 * (x + length_mm - x[::-1])  # exact mirror symmetry about the middle
    x[0], x[-1] = 0.0, length_mm
    return x


def graded_box_mesh(
    nx: int,
    ny: int,
    nz: int,
    ratio: float = 1.0,
    size_mm: tuple[float, float, float] = SIZE_MM,
    ratio_z: float | None = None,
) -> Mesh:
    """Structured mesh of the box [0, lx] x [0, ly] x [0, lz] mm (the quarter model) with
    nx x ny x nz hexahedra, node spacing graded geometrically (:func:`graded_coordinates`) toward
    the free faces x = lx, y = ly (largest elements at the symmetry planes x = 0, y = 0) and
    toward both plates z = 0, lz (largest at mid-height, symmetric about it): the largest element
    is ``ratio`` (>= 1) times the smallest along x and y, ``ratio_z`` (>= 1; None: ``ratio``)
    times along z; ratio 1 is uniform (:func:`box_mesh`). Node and element numbering do not
    depend on the ratios."""
    for name, n in zip("xyz", (nx, ny, nz)):
        if int(n) != n or n < 1:
            raise ValueError(f"mesh n{name} = {n!r} is out of range: a whole number >= 1")
    nx, ny, nz = int(nx), int(ny), int(nz)
    ratios = (ratio, ratio, ratio if ratio_z is None else ratio_z)
    x, y, z = (
        graded_coordinates(n, L, r, toward)
        for n, L, r, toward in zip((nx, ny, nz), size_mm, ratios, ("end", "end", "both"))
    )
    Z, Y, X = np.meshgrid(z, y, x, indexing="ij")
    nodes = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    i, j, k = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    base = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1)  # (ne, 3)
    corners = base[:, None, :] + HEX_CORNERS[None]  # (ne, 8, 3)
    elements = corners[..., 0] + (nx + 1) * (corners[..., 1] + (ny + 1) * corners[..., 2])
    order = np.lexsort((base[:, 0], base[:, 1], base[:, 2]))  # x fastest
    return Mesh(nodes, elements[order], (nx, ny, nz))


def box_mesh(nx: int, ny: int, nz: int, size_mm: tuple[float, float, float] = SIZE_MM) -> Mesh:
    """Uniform structured mesh of the box [0, lx] x [0, ly] x [0, lz] mm with nx x ny x nz
    hexahedra."""
    return graded_box_mesh(nx, ny, nz, 1.0, size_mm)


@dataclass(frozen=True)
class MeshSpec:
    """A parsed mesh spec: the quarter mesh (nx, ny, nz elements over the full height), its node
    spacing and element, and the model that solves it.

    symmetry : ``eighth`` (solve the lower half z <= 75 mm, unfold the answer; needs nz even) or
               ``quarter`` (solve the whole height)
    grading  : largest / smallest element length along each direction (>= 1; 1 = uniform), see
               :func:`graded_box_mesh`; along x and y only when ``grading_z`` is given
    element  : ``hex8`` or ``hex27`` (:data:`ELEMENTS`)
    grading_z: largest / smallest element length along z, toward the plates (>= 1), or None: the
               same as ``grading``; stored as None when it equals ``grading`` (one discretisation,
               one spec and one :attr:`key`)
    """

    shape: tuple[int, int, int]
    symmetry: str
    grading: float = 1.0
    element: str = "hex8"
    grading_z: float | None = None

    def __post_init__(self):
        if self.grading_z is not None and float(self.grading_z) == float(self.grading):
            object.__setattr__(self, "grading_z", None)

    @property
    def mesh(self) -> Mesh:
        """The quarter mesh of the whole height of the default specimen (what responses are
        reported on)."""
        return self.build()

    def build(self, size_mm: tuple[float, float, float] = SIZE_MM) -> Mesh:
        """The quarter mesh of the whole height of a quarter model of extents ``size_mm`` (mm;
        :func:`quarter_size` of the specimen)."""
        mesh = graded_box_mesh(
            *self.shape, ratio=self.grading, size_mm=size_mm, ratio_z=self.grading_z
        )
        if self.element == "hex27":
            from problems.fe.mesh_quadratic import quadratic_mesh

            mesh = quadratic_mesh(mesh)
        return mesh

    @property
    def key(self) -> str:
        """The discretisation: ``"NX,NY,NZ"`` then ``:gR`` when graded, ``:gzR`` when the
        grading toward the plates differs from it and ``:hex27`` for the 27-node element (a
        uniform 8-node mesh keeps the bare ``"NX,NY,NZ"``)."""
        tokens = [",".join(map(str, self.shape))]
        if self.grading != 1.0:
            tokens.append(f"g{self.grading:g}")
        if self.grading_z is not None:
            tokens.append(f"gz{self.grading_z:g}")
        if self.element != "hex8":
            tokens.append(self.element)
        return ":".join(tokens)

    def __str__(self) -> str:
        return f"{self.key}:{self.symmetry}"


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


#: what may follow the size in a mesh spec (for error messages)
_TOKENS_HELP = f"{'|'.join(SYMMETRIES)}|gR (R >= 1)|gzR (R >= 1)|{'|'.join(ELEMENTS)}"


def _grading(token: str, spec, prefix: str = "g") -> float:
    """The ratio R of a ``gR`` (``prefix`` ``g``) or ``gzR`` (``gz``: toward the plates) token;
    ValueError unless R is a finite number >= 1."""
    try:
        ratio = float(token[len(prefix) :])
    except ValueError:
        ratio = float("nan")
    if not (np.isfinite(ratio) and ratio >= 1.0):
        kind = "grading" if prefix == "g" else "grading toward the plates"
        raise ValueError(
            f"mesh {spec!r}: {kind} {token!r} is out of range; allowed: {prefix}R with R a "
            "number >= 1 (largest / smallest element length)"
        )
    return ratio


def parse_mesh_spec(spec: str | tuple[int, int, int] | MeshSpec) -> MeshSpec:
    """Parse ``MESH[:TOKEN...]``: MESH a preset (``coarse``, ``paper``, ``fine``, ``xfine``; or
    ``converged``, a full spec in :data:`problems.fe.presets.SPEC_PRESETS`, whose tokens may not
    be given again), ``NX,NY,NZ`` or
    a tuple; then, in any order and each at most once, a symmetry ``eighth`` or
    ``quarter`` (default ``eighth`` where it is exact, NZ even), a grading ``gR`` (R >= 1 the
    largest / smallest element length along every direction, :func:`graded_box_mesh`; default
    uniform, ``g1``), a grading toward the plates ``gzR`` (R >= 1: the ratio along z, overriding
    ``gR`` there; default that of ``gR``; ``6,6,12:g16:gz8`` grades 16 toward the free faces and
    8 toward the plates) and an element ``hex8`` (default) or ``hex27``. ValueError (one line)
    for anything else and for NZ < 2 (every node on a plate: nothing to solve)."""
    if isinstance(spec, MeshSpec):
        return spec
    given: dict[str, object] = {}  # symmetry, grading, grading_z, element
    if isinstance(spec, tuple):
        for name, n in zip("xyz", spec):
            if int(n) != n or n < 1:
                raise ValueError(f"mesh n{name} = {n!r} is out of range: a whole number >= 1")
        shape = tuple(int(n) for n in spec)
    else:
        base, *tokens = (t.strip() for t in str(spec).split(":"))
        if base in SPEC_PRESETS:  # its own tokens first: given again, they are given twice
            base, *preset_tokens = SPEC_PRESETS[base].split(":")
            tokens = preset_tokens + tokens
        if base in MESH_PRESETS:
            shape = MESH_PRESETS[base]
        elif re.fullmatch(r"\d+\s*,\s*\d+\s*,\s*\d+", base):
            shape = tuple(int(t) for t in base.split(","))
            for name, n in zip("xyz", shape):
                if n < 1:
                    raise ValueError(f"mesh n{name} = {n!r} is out of range: a whole number >= 1")
        else:
            raise ValueError(
                f"mesh {spec!r} is unknown; allowed: {', '.join([*MESH_PRESETS, *SPEC_PRESETS])} "
                "or NX,NY,NZ "
                f"(whole numbers >= 1), optionally followed by :TOKEN with TOKEN {_TOKENS_HELP}"
            )
        for token in tokens:
            if token in SYMMETRIES:
                kind, value = "symmetry", token
            elif token in ELEMENTS:
                kind, value = "element", token
            elif token.startswith("gz"):  # before gR, which would take it
                kind, value = "grading_z", _grading(token, spec, "gz")
            elif re.fullmatch(r"g.*", token):
                kind, value = "grading", _grading(token, spec)
            else:
                raise ValueError(
                    f"mesh {spec!r}: token {token!r} is unknown; allowed after the size: "
                    f"{_TOKENS_HELP}"
                )
            if kind in given:
                what = "grading toward the plates (gzR)" if kind == "grading_z" else kind
                raise ValueError(f"mesh {spec!r}: {what} given twice; allowed: once each")
            given[kind] = value
    if shape[2] < 2:
        raise ValueError(
            f"mesh {spec!r}: NZ = {shape[2]} leaves no node between the plates (no free dof); "
            "allowed: NZ >= 2"
        )
    symmetry = (
        check_symmetry(given["symmetry"], shape, f"mesh {spec!r}: symmetry")
        if "symmetry" in given
        else default_symmetry(shape)
    )
    return MeshSpec(
        shape,
        symmetry,
        given.get("grading", 1.0),
        given.get("element", "hex8"),
        given.get("grading_z"),
    )


def discretisation_key(spec: str | tuple[int, int, int] | MeshSpec) -> str:
    """``"NX,NY,NZ[:gR][:gzR][:hex27]"`` of a spec (:attr:`MeshSpec.key`): two specs with the
    same key give the same answer (the eighth and the quarter model of one mesh agree to
    round-off), whatever their names."""
    return parse_mesh_spec(spec).key


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

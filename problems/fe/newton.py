"""Quasi-static small-strain FE analysis of the quarter cube between rigid plates.

The quarter (x, y in [0, 75], z in [0, 150] mm) is solved whole (``symmetry="quarter"``) or, using
the mid-height symmetry of identical plates, as its lower half (``symmetry="eighth"``: z in [0, 75]
mm, mid-plane u_z = -delta/2 prescribed, u_x and u_y free there) whose answer :func:`run` unfolds
onto the quarter mesh, so a :class:`Response` is the same whichever model solved it.

Full Newton-Raphson with the material's consistent tangent (possibly non-symmetric), assembled by
compiled kernels straight into the free-free block; each correction solved by GMRES on the exact
tangent, preconditioned by a reused CHOLMOD factorisation of a tangent's symmetric part, to a
Newton forcing term that keeps the convergence quadratic (or by SuperLU per iteration:
``NewtonSettings.linear_solver``; see problems/fe/linear_solver.py); convergence on the relative
residual force *and* the relative displacement correction, fixed sub-increments between snapshots
and automatic bisection of an increment that fails (material return mapping failure, divergence,
too many iterations, singular tangent), with a bounded number of cuts. A run that still fails
returns a :class:`Response` flagged ``converged=False`` with the snapshots completed so far and a
message saying where and why; it never raises into the caller.

Units: mm, N, MPa. Compression of the specimen is reported positive (``snapshots_mm``,
``reaction_kN``); displacement fields keep their sign (the top moves by ``-delta`` in z).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from functools import cached_property
from typing import Callable, Protocol

import numpy as np
import scipy.sparse as sp

from problems.fe.assembly import (
    FusedAssembler,
    Pattern,
    build_pattern,
    element_forces,
    element_matrices,
)
from problems.fe.cache import shared
from problems.fe.ddm import (
    GlobalDDM,
    Sensitivities,
    SensitivitySettings,
    select_parameters,
)
from problems.fe.element import element_mean, strain_operators
from problems.fe.linear_solver import (
    LINEAR_SOLVERS,
    Factor,
    LinearSolver,
    LUGmresFactor,
    SingularMatrixError,
    make_linear_solver,
    superlu_factor,
)
from problems.fe.mesh import (
    Mesh,
    check_symmetry,
    lower_half,
    nested_dissection_order,
    unfold_mid_height,
)
from problems.materials.base import Material

PLATES = ("friction", "frictionless")
ASSEMBLIES = ("fused", "numpy")


@dataclass(frozen=True)
class Loading:
    """Prescribed loading of the test.

    displacement_mm : total downward displacement of the top plate, mm (> 0)
    snapshots       : number of equally spaced output states (>= 1)
    plates          : ``friction`` (no lateral slip on top and bottom) or ``frictionless``
    """

    displacement_mm: float = 1.5
    snapshots: int = 10
    plates: str = "friction"

    def __post_init__(self):
        if not (np.isfinite(self.displacement_mm) and self.displacement_mm > 0):
            raise ValueError(
                f"displacement_mm = {self.displacement_mm!r} is out of range: must be > 0 mm"
            )
        if int(self.snapshots) != self.snapshots or self.snapshots < 1:
            raise ValueError(f"snapshots = {self.snapshots!r} is out of range: a whole number >= 1")
        if self.plates not in PLATES:
            raise ValueError(f"plates = {self.plates!r} is unknown; allowed: {', '.join(PLATES)}")

    @property
    def fractions(self) -> np.ndarray:
        """(N,) fraction of ``displacement_mm`` at each snapshot: k / N, equally spaced."""
        return np.arange(1, self.snapshots + 1) / self.snapshots

    @property
    def snapshots_mm(self) -> np.ndarray:
        return self.displacement_mm * self.fractions


@dataclass(frozen=True)
class MachineLoading(Loading):
    """Loading at the plate displacements a testing machine logged at each image (a real test).

    levels_mm : (N,) top-plate displacement at each snapshot, mm, strictly increasing, > 0
                (``displacement_mm`` and ``snapshots`` are its last value and length)
    """

    levels_mm: tuple[float, ...] = (1.5,)

    def __init__(self, levels_mm, plates: str = "friction"):
        levels = tuple(float(v) for v in np.ravel(levels_mm))
        if (
            not levels
            or not np.all(np.isfinite(levels))
            or levels[0] <= 0
            or np.any(np.diff(levels) <= 0)
        ):
            raise ValueError(
                f"levels_mm = {levels!r} is out of range: finite, > 0 mm and strictly increasing"
            )
        object.__setattr__(self, "levels_mm", levels)
        super().__init__(levels[-1], len(levels), plates)

    @property
    def fractions(self) -> np.ndarray:
        return np.array(self.levels_mm) / self.displacement_mm


@dataclass(frozen=True)
class NewtonSettings:
    """Nonlinear solver settings.

    rtol_force        : ||R_free|| <= rtol_force * ||reaction forces||
    rtol_displacement : ||du|| <= rtol_displacement * ||increment||
    max_iterations    : Newton iterations per increment before the increment is cut
    substeps          : increments between two snapshots
    max_cuts          : total bisections allowed in a run
    linear_rtol       : an increment whose residual is below linear_rtol * rtol_force is accepted
                        without the displacement test (Abaqus' "linear increment" rule)
    linear_solver     : ``auto`` (``cholmod-gmres`` when kvxopt is installed, else ``superlu``),
                        ``cholmod-gmres`` (CHOLMOD of the tangent's symmetric part, reused across
                        iterations, preconditioning GMRES on the exact tangent) or ``superlu`` (a
                        new LU per iteration, the old path); see problems/fe/linear_solver.py
    assembly          : ``fused`` (compiled kernels straight into the free-free block) or ``numpy``
                        (the batched numpy reference and a full CSR matrix, the old path)
    sensitivity       : how a run with sensitivities solves them
                        (:class:`problems.fe.ddm.SensitivitySettings`)
    on_linear_solve   : None, or a callable ``f(kind, Kff, rhs)`` told of every linear system a
                        Newton iteration solves, before it is solved: ``kind`` is ``"predictor"``
                        (the first system of an increment) or ``"correction"``, ``Kff`` the free
                        block of the tangent in elimination order (CSC, N/mm; not to be changed),
                        ``rhs`` the right-hand side in ``BoundaryConditions.free`` order (N);
                        for instruments (bench/perf/linear_solvers.py keeps the tangents); the
                        run's answer does not depend on it
    """

    rtol_force: float = 1e-8
    rtol_displacement: float = 1e-8
    max_iterations: int = 20
    substeps: int = 1
    max_cuts: int = 8
    linear_rtol: float = 1e-4
    linear_solver: str = "auto"
    assembly: str = "fused"
    sensitivity: SensitivitySettings = SensitivitySettings()
    on_linear_solve: Callable | None = field(default=None, compare=False)

    def __post_init__(self):
        if self.linear_solver not in LINEAR_SOLVERS:
            raise ValueError(
                f"linear_solver = {self.linear_solver!r} is unknown; allowed: "
                f"{', '.join(LINEAR_SOLVERS)}"
            )
        if self.assembly not in ASSEMBLIES:
            raise ValueError(
                f"assembly = {self.assembly!r} is unknown; allowed: {', '.join(ASSEMBLIES)}"
            )


@dataclass(frozen=True, eq=False)
class Discretisation:
    """Everything about a mesh that does not change between runs: B-bar, volumes, sparsity.

    ``mesh`` is the mesh that is solved; ``full_mesh`` the quarter mesh of the whole height that
    responses are reported on (the same mesh for ``symmetry="quarter"``, twice as tall for
    ``eighth``).
    """

    mesh: Mesh
    B: np.ndarray  # (ne, g, 6, nd): g = 8, nd = 24 (8-node) or g = 27, nd = 81 (27-node)
    dV: np.ndarray  # (ne, g) mm^3
    pattern: Pattern
    symmetry: str = "quarter"
    full_mesh: Mesh | None = None

    def __post_init__(self):
        if self.full_mesh is None:
            object.__setattr__(self, "full_mesh", self.mesh)

    @property
    def n_points(self) -> int:
        return self.dV.size


def discretise(mesh: Mesh, *, use_b_bar: bool = True, symmetry: str = "quarter") -> Discretisation:
    """Precompute the strain operators, integration weights and sparsity pattern of ``mesh``.

    ``mesh`` is the quarter mesh of the whole height. ``symmetry="eighth"`` solves only its lower
    half (nz even, mesh symmetric about mid-height; exact for identical plates, which are the only
    option); runs still report on ``mesh``. Mesh specs choose it by default where it is exact
    (:func:`problems.fe.mesh.parse_mesh_spec`); this low-level call solves what it is given.
    The element is the mesh's: 8-node hexahedra with mean dilatation or 27-node hexahedra with the
    Q2-P1 B-bar (:func:`problems.fe.element.strain_operators`). ``use_b_bar=False`` gives the
    standard fully integrated element, which locks under (nearly) isochoric deformation; it exists
    to demonstrate that, not for production runs.
    """
    check_symmetry(symmetry, mesh.shape)
    full = mesh
    if symmetry == "eighth":
        mesh = lower_half(mesh)
    B, dV = strain_operators(mesh.nodes[mesh.elements], use_b_bar)
    return Discretisation(mesh, B, dV, build_pattern(mesh.elements, mesh.n_nodes), symmetry, full)


@dataclass(frozen=True, eq=False)
class BoundaryConditions:
    """Constrained dofs of the plate test and the extraction map of the free-free block.

    quarter: x0 u_x = 0, y0 u_y = 0, z0 (bottom plate) u_z = 0, z1 (top plate) u_z = -delta;
             friction plates also fix u_x, u_y on z0 and z1.
    eighth : the same on x0, y0 and z0; z1 is the mid-height plane: u_z = -delta/2, u_x and u_y
             free (no shear traction on a symmetry plane), whatever the plates.
    """

    disc: Discretisation
    plates: str

    @cached_property
    def fixed(self) -> np.ndarray:
        m = self.disc.mesh
        dofs = [3 * m.face("x0"), 3 * m.face("y0") + 1, 3 * m.face("z0") + 2, self.top_z]
        if self.plates == "friction":
            for face in ("z0", "z1") if self.disc.symmetry == "quarter" else ("z0",):
                dofs += [3 * m.face(face), 3 * m.face(face) + 1]
        return np.unique(np.concatenate(dofs))

    @cached_property
    def top_z(self) -> np.ndarray:
        """The prescribed moving dofs: u_z of the top plate (quarter) or of the mid-height plane
        (eighth)."""
        return 3 * self.disc.mesh.face("z1") + 2

    @property
    def top_fraction(self) -> float:
        """Displacement of the ``top_z`` dofs per unit top-plate displacement."""
        return 0.5 if self.disc.symmetry == "eighth" else 1.0

    def plate_force_kN(self, f_int: np.ndarray) -> float:
        """Vertical force of the whole specimen on the top plate, kN, compression positive.

        quarter: -4 x the z internal forces on the top plate; eighth: 4 x those on the bottom plate,
        the mirror image of the top plate (equal to the mid-plane force to the Newton tolerance).
        """
        if self.disc.symmetry == "eighth":
            return 4.0 * f_int[3 * self.disc.mesh.face("z0") + 2].sum() / 1000.0
        return -4.0 * f_int[self.top_z].sum() / 1000.0

    @cached_property
    def free(self) -> np.ndarray:
        mask = np.ones(self.disc.pattern.n_dofs, bool)
        mask[self.fixed] = False
        return np.nonzero(mask)[0]

    @cached_property
    def _free_block(self):
        """Map from global CSR entries to the CSC structure of P K_ff P^T (P: nested dissection)."""
        p = self.disc.pattern
        nd = (3 * nested_dissection_order(self.disc.mesh)[:, None] + np.arange(3)).ravel()
        is_free = np.zeros(p.n_dofs, bool)
        is_free[self.free] = True
        perm = nd[is_free[nd]]  # free dofs in elimination order
        new = np.full(p.n_dofs, -1)
        new[perm] = np.arange(len(perm))
        rows = np.repeat(np.arange(p.n_dofs), np.diff(p.indptr))
        keep = np.nonzero((new[rows] >= 0) & (new[p.indices] >= 0))[0]
        r, c = new[rows[keep]], new[p.indices[keep]]
        order = np.lexsort((r, c))  # CSC: by column, then row
        indptr = np.concatenate([[0], np.cumsum(np.bincount(c, minlength=len(perm)))])
        return keep[order], r[order], indptr, perm

    @property
    def elimination_order(self) -> np.ndarray:
        """Free dofs in the order the sparse factorisation eliminates them."""
        return self._free_block[3]

    def free_block(self, K: sp.csr_matrix) -> sp.csc_matrix:
        """The free-free block of K, permuted to the elimination order (CSC)."""
        take, indices, indptr, perm = self._free_block
        n = len(perm)
        return sp.csc_matrix((K.data[take], indices, indptr), shape=(n, n))


@dataclass
class Response:
    """Result of one forward run (only the completed snapshots when ``converged`` is False).

    mesh          : the quarter mesh of the whole height (also when the eighth model solved it)
    snapshots_mm  : (N,) top-plate displacement at each snapshot, mm (compression positive)
    reaction_kN   : (N,) vertical plate force on the whole specimen (4 x quarter), kN, compression
                    positive
    displacements : (N, n_nodes, 3) nodal displacement field, mm
    stress        : (N, n_elements, 6) element-mean stress, MPa
    state         : (N, n_elements, n_state) element-mean history variables (e.g. eqps)
    symmetry      : the model that was solved (``eighth``: fields above z = 75 mm are mirror images)
    sensitivities : derivatives of displacements and plate forces with respect to material
                    parameters (:class:`problems.fe.ddm.Sensitivities`) when the run was
                    asked for them, else None
    """

    mesh: Mesh
    snapshots_mm: np.ndarray
    reaction_kN: np.ndarray
    displacements: np.ndarray
    stress: np.ndarray
    state: np.ndarray
    state_names: tuple[str, ...]
    converged: bool
    message: str
    increments: int
    iterations: int
    cuts: int
    wall_s: float
    timing: dict = field(default_factory=dict)
    residual_history: list = field(default_factory=list)  # per increment: relative residual norms
    symmetry: str = "quarter"
    sensitivities: Sensitivities | None = None  # when run(sensitivities=...) asked for them

    def front_face(self, points_mm) -> tuple[np.ndarray, np.ndarray]:
        """In-plane displacements of the front face x = 75 mm at points (m, 2) = (y, z) mm.

        Returns ``u_h`` (horizontal, u_y) and ``u_v`` (vertical, u_z), each (N, m) mm.
        """
        from problems.fe.front_face import front_face_operator

        W = front_face_operator(self.mesh, points_mm)
        return self.displacements[:, :, 1] @ W.T, self.displacements[:, :, 2] @ W.T


def run(
    disc: Discretisation,
    material: Material,
    loading: Loading = Loading(),
    settings: NewtonSettings = NewtonSettings(),
    *,
    progress: bool = False,
    sensitivities=False,
    predictor: Predictor | None = None,
) -> Response:
    """Run the plate-compression test on ``disc`` with ``material``; never raises on
    non-convergence.

    ``progress`` shows a progress bar over the snapshots (for long runs on fine meshes).
    ``sensitivities`` (True: all of ``material.parameter_names``; or a sequence of some of those
    names) also computes the exact derivatives of the displacements and plate forces with respect
    to those parameters by direct differentiation (problems/fe/ddm.py) into
    ``Response.sensitivities``; the response itself is the same as without them.
    ``predictor``: another predictor of each increment (:class:`Predictor`, for experiments;
    default the tangent predictor).
    """
    t0 = time.perf_counter()
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=loading.snapshots, desc="snapshots", unit="snap")
    bc = BoundaryConditions(disc, loading.plates)
    solver = _Newton(disc, material, bc, settings, predictor)
    ne, nn = disc.mesh.n_elements, disc.mesh.n_nodes
    ng = disc.dV.shape[1]  # Gauss points per element
    u = np.zeros(disc.pattern.n_dofs)
    stress = np.zeros((disc.n_points, 6))
    state = material.initial_state(disc.n_points)
    D = None
    ddm = None
    if sensitivities is not False and sensitivities is not None:
        columns = select_parameters(material, sensitivities)
        ddm = GlobalDDM(solver, material, columns, settings.sensitivity)
    out_u, out_s, out_h, out_f, out_d = [], [], [], [], []
    nominal = 1.0 / (loading.snapshots * settings.substeps)
    step, lam, increments, cuts, message = nominal, 0.0, 0, 0, "converged"
    converged = True
    fractions = loading.fractions
    for k in range(1, loading.snapshots + 1):
        target = fractions[k - 1]
        while lam < target - 1e-12:
            dlam = min(step, target - lam)
            inc = solver.increment(
                u, stress, state, D, -dlam * loading.displacement_mm * bc.top_fraction
            )
            if inc.ok:
                if ddm is not None:
                    ddm.advance(inc, stress, state)
                u, stress, state, D, f_int = inc.u, inc.stress, inc.state, inc.tangent, inc.f_int
                lam += dlam
                increments += 1
                step = min(2.0 * step, nominal)  # grow back after a cut
                continue
            cuts += 1
            if cuts > settings.max_cuts:
                converged = False
                message = (
                    f"failed at snapshot {k}/{loading.snapshots} (top displacement "
                    f"{lam * loading.displacement_mm:.4g} -> "
                    f"{(lam + dlam) * loading.displacement_mm:.4g} mm): {inc.reason}; gave up "
                    f"after {settings.max_cuts} cuts"
                )
                break
            step = dlam / 2.0
        if not converged:
            break
        out_u.append(u.reshape(nn, 3).copy())
        out_s.append(element_mean(stress.reshape(ne, ng, 6)))
        out_h.append(element_mean(state.reshape(ne, ng, -1)))
        out_f.append(bc.plate_force_kN(f_int))
        out_d.append(lam * loading.displacement_mm)
        if ddm is not None:
            ddm.snapshot()
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    n_state = len(material.state_names)
    fields = (
        np.array(out_u).reshape(len(out_u), nn, 3),
        np.array(out_s).reshape(len(out_s), ne, 6),
        np.array(out_h).reshape(len(out_h), ne, n_state),
    )
    if disc.symmetry == "eighth":
        fields = unfold_mid_height(disc.full_mesh, np.array(out_d), *fields, material.state_names)
    return Response(
        mesh=disc.full_mesh,
        snapshots_mm=np.array(out_d),
        reaction_kN=np.array(out_f),
        displacements=fields[0],
        stress=fields[1],
        state=fields[2],
        state_names=tuple(material.state_names),
        converged=converged,
        message=message,
        increments=increments,
        iterations=solver.iterations,
        cuts=cuts,
        wall_s=time.perf_counter() - t0,
        timing=dict(solver.timing),
        residual_history=solver.residual_history,
        symmetry=disc.symmetry,
        sensitivities=None if ddm is None else ddm.result(disc.full_mesh),
    )


@dataclass
class _Increment:
    """Result of one increment. ``factor`` is the last factorisation (or preconditioner) the
    increment used and ``factor_at_converged`` whether its matrix is the tangent at the converged
    state (then it solves with that tangent directly); :meth:`_Newton.converged_factor` gives one
    that always does, for sensitivity solves after the increment."""

    ok: bool
    reason: str = ""
    u: np.ndarray | None = None
    stress: np.ndarray | None = None
    state: np.ndarray | None = None
    tangent: np.ndarray | None = None
    f_int: np.ndarray | None = None
    factor: Factor | None = None
    factor_at_converged: bool = False
    strain_increment: np.ndarray | None = None  # (n_points, 6) of the converged update


#: Newton forcing terms of the Krylov solves (relative linear residual asked of GMRES). Predictor:
#: ETA_PREDICTOR. Correction at relative residual r: ``FORCING * r`` -- the linear residual then
#: adds FORCING * r^2 to the next r, so convergence stays quadratic -- but never tighter than needed
#: to land below the final acceptance level a = rtol_force * linear_rtol (``FORCING * a / r``),
#: clipped to [ETA_MIN, ETA_MAX]. Measured on coarse, nine cases, 5 and 10 snapshots: with
#: ETA_MAX = 1e-3 an early correction near the onset of plasticity can land on a different set of
#: yielding points and cost an extra iteration (r: 1.9e-4 -> 6.5e-7 instead of 4.3e-8); 1e-4 gives
#: the exact solves' residual histories (largest r_next / r^2 = 13 in both); ETA_PREDICTOR = 1e-4 or
#: FORCING = 1 cost extra iterations, tighter values only Krylov iterations.
ETA_PREDICTOR, FORCING, ETA_MIN, ETA_MAX = 1e-5, 0.3, 1e-12, 1e-4

#: refactorise the preconditioner once its ageing has cost this many extra Krylov iterations: one
#: CHOLMOD numeric factorisation costs about 10-20 iterations (triangular solve pair + product) on
#: coarse to fine (bench/perf/linear_solvers.py: factor / (solve at 1e-12 / its))
REFACTOR_ITERATIONS = 15


#: eigenvalue floor of :func:`positive_part`, relative to each point's largest eigenvalue
SPD_FLOOR = 1e-2


def positive_part(D: np.ndarray) -> np.ndarray:
    """The symmetric positive definite part of material tangents D (..., 6, 6) MPa: the symmetric
    part ``(D + D^T) / 2`` with every eigenvalue raised to at least SPD_FLOOR x the point's largest.

    A non-associated flow makes D non-symmetric; where the symmetric parts of many points have
    negative eigenvalues (the exponent cases: ``dF/dsigma`` is much steeper in the meridian than
    ``dG/dsigma``), the symmetric part of the global tangent can lose definiteness although the
    tangent itself is regular and Newton converges quadratically. The tangent assembled from these
    parts is positive definite, so CHOLMOD factorises it and it preconditions GMRES on the exact
    tangent (35-40 Krylov iterations to 1e-10 on ``5,5,10:g4:hex27``, where the symmetric part
    with a diagonal shift of 1e-2 x its diagonal takes 60-70)."""
    Ds = 0.5 * (D + np.swapaxes(D, -1, -2))
    w, V = np.linalg.eigh(Ds)
    w = np.maximum(w, SPD_FLOOR * w[..., -1:])
    return np.einsum("...ij,...j,...kj->...ik", V, w, V)


def forcing_term(rel_r: float, settings: NewtonSettings) -> float:
    """Relative tolerance of the linear solve of a Newton correction at relative residual
    ``rel_r``."""
    final = settings.rtol_force * settings.linear_rtol
    return min(ETA_MAX, max(ETA_MIN, FORCING * rel_r, FORCING * final / max(rel_r, 1e-300)))


class Predictor(Protocol):
    """Another predictor of the Newton increments (``run(predictor=...)``; an experiment's hook,
    e.g. bench/perf/newton_variants.py). The Newton iterations, their tests and counters stay the
    production ones.

    ``predict(du, dtop_mm, tangent)``: the displacement increment (all dofs, mm) the iterations
    start from; ``du`` has the prescribed part of an increment of ``dtop_mm`` (mm) set and zeros
    elsewhere, ``tangent()`` gives the production tangent predictor as ``(du, why)`` (one linear
    solve, counted). Returns ``(du, why)``, ``why`` non-empty when the prediction failed (the
    increment is then cut). ``converged(du)``: the converged increment (mm), after each converged
    increment."""

    def predict(self, du, dtop_mm, tangent) -> tuple[np.ndarray, str]: ...

    def converged(self, du) -> None: ...


def _perm_position(bc: BoundaryConditions) -> np.ndarray:
    pos = np.full(bc.disc.pattern.n_dofs, -1)
    pos[bc.free] = np.arange(len(bc.free))
    return pos[bc.elimination_order]


def _free_block_slot(bc: BoundaryConditions):
    """Slot map of element entries into the free-free block in elimination order (-1: constrained
    row or column) and that block's CSC structure, as :meth:`BoundaryConditions.free_block` has
    it."""
    take, indices, indptr, _ = bc._free_block
    position = np.full(len(bc.disc.pattern.indices), -1, dtype=np.int64)
    position[take] = np.arange(len(take))
    return position[bc.disc.pattern.slot], indices, indptr


class _Newton:
    """Newton iterations of one load increment; keeps counters and timings across increments.

    ``timing``: assembly_s (tangent into the free-free block, predictor right-hand side, internal
    force, strain), material_s, factor_s (factorisations of the linear solver), solve_s (Krylov
    iterations or triangular solves), all wall seconds; factorisations (of them
    exact_factorisations, LUs, and spd_substitutes, CHOLMOD factors of :func:`positive_part`
    tangents), krylov_iterations and handed_predictors (predictors solved with a factor from the
    sensitivity solves, :meth:`adopt_factor`) are counts.
    """

    def __init__(
        self,
        disc: Discretisation,
        material: Material,
        bc: BoundaryConditions,
        settings: NewtonSettings,
        predictor: Predictor | None = None,
    ):
        self.disc, self.material, self.bc, self.settings = disc, material, bc, settings
        self.predictor = predictor
        self.iterations = 0
        self.timing = {
            "assembly_s": 0.0,
            "material_s": 0.0,
            "factor_s": 0.0,
            "solve_s": 0.0,
            "factorisations": 0,
            # of them: exact LUs (``superlu``, or the fallback of ``cholmod-gmres``) and CHOLMOD
            # factors of the positive definite substitute of a tangent (:func:`positive_part`)
            "exact_factorisations": 0,
            "spd_substitutes": 0,
            "krylov_iterations": 0,
            # predictors solved with a factor the sensitivity solves handed over (adopt_factor)
            "handed_predictors": 0,
        }
        self.residual_history: list[list[float]] = []
        # elimination order -> index in bc.free (cached: the ordering is computed once per mesh and
        # plates)
        self._perm_position = shared(disc, ("perm position", bc.plates), lambda: _perm_position(bc))
        self.linear: LinearSolver = shared(
            disc,
            ("linear", bc.plates, settings.linear_solver),
            lambda: make_linear_solver(settings.linear_solver),
        )
        self._fused = (
            shared(disc, "fused", lambda: FusedAssembler(disc.B, disc.dV, disc.pattern))
            if settings.assembly == "fused"
            else None
        )
        self._free_slot = (
            shared(disc, ("free slot", bc.plates), lambda: _free_block_slot(bc))
            if self._fused is not None
            else None
        )
        self._factor: Factor | None = None  # the current factorisation / preconditioner
        self._factor_D = None  # the material tangent it was formed from
        # the last free block assembled and the tangent array it is of (the same object): the
        # sensitivity solve assembles the converged tangent, which the next predictor reuses
        self._kff_of: tuple | None = None
        # (LU-preconditioned factor, the tangent it is of) for the next predictor: adopt_factor
        self._predictor_factor: tuple | None = None
        self._fresh_rate = None  # Krylov iterations per decade right after it
        self._excess = 0.0  # Krylov iterations its ageing has added since

    def _virgin_tangent(self):
        n = self.disc.n_points
        return self.material.update(
            np.zeros((n, 6)), np.zeros((n, 6)), self.material.initial_state(n)
        ).tangent

    def _tangent(self, D):
        """Global tangent K (CSR, N/mm) for the material tangents D (n_points, 6, 6) MPa
        (None: virgin)."""
        t = time.perf_counter()
        if D is None:  # virgin state: the material's response to a zero increment
            D = self._virgin_tangent()
        if self._fused is not None:
            K = self._fused.matrix(D)
        else:
            ne, ng = self.disc.dV.shape
            K = self.disc.pattern.matrix(
                element_matrices(
                    self.disc.B,
                    np.broadcast_to(D, (self.disc.n_points, 6, 6)).reshape(ne, ng, 6, 6),
                    self.disc.dV,
                )
            )
        self.timing["assembly_s"] += time.perf_counter() - t
        return K

    def _tangent_free(self, D):
        """The free-free block of the tangent K(D), permuted to the elimination order (CSC, N/mm).

        Fused assembly writes it directly (no full matrix); numpy assembly extracts it from K.
        The block of the last array assembled is kept and returned again for the same array (the
        predictor of the increment after a sensitivity solve reuses the converged tangent's).
        """
        if D is not None and self._kff_of is not None and self._kff_of[0] is D:
            return self._kff_of[1]  # same array object, never written after the update
        Kff = self._assemble_free(D)
        if D is not None:
            self._kff_of = (D, Kff)
        return Kff

    def _assemble_free(self, D):
        """The free-free block of K(D) in elimination order (CSC, N/mm), assembled (no reuse)."""
        if self._fused is None:
            K = self._tangent(D)
            t = time.perf_counter()
            Kff = self.bc.free_block(K)
            self.timing["assembly_s"] += time.perf_counter() - t
        else:
            t = time.perf_counter()
            slot, indices, indptr = self._free_slot
            n = len(indptr) - 1
            Kff = sp.csc_matrix(
                (
                    self._fused.tangent(
                        self._virgin_tangent() if D is None else D, slot, len(indices)
                    ),
                    indices,
                    indptr,
                ),
                shape=(n, n),
            )
            self.timing["assembly_s"] += time.perf_counter() - t
        return Kff

    def _predictor(self, D, du):
        """K_ff(D) and -(K(D) du) on the free dofs, N, for an increment du that is non-zero on
        prescribed dofs only (fused: element by element, without the constrained columns of K)."""
        if self._fused is None:
            K = self._tangent(D)
            t = time.perf_counter()
            Kff, rhs = self.bc.free_block(K), -(K @ du)[self.bc.free]
            self.timing["assembly_s"] += time.perf_counter() - t
            return Kff, rhs
        Kff = self._tangent_free(D)
        t = time.perf_counter()
        eps = self._fused.strain(du)
        sig = np.einsum("pij,pj->pi", D, eps) if np.ndim(D) == 3 else eps @ np.asarray(D).T
        rhs = -self._fused.internal_force(sig)[self.bc.free]
        self.timing["assembly_s"] += time.perf_counter() - t
        return Kff, rhs

    def _strain(self, du):
        if self._fused is not None:
            return self._fused.strain(du)
        return np.einsum("egia,ea->egi", self.disc.B, du[self.disc.pattern.edofs]).reshape(-1, 6)

    def _internal_force(self, stress):
        if self._fused is not None:
            return self._fused.internal_force(stress)
        return self.disc.pattern.vector(
            element_forces(self.disc.B, stress.reshape(self.disc.dV.shape + (6,)), self.disc.dV)
        )

    def _factorise(self, Kff, D) -> Factor:
        """Factorise ``Kff``, the free block of K(D); where its symmetric part is not positive
        definite a preconditioning solver factorises K(positive_part(D)) instead
        (:func:`positive_part`), whose CHOLMOD factor preconditions GMRES on ``Kff``."""
        t = time.perf_counter()
        factor = self.linear.factorise(
            Kff,
            spd=lambda: self._assemble_free(
                positive_part(self._virgin_tangent() if D is None else D)
            ),
        )
        self.timing["factor_s"] += time.perf_counter() - t
        self.timing["factorisations"] += 1
        self.timing["exact_factorisations"] += factor.exact
        self.timing["spd_substitutes"] += getattr(factor, "substitute", False)
        self._factor, self._factor_D = factor, D
        self._fresh_rate, self._excess = None, 0.0
        return factor

    def _solve(self, Kff, rhs_free, D, rtol):
        """Solve K_ff du = rhs for the free dofs (rhs and du in ``bc.free`` order), K_ff the free
        block of K(D) in elimination order (:meth:`_tangent_free`).

        Reuses the current factorisation as a preconditioner while the Krylov iterations its
        ageing has added (beyond the iterations per decade of tolerance of its first solve) stay
        below REFACTOR_ITERATIONS, about what a numeric factorisation costs in iterations; else
        (and always for direct solvers) factorises K_ff. Counting iterations, not seconds, keeps
        runs reproducible. ``rtol`` is the relative residual asked of a Krylov solve. Returns the
        correction and "" or NaNs and the reason (singular tangent).
        """
        du = np.empty_like(rhs_free)
        try:
            factor = None
            if self._factor is not None and self._excess <= REFACTOR_ITERATIONS:
                factor = self._factor.for_matrix(Kff)
            if factor is None:
                factor = self._factorise(Kff, D)
            else:
                self._factor, self._factor_D = factor, D
            its = self._apply(factor, rhs_free, rtol, du)
            if its:  # bookkeeping of the preconditioner's ageing (iterations per decade of rtol)
                decades = max(-math.log10(max(rtol, 1e-16)), 1.0)
                if self._fresh_rate is None:
                    self._fresh_rate = its / decades
                else:
                    self._excess += max(its - self._fresh_rate * decades, 0.0)
            why = ""
        except SingularMatrixError as exc:  # exactly singular tangent
            du[:], why = np.nan, f"singular tangent ({exc})"
            self._factor = None
        return du, why

    def _apply(self, factor: Factor, rhs_free, rtol, du) -> int:
        """``du`` (``bc.free`` order) <- the solve of ``factor`` (elimination order) for
        ``rhs_free``, timed; returns (and counts) its Krylov iterations."""
        t = time.perf_counter()
        du[self._perm_position] = factor.solve(rhs_free[self._perm_position], rtol)
        self.timing["solve_s"] += time.perf_counter() - t
        self.timing["krylov_iterations"] += factor.krylov_iterations
        return factor.krylov_iterations

    def adopt_factor(self, factor: Factor, Kff, D) -> None:
        """Solve the next increment's predictor, whose matrix is ``Kff`` (the free block of the
        converged tangent ``D``), with the LU ``factor`` the sensitivity solves made of it:
        GMRES preconditioned by it (:class:`problems.fe.linear_solver.LUGmresFactor`) stops after
        one iteration at ETA_PREDICTOR, where the CHOLMOD preconditioner of a plain run takes 7-9
        and at times a factorisation. The corrections keep the CHOLMOD factor and its ageing
        bookkeeping (a preconditioner application of the LU costs 1.6x CHOLMOD's on ``paper``)."""
        self._predictor_factor = (LUGmresFactor(factor, Kff), D)

    def _solve_handed(self, factor: Factor, rhs_free, rtol):
        """:meth:`_solve` with a factor handed over by :meth:`adopt_factor`, which leaves the
        current factorisation and its ageing bookkeeping as they are."""
        du = np.empty_like(rhs_free)
        try:
            self._apply(factor, rhs_free, rtol, du)
            self.timing["handed_predictors"] += 1
            why = ""
        except SingularMatrixError as exc:
            du[:], why = np.nan, f"singular tangent ({exc})"
        return du, why

    def converged_factor(self, inc: _Increment, exact: bool = False) -> Factor:
        """A factor that solves with the free block of the tangent at the converged state of ``inc``
        (elimination order), for sensitivity solves: ``inc.factor`` if it was formed there, else
        that factor as the preconditioner of the converged tangent or, for direct solvers, a new
        factorisation. ``exact=True`` insists on a direct factorisation (SuperLU unless the kept one
        is exact): cheaper than GMRES for 6-7 right-hand sides at tight tolerances
        (bench/perf/linear_solvers.py, column "7 rhs")."""
        if inc.factor is not None and inc.factor_at_converged and (inc.factor.exact or not exact):
            return inc.factor
        Kff = self._tangent_free(inc.tangent)
        if exact:
            t = time.perf_counter()
            f = superlu_factor(Kff)
            self.timing["factor_s"] += time.perf_counter() - t
            self.timing["factorisations"] += 1
            self.timing["exact_factorisations"] += 1
            return f
        if inc.factor is not None:
            f = inc.factor.for_matrix(Kff)
            if f is not None:
                return f
        return self._factorise(Kff, inc.tangent)

    def _converged(self, **kw) -> _Increment:
        D = kw["tangent"]
        at = (
            self._factor is not None
            and self._factor_D is not None
            and (
                self._factor_D is D
                or (np.shape(self._factor_D) == np.shape(D) and np.array_equal(self._factor_D, D))
            )
        )
        return _Increment(True, factor=self._factor, factor_at_converged=bool(at), **kw)

    def _tangent_predictor(self, du, D_n):
        """The tangent predictor's correction of the free dofs for the prescribed part of ``du``:
        linearised about the converged state (tangents ``D_n``), so the prescribed jump is spread
        over the body instead of being concentrated in the boundary layer of elements. Returns
        (correction, why it failed or "")."""
        Kff, rhs = self._predictor(D_n, du)
        if self.settings.on_linear_solve is not None:
            self.settings.on_linear_solve("predictor", Kff, rhs)
        handed, self._predictor_factor = self._predictor_factor, None
        if handed is not None and handed[1] is D_n and handed[0].A is Kff:
            corr, why = self._solve_handed(handed[0], rhs, ETA_PREDICTOR)
        else:
            corr, why = self._solve(Kff, rhs, D_n, ETA_PREDICTOR)
        self.iterations += 1
        return corr, why

    def increment(self, u_n, stress_n, state_n, D_n, dtop_mm) -> _Increment:
        s, bc = self.settings, self.bc
        du = np.zeros_like(u_n)
        du[bc.top_z] = dtop_mm
        if D_n is None:
            D_n = self._virgin_tangent()
        if self.predictor is None:
            corr, why = self._tangent_predictor(du, D_n)
            if why:
                return _Increment(False, why)
            du[bc.free] += corr
        else:

            def tangent():
                d = du.copy()
                c, why = self._tangent_predictor(d, D_n)
                if not why:
                    d[bc.free] += c
                return d, why

            du, why = self.predictor.predict(du, dtop_mm, tangent)
            if why:
                return _Increment(False, why)
            corr = du[bc.free].copy()
        norms = []
        for it in range(s.max_iterations):
            t = time.perf_counter()
            deps = self._strain(du)
            self.timing["assembly_s"] += time.perf_counter() - t
            t = time.perf_counter()
            upd = self.material.update(deps, stress_n, state_n)
            self.timing["material_s"] += time.perf_counter() - t
            if not np.all(upd.ok):
                why = f"material return mapping failed at {np.count_nonzero(~upd.ok)} points"
                diagnose = getattr(self.material, "failure_reason", None)
                detail = diagnose(deps, stress_n, state_n, upd.ok) if diagnose else ""
                return _Increment(False, f"{why} ({detail})" if detail else why)
            t = time.perf_counter()
            f_int = self._internal_force(upd.stress)
            self.timing["assembly_s"] += time.perf_counter() - t
            r_free = f_int[bc.free]
            scale = max(np.linalg.norm(f_int[bc.fixed]), 1e-30)
            rel_r = np.linalg.norm(r_free) / scale
            rel_u = np.linalg.norm(corr) / max(np.linalg.norm(du), 1e-30)
            norms.append(rel_r)
            if not np.isfinite(rel_r):
                return _Increment(False, "residual is not finite")
            if rel_r <= s.rtol_force * (1.0 if rel_u <= s.rtol_displacement else s.linear_rtol):
                self.residual_history.append(norms)
                if self.predictor is not None:
                    self.predictor.converged(du)
                return self._converged(
                    u=u_n + du,
                    stress=upd.stress,
                    state=upd.state,
                    tangent=upd.tangent,
                    f_int=f_int,
                    strain_increment=deps,
                )
            if it >= 3 and rel_r > 1e3 * norms[0]:
                return _Increment(False, f"Newton diverged (relative residual {rel_r:.3g})")
            Kff = self._tangent_free(upd.tangent)
            if s.on_linear_solve is not None:
                s.on_linear_solve("correction", Kff, -r_free)
            corr, why = self._solve(Kff, -r_free, upd.tangent, forcing_term(rel_r, s))
            self.iterations += 1
            if why or not np.all(np.isfinite(corr)):
                return _Increment(False, why or "non-finite correction")
            du[bc.free] += corr
        return _Increment(
            False,
            f"no convergence in {s.max_iterations} Newton iterations (relative residual "
            f"{norms[-1]:.3g})",
        )

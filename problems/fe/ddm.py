"""Parameter sensitivities of a whole FE run by the direct differentiation method (DDM).

One forward run plus, after each converged increment, one linear solve with the consistent
tangent at the converged state for all parameters at once gives the exact derivatives of the
nodal displacements and of the plate force at every snapshot with respect to the material's
parameters (``material.parameter_names``), instead of n + 1 (forward differences) or 2 n + 1
(central) runs. The equations and measurements are in docs/fe_model.md, section "Parameter
sensitivities (DDM)".

For one converged increment n -> n+1 with strain increment deps = B (u_{n+1} - u_n) and
U_n = du_n/dp, S_n = dsigma_n/dp, H_n = dstate_n/dp known (zero before the first increment):

1. one material pass (:func:`problems.materials.ddm.affine_sensitivity`) with the known part
   ``-B U_n`` of ddeps gives c and h, the stress and history sensitivities for U_{n+1} = 0, and
   T = [T_s; T_q] = d(stress, state)/d(deps) of the update: ``S_{n+1} = c + T_s B U_{n+1}``,
   ``H_{n+1} = h + T_q B U_{n+1}`` (T_s the consistent tangent);
2. equilibrium of the free dofs, ``sum B^T S_{n+1} dV = 0``, is ``K_T U_{n+1} = -sum B^T c dV``
   on the free dofs (the pseudo-load); prescribed dofs, the eighth's mid-plane included, have
   U = 0 because the prescribed displacements do not depend on the parameters;
3. S_{n+1} and H_{n+1} (the history for the next increment) by the affine map of step 1, in one
   pass over the elements (:func:`_affine_kernel`) that also forms B U_{n+1} and the
   internal-force sensitivity of step 4. A material without the one-pass split (or
   ``SensitivitySettings(affine=False)``) is called twice through its ``sensitivity``
   interface: before the solve with ``-B U_n``, after it with ``B (U_{n+1} - U_n)``; same
   Jacobian to round-off;
4. the plate-force sensitivity is the plate force of the internal-force sensitivity
   ``sum B^T S_{n+1} dV`` (same definition and factor as the plate force).

The converged tangent's free block assembled for step 2 is the next increment's predictor
matrix; the Newton solver keeps it (``_Newton._tangent_free``), so the run's own work is one
assembly lighter and, up to ``mixed_min_dofs`` free dofs (:class:`SensitivitySettings`), its
answers bit for bit those of a plain run. Above it the direct solves also hand their LU of that
matrix to the Newton solver (``hand_over``, ``_Newton.adopt_factor``), which solves the next
predictor with it (one Krylov iteration instead of 7-9 with its CHOLMOD preconditioner, and at
times a factorisation): the response is then the plain run's to the Newton tolerance, no longer
bit for bit.

Bisected increments are increments like the others: only converged ones reach step 1. Only the
columns asked for are carried (the one-pass path) or solved (the two-call path, where the
material propagates all of its parameters and the others keep U = 0 and are dropped).

Units: displacement sensitivities in mm per parameter unit, plate-force sensitivities in kN per
parameter unit (parameter units: MPa, degrees or -); pseudo-loads in N per parameter unit.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from problems.fe.cache import shared
from problems.fe.linear_solver import SingularMatrixError, mixed_superlu_factor, superlu_factor
from problems.materials.base import MaterialUpdate
from problems.materials.ddm import affine_sensitivity
from problems.numba_cache import heal as heal_numba_cache

#: relative residual ||K X - F|| / ||F|| of each column of the Krylov solve of the sensitivity
#: equations. Measured (coarse, linear-compression, against solves to 1e-12): the Jacobian's
#: relative error is about a third of it (3e-9 at 1e-8) and does not grow over the increments;
#: 1e-12 costs 1.9x the Krylov iterations of 1e-8 (bench/perf/jacobian.py, docs/fe_model.md).
SENSITIVITY_RTOL = 1e-8

#: how the sensitivity equations can be solved (:attr:`SensitivitySettings.mode`)
SOLVE_MODES = ("auto", "direct", "krylov")
#: ``auto`` solves directly up to this many free dofs (coarse 749, paper 8 160), with Krylov
#: above (fine, ~25 000, where the LU's fill-in grows faster); docs/fe_model.md
DIRECT_MAX_DOFS = 10_000
#: relative residual of each column of the mixed-precision solves: one refinement step of the
#: single-precision solve per increment reaches it (3e-12-7e-12 on paper), and the Jacobians are
#: the double LU's to 3e-11 per column (docs/fe_model.md)
MIXED_RTOL = 1e-10


@dataclass(frozen=True)
class SensitivitySettings:
    """How the sensitivity equations of a run are solved (a field of
    :class:`problems.fe.newton.NewtonSettings`; measurements in docs/fe_model.md and
    bench/perf/jacobian.py).

    mode           : ``direct`` (a SuperLU factorisation of the converged tangent, P
                     back-substitutions), ``krylov`` (GCR for the P columns with a shared, growing
                     search space, preconditioned by the Newton solver's CHOLMOD factorisation; no
                     factorisation) or ``auto``: direct for ``superlu`` Newton runs and up to
                     :data:`DIRECT_MAX_DOFS` free dofs, krylov above
    affine         : one material pass per increment where the material offers it
                     (:func:`problems.materials.ddm.affine_sensitivity`); False: the two
                     ``sensitivity`` calls of the material interface (same Jacobian to round-off)
    mixed_min_dofs : above this many free dofs the direct solves factorise in single precision and
                     refine in double to :data:`MIXED_RTOL` (faster there: paper 1.52 s against
                     1.97 s); up to it the double LU (``coarse``, 749 dofs, stays bit for bit)
    hand_over      : above ``mixed_min_dofs``, hand each direct solve's LU of the converged tangent
                     to the Newton solver, which solves the next increment's predictor (same
                     matrix) with it: one Krylov iteration instead of 7-9; the response is then the
                     plain run's to the Newton tolerance, no longer bit for bit
    """

    mode: str = "auto"
    affine: bool = True
    mixed_min_dofs: int = 3_000
    hand_over: bool = True

    def __post_init__(self):
        if self.mode not in SOLVE_MODES:
            raise ValueError(
                f"sensitivity solve mode {self.mode!r} is unknown; allowed: "
                f"{', '.join(SOLVE_MODES)}"
            )


#: memory of the Krylov search space (U and A U), bytes; GCR restarts when it is full
KRYLOV_MEMORY = 64 * 2**20
KRYLOV_MAX_VECTORS = 240

_JIT = dict(cache=True, nogil=True, error_model="numpy")


@dataclass
class Sensitivities:
    """Derivatives of a :class:`~problems.fe.newton.Response` with respect to material parameters.

    parameter_names : the P columns (a subset of ``material.parameter_names``, in the order asked)
    displacements   : (N, n_nodes, 3, P) d(nodal displacement)/dp on the response's mesh (the
                      quarter of the whole height), mm per parameter unit
    reaction_kN     : (N, P) d(plate force)/dp, kN per parameter unit (compression positive, as
                      ``Response.reaction_kN``)
    ok              : False when a sensitivity solve failed (then the arrays hold NaN)
    message         : why it failed, else ""
    residual        : largest relative equilibrium residual of the sensitivity equations over all
                      increments, ||dF_int on free dofs|| / ||dF_int on prescribed dofs|| (a check)
    wall_s          : wall time spent on the sensitivities inside the run, s
    timing          : where that time went: material_s (the material pass and the fused
                      strain/affine/internal-force pass; or the two ``sensitivity`` calls),
                      assembly_s (pseudo-loads, converged tangents; in the two-call path also
                      strains and internal-force sensitivities), factor_s, solve_s (s);
                      factorisations, krylov_iterations (preconditioner applications), mode (the
                      solve mode used); mixed_factorisations (of them in single precision),
                      refinements (their refinement steps), fallbacks (of them redone in double)
    """

    parameter_names: tuple[str, ...]
    displacements: np.ndarray
    reaction_kN: np.ndarray
    ok: bool = True
    message: str = ""
    residual: float = 0.0
    wall_s: float = 0.0
    timing: dict = field(default_factory=dict)

    def front_face(self, points_mm, mesh, operator=None) -> tuple[np.ndarray, np.ndarray]:
        """d u_h/dp and d u_v/dp at front-face points (m, 2) = (y, z) mm, each (N, m, P) mm per
        parameter unit (the interpolation of :meth:`Response.front_face`; ``mesh`` its mesh;
        ``operator``: its interpolation operator when the caller has it already)."""
        from problems.fe.front_face import front_face_operator

        W = front_face_operator(mesh, points_mm) if operator is None else operator
        N, nn, _, P = self.displacements.shape

        def apply(component):
            d = self.displacements[:, :, component, :].transpose(1, 0, 2).reshape(nn, N * P)
            return np.asarray(W @ d).reshape(-1, N, P).transpose(1, 0, 2)

        return apply(1), apply(2)


def select_parameters(material, parameters) -> list[int]:
    """Column indices into ``material.parameter_names`` of ``parameters`` (True: all of them)."""
    names = tuple(getattr(material, "parameter_names", ()))
    if not names or not hasattr(material, "sensitivity"):
        raise ValueError(f"material {type(material).__name__} offers no parameter sensitivities")
    if parameters is True:
        return list(range(len(names)))
    wanted = [parameters] if isinstance(parameters, str) else list(parameters)
    unknown = [p for p in wanted if p not in names]
    if unknown or len(set(wanted)) != len(wanted) or not wanted:
        raise ValueError(f"sensitivities {wanted!r}: give distinct names among {', '.join(names)}")
    return [names.index(p) for p in wanted]


class GlobalDDM:
    """Carries the parameter sensitivities through the increments of one Newton run.

    ``newton`` is the run's ``_Newton`` solver: its assembly, boundary conditions and linear
    solver are reused, its state (the factorisation its iterations reuse, its counters) is never
    changed, so the run's answers are bit for bit those of a run without sensitivities -- except
    above ``mixed_min_dofs`` free dofs with ``hand_over``, where each direct solve's factorisation
    is handed to the Newton solver for the next predictor (same answers to the Newton tolerance).
    ``columns`` are the indices of the parameters to solve for; ``settings`` a
    :class:`SensitivitySettings`.
    """

    def __init__(self, newton, material, columns, settings: SensitivitySettings):
        from problems.fe.assembly import FusedAssembler

        self.settings = settings
        mode = settings.mode
        self.newton, self.material = newton, material
        self.bc, self.disc = newton.bc, newton.disc
        disc = self.disc
        self._fused = shared(disc, "fused", lambda: FusedAssembler(disc.B, disc.dV, disc.pattern))
        self.names = tuple(material.parameter_names)
        self.columns = np.asarray(columns, dtype=np.int64)
        # one material pass per increment (problems.materials.ddm.affine_sensitivity) where the
        # material offers it, with only the columns asked for; else two ``sensitivity`` calls
        # per increment with all P columns (the material's interface)
        self.affine = settings.affine and _has_affine_pass(material)
        P = len(self.columns) if self.affine else len(self.names)
        # the solved columns' positions in the carried arrays below
        self.cols = np.arange(P) if self.affine else self.columns
        n_pts, ns = disc.n_points, len(material.state_names)
        self.U = np.zeros((disc.pattern.n_dofs, P))  # dU/dp, mm per unit
        self.eps = np.zeros((n_pts, P, 6))  # B dU/dp
        self.dstress = np.zeros((n_pts, P, 6))
        self.dstate = np.zeros((n_pts, P, ns))
        self.dforce = np.zeros(len(self.columns))
        if mode == "auto":
            small = len(self.bc.free) <= DIRECT_MAX_DOFS
            mode = "direct" if (newton.linear.name == "superlu" or small) else "krylov"
        self.mode = mode
        self._gcr = None
        self.ok, self.message, self.residual = True, "", 0.0
        self.wall_s = 0.0
        self.timing = {
            "material_s": 0.0,
            "assembly_s": 0.0,
            "factor_s": 0.0,
            "solve_s": 0.0,
            "factorisations": 0,
            # of them in single precision with refinement (mixed_min_dofs), its refinement
            # steps, and those that fell back to a double LU
            "mixed_factorisations": 0,
            "refinements": 0,
            "fallbacks": 0,
            "krylov_iterations": 0,
            # converged tangents assembled here that the next increment's predictor then reused:
            # work the plain run does itself (part of assembly_s), s
            "reused_tangent_s": 0.0,
        }
        self._last_tangent_s = 0.0
        self._snap_u: list[np.ndarray] = []
        self._snap_f: list[np.ndarray] = []

    # ---------------------------------------------------------------------------------- one step
    def advance(self, inc, stress_n, state_n) -> None:
        """Sensitivities at the converged state of increment ``inc`` (an ``_Increment`` with
        ``strain_increment``), from the converged (stress_n, state_n) it started from."""
        if not self.ok:
            return
        t0 = time.perf_counter()
        saved = dict(self.newton.timing)  # the Newton solver's counters stay those of the run
        try:
            self._advance(inc, stress_n, state_n)
        except SingularMatrixError as exc:
            self._fail(f"sensitivity solve failed: singular tangent ({exc})")
        finally:
            for k, v in self.newton.timing.items():
                if k in self.timing:
                    self.timing[k] += v - saved[k]
            self.newton.timing.clear()
            self.newton.timing.update(saved)
            self.wall_s += time.perf_counter() - t0

    def _advance(self, inc, stress_n, state_n) -> None:
        mat, bc, cols = self.material, self.bc, self.cols
        deps = inc.strain_increment
        upd = MaterialUpdate(inc.stress, inc.tangent, inc.state, np.ones(len(deps), bool))
        t = time.perf_counter()
        T = None
        if self.affine:  # c, h and T = d(stress, state)/d(deps) in one pass
            c, h, T = affine_sensitivity(
                mat, deps, stress_n, state_n, upd, self.dstress, self.dstate, -self.eps, cols
            )
        else:
            c, _ = mat.sensitivity(
                deps, stress_n, state_n, upd, self.dstress, self.dstate, -self.eps
            )
        self.timing["material_s"] += time.perf_counter() - t
        t = time.perf_counter()
        rhs = -self._forces(c)[bc.free]  # (n_free, k) N per unit
        self.timing["assembly_s"] += time.perf_counter() - t
        X = self._solve(inc, rhs)
        t = time.perf_counter()
        U = np.zeros_like(self.U)
        if T is not None:
            # one pass over the elements: strains B U_{n+1}, dstress = c + T_s B U_{n+1},
            # dstate = h + T_q B U_{n+1} and their internal forces
            U[bc.free] = X
            eps, dstress, dstate = np.empty_like(c), np.empty_like(c), np.empty_like(h)
            f = np.empty((self.disc.pattern.n_dofs, len(cols)))
            _affine_kernel(
                self._fused.B,
                self._fused.dV,
                self._fused.edofs,
                U,
                c,
                h,
                T,
                eps,
                dstress,
                dstate,
                f,
            )
            self.timing["material_s"] += time.perf_counter() - t
            if not (np.all(np.isfinite(f)) and np.all(np.isfinite(X))):
                self._fail("sensitivity is not finite")
                return
        else:
            U[np.ix_(bc.free, cols)] = X
            eps = np.zeros_like(self.eps)
            _strains_kernel(self._fused.B, U, cols, self._fused.edofs, eps)
            self.timing["assembly_s"] += time.perf_counter() - t
            t = time.perf_counter()
            dstress, dstate = mat.sensitivity(
                deps, stress_n, state_n, upd, self.dstress, self.dstate, eps - self.eps
            )
            self.timing["material_s"] += time.perf_counter() - t
            if not (np.all(np.isfinite(X)) and np.all(np.isfinite(dstress[:, cols]))):
                self._fail("sensitivity is not finite")
                return
            t = time.perf_counter()
            f = self._forces(dstress)  # (n_dofs, k)
            self.timing["assembly_s"] += time.perf_counter() - t
        self.U, self.eps, self.dstress, self.dstate = U, eps, dstress, dstate
        self.dforce = np.array([bc.plate_force_kN(f[:, j]) for j in range(f.shape[1])])
        scale = max(float(np.linalg.norm(f[bc.fixed])), 1e-300)
        self.residual = max(self.residual, float(np.linalg.norm(f[bc.free])) / scale)

    def _fail(self, message: str) -> None:
        self.ok, self.message = False, message
        self.U[:] = np.nan
        self.dforce = np.full(len(self.columns), np.nan)

    def _forces(self, stress) -> np.ndarray:
        """sum B^T stress[:, j] dV for the solved columns j, (n_dofs, k) N per unit."""
        out = np.empty((self.disc.pattern.n_dofs, len(self.columns)))
        _forces_kernel(
            self._fused.B,
            np.ascontiguousarray(stress),
            self.cols,
            self._fused.dV,
            self._fused.edofs,
            out,
        )
        return out

    def _converged_tangent(self, inc):
        """The free block of the converged tangent (kept by the Newton solver for the next
        predictor); the previous one's assembly time counts as reused once this one is asked."""
        self.timing["reused_tangent_s"] += self._last_tangent_s
        t = time.perf_counter()
        Kff = self.newton._tangent_free(inc.tangent)
        self._last_tangent_s = time.perf_counter() - t
        return Kff

    def _solve(self, inc, rhs) -> np.ndarray:
        """K_T X = rhs on the free dofs (``bc.free`` order, (n_free, k)) with the tangent at the
        converged state of ``inc``."""
        perm = self.newton._perm_position
        kept = inc.factor if (inc.factor is not None and inc.factor_at_converged) else None
        b = np.ascontiguousarray(rhs[perm])
        X = np.empty_like(rhs)
        if kept is not None and kept.exact:
            t = time.perf_counter()
            X[perm] = kept.solve(b)
            self.timing["solve_s"] += time.perf_counter() - t
            return X
        if self.mode == "direct" and not (kept is not None and _symmetric(inc.tangent)):
            Kff = self._converged_tangent(inc)
            mixed = Kff.shape[0] > self.settings.mixed_min_dofs
            t = time.perf_counter()
            factor = mixed_superlu_factor(Kff) if mixed else superlu_factor(Kff)
            self.timing["factor_s"] += time.perf_counter() - t
            self.timing["factorisations"] += 1
            t = time.perf_counter()
            X[perm] = factor.solve(b, MIXED_RTOL) if mixed else factor.solve(b)
            self.timing["solve_s"] += time.perf_counter() - t
            if mixed:
                self.timing["mixed_factorisations"] += 1
                self.timing["refinements"] += getattr(factor, "refinements", 0)
                self.timing["fallbacks"] += bool(getattr(factor, "fallback", True))
                if (
                    self.settings.hand_over
                ):  # the next increment's Newton solves start from this factor
                    self.newton.adopt_factor(factor, Kff, inc.tangent)
            return X
        # krylov (or a symmetric tangent whose CHOLMOD factor the increment kept: then exact, one
        # iteration per column): the Newton's CHOLMOD factor preconditions GCR
        Kff = kept.A if kept is not None else self._converged_tangent(inc)
        precond = inc.factor
        if precond is None:  # no factor to reuse (cannot happen after a converged increment)
            precond = superlu_factor(Kff)
        t = time.perf_counter()
        if self._gcr is None:
            self._gcr = RecycledGCR(Kff.shape[0], len(self.columns))
        X[perm], its = self._gcr.solve(Kff, _preconditioner(precond), b, SENSITIVITY_RTOL)
        self.timing["solve_s"] += time.perf_counter() - t
        self.timing["krylov_iterations"] += its
        return X

    # ------------------------------------------------------------------------------ snapshots
    def snapshot(self) -> None:
        """Keep the current sensitivities as those of a snapshot."""
        nn = self.disc.mesh.n_nodes
        self._snap_u.append(self.U[:, self.cols].reshape(nn, 3, len(self.columns)).copy())
        self._snap_f.append(np.array(self.dforce, dtype=float))

    def result(self, full_mesh) -> Sensitivities:
        """The snapshots' sensitivities, unfolded onto ``full_mesh`` for the eighth model: u_x, u_y
        even, u_z odd (u_z(L - z) = -delta - u_z(z) and delta does not depend on the parameters)."""
        k, nn = len(self.columns), self.disc.mesh.n_nodes
        U = np.array(self._snap_u).reshape(len(self._snap_u), nn, 3, k)
        if self.disc.symmetry == "eighth":
            from problems.fe.mesh import mid_height_mirror

            node_src, node_up, _, _ = mid_height_mirror(full_mesh)
            U = U[:, node_src]
            U[:, node_up, 2] *= -1.0
        force = np.array(self._snap_f).reshape(len(self._snap_f), k)
        return Sensitivities(
            tuple(self.names[j] for j in self.columns),
            U,
            force,
            self.ok,
            self.message,
            self.residual,
            self.wall_s,
            {**self.timing, "mode": self.mode},
        )


def _has_affine_pass(material) -> bool:
    """Whether :func:`problems.materials.ddm.affine_sensitivity` handles ``material``."""
    from problems.materials.drucker_prager import DruckerPrager

    return isinstance(material, DruckerPrager)


def _symmetric(D) -> bool:
    """Whether the material tangents D (n_points, 6, 6) or (6, 6) are all exactly symmetric."""
    D = np.asarray(D)
    return bool(np.array_equal(D, np.swapaxes(D, -1, -2)))


def _preconditioner(factor):
    """The preconditioner application v -> M^-1 v of a Newton factor: one CHOLMOD solve with the
    symmetric part of the tangent it was formed from, or an exact solve."""
    return getattr(factor, "_psolve", None) or factor.solve


class RecycledGCR:
    """Preconditioned generalized conjugate residuals for several right-hand sides with one matrix.

    All columns share one search space: directions ``U`` (rows) with ``C = A U`` orthonormal
    (rows), grown by z = M^-1 r, c = A z orthogonalised against C (classical Gram-Schmidt,
    twice). Each column first takes the minimal-residual combination of the directions the
    earlier columns built (x = U^T C r), then extends the space until its residual is below
    ``rtol ||b||``; the later columns need fewer new directions (measured: a third fewer
    preconditioner applications than GMRES column by column on coarse, 30 % fewer on paper).
    The space is dropped when the matrix changes (each increment) and when it is full
    (restart). In exact arithmetic one column alone is GMRES with right preconditioning.
    """

    def __init__(self, n: int, k: int):
        self.max = int(max(2 * k + 2, min(KRYLOV_MAX_VECTORS, KRYLOV_MEMORY // (16 * max(n, 1)))))
        self.U = np.empty((self.max, n))
        self.C = np.empty((self.max, n))

    def solve(self, A, psolve, B, rtol: float, max_iterations: int = 2000):
        """X (n, k) with ||A X[:, j] - B[:, j]|| <= rtol ||B[:, j]|| (true residual) and the
        number of preconditioner applications. Raises SingularMatrixError when a column stalls."""
        n, k = B.shape
        X = np.zeros((n, k))
        r = 0
        its = 0
        for j in range(k):
            b = B[:, j]
            target = max(rtol, 1e-15) * float(np.linalg.norm(b))
            if target == 0.0:
                continue
            x = np.zeros(n)
            res = b.copy()
            for _sweep in range(4):  # a true-residual check ends each sweep
                if r:
                    a = self.C[:r] @ res
                    x += a @ self.U[:r]
                    res -= a @ self.C[:r]
                while float(np.linalg.norm(res)) > target:
                    if r == self.max:  # full: restart from the current iterate
                        r = 0
                    z = np.asarray(psolve(res), dtype=float).reshape(n)
                    c = A @ z
                    its += 1
                    if its > max_iterations:
                        raise SingularMatrixError(
                            f"GCR did not reach {rtol:g} in {max_iterations} iterations"
                        )
                    if r:  # classical Gram-Schmidt, again when it cancelled much (twice is enough)
                        Cr, Ur = self.C[:r], self.U[:r]
                        for _ in range(2):
                            before = float(np.linalg.norm(c))
                            h = Cr @ c
                            c -= h @ Cr
                            z -= h @ Ur
                            if float(np.linalg.norm(c)) > 0.5 * before:
                                break
                    beta = float(np.linalg.norm(c))
                    if not np.isfinite(beta) or beta == 0.0:
                        raise SingularMatrixError("GCR broke down (zero or non-finite direction)")
                    self.U[r], self.C[r] = z / beta, c / beta
                    alpha = self.C[r] @ res
                    x += alpha * self.U[r]
                    res -= alpha * self.C[r]
                    r += 1
                res = b - A @ x
                if float(np.linalg.norm(res)) <= target:
                    break
            else:
                raise SingularMatrixError(f"GCR residual stalls above {rtol:g}")
            X[:, j] = x
        return X, its


@njit(**_JIT)
def _strains_kernel(B, U, cols, edofs, out):
    """out[p, j] = B_p U[edofs_e, j] for the columns j in ``cols`` (others untouched)."""
    ne, ng, _, nd = B.shape
    k = cols.shape[0]
    ue = np.empty((k, nd))
    for e in range(ne):
        for a in range(nd):
            for q in range(k):
                ue[q, a] = U[edofs[e, a], cols[q]]
        for g in range(ng):
            p = e * ng + g
            for q in range(k):
                c = cols[q]
                for i in range(6):
                    s = 0.0
                    for a in range(nd):
                        s += B[e, g, i, a] * ue[q, a]
                    out[p, c, i] = s


@njit(**_JIT)
def _forces_kernel(B, S, cols, dV, edofs, out):
    """out[:, q] = sum_e sum_g B^T S[:, cols[q]] dV scattered to the global dofs."""
    ne, ng = dV.shape
    nd = B.shape[3]
    k = cols.shape[0]
    out[:, :] = 0.0
    fe = np.empty((k, nd))
    for e in range(ne):
        fe[:, :] = 0.0
        for g in range(ng):
            p = e * ng + g
            w = dV[e, g]
            for q in range(k):
                c = cols[q]
                for i in range(6):
                    si = S[p, c, i] * w
                    for a in range(nd):
                        fe[q, a] += B[e, g, i, a] * si
        for a in range(nd):
            d = edofs[e, a]
            for q in range(k):
                out[d, q] += fe[q, a]


@njit(**_JIT)
def _affine_kernel(B, dV, edofs, U, c, h, T, eps, dstress, dstate, f):
    """For every column q of U (n_dofs, k): eps[p, q] = B_p U_e, dstress[p, q] = c[p, q] +
    T[p, :6] eps[p, q], dstate[p, q] = h[p, q] + T[p, 6:] eps[p, q] and f[:, q] = sum B^T
    dstress[:, q] dV (a non-finite dstress makes f non-finite)."""
    ne, ng = dV.shape
    nd = B.shape[3]
    k, ns = c.shape[1], h.shape[2]
    f[:, :] = 0.0
    ue = np.empty((k, nd))
    fe = np.empty((k, nd))
    ep = np.empty(6)
    for e in range(ne):
        for a in range(nd):
            for q in range(k):
                ue[q, a] = U[edofs[e, a], q]
        fe[:, :] = 0.0
        for g in range(ng):
            p = e * ng + g
            w = dV[e, g]
            for q in range(k):
                for i in range(6):
                    s = 0.0
                    for a in range(nd):
                        s += B[e, g, i, a] * ue[q, a]
                    ep[i] = s
                    eps[p, q, i] = s
                for r in range(6):
                    s = c[p, q, r]
                    for j in range(6):
                        s += T[p, r, j] * ep[j]
                    dstress[p, q, r] = s
                    sw = s * w
                    for a in range(nd):
                        fe[q, a] += B[e, g, r, a] * sw
                for r in range(ns):
                    s = h[p, q, r]
                    for j in range(6):
                        s += T[p, 6 + r, j] * ep[j]
                    dstate[p, q, r] = s
        for a in range(nd):
            d = edofs[e, a]
            for q in range(k):
                f[d, q] += fe[q, a]


heal_numba_cache(globals())  # a torn cache file of these kernels: named, removed

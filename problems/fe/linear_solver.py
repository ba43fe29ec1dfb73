"""Linear solvers of the Newton corrections: ``K_ff du = r`` on the free dofs of the cube.

One small interface, two implementations, chosen by ``NewtonSettings.linear_solver``:

* ``cholmod-gmres`` (``auto`` picks it when :mod:`kvxopt` is installed): the preconditioner is a
  supernodal Cholesky factorisation (CHOLMOD, through kvxopt) of the *symmetric part*
  ``(K + K^T) / 2`` of a tangent, and the exact, possibly non-symmetric, tangent is solved by
  right-preconditioned restarted GMRES to a relative residual the caller chooses (the Newton
  forcing term). The factorisation is about 5x cheaper than an LU of the same matrix in the same
  ordering, the symbolic analysis is done once per sparsity pattern, and a factorisation can be
  reused as the preconditioner of later tangents (:meth:`Factor.for_matrix`): the Newton solver
  refactorises only when the extra Krylov iterations of a stale preconditioner have cost more than
  a factorisation. For a symmetric tangent (elastic, associated flow) the preconditioner is
  exact and GMRES stops after one iteration. If the symmetric part is not positive definite (a
  strongly non-associated flow can make it so: the exponent cases on 27-node meshes) the caller's
  positive definite substitute of the same pattern is factorised instead (``factorise(A, spd=)``;
  the Newton solver hands it the tangent assembled from the positive part of each point's
  material tangent), and only without one, or if that fails too, SuperLU of the tangent itself
  (exact, about 15x a CHOLMOD factorisation on ``5,5,10:g4:hex27`` and not reusable as a
  preconditioner).
* ``superlu``: scipy's SuperLU LU of the tangent, a new factorisation per call; the reference.

Not a Newton solver: :func:`mixed_superlu_factor`, SuperLU of the matrix rounded to single
precision whose solves are refined in double to a requested relative residual (falling back to
the double LU where that stalls); the direct sensitivity solves use it above
``SensitivitySettings.mixed_min_dofs`` free dofs, where it is measured faster.

Both take the free-free block already permuted into the nested-dissection elimination order
(:meth:`problems.fe.newton.BoundaryConditions.free_block`), which CHOLMOD uses as its ordering and
SuperLU as its column order (with diagonal pivoting). Measurements: ``bench/perf/linear_solvers.py``
and docs/fe_model.md.

Failures: an exactly singular matrix raises :class:`SingularMatrixError` from ``factorise``; a
Krylov solve that cannot reach its tolerance falls back to an exact LU of that matrix and only
raises :class:`SingularMatrixError` if that fails too. The Newton solver turns both into a flagged,
cut increment, never an exception of the run.

Units: whatever the matrix carries (N/mm for the stiffness, N for the right-hand sides, mm for
the solutions).
"""

from __future__ import annotations

import math
from typing import Callable, Protocol

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

#: the values ``NewtonSettings.linear_solver`` accepts
LINEAR_SOLVERS = ("auto", "cholmod-gmres", "superlu")


class SingularMatrixError(ArithmeticError):
    """The matrix could not be factorised (exactly singular pivot) or a solve did not converge."""


class Factor(Protocol):
    """A factorisation (or preconditioner) of an n x n matrix that solves with it.

    exact : True when ``solve`` is a direct solve (the tolerance is then irrelevant)
    krylov_iterations : Krylov iterations of the last ``solve`` (0 for direct solves)
    """

    n: int
    exact: bool
    krylov_iterations: int

    def solve(self, rhs: np.ndarray, rtol: float = 1e-12) -> np.ndarray:
        """Solution of ``A x = rhs`` for rhs (n,) or (n, k); relative residual <= rtol per
        column."""
        ...

    def for_matrix(self, A: sp.spmatrix) -> "Factor | None":
        """This factorisation as the preconditioner of another matrix A of the same pattern, or None
        when it cannot serve as one (direct solvers: the caller must factorise A)."""
        ...


class LinearSolver(Protocol):
    """Makes :class:`Factor` objects; keeps whatever analysis can be reused across calls."""

    name: str

    def factorise(self, A: sp.spmatrix, spd: Callable[[], sp.spmatrix] | None = None) -> Factor:
        """Factorise A (n x n, CSC, already in elimination order); raises SingularMatrixError.

        ``spd``: None, or a callable giving a symmetric positive definite matrix of A's pattern
        (CSC, same order) close to A, whose factorisation a preconditioning solver uses when the
        symmetric part of A is not positive definite (direct solvers ignore it)."""
        ...


def make_linear_solver(name: str = "auto") -> LinearSolver:
    """The solver called ``name`` (one of :data:`LINEAR_SOLVERS`)."""
    if name not in LINEAR_SOLVERS:
        raise ValueError(
            f"linear_solver = {name!r} is unknown; allowed: {', '.join(LINEAR_SOLVERS)}"
        )
    if name == "auto":
        name = "cholmod-gmres" if cholmod_available() else "superlu"
    if name == "cholmod-gmres":
        if not cholmod_available():
            raise ValueError(
                "linear_solver = 'cholmod-gmres' needs the kvxopt package (pip install kvxopt); "
                "use 'superlu' or 'auto' without it"
            )
        return CholmodGmresSolver()
    return SuperLUSolver()


def cholmod_available() -> bool:
    """Whether kvxopt (CHOLMOD) can be imported."""
    try:
        import kvxopt.cholmod  # noqa: F401
    except ImportError:
        return False
    return True


# --------------------------------------------------------------------------------------- SuperLU
class SuperLUFactor:
    """SuperLU LU factors of one matrix (exact solves)."""

    exact = True
    krylov_iterations = 0

    def __init__(self, lu):
        self._lu = lu
        self.n = lu.shape[0]

    def solve(self, rhs: np.ndarray, rtol: float = 1e-12) -> np.ndarray:
        return self._lu.solve(np.asarray(rhs, dtype=float))

    def for_matrix(self, A):
        return None


def _splu(A: sp.csc_matrix):
    """scipy's SuperLU of A in its given order; RuntimeError if exactly singular."""
    # The ordering is already fill-reducing: keep it (NATURAL) and pivot on the diagonal.
    return spla.splu(
        A, permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
    )


def superlu_factor(A: sp.spmatrix) -> SuperLUFactor:
    """SuperLU of A in its given (fill-reducing) order, diagonal pivoting; SingularMatrixError if
    singular."""
    try:
        lu = _splu(sp.csc_matrix(A))
    except RuntimeError as exc:  # "Factor is exactly singular"
        raise SingularMatrixError(str(exc)) from exc
    return SuperLUFactor(lu)


class SuperLUSolver:
    """A new SuperLU factorisation per call (no reuse)."""

    name = "superlu"

    def factorise(self, A: sp.spmatrix, spd=None) -> SuperLUFactor:
        return superlu_factor(A)


# ------------------------------------------------------------------- SuperLU, mixed precision
#: most refinement steps of :class:`MixedSuperLUFactor` before it falls back to the double LU
MIXED_MAX_STEPS = 8
#: a refinement step must shrink the largest relative residual at least by this factor, else
#: the single-precision factors are not good enough for this matrix (double LU instead)
MIXED_MIN_REDUCTION = 0.1


class MixedSuperLUFactor:
    """SuperLU LU factors of A in single precision; solves in double by iterative refinement.

    The factorisation is :func:`superlu_factor`'s (same order, diagonal pivoting) of A rounded to
    float32: half the memory traffic, about 1.6x faster on ``paper``. ``solve`` starts from the
    single-precision solution (relative residual ~1e-5 on the plastic tangents of ``paper``) and
    adds corrections ``M^-1 (b - A x)`` with the residual in double until every column's relative
    residual is <= rtol: one step reaches 3e-12-7e-12 on ``paper``, so the answer is the double
    LU's to ~1e-12 (docs/fe_model.md, "Parameter sensitivities"). Columns are scaled before the
    cast (no float32 under- or overflow). If a step does not shrink the residual by
    MIXED_MIN_REDUCTION, or MIXED_MAX_STEPS do not reach rtol, the matrix is factorised in double
    (:func:`superlu_factor`) and solved exactly from then on (``fallback`` True).

    refinements : refinement steps (residual corrections) over all ``solve`` calls
    """

    exact = False
    krylov_iterations = 0

    def __init__(self, A: sp.csc_matrix, lu32):
        self.A = A
        self.n = A.shape[0]
        self._lu32 = lu32
        self._exact: SuperLUFactor | None = None
        self.refinements = 0

    @property
    def fallback(self) -> bool:
        return self._exact is not None

    def _single(self, R: np.ndarray) -> np.ndarray:
        """M^-1 R (single-precision factors) for R (n, k) in double, column by column scaled."""
        scale = np.abs(R).max(axis=0)
        scale[scale == 0.0] = 1.0
        Y = self._lu32.solve(np.asarray(R / scale, dtype=np.float32))
        return np.asarray(Y, dtype=float).reshape(R.shape) * scale

    def solve(self, rhs: np.ndarray, rtol: float = 1e-12) -> np.ndarray:
        rhs = np.asarray(rhs, dtype=float)
        if self._exact is not None:
            return self._exact.solve(rhs)
        B = rhs.reshape(self.n, -1)
        bnorm = np.linalg.norm(B, axis=0)
        nonzero = bnorm > 0.0
        X = self._single(B)
        previous = 1.0  # the relative residual of x = 0
        for step in range(MIXED_MAX_STEPS + 1):
            R = B - self.A @ X
            rel = np.linalg.norm(R, axis=0)[nonzero] / bnorm[nonzero]
            worst = float(rel.max()) if rel.size else 0.0
            if worst <= max(rtol, 1e-15):
                return X.reshape(rhs.shape)
            if step == MIXED_MAX_STEPS or not worst <= MIXED_MIN_REDUCTION * previous:
                break  # stalls, diverges or is not finite
            previous = worst
            X += self._single(R)
            self.refinements += 1
        self._exact = superlu_factor(self.A)
        return self._exact.solve(rhs)

    def for_matrix(self, A):
        return None

    def preconditioner(self):
        """v -> M^-1 v (one column, double in and out) with the single-precision factors, or the
        exact solve once the factorisation fell back to double."""
        if self._exact is not None:
            return self._exact.solve
        return lambda v: self._single(v.reshape(self.n, 1)).reshape(v.shape)


def mixed_superlu_factor(A: sp.spmatrix) -> MixedSuperLUFactor | SuperLUFactor:
    """:class:`MixedSuperLUFactor` of A; the double :func:`superlu_factor` when the single-
    precision factorisation fails (then SingularMatrixError only if A is singular in double)."""
    A = sp.csc_matrix(A)
    data32 = A.data.astype(np.float32)
    if np.all(np.isfinite(data32)):
        A32 = sp.csc_matrix((data32, A.indices, A.indptr), shape=A.shape)
        try:
            lu32 = _splu(A32)
        except RuntimeError:  # singular in single precision: try double
            pass
        else:
            return MixedSuperLUFactor(A, lu32)
    return superlu_factor(A)


# ----------------------------------------------------------------- LU-preconditioned GMRES
class LUGmresFactor:
    """GMRES on a matrix ``A`` right-preconditioned by the LU factors of a nearby matrix of the
    same pattern (a :class:`MixedSuperLUFactor` or :class:`SuperLUFactor` of the converged tangent
    of the previous increment, from the sensitivity solves).

    The Newton solver of a run with sensitivities above ``mixed_min_dofs`` free dofs
    solves each increment's predictor with it (:meth:`problems.fe.newton._Newton.adopt_factor`):
    the predictor matrix *is* the factorised tangent, so one Krylov iteration reaches the
    predictor's tolerance. A solve that does not converge falls back to an exact SuperLU of ``A``
    (as :class:`CholmodGmresFactor`).
    """

    exact = False

    def __init__(self, factor, A, psolve=None):
        self.factor = factor
        self._psolve = psolve if psolve is not None else _lu_preconditioner(factor)
        self.A = A
        self.n = A.shape[0]
        self.krylov_iterations = 0
        self._exact: SuperLUFactor | None = None

    def for_matrix(self, A) -> "LUGmresFactor":
        return LUGmresFactor(self.factor, A, self._psolve)

    def solve(self, rhs: np.ndarray, rtol: float = 1e-12) -> np.ndarray:
        rhs = np.asarray(rhs, dtype=float)
        if self._exact is not None:
            return self._exact.solve(rhs)
        x, self.krylov_iterations = gmres_columns(self.A, self._psolve, rhs, rtol)
        if x is None:  # stagnation or breakdown: solve this matrix exactly from now on
            self._exact = superlu_factor(self.A)
            return self._exact.solve(rhs)
        return x


def _lu_preconditioner(factor):
    """v -> M^-1 v of an LU factor (single-precision factors where it has them)."""
    make = getattr(factor, "preconditioner", None)
    return make() if make is not None else factor.solve


# --------------------------------------------------------------------------------- CHOLMOD+GMRES
class _SymmetricPartPattern:
    """Lower triangle of (A + A^T)/2 for a structurally symmetric CSC pattern, and its CHOLMOD
    analysis."""

    def __init__(self, indptr: np.ndarray, indices: np.ndarray, n: int):
        import kvxopt
        import kvxopt.cholmod as cholmod

        self.indptr, self.indices, self.n = indptr, indices, n
        cols = np.repeat(np.arange(n), np.diff(indptr))
        lower = np.nonzero(indices >= cols)[0]  # CSC order: by column, then row
        rows_l, cols_l = indices[lower], cols[lower]
        keys = cols.astype(np.int64) * n + indices  # sorted (CSC with sorted indices)
        if np.any(np.diff(keys) <= 0):
            raise ValueError("matrix indices must be sorted and unique")
        transposed = np.searchsorted(keys, rows_l.astype(np.int64) * n + cols_l)
        if np.any(transposed >= len(keys)) or np.any(
            keys[np.minimum(transposed, len(keys) - 1)] != rows_l.astype(np.int64) * n + cols_l
        ):
            raise ValueError("matrix pattern is not structurally symmetric")
        self.lower, self.transposed = lower, transposed
        self.matrix = kvxopt.spmatrix(
            np.zeros(len(lower)), rows_l.astype(int), cols_l.astype(int), (n, n)
        )
        cp, ri, _ = self.matrix.CCS
        if not (
            np.array_equal(np.asarray(ri).ravel(), rows_l)
            and np.array_equal(np.asarray(cp).ravel(), indptr_of(cols_l, n))
        ):
            raise RuntimeError("unexpected kvxopt storage order")
        cholmod.options["supernodal"] = 2
        # The rows are already in nested-dissection order: CHOLMOD keeps it.
        self.symbolic = cholmod.symbolic(self.matrix, p=kvxopt.matrix(np.arange(n, dtype=int)))
        self.generation = 0

    def matches(self, A: sp.csc_matrix) -> bool:
        return A.shape[0] == self.n and (
            A.indices is self.indices
            or (
                len(A.indices) == len(self.indices)
                and np.array_equal(A.indptr, self.indptr)
                and np.array_equal(A.indices, self.indices)
            )
        )


def indptr_of(cols: np.ndarray, n: int) -> np.ndarray:
    """CSC column pointer of sorted column indices."""
    return np.concatenate([[0], np.cumsum(np.bincount(cols, minlength=n))])


class CholmodGmresFactor:
    """CHOLMOD factor of the symmetric part of one matrix, preconditioning GMRES on a matrix
    ``A``; ``substitute`` when that matrix was the caller's positive definite substitute
    (``CholmodGmresSolver.factorise(A, spd=)``), not the symmetric part of a tangent."""

    exact = False

    def __init__(
        self,
        solver: "CholmodGmresSolver",
        pattern: _SymmetricPartPattern,
        generation: int,
        A,
        substitute: bool = False,
    ):
        self._solver, self._pattern, self._generation = solver, pattern, generation
        self.substitute = substitute
        self.A = A
        self.n = A.shape[0]
        self.krylov_iterations = 0
        self._exact: SuperLUFactor | None = None

    def _psolve(self, v: np.ndarray) -> np.ndarray:
        import kvxopt
        import kvxopt.cholmod as cholmod

        if self._pattern.generation != self._generation:
            raise RuntimeError(
                "this factorisation was overwritten by a later one of the same solver; "
                "use a factor only until the solver factorises again"
            )
        y = kvxopt.matrix(np.asfortranarray(v, dtype=float))
        cholmod.solve(self._pattern.symbolic, y)
        return np.asarray(y).reshape(v.shape)

    def for_matrix(self, A) -> "CholmodGmresFactor":
        return CholmodGmresFactor(self._solver, self._pattern, self._generation, A, self.substitute)

    def solve(self, rhs: np.ndarray, rtol: float = 1e-12) -> np.ndarray:
        rhs = np.asarray(rhs, dtype=float)
        if self._exact is not None:
            return self._exact.solve(rhs)
        x, self.krylov_iterations = gmres_columns(self.A, self._psolve, rhs, rtol)
        self._solver.krylov_iterations += self.krylov_iterations
        if x is None:  # stagnation or breakdown: solve this matrix exactly from now on
            self._exact = superlu_factor(self.A)
            self._solver.fallbacks += 1
            return self._exact.solve(rhs)
        return x


class CholmodGmresSolver:
    """CHOLMOD-preconditioned GMRES; keeps the symbolic analysis of the last pattern.

    fallbacks       : factorisations that fell back to SuperLU of the matrix itself (exact)
    spd_substitutes : factorisations whose symmetric part was not positive definite and that
                      factorised the caller's positive definite substitute instead
    """

    name = "cholmod-gmres"

    def __init__(self):
        self._pattern: _SymmetricPartPattern | None = None
        self.krylov_iterations = 0
        self.fallbacks = 0
        self.spd_substitutes = 0

    def _numeric(self, values: np.ndarray) -> bool:
        """CHOLMOD numeric factorisation of the current pattern with these lower-triangle values;
        whether it completed (the matrix is positive definite)."""
        import kvxopt
        import kvxopt.cholmod as cholmod

        p = self._pattern
        if not np.all(np.isfinite(values)):
            return False
        # same pattern: the symbolic analysis stays valid
        p.matrix.V = kvxopt.matrix(values)
        p.generation += 1
        cholmod.options["supernodal"] = 2
        try:
            cholmod.numeric(p.matrix, p.symbolic)
            cholmod.diag(p.symbolic)  # raises unless the factorisation completed
        except (ArithmeticError, ValueError):
            p.generation += 1  # no factor of this generation exists
            return False
        return True

    def factorise(
        self, A: sp.spmatrix, spd: Callable[[], sp.spmatrix] | None = None
    ) -> CholmodGmresFactor | SuperLUFactor:
        A = sp.csc_matrix(A)
        if self._pattern is None or not self._pattern.matches(A):
            self._pattern = _SymmetricPartPattern(A.indptr, A.indices, A.shape[0])
        p = self._pattern
        if self._numeric(0.5 * (A.data[p.lower] + A.data[p.transposed])):
            return CholmodGmresFactor(self, p, p.generation, A)
        if spd is not None:
            M = sp.csc_matrix(spd())
            if p.matches(M) and self._numeric(0.5 * (M.data[p.lower] + M.data[p.transposed])):
                self.spd_substitutes += 1
                return CholmodGmresFactor(self, p, p.generation, A, substitute=True)
        # symmetric part not positive definite: an exact LU of the tangent instead
        self.fallbacks += 1
        return superlu_factor(A)


def gmres_columns(A, psolve, rhs: np.ndarray, rtol: float) -> tuple[np.ndarray | None, int]:
    """Preconditioned GMRES (:func:`gmres`) on ``A`` for each column of ``rhs`` (n,) or (n, k):
    the solution shaped like ``rhs`` and the Krylov iterations spent, or ``(None, iterations)``
    as soon as a column stagnates or breaks down (the caller then solves exactly)."""
    cols = rhs.reshape(A.shape[0], -1)
    out = np.empty_like(cols)
    total = 0
    for j in range(cols.shape[1]):
        x, its, ok = gmres(A.dot, psolve, cols[:, j], rtol)
        total += its
        if not ok:
            return None, total
        out[:, j] = x
    return out.reshape(rhs.shape), total


def gmres(matvec, psolve, b: np.ndarray, rtol: float, restart: int = 40, maxiter: int = 200):
    """Right-preconditioned restarted GMRES (flexible form, classical Gram-Schmidt twice).

    Solves ``A x = b`` to ``||b - A x|| <= rtol ||b||`` (checked on the true residual at the end of
    every cycle). Returns ``(x, iterations, converged)``; ``iterations`` counts preconditioner
    applications (= matrix products in the Arnoldi process).
    """
    n = b.shape[0]
    x = np.zeros(n)
    bnorm = float(np.linalg.norm(b))
    if bnorm == 0.0:
        return x, 0, True
    target = max(rtol, 1e-15) * bnorm
    r = b.copy()
    beta = bnorm
    total = 0
    m = min(restart, n)
    V = np.empty((m + 1, n))
    Z = np.empty((m, n))
    while total < maxiter:
        H = np.zeros((m + 1, m))
        cs, sn = np.zeros(m), np.zeros(m)
        g = np.zeros(m + 1)
        g[0] = beta
        V[0] = r / beta
        k = 0
        for j in range(m):
            Z[j] = psolve(V[j])
            w = matvec(Z[j])
            total += 1
            h = V[: j + 1] @ w
            w -= h @ V[: j + 1]
            h2 = V[: j + 1] @ w
            w -= h2 @ V[: j + 1]
            h += h2
            hn = float(np.linalg.norm(w))
            H[: j + 1, j] = h
            H[j + 1, j] = hn
            for i in range(j):  # apply the previous Givens rotations
                t = cs[i] * H[i, j] + sn[i] * H[i + 1, j]
                H[i + 1, j] = -sn[i] * H[i, j] + cs[i] * H[i + 1, j]
                H[i, j] = t
            d = math.hypot(H[j, j], H[j + 1, j])
            if d == 0.0 or not np.isfinite(d):
                return x, total, False
            cs[j], sn[j] = H[j, j] / d, H[j + 1, j] / d
            H[j, j], H[j + 1, j] = d, 0.0
            g[j + 1] = -sn[j] * g[j]
            g[j] *= cs[j]
            k = j + 1
            if abs(g[j + 1]) <= target or hn <= 1e-300 or total >= maxiter:
                break
            V[j + 1] = w / hn
        y = np.zeros(k)
        for i in range(k - 1, -1, -1):  # back substitution with the triangular H
            y[i] = (g[i] - H[i, i + 1 : k] @ y[i + 1 : k]) / H[i, i]
        x += y @ Z[:k]
        r = b - matvec(x)
        beta = float(np.linalg.norm(r))
        if not np.isfinite(beta):
            return x, total, False
        if beta <= target:
            return x, total, True
    return x, total, False

"""The linear solvers of the Newton corrections: same answers, flagged failures, the interface."""

import numpy as np
import pytest
import scipy.sparse as sp

from problems.fe.linear_solver import (
    LINEAR_SOLVERS,
    LUGmresFactor,
    MixedSuperLUFactor,
    SingularMatrixError,
    SuperLUFactor,
    cholmod_available,
    gmres,
    make_linear_solver,
    mixed_superlu_factor,
    superlu_factor,
)
from problems.fe.mesh import box_mesh
from problems.fe.newton import BoundaryConditions, Loading, NewtonSettings, _Newton, discretise, run
from problems.materials import LinearElastic, MaterialUpdate
from problems.materials.drucker_prager import make_material

needs_cholmod = pytest.mark.skipif(not cholmod_available(), reason="kvxopt not installed")

E, NU = 30_000.0, 0.2
# non-associated (psi != beta): the consistent tangent is non-symmetric
PLASTIC = {"E": E, "nu": NU, "beta": 40.0, "K": 0.8, "psi": 15.0, "sigma0": 20.0, "H": 2000.0}


def _plastic():
    return make_material("linear", "compression", PLASTIC)


def _rel(a, b):
    return np.abs(a - b).max() / np.abs(b).max()


@needs_cholmod
def test_cholmod_gmres_and_superlu_give_the_same_plastic_newton_answer():
    disc = discretise(box_mesh(6, 6, 12))
    tight = dict(rtol_force=1e-10, rtol_displacement=1e-10)
    ref = run(
        disc,
        _plastic(),
        Loading(1.5, 5),
        NewtonSettings(linear_solver="superlu", assembly="numpy", **tight),
    )
    new = run(
        disc, _plastic(), Loading(1.5, 5), NewtonSettings(linear_solver="cholmod-gmres", **tight)
    )
    assert ref.converged and new.converged
    assert new.state[-1, :, 0].max() > 1e-3  # really plastic
    assert ref.timing["krylov_iterations"] == 0 and new.timing["krylov_iterations"] > 0
    assert new.timing["factorisations"] < new.iterations  # the preconditioner is reused
    assert _rel(new.reaction_kN, ref.reaction_kN) < 1e-10
    assert _rel(new.displacements, ref.displacements) < 1e-10
    assert _rel(new.stress, ref.stress) < 1e-9
    # inexact solves cost no Newton iteration
    assert new.iterations == ref.iterations


class _Singular(LinearElastic):
    """Elastic stresses, but a zero tangent: every Newton matrix is singular."""

    def update(self, deps, stress_old, state_old):
        upd = super().update(deps, stress_old, state_old)
        return MaterialUpdate(upd.stress, np.zeros_like(upd.tangent), upd.state, upd.ok)


@pytest.mark.parametrize("solver", ["superlu", pytest.param("cholmod-gmres", marks=needs_cholmod)])
def test_singular_tangent_is_a_flagged_failure_not_an_exception(solver):
    r = run(
        discretise(box_mesh(2, 2, 4)),
        _Singular(E, NU),
        Loading(1.5, 2),
        NewtonSettings(linear_solver=solver, max_cuts=2),
    )
    assert not r.converged
    assert "singular tangent" in r.message and "snapshot 1/2" in r.message
    assert len(r.snapshots_mm) == 0


@pytest.mark.parametrize("solver", ["superlu", pytest.param("cholmod-gmres", marks=needs_cholmod)])
def test_factorise_singular_matrix_raises_singular_matrix_error(solver):
    A = sp.csc_matrix(np.array([[1.0, 2.0, 0.0], [2.0, 4.0, 0.0], [0.0, 0.0, 1.0]]))
    with pytest.raises(SingularMatrixError):
        make_linear_solver(solver).factorise(A)


def test_settings_name_the_bad_value_and_the_allowed_ones():
    with pytest.raises(
        ValueError,
        match=r"linear_solver = 'mumps' is unknown; allowed: auto, cholmod-gmres, superlu",
    ):
        NewtonSettings(linear_solver="mumps")
    with pytest.raises(ValueError, match=r"assembly = 'dense' is unknown; allowed: fused, numpy"):
        NewtonSettings(assembly="dense")
    with pytest.raises(ValueError, match="unknown; allowed"):
        make_linear_solver("umfpack")
    assert set(LINEAR_SOLVERS) == {"auto", "cholmod-gmres", "superlu"}
    assert make_linear_solver("auto").name == (
        "cholmod-gmres" if cholmod_available() else "superlu"
    )


def _tangent_block(material, disc, plates="friction"):
    """Free-free block of a plastic tangent (elimination order) from a short run."""
    bc = BoundaryConditions(disc, plates)
    newton = _Newton(disc, material, bc, NewtonSettings())
    n = disc.n_points
    strain = (
        np.tile([1e-3, 1e-3, -5e-3, 1e-3, 0.0, 0.0], (n, 1)) * np.linspace(0.5, 1.5, n)[:, None]
    )
    upd = material.update(strain, np.zeros((n, 6)), material.initial_state(n))
    assert upd.ok.all() and upd.state[:, 0].min() > 0  # every point plastic
    return bc.free_block(newton._tangent(upd.tangent))


@pytest.mark.parametrize("solver", ["superlu", pytest.param("cholmod-gmres", marks=needs_cholmod)])
def test_factor_solves_one_or_several_right_hand_sides(solver):
    A = _tangent_block(_plastic(), discretise(box_mesh(3, 3, 6)))
    assert abs(A - A.T).max() > 1e-3 * abs(A).max()  # non-symmetric
    f = make_linear_solver(solver).factorise(A)
    rng = np.random.default_rng(1)
    B = rng.standard_normal((A.shape[0], 7))
    X = f.solve(B, 1e-12)
    assert X.shape == B.shape
    assert np.linalg.norm(A @ X - B) / np.linalg.norm(B) < 1e-10
    x = f.solve(B[:, 2], 1e-12)
    assert x.shape == (A.shape[0],) and np.allclose(
        x, X[:, 2], rtol=1e-8, atol=1e-12 * np.abs(X).max()
    )


def test_mixed_precision_factor_solves_to_the_superlu_answer():
    A = _tangent_block(_plastic(), discretise(box_mesh(3, 3, 6)))
    assert abs(A - A.T).max() > 1e-3 * abs(A).max()  # non-symmetric
    B = np.random.default_rng(5).standard_normal((A.shape[0], 7))
    B[:, 3] = 0.0  # a zero column stays zero
    ref = superlu_factor(A).solve(B)
    f = mixed_superlu_factor(A)
    assert isinstance(f, MixedSuperLUFactor) and not f.exact and f.for_matrix(A) is None
    single = f._single(B)  # the single-precision solve alone is not the answer ...
    assert np.linalg.norm(single - ref) / np.linalg.norm(ref) > 1e-9
    X = f.solve(B, 1e-12)  # ... its refinement is
    assert X.shape == B.shape and not X[:, 3].any()
    assert 1 <= f.refinements <= 4 and not f.fallback
    for j in range(B.shape[1]):
        assert np.linalg.norm(X[:, j] - ref[:, j]) <= 1e-10 * max(np.linalg.norm(ref[:, j]), 1e-300)
    x = f.solve(B[:, 2], 1e-12)
    assert x.shape == (A.shape[0],)
    assert np.linalg.norm(x - ref[:, 2]) / np.linalg.norm(ref[:, 2]) < 1e-10


def _ill_conditioned(d: float) -> sp.csc_matrix:
    """Identity with a 2 x 2 block [[1, 1], [1, 1 + d]] (condition ~ 4 / d) in the middle."""
    A = sp.lil_matrix(sp.identity(6))
    A[2, 3] = A[3, 2] = 1.0
    A[3, 3] = 1.0 + d
    return sp.csc_matrix(A)


def test_mixed_precision_factor_falls_back_to_the_double_lu():
    b = np.arange(1.0, 7.0)
    # 1 + 1e-7 is 1 + 1.19e-7 in float32: the single factors are 19 % off, refinement stalls
    A = _ill_conditioned(1e-7)
    f = mixed_superlu_factor(A)
    assert isinstance(f, MixedSuperLUFactor)
    x = f.solve(b, 1e-12)
    assert f.fallback and np.allclose(x, superlu_factor(A).solve(b), rtol=1e-12, atol=0.0)
    # 1 + 1e-9 is 1 in float32: singular in single precision, a double LU from the start
    A = _ill_conditioned(1e-9)
    f = mixed_superlu_factor(A)
    assert isinstance(f, SuperLUFactor)
    assert np.linalg.norm(A @ f.solve(b) - b) <= 1e-6 * np.linalg.norm(b)
    with pytest.raises(SingularMatrixError):  # singular in double too
        mixed_superlu_factor(_ill_conditioned(0.0))


def test_lu_preconditioned_gmres_is_exact_on_its_matrix_and_solves_a_nearby_one():
    """The sensitivity solves' LU of a tangent (single precision + refinement) handed to the
    Newton predictor: one GMRES iteration at 1e-5 on that very matrix, several on another."""
    A = _tangent_block(_plastic(), discretise(box_mesh(3, 3, 6)))
    b = np.random.default_rng(3).standard_normal(A.shape[0])
    lu = mixed_superlu_factor(A)
    assert isinstance(lu, MixedSuperLUFactor)
    f = LUGmresFactor(lu, A)
    assert not f.exact
    x = f.solve(b, 1e-5)
    assert f.krylov_iterations == 1 and np.linalg.norm(A @ x - b) <= 1e-5 * np.linalg.norm(b)
    x = f.solve(b, 1e-11)
    assert np.linalg.norm(A @ x - b) <= 1e-11 * np.linalg.norm(b)
    A2 = A.copy()
    A2.data *= 1.0 + 0.05 * np.random.default_rng(2).standard_normal(A2.nnz)  # a nearby matrix
    g = f.for_matrix(A2)
    assert g.A is A2 and g.factor is lu
    X = g.solve(np.column_stack([b, 2.0 * b]), 1e-11)
    assert g.krylov_iterations > 2
    for j in range(2):
        assert np.linalg.norm(A2 @ X[:, j] - (j + 1) * b) <= 1e-11 * (j + 1) * np.linalg.norm(b)
    # an exact (double) LU preconditions too: one iteration even at 1e-12
    h = LUGmresFactor(superlu_factor(A), A)
    x = h.solve(b, 1e-12)
    assert h.krylov_iterations == 1 and np.linalg.norm(A @ x - b) <= 1e-12 * np.linalg.norm(b)


@needs_cholmod
def test_preconditioner_reuse_and_stale_factor_detection():
    disc = discretise(box_mesh(3, 3, 6))
    A = _tangent_block(_plastic(), disc)
    solver = make_linear_solver("cholmod-gmres")
    f = solver.factorise(A)
    A2 = A.copy()
    A2.data *= 1.0 + 0.05 * np.random.default_rng(2).standard_normal(A2.nnz)  # a nearby matrix
    g = f.for_matrix(A2)
    b = np.ones(A.shape[0])
    x = g.solve(b, 1e-11)
    assert np.linalg.norm(A2 @ x - b) / np.linalg.norm(b) < 1e-10 and g.krylov_iterations > 1
    solver.factorise(A2)  # overwrites the numeric factorisation f and g were using
    with pytest.raises(RuntimeError, match="overwritten"):
        g.solve(b, 1e-11)


@needs_cholmod
def test_increment_exposes_a_factor_of_the_converged_tangent():
    disc = discretise(box_mesh(3, 3, 6))
    mat = _plastic()
    bc = BoundaryConditions(disc, "friction")
    newton = _Newton(disc, mat, bc, NewtonSettings(rtol_force=1e-10, rtol_displacement=1e-10))
    u0 = np.zeros(disc.pattern.n_dofs)
    inc = newton.increment(
        u0, np.zeros((disc.n_points, 6)), mat.initial_state(disc.n_points), None, -0.5
    )
    # plastic: the tangent moved
    assert inc.ok and inc.factor is not None and not inc.factor_at_converged
    f = newton.converged_factor(inc)
    K = bc.free_block(newton._tangent(inc.tangent))
    b = np.random.default_rng(3).standard_normal((K.shape[0], 3))
    assert np.linalg.norm(K @ f.solve(b, 1e-12) - b) / np.linalg.norm(b) < 1e-10
    fx = newton.converged_factor(inc, exact=True)
    assert fx.exact and np.linalg.norm(K @ fx.solve(b) - b) / np.linalg.norm(b) < 1e-12
    # elastic: the predictor's factor is formed at the converged tangent already
    el = LinearElastic(E, NU)
    n2 = _Newton(disc, el, bc, NewtonSettings())
    inc = n2.increment(
        u0, np.zeros((disc.n_points, 6)), el.initial_state(disc.n_points), None, -0.5
    )
    assert inc.ok and inc.factor_at_converged and n2.converged_factor(inc) is inc.factor


def test_gmres_solves_a_non_symmetric_system_and_reports_failure():
    rng = np.random.default_rng(4)
    n = 60
    S = rng.standard_normal((n, n))
    S = S @ S.T + n * np.eye(n)
    W = rng.standard_normal((n, n))
    A = S + 0.3 * (W - W.T)
    Sinv = np.linalg.inv(S)
    b = rng.standard_normal(n)
    x, its, ok = gmres(lambda v: A @ v, lambda v: Sinv @ v, b, 1e-12)
    assert ok and 1 < its < n and np.linalg.norm(A @ x - b) <= 1e-12 * np.linalg.norm(b) * 1.01
    x, its, ok = gmres(lambda v: A @ v, lambda v: Sinv @ v, b, 1e-14, restart=2, maxiter=4)
    assert not ok and its == 4
    x, its, ok = gmres(lambda v: A @ v, lambda v: Sinv @ v, np.zeros(n), 1e-12)
    assert ok and its == 0 and not x.any()


def test_the_linear_solve_hook_sees_every_newton_system_and_changes_nothing():
    """``NewtonSettings.on_linear_solve`` is told of each system (one predictor per increment,
    then the corrections) before it is solved; the answer is the one without the hook."""
    disc = discretise(box_mesh(3, 3, 6))
    seen = []

    def hook(kind, Kff, rhs):
        seen.append((kind, Kff.shape[0], rhs.shape[0]))

    plain = run(disc, _plastic(), Loading(1.5, 3), NewtonSettings())
    hooked = run(disc, _plastic(), Loading(1.5, 3), NewtonSettings(on_linear_solve=hook))
    assert hooked.converged and plain.converged
    assert [k for k, *_ in seen].count("predictor") == hooked.increments == 3
    assert len(seen) == hooked.iterations > hooked.increments  # corrections were needed
    n_free = len(BoundaryConditions(disc, "friction").free)
    assert {(n, m) for _, n, m in seen} == {(n_free, n_free)}
    assert np.array_equal(hooked.displacements, plain.displacements)
    assert NewtonSettings(on_linear_solve=hook) == NewtonSettings()  # not a setting of the answer

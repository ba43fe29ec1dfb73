"""Tangents whose symmetric part is not positive definite (strongly non-associated flow: the
exponent cases on 27-node meshes) are preconditioned by CHOLMOD of a positive definite substitute,
not solved by a new exact LU per Newton iteration (issue 25: 9,9,18:g4:hex27 exponent runs took
6-9x their hyperbolic twins, 17 of 19 factorisations of 5,5,10:g4:hex27 were SuperLU)."""

import numpy as np
import pytest
import scipy.sparse as sp

from problems.fe.linear_solver import (
    CholmodGmresFactor,
    CholmodGmresSolver,
    SuperLUFactor,
    cholmod_available,
)
from problems.fe.mesh import parse_mesh_spec
from problems.fe.newton import SPD_FLOOR, Loading, NewtonSettings, discretise, positive_part, run
from problems.inverse.cases import get_case
from problems.inverse.forward import FORWARD_SETTINGS, case_material

needs_cholmod = pytest.mark.skipif(not cholmod_available(), reason="kvxopt not installed")


def test_positive_part_is_the_symmetric_part_with_its_eigenvalues_floored():
    rng = np.random.default_rng(0)
    D = rng.standard_normal((50, 6, 6)) * 1e4
    P = positive_part(D)
    assert np.allclose(P, np.swapaxes(P, 1, 2))
    w_sym = np.linalg.eigvalsh(0.5 * (D + np.swapaxes(D, 1, 2)))
    w = np.linalg.eigvalsh(P)
    assert np.all(w_sym[:, 0] < 0)  # every point indefinite
    assert np.allclose(w[:, -1], w_sym[:, -1])
    assert np.all(w[:, 0] >= SPD_FLOOR * w[:, -1] * (1 - 1e-12))
    # a positive definite symmetric part (here: elastic plus a skew part) is kept as it is
    C = np.diag([3.0, 3.0, 3.0, 1.0, 1.0, 1.0]) * 1e4 + np.ones((6, 6)) * 1e3
    skew = np.triu(np.ones((6, 6)), 1) * 500.0
    assert np.allclose(positive_part(C + skew - skew.T), C, rtol=0, atol=1e-9)


def _indefinite_system(n=60):
    """A regular, structurally symmetric, non-symmetric matrix whose symmetric part has negative
    eigenvalues, and a positive definite matrix of its pattern near it."""
    main = np.linspace(4.0, 8.0, n)
    main[[10, 40]] = -0.5  # two negative pivots: the symmetric part is indefinite
    off = np.full(n - 1, 1.0)
    skew = np.full(n - 1, 3.0)
    A = sp.diags([off - skew, main, off + skew], [-1, 0, 1], format="csc")
    spd = sp.diags([off, np.abs(main) + 2.5, off], [-1, 0, 1], format="csc")
    A.sort_indices()
    spd.sort_indices()
    return A, spd


@needs_cholmod
def test_cholmod_factorises_the_substitute_when_the_symmetric_part_is_indefinite():
    A, spd = _indefinite_system()
    assert np.linalg.eigvalsh((0.5 * (A + A.T)).toarray())[0] < 0
    b = np.random.default_rng(1).standard_normal(A.shape[0])
    solver = CholmodGmresSolver()
    f = solver.factorise(A)  # no substitute: the exact LU, as before
    assert isinstance(f, SuperLUFactor) and solver.fallbacks == 1
    g = solver.factorise(A, spd=lambda: spd)
    assert isinstance(g, CholmodGmresFactor) and g.substitute and solver.spd_substitutes == 1
    x = g.solve(b, 1e-12)
    assert np.linalg.norm(A @ x - b) <= 1e-11 * np.linalg.norm(b)
    assert g.krylov_iterations > 1  # GMRES did the work, not an exact solve
    assert g.for_matrix(A).substitute  # reused as a preconditioner, still flagged
    # a definite symmetric part never asks for the substitute
    h = solver.factorise(spd, spd=lambda: pytest.fail("substitute built needlessly"))
    assert isinstance(h, CholmodGmresFactor) and not h.substitute


@needs_cholmod
def test_exponent_run_on_hex27_needs_no_exact_lu_and_gives_the_superlu_answer():
    """3,3,6:hex27 exponent-compression: the symmetric part of the tangent is indefinite from
    ~0.3 mm. Before the substitute: 11 factorisations, 8 of them SuperLU (Newton 44 iterations,
    no cuts); now 3, none exact. The answer is the exact-LU run's to the Newton tolerance."""
    case = get_case("exponent-compression")
    mat = case_material(case, case.reference)
    disc = discretise(parse_mesh_spec("3,3,6:hex27").mesh, symmetry="eighth")
    load = Loading(1.5, 10)
    r = run(disc, mat, load, FORWARD_SETTINGS)
    ref = run(
        disc,
        mat,
        load,
        NewtonSettings(rtol_force=1e-10, rtol_displacement=1e-10, linear_solver="superlu"),
    )
    assert r.converged and ref.converged and r.cuts == 0
    t = r.timing
    assert t["spd_substitutes"] >= 1  # the indefinite case was met
    assert t["exact_factorisations"] == 0
    assert t["factorisations"] <= 5
    assert r.iterations <= ref.iterations + 2
    np.testing.assert_allclose(r.reaction_kN, ref.reaction_kN, rtol=1e-9)
    scale = np.abs(ref.displacements).max()
    assert np.abs(r.displacements - ref.displacements).max() <= 1e-9 * scale

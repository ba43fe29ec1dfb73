"""Verification of the 27-node hexahedron with the Q2-P1 B-bar (problems/fe/element.py).

Patch test on curved elements, a quadratic field reproduced exactly, no locking near
incompressibility, convergence of the bonded cube's force to the independent reference, a plastic
run to 1.5 mm, exact DDM sensitivities, face interpolation and VTU export.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from problems.fe.assembly import FusedAssembler, element_matrices
from problems.fe.element import GAUSS27_POINTS, GAUSS27_WEIGHTS, shape_functions_27
from problems.fe.front_face import front_face_operator, measurement_grid
from problems.fe.mesh import box_mesh, distort
from problems.fe.mesh_quadratic import HEX27_OFFSETS, quadratic_mesh
from problems.fe.newton import Loading, discretise, run
from problems.inverse.cases import get_case
from problems.inverse.forward import FORWARD_SETTINGS, case_material
from problems.materials import LinearElastic

E, NU = 30_000.0, 0.2
#: whole-cube plate force of the bonded cube at delta = 0.1 mm, E = 30 GPa, nu = 0.2, kN:
#: independent scikit-fem computation with 27-node hexahedra, 12 x 12 x 24 graded (issue 25)
BONDED_REFERENCE_KN = 461.88


def test_shape_functions_are_lagrange_and_gauss_rule_is_exact():
    # partition of unity and derivatives: tests/test_fe.py (both elements)
    N, _ = shape_functions_27(HEX27_OFFSETS - 1.0)
    assert np.abs(N - np.eye(27)).max() < 1e-15
    # x^4 y^2 z^5 integrates exactly over [-1, 1]^3 (0 for the odd power)
    x, y, z = GAUSS27_POINTS.T
    assert GAUSS27_WEIGHTS @ (x**4 * y**2) == pytest.approx(8.0 / 15.0, rel=1e-14)
    assert abs(GAUSS27_WEIGHTS @ (x**4 * y**2 * z**5)) < 1e-15


def test_quadratic_mesh_of_a_graded_mesh_has_midpoint_nodes_and_the_same_corners():
    base = box_mesh(2, 3, 4)
    nodes = base.nodes.copy()
    nodes[:, 2] = 150.0 * (nodes[:, 2] / 150.0) ** 1.5  # graded in z
    m = quadratic_mesh(type(base)(nodes, base.elements, base.shape))
    assert m.elements.shape == (24, 27) and m.n_nodes == 5 * 7 * 9
    assert np.array_equal(m.nodes[m.elements[:, :8]], nodes[base.elements])
    e = m.elements[5]
    assert np.allclose(m.nodes[e[8]], 0.5 * (m.nodes[e[0]] + m.nodes[e[1]]))
    assert np.allclose(m.nodes[e[26]], m.nodes[e[:8]].mean(axis=0))
    assert np.array_equal(np.sort(m.face("x1")), np.nonzero(np.isclose(m.nodes[:, 0], 75.0))[0])


def _solve_dirichlet(mesh, u_exact, use_b_bar=True, nu=NU):
    """Displacements with every boundary node prescribed from ``u_exact`` (n_nodes, 3)."""
    disc = discretise(mesh, use_b_bar=use_b_bar)
    K = FusedAssembler(disc.B, disc.dV, disc.pattern).matrix(LinearElastic(E, nu).stiffness)
    interior = mesh.grid_index()[1:-1, 1:-1, 1:-1].ravel()
    free = (3 * interior[:, None] + np.arange(3)).ravel()
    fixed = np.setdiff1d(np.arange(mesh.n_dofs), free)
    u = np.zeros(mesh.n_dofs)
    u[fixed] = u_exact.ravel()[fixed]
    u[free] = spla.spsolve(K[free][:, free].tocsc(), -K[free][:, fixed] @ u[fixed])
    return u, disc


def test_patch_test_on_curved_elements_reproduces_a_linear_field():
    """Mid-side nodes moved off the straight edges: isoparametric elements keep linear fields."""
    mesh = distort(quadratic_mesh(distort(box_mesh(2, 2, 3), 0.2, seed=3)), 0.1, seed=4)
    A = np.array([[1.0, 0.3, -0.2], [0.5, -0.8, 0.4], [-0.1, 0.6, 0.9]]) * 1e-3
    u_exact = mesh.nodes @ A.T + np.array([0.01, -0.02, 0.03])
    u, disc = _solve_dirichlet(mesh, u_exact)
    assert np.max(np.abs(u - u_exact.ravel())) < 1e-10 * np.abs(u_exact).max()
    eps = np.einsum("egia,ea->egi", disc.B, u[disc.pattern.edofs])
    s = 0.5 * (A + A.T)
    expected = [s[0, 0], s[1, 1], s[2, 2], 2 * s[1, 2], 2 * s[0, 2], 2 * s[0, 1]]
    assert np.max(np.abs(eps - expected)) < 1e-12


def _graded(nx, ny, nz):
    """A rectangular mesh with unequal spacings (affine elements)."""
    base = box_mesh(nx, ny, nz)
    nodes = base.nodes.copy()
    nodes[:, 0] = 75.0 * (nodes[:, 0] / 75.0) ** 1.3
    nodes[:, 2] = 150.0 * (nodes[:, 2] / 150.0) ** 0.8
    return type(base)(nodes, base.elements, base.shape)


def test_quadratic_displacement_field_is_reproduced_exactly():
    """An equilibrated quadratic field (harmonic and divergence free: no body force) is the FE
    solution; a quadratic field with a linear divergence has the exact B-bar strain."""
    mesh = quadratic_mesh(_graded(2, 2, 3))
    x, y, z = (mesh.nodes / 100.0).T
    u_exact = 1e-2 * np.column_stack([x * x - y * y + y * z, -2 * x * y + x * z, x * y])
    u, disc = _solve_dirichlet(mesh, u_exact)
    assert np.max(np.abs(u - u_exact.ravel())) < 1e-10 * np.abs(u_exact).max()
    # u = (x^2, y z, x z) mm: div u = 2 x + x, linear, so the projection onto P1 is exact
    X = mesh.nodes
    v = np.column_stack([X[:, 0] ** 2, X[:, 1] * X[:, 2], X[:, 0] * X[:, 2]]) * 1e-4
    eps = np.einsum("egia,ea->egi", disc.B, v.ravel()[disc.pattern.edofs])
    N, _ = shape_functions_27(GAUSS27_POINTS)
    xg, yg, zg = np.moveaxis(np.einsum("ga,eai->egi", N, X[mesh.elements]), -1, 0) * 1e-4
    exact = np.stack([2 * xg, zg, xg, yg, zg, 0 * xg], axis=-1)
    assert np.max(np.abs(eps - exact)) < 1e-12 * np.abs(exact).max() * 1e4


def test_q2p1_does_not_lock_near_incompressibility():
    """nu = 0.49999, bonded cube: Q2-P1 on 2 x 2 x 4 is within 1 % of 6 x 6 x 12; the fully
    integrated 27-node element is 10 % stiffer (measured 0.58 % and 10.2 %)."""
    mat, load = LinearElastic(E, 0.49999), Loading(0.1, 1)
    ref = run(discretise(quadratic_mesh(box_mesh(6, 6, 12)), symmetry="eighth"), mat, load)
    coarse = quadratic_mesh(box_mesh(2, 2, 4))
    p1, full = (
        run(discretise(coarse, use_b_bar=b, symmetry="eighth"), mat, load).reaction_kN[-1]
        for b in (True, False)
    )
    F = ref.reaction_kN[-1]
    assert abs(p1 / F - 1) < 0.01
    assert full / F - 1 > 0.08
    assert (full - F) > 10 * abs(p1 - F)


def test_bonded_cube_force_converges_faster_than_the_8_node_element():
    """Errors against the independent reference at equal dofs (1 911, 4 131): 27-node 3x3x6 and
    4x4x8 against 8-node 6x6x12 and 8x8x16; the observed order is higher."""
    mat, load = LinearElastic(E, NU), Loading(0.1, 1)

    def error(mesh):
        F = run(discretise(mesh, symmetry="eighth"), mat, load).reaction_kN[-1]
        return F / BONDED_REFERENCE_KN - 1

    e27 = [error(quadratic_mesh(box_mesh(n, n, 2 * n))) for n in (3, 4)]
    e8 = [error(box_mesh(n, n, 2 * n)) for n in (6, 8)]
    print("27-node", e27, "8-node", e8)
    assert 0 < e27[0] < e8[0] / 3 and 0 < e27[1] < e8[1] / 3
    order27, order8 = np.log(e27[0] / e27[1]) / np.log(4 / 3), np.log(e8[0] / e8[1]) / np.log(8 / 6)
    assert order27 > order8 + 0.3


def _case(name="linear-compression"):
    case = get_case(name)
    return case, case_material(case, case.reference)


def test_plastic_cube_runs_to_1_5_mm_and_agrees_with_a_fine_8_node_mesh():
    _, mat = _case()
    r = run(
        discretise(quadratic_mesh(box_mesh(3, 3, 6)), symmetry="eighth"),
        mat,
        Loading(1.5, 5),
        FORWARD_SETTINGS,
    )
    assert r.converged and r.snapshots_mm[-1] == pytest.approx(1.5)
    assert r.stress.shape == (5, 54, 6) and np.all(r.state[-1, :, 0] > 0)  # yielded everywhere
    # 27-node 6 x 6 x 12: 969.5 kN at 1.5 mm (8-node 12 x 12 x 24: 975.4 kN; this mesh 975.9)
    assert r.reaction_kN[-1] == pytest.approx(969.5, rel=0.01)


@pytest.mark.parametrize("name", ["linear-compression", "exponent-tension"])
def test_ddm_sensitivities_match_central_differences(name):
    """Every material parameter, relative step 1e-5 (measured 1e-10 to 8e-10 on
    linear-compression; 1e-9 to 2e-8 at 1e-4, so truncation is below the bound)."""
    from problems.materials.drucker_prager import make_material

    case, mat = _case(name)
    disc = discretise(quadratic_mesh(box_mesh(1, 1, 2)), symmetry="eighth")
    load = Loading(1.5, 3)
    r = run(disc, mat, load, FORWARD_SETTINGS, sensitivities=True)
    assert r.converged and r.sensitivities.ok
    params = case.material_parameters(case.reference)
    for j, p in enumerate(r.sensitivities.parameter_names):
        if p not in params:
            continue
        h = 1e-5 * abs(params[p])
        runs = [
            run(
                disc,
                make_material(case.form, case.hardening, {**params, p: params[p] + s * h}),
                load,
                FORWARD_SETTINGS,
            )
            for s in (1, -1)
        ]
        du = (runs[0].displacements - runs[1].displacements) / (2 * h)
        df = (runs[0].reaction_kN - runs[1].reaction_kN) / (2 * h)
        dU = r.sensitivities.displacements[..., j]
        assert np.linalg.norm(dU - du) <= 1e-6 * np.linalg.norm(du), p
        assert np.linalg.norm(r.sensitivities.reaction_kN[:, j] - df) <= 1e-6 * np.linalg.norm(df)


def test_front_face_interpolation_is_biquadratic():
    mesh = quadratic_mesh(_graded(3, 3, 5))
    pts = measurement_grid(7.0, 3.0)
    W = front_face_operator(mesh, pts)
    y, z = mesh.nodes[:, 1], mesh.nodes[:, 2]
    f = 1.0 + 0.1 * y - 0.02 * z + 1e-3 * y * y * z * z - 2e-3 * y * z
    yp, zp = pts.T
    exact = 1.0 + 0.1 * yp - 0.02 * zp + 1e-3 * yp * yp * zp * zp - 2e-3 * yp * zp
    assert np.max(np.abs(W @ f - exact)) < 1e-9 * np.abs(exact).max()
    assert np.allclose(W.sum(axis=1), 1.0)


def _face_field(mesh, snapshots=2):
    """A response stand-in whose front-face displacements are biquadratic in (y, z) per element
    (exactly representable on 27-node elements, not on a bilinear interpolant of their nodes)."""
    from types import SimpleNamespace

    y, z = mesh.nodes[:, 1], mesh.nodes[:, 2]
    u = np.zeros((snapshots, mesh.n_nodes, 3))
    for k in range(snapshots):
        u[k, :, 1] = (k + 1) * (1e-3 * y + 2e-10 * y * y * z * z - 4e-7 * y * z)
        u[k, :, 2] = -(k + 1) * (2e-3 * z + 1e-10 * y * y * z * z + 3e-7 * y * y)
    return SimpleNamespace(mesh=mesh, displacements=u)


def test_dic_route_deforms_the_images_by_the_element_field():
    """The DIC route's field is the elements' own interpolation, the one the FE route samples:
    biquadratic on a graded 27-node mesh (exact for a biquadratic field, at the grid points equal
    to the FE route's operator), bilinear on 8-node meshes as before (scipy's grid interpolant)."""
    from scipy.interpolate import RegularGridInterpolator

    from problems.dic.route import front_face_fields
    from problems.fe.mesh import parse_mesh_spec

    mesh = quadratic_mesh(parse_mesh_spec("3,3,6:g8").build())
    resp = _face_field(mesh)
    rng = np.random.default_rng(4)
    y, z = rng.uniform(0, 75, (40, 25)), rng.uniform(0, 150, (40, 25))
    y[0, :2], z[0, :2] = (0.0, 75.0), (150.0, 0.0)  # the face's edges
    for k, field in enumerate(front_face_fields(resp)):
        uy, uz = field(y, z)
        assert uy.shape == y.shape
        exact_y = (k + 1) * (1e-3 * y + 2e-10 * y * y * z * z - 4e-7 * y * z)
        exact_z = -(k + 1) * (2e-3 * z + 1e-10 * y * y * z * z + 3e-7 * y * y)
        assert np.abs(uy - exact_y).max() < 1e-14 and np.abs(uz - exact_z).max() < 1e-14  # mm
        pts = measurement_grid()
        W = front_face_operator(mesh, pts)
        u = resp.displacements[k]
        got = field(pts[:, 0], pts[:, 1])
        assert np.abs(got[0] - W @ u[:, 1]).max() < 1e-15 * np.abs(u).max()
        assert np.abs(got[1] - W @ u[:, 2]).max() < 1e-15 * np.abs(u).max()
    # a bilinear interpolant through the 27-node grid (what the route did before) is not that field
    g = mesh.grid_index()[-1]
    ys, zs = mesh.nodes[g[:, 0], 1], mesh.nodes[g[0, :], 2]
    bilinear = RegularGridInterpolator((ys, zs), resp.displacements[0][g, 1])
    old = bilinear(np.column_stack([y.ravel(), z.ravel()])).reshape(y.shape)
    assert np.abs(old - front_face_fields(resp)[0](y, z)[0]).max() > 3e-4  # mm (0.69 um here)

    hex8 = parse_mesh_spec("4,4,8:g8").build()
    resp8 = _face_field(hex8)
    g = hex8.grid_index()[-1]
    ys, zs = hex8.nodes[g[:, 0], 1], hex8.nodes[g[0, :], 2]
    for k, field in enumerate(front_face_fields(resp8)):
        for c, got in zip((1, 2), field(y, z)):
            want = RegularGridInterpolator((ys, zs), resp8.displacements[k][g, c])(
                np.column_stack([y.ravel(), z.ravel()])
            )
            np.testing.assert_allclose(got.ravel(), want, rtol=0, atol=1e-15)


def test_vtu_writes_triquadratic_cells(tmp_path):
    import meshio

    from problems.fe.vtu import write_vtu

    r = run(discretise(quadratic_mesh(box_mesh(1, 1, 2))), LinearElastic(E, NU), Loading(0.1, 1))
    back = meshio.read(write_vtu(r, tmp_path)[-1])
    assert back.cells[0].type == "hexahedron27"
    assert np.array_equal(back.cells[0].data, r.mesh.elements)
    assert np.allclose(back.point_data["displacement"], r.displacements[-1])


def test_fused_assembly_matches_the_numpy_reference():
    disc = discretise(distort(quadratic_mesh(box_mesh(2, 1, 2)), 0.1, seed=2))
    D = np.random.default_rng(1).normal(size=(disc.n_points, 6, 6)) * 100.0
    K = FusedAssembler(disc.B, disc.dV, disc.pattern).matrix(D)
    ne = disc.mesh.n_elements
    ref = disc.pattern.matrix(element_matrices(disc.B, D.reshape(ne, 27, 6, 6), disc.dV))
    assert abs(K - ref).max() < 1e-12 * abs(ref).max()


def test_eighth_and_quarter_models_agree():
    """The mid-height mirror of the 27-node grid: the eighth's unfolded answer is the quarter's
    (measured 1e-15 relative on all nine cases, 3 x 3 x 6)."""
    _, mat = _case("hyperbolic-shear")
    m = quadratic_mesh(box_mesh(2, 2, 4))
    r = {
        s: run(discretise(m, symmetry=s), mat, Loading(1.5, 3), FORWARD_SETTINGS)
        for s in ("eighth", "quarter")
    }
    e, q = r["eighth"], r["quarter"]
    assert e.converged and q.converged
    assert np.abs(e.displacements - q.displacements).max() < 1e-10 * np.abs(q.displacements).max()
    assert np.allclose(e.reaction_kN, q.reaction_kN, rtol=1e-10)
    assert np.allclose(e.stress, q.stress, rtol=1e-8, atol=1e-8 * np.abs(q.stress).max())

"""The mid-height symmetry: the eighth model (z <= 75 mm, unfolded) gives the quarter model's
answers."""

import json

import numpy as np
import pytest

from problems.fe.front_face import measurement_grid
from problems.fe.mesh import (
    MESH_PRESETS,
    SYMMETRIES,
    box_mesh,
    distort,
    lower_half,
    mid_height_mirror,
    parse_mesh,
    parse_mesh_spec,
)
from problems.fe.newton import Loading, NewtonSettings, discretise, run
from problems.inverse.cases import CASES
from problems.inverse.forward import FORWARD_SETTINGS, case_material, discretisation
from problems.materials import LinearElastic, MaterialUpdate

POINTS = measurement_grid()
SMALL = box_mesh(3, 3, 6)  # quarter 3 x 3 x 6, its eighth 3 x 3 x 3: same 25 mm element size


def _rel(a, b):
    return np.linalg.norm(np.asarray(a) - np.asarray(b)) / np.linalg.norm(b)


def _pair(mesh, material, loading, settings=FORWARD_SETTINGS):
    q = run(discretise(mesh, symmetry="quarter"), material, loading, settings)
    e = run(discretise(mesh, symmetry="eighth"), material, loading, settings)
    assert q.converged and e.converged, (q.message, e.message)
    assert q.symmetry == "quarter" and e.symmetry == "eighth"
    return q, e


def _assert_same(q, e, tol=1e-8):
    assert e.mesh.shape == q.mesh.shape and e.displacements.shape == q.displacements.shape
    np.testing.assert_array_equal(e.snapshots_mm, q.snapshots_mm)
    np.testing.assert_allclose(e.reaction_kN, q.reaction_kN, rtol=tol)
    for a, b in zip(e.front_face(POINTS), q.front_face(POINTS)):
        assert _rel(a, b) < tol
    # the unfolded fields: displacements of mirrored nodes, stress and history of mirrored elements
    assert _rel(e.displacements, q.displacements) < tol
    assert _rel(e.stress, q.stress) < tol
    if q.state.size:
        assert _rel(e.state, q.state) < tol


@pytest.mark.parametrize("name", sorted(CASES))
def test_eighth_equals_quarter_friction_plates_all_cases(name):
    case = CASES[name]
    q, e = _pair(SMALL, case_material(case, case.reference), Loading(plates="friction"))
    _assert_same(q, e)
    # the shear stresses of the upper half are really mirrored with a sign change, not zero
    upper = np.arange(SMALL.n_elements) >= SMALL.n_elements // 2
    assert np.abs(q.stress[-1][upper][:, 3:5]).max() > 0.1


def test_eighth_equals_quarter_frictionless_plates():
    case = CASES["hyperbolic-shear"]
    q, e = _pair(SMALL, case_material(case, case.reference), Loading(plates="frictionless"))
    _assert_same(q, e)


def test_eighth_equals_quarter_on_coarse_through_the_mesh_spec():
    case = CASES["linear-compression"]
    mat = case_material(case, case.reference)
    de, dq = discretisation("coarse"), discretisation("coarse:quarter")
    assert de.symmetry == "eighth" and dq.symmetry == "quarter"
    assert de.mesh.shape == (6, 6, 6) and de.full_mesh.shape == dq.mesh.shape == (6, 6, 12)
    assert discretisation("6,6,12:eighth") is de  # one cache entry per model
    q, e = (
        run(dq, mat, Loading(1.5, 5), FORWARD_SETTINGS),
        run(de, mat, Loading(1.5, 5), FORWARD_SETTINGS),
    )
    _assert_same(q, e)


def test_unfolded_displacements_are_the_mirror_images():
    r = run(discretise(box_mesh(2, 2, 4), symmetry="eighth"), LinearElastic(), Loading(1.2, 2))
    g = r.mesh.grid_index()
    for u, delta in zip(r.displacements, r.snapshots_mm):
        np.testing.assert_array_equal(u[g, :2], u[g[:, :, ::-1], :2])
        np.testing.assert_allclose(u[g, 2] + u[g[:, :, ::-1], 2], -delta, rtol=0, atol=1e-15)
        assert np.allclose(u[r.mesh.face("z1"), 2], -delta) and np.allclose(
            u[r.mesh.face("z0")], 0.0
        )


def test_frictionless_eighth_matches_closed_form():
    E, nu, delta = 30_000.0, 0.2, 1.5
    r = run(
        discretise(box_mesh(2, 2, 4), symmetry="eighth"),
        LinearElastic(E, nu),
        Loading(delta, 2, "frictionless"),
    )
    np.testing.assert_allclose(
        r.reaction_kN, E * 150.0**2 * r.snapshots_mm / 150.0 / 1000.0, rtol=1e-12
    )
    u_h, u_v = r.front_face(POINTS)
    np.testing.assert_allclose(u_v[-1], -delta / 150.0 * POINTS[:, 1], rtol=0, atol=1e-13)
    np.testing.assert_allclose(u_h[-1], nu * delta / 150.0 * POINTS[:, 0], rtol=0, atol=1e-13)


def test_mesh_specs_choose_the_eighth_where_exact():
    # every preset has its exact eighth
    assert all(nz % 2 == 0 for _, _, nz in MESH_PRESETS.values())
    for name, shape in MESH_PRESETS.items():
        assert parse_mesh_spec(name).symmetry == "eighth" and parse_mesh_spec(name).shape == shape
        assert parse_mesh_spec(f"{name}:quarter").symmetry == "quarter"
        # the quarter mesh either way
        assert parse_mesh(f"{name}:quarter").shape == parse_mesh(name).shape == shape
    assert parse_mesh_spec("4,4,7").symmetry == "quarter"  # odd NZ: no mid-height node plane
    assert parse_mesh_spec((4, 4, 8)).symmetry == "eighth"
    assert str(parse_mesh_spec("coarse")) == "6,6,12:eighth"
    with pytest.raises(ValueError, match="needs an even NZ.*NZ = 7"):
        parse_mesh_spec("4,4,7:eighth")
    with pytest.raises(
        ValueError, match=r"token 'half' is unknown; allowed after the size: eighth\|quarter"
    ):
        parse_mesh_spec("coarse:half")
    with pytest.raises(ValueError, match="NX,NY,NZ"):
        parse_mesh_spec("medium:quarter")
    assert SYMMETRIES == ("eighth", "quarter")


def test_lower_half_keeps_the_element_size_and_is_a_prefix():
    full = parse_mesh("coarse")
    half = lower_half(full)
    assert half.shape == (6, 6, 6) and half.nodes[:, 2].max() == 75.0
    np.testing.assert_array_equal(half.nodes, full.nodes[: half.n_nodes])
    np.testing.assert_array_equal(half.elements, full.elements[: half.n_elements])
    node_src, node_up, elem_src, elem_up = mid_height_mirror(full)
    assert node_src.max() < half.n_nodes and elem_src.max() < half.n_elements
    assert node_up.sum() == full.n_nodes - half.n_nodes and elem_up.sum() == half.n_elements
    # a mirrored element's nodes are the mirror images of its source's nodes
    mirrored = full.nodes[full.elements[elem_up]]
    source = full.nodes[full.elements[elem_src[elem_up]]]
    assert np.allclose(np.sort(150.0 - mirrored[..., 2], axis=1), np.sort(source[..., 2], axis=1))
    with pytest.raises(ValueError, match="even nz"):
        lower_half(box_mesh(2, 2, 3))
    with pytest.raises(ValueError, match="not symmetric"):
        discretise(distort(box_mesh(3, 3, 4), 0.2, seed=3), symmetry="eighth")


class _Hopeless(LinearElastic):
    def update(self, deps, stress_old, state_old):
        upd = super().update(deps, stress_old, state_old)
        return MaterialUpdate(upd.stress, upd.tangent, upd.state, np.zeros(len(deps), bool))


def test_failed_eighth_run_reports_on_the_quarter_mesh():
    r = run(
        discretise(box_mesh(2, 2, 4), symmetry="eighth"),
        _Hopeless(),
        Loading(1.5, 2),
        NewtonSettings(max_cuts=1),
    )
    assert not r.converged and len(r.snapshots_mm) == 0
    assert r.displacements.shape == (0, r.mesh.n_nodes, 3) and r.mesh.shape == (2, 2, 4)


def test_vtu_and_dic_fields_see_the_whole_height(tmp_path):
    import meshio

    from problems.dic.route import front_face_fields
    from problems.fe.vtu import write_vtu

    case = CASES["linear-compression"]
    q, e = _pair(box_mesh(2, 2, 4), case_material(case, case.reference), Loading(1.5, 2))
    back = meshio.read(write_vtu(e, tmp_path)[-1])
    assert back.points[:, 2].max() == 150.0 and len(back.points) == q.mesh.n_nodes
    np.testing.assert_allclose(
        back.point_data["displacement"], q.displacements[-1], rtol=0, atol=1e-12
    )
    y, z = np.meshgrid(np.linspace(0, 75, 7), np.linspace(0, 150, 13), indexing="ij")
    for fe, fq in zip(front_face_fields(e), front_face_fields(q)):
        for a, b in zip(fe(y, z), fq(y, z)):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


def test_forward_cli_symmetry_option(tmp_path, capsys):
    from bench.cli import main

    docs = {}
    for sym in SYMMETRIES:
        out = tmp_path / f"{sym}.json"
        assert (
            main(
                [
                    "forward",
                    "--mesh",
                    "2,2,4",
                    "--snapshots",
                    "2",
                    "--symmetry",
                    sym,
                    "--json",
                    str(out),
                ]
            )
            == 0
        )
        docs[sym] = json.loads(out.read_text())
    assert docs["eighth"]["symmetry"] == "eighth" and docs["eighth"]["solved_mesh"]["nz"] == 2
    assert (
        docs["quarter"]["solved_mesh"]["nz"] == 4
        and docs["eighth"]["mesh"] == docs["quarter"]["mesh"]
    )
    np.testing.assert_allclose(
        docs["eighth"]["reaction_kN"], docs["quarter"]["reaction_kN"], rtol=1e-10
    )
    np.testing.assert_allclose(
        docs["eighth"]["front_face"]["u_v"],
        docs["quarter"]["front_face"]["u_v"],
        rtol=0,
        atol=1e-12,
    )
    capsys.readouterr()
    assert main(["forward", "--mesh", "2,2,4", "--symmetry", "half"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "femubench forward: error: --symmetry 'half' is unknown; allowed: eighth, quarter"
    assert main(["forward", "--mesh", "2,2,3", "--symmetry", "eighth"]) == 2
    assert "needs an even NZ" in capsys.readouterr().err
    # a graded or quadratic spec names no symmetry: --symmetry is its only statement
    assert main(["forward", "--mesh", "2,2,4:g4", "--snapshots", "1", "--symmetry", "quarter"]) == 0
    assert "solved as the quarter" in capsys.readouterr().out
    assert main(["forward", "--mesh", "2,2,4:g4:eighth", "--symmetry", "quarter"]) == 2
    assert "contradicts --mesh '2,2,4:g4:eighth'" in capsys.readouterr().err

"""Mesh specs with grading and element tokens, and graded structured meshes
(problems/fe/mesh.py)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bench.experiment.spec import RunSpec, config_hash
from problems.fe.front_face import measurement_grid
from problems.fe.mesh import (
    MESH_PRESETS,
    MeshSpec,
    box_mesh,
    discretisation_key,
    graded_box_mesh,
    graded_coordinates,
    parse_mesh_spec,
)
from problems.fe.newton import Loading, discretise, run
from problems.inverse.cases import CASES
from problems.inverse.forward import FORWARD_SETTINGS, case_material
from problems.materials import LinearElastic

ROOT = Path(__file__).resolve().parents[1]


def test_tokens_in_any_order_are_fields_of_the_spec():
    a = parse_mesh_spec("14,14,26:g4:hex27:quarter")
    b = parse_mesh_spec("14,14,26:quarter:hex27:g4")
    assert a == b == MeshSpec((14, 14, 26), "quarter", 4.0, "hex27")
    assert str(a) == "14,14,26:g4:hex27:quarter" and a.key == "14,14,26:g4:hex27"
    c = parse_mesh_spec("paper:g2.5")
    assert (c.shape, c.symmetry, c.grading, c.element) == ((14, 14, 26), "eighth", 2.5, "hex8")
    assert discretisation_key("paper:g2.5:eighth") == discretisation_key("14,14,26:quarter:g2.5")
    assert discretisation_key("coarse:hex27") == "6,6,12:hex27"


def test_uniform_hex8_specs_keep_their_names_and_keys():
    for name, shape in MESH_PRESETS.items():
        key = ",".join(map(str, shape))
        for text in (name, f"{name}:hex8", f"{name}:g1", f"{name}:quarter:g1:hex8"):
            assert discretisation_key(text) == key
        assert str(parse_mesh_spec(name)) == f"{key}:eighth"
    assert parse_mesh_spec("coarse") == MeshSpec((6, 6, 12), "eighth")
    assert str(parse_mesh_spec("4,4,7")) == "4,4,7:quarter"


def test_shipped_records_keep_their_hashes():
    runs = sorted((ROOT / "results" / "comparison" / "runs").glob("*.json"))[:40]
    assert runs, "no shipped records"
    meshes = set()
    for path in runs:
        record = json.loads(path.read_text())
        config = RunSpec.from_dict(record["config"])
        assert config_hash(config) == record["config_hash"] == path.stem
        meshes.add(config.mesh)
    for mesh in meshes:  # the names stay the bare uniform 8-node discretisations
        assert parse_mesh_spec(mesh) == MeshSpec(MESH_PRESETS[mesh], "eighth")
        assert discretisation_key(mesh) == ",".join(map(str, MESH_PRESETS[mesh]))


@pytest.mark.parametrize(
    "text, words",
    [
        ("coarse:g0.5", "grading 'g0.5' is out of range"),
        ("coarse:gx", "grading 'gx' is out of range"),
        ("coarse:ginf", "grading 'ginf' is out of range"),
        ("coarse:g4:g2", "grading given twice"),
        ("coarse:hex8:hex27", "element given twice"),
        ("coarse:eighth:quarter", "symmetry given twice"),
        ("coarse:hex20", "token 'hex20' is unknown"),
        ("coarse:", "token '' is unknown"),
        ("4,4,7:g2:eighth", "needs an even NZ"),
        ("medium:g2", "is unknown; allowed: coarse"),
        ("coarse:gz0.5", "grading toward the plates 'gz0.5' is out of range"),
        ("coarse:gzx", "grading toward the plates 'gzx' is out of range"),
        ("coarse:gz", "grading toward the plates 'gz' is out of range"),
        ("coarse:gzinf", "grading toward the plates 'gzinf' is out of range"),
        ("coarse:gz8:g4:gz4", "grading toward the plates (gzR) given twice"),
        ("coarse:gz8:gz8", "grading toward the plates (gzR) given twice"),
    ],
)
def test_bad_specs_fail_with_one_line(text, words):
    with pytest.raises(ValueError) as exc:
        parse_mesh_spec(text)
    msg = str(exc.value)
    assert words in msg and repr(text) in msg and "\n" not in msg


def test_ratio_one_is_the_uniform_mesh_bit_for_bit():
    u, g = box_mesh(3, 4, 6), graded_box_mesh(3, 4, 6, 1.0)
    assert np.array_equal(u.nodes, g.nodes) and np.array_equal(u.elements, g.elements)
    s = parse_mesh_spec("3,4,6:g1").mesh
    assert np.array_equal(s.nodes, u.nodes) and np.array_equal(s.elements, u.elements)


def test_graded_spacing_has_the_ratio_and_the_mid_height_mirror():
    x = graded_coordinates(6, 75.0, 4.0, "end")
    h = np.diff(x)
    assert x[0] == 0.0 and x[-1] == 75.0 and np.all(np.diff(h) < 0)  # smallest at the free face
    assert h[0] / h[-1] == pytest.approx(4.0, rel=1e-12)
    z = graded_coordinates(12, 150.0, 4.0, "both")
    hz = np.diff(z)
    assert hz[5] / hz[0] == pytest.approx(4.0, rel=1e-12) and hz[0] == pytest.approx(hz[-1])
    assert np.array_equal(z + z[::-1], np.full(13, 150.0)) and z[6] == 75.0
    m = parse_mesh_spec("4,4,8:g3").mesh
    assert m.nodes[:, 0].max() == 75.0 and m.nodes[:, 2].max() == 150.0
    assert np.allclose(np.unique(m.nodes[:, 0]), graded_coordinates(4, 75.0, 3.0, "end"))
    # the element volumes add up to the quarter cube
    assert np.prod(np.ptp(m.nodes, axis=0)) == pytest.approx(75.0 * 75.0 * 150.0)


def test_eighth_and_quarter_agree_on_a_graded_mesh_and_the_face_api_is_unchanged():
    mesh = parse_mesh_spec("3,3,6:g4").mesh
    case = CASES["linear-compression"]
    load = Loading(1.5, 3)
    q, e = (
        run(
            discretise(mesh, symmetry=s),
            case_material(case, case.reference),
            load,
            FORWARD_SETTINGS,
        )
        for s in ("quarter", "eighth")
    )
    assert q.converged and e.converged
    np.testing.assert_allclose(e.reaction_kN, q.reaction_kN, rtol=1e-8)
    points = measurement_grid()
    uh, uv = e.front_face(points)
    qh, qv = q.front_face(points)
    assert uh.shape == qh.shape == (3, len(points)) and uv.shape == (3, len(points))
    assert np.abs(uv - qv).max() < 1e-8 * np.abs(qv).max()
    # bilinear face interpolation reproduces the nodal values at front-face nodes
    top = e.mesh.face("x1")
    node_yz = e.mesh.nodes[top][:, 1:]
    nh, nv = e.front_face(node_yz)
    assert np.allclose(nv[-1], e.displacements[-1, top, 2], atol=1e-12)
    assert np.allclose(nh[-1], e.displacements[-1, top, 1], atol=1e-12)


def _bonded_force_kN(spec: str) -> float:
    """Whole-cube plate force (kN) of the bonded elastic cube at 0.1 mm (E = 30 GPa, nu = 0.2)."""
    disc = discretise(parse_mesh_spec(spec).mesh, symmetry="eighth")
    return run(disc, LinearElastic(30_000.0, 0.2), Loading(0.1, 1)).reaction_kN[-1]


def test_bonded_cube_converges_faster_on_graded_meshes():
    """Errors against the independent 461.88 kN on 4,4,8 / 8,8,16 (h halved): graded (ratio 4)
    errors are smaller and fall with a higher observed order than uniform ones."""
    ref = 461.88
    uniform = [_bonded_force_kN(f"{n},{n},{2 * n}") / ref - 1 for n in (4, 8)]
    graded = [_bonded_force_kN(f"{n},{n},{2 * n}:g4") / ref - 1 for n in (4, 8)]
    assert all(e > 0 for e in uniform + graded)  # stiff from above
    assert graded[0] < 0.7 * uniform[0] and graded[1] < 0.6 * uniform[1]
    order_u, order_g = (np.log2(a / b) for a, b in (uniform, graded))
    assert order_g > order_u + 0.2, (order_u, order_g)

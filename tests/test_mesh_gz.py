"""The ``gzR`` mesh-spec token: a grading ratio toward the plates (z) apart from the lateral one
(``gR``, toward the free faces x, y) (problems/fe/mesh.py)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from bench.cli import main
from bench.studies.convergence import record_path
from problems.analysis.convergence import GCI_ORDERS, gci_order
from problems.fe.mesh import MeshSpec, discretisation_key, graded_box_mesh, parse_mesh_spec
from problems.fe.newton import Loading, discretise, run
from problems.inverse.cases import CASES
from problems.inverse.forward import FORWARD_SETTINGS, case_material, discretisation


def _ratio(coords: np.ndarray) -> float:
    """Largest / smallest element length of the distinct node coordinates along one axis."""
    h = np.diff(np.unique(coords))
    return h.max() / h.min()


@pytest.mark.parametrize(
    "spec, lateral, vertical",
    [("4,4,8:g16:gz8", 16.0, 8.0), ("4,4,8:gz8", 1.0, 8.0), ("4,4,8:g3:gz1", 3.0, 1.0)],
)
def test_z_follows_the_plate_ratio_and_x_y_the_lateral_one(spec, lateral, vertical):
    m = parse_mesh_spec(spec).mesh
    for axis, ratio in zip(range(3), (lateral, lateral, vertical)):
        assert _ratio(m.nodes[:, axis]) == pytest.approx(ratio, rel=1e-12, abs=1e-12)
    # the lateral coordinates are those of the isotropic mesh of the lateral ratio
    iso = graded_box_mesh(4, 4, 8, lateral)
    assert np.array_equal(m.nodes[:, :2], iso.nodes[:, :2])
    assert np.array_equal(m.elements, iso.elements)
    # z stays exactly mirror-symmetric about mid-height: the eighth model stays exact
    z = np.unique(m.nodes[:, 2])
    assert np.array_equal(z + z[::-1], np.full(len(z), 150.0)) and z[4] == 75.0
    # the smallest z elements touch the plates, the smallest x elements the free face
    hz = np.diff(z)
    assert vertical == 1.0 or (hz[0] == hz.min() and hz[-1] == pytest.approx(hz.min()))
    hx = np.diff(np.unique(m.nodes[:, 0]))
    assert lateral == 1.0 or hx[-1] == hx.min()


def test_graded_box_mesh_ratio_z_none_is_the_isotropic_mesh():
    a, b = graded_box_mesh(3, 3, 6, 4.0), graded_box_mesh(3, 3, 6, 4.0, ratio_z=None)
    assert np.array_equal(a.nodes, b.nodes)
    c = graded_box_mesh(3, 3, 6, 4.0, ratio_z=2.0)
    assert _ratio(c.nodes[:, 2]) == pytest.approx(2.0, rel=1e-12)
    assert not np.array_equal(a.nodes[:, 2], c.nodes[:, 2])


def test_keys_round_trip_and_equal_ratios_are_one_discretisation():
    s = parse_mesh_spec("6,6,12:g16:gz8:hex27")
    assert (s.grading, s.grading_z, s.element) == (16.0, 8.0, "hex27")
    assert s.key == "6,6,12:g16:gz8:hex27" and parse_mesh_spec(s.key).key == s.key
    assert parse_mesh_spec(str(s)) == s  # the canonical name the discretisation cache uses
    assert parse_mesh_spec("6,6,12:hex27:gz8:g16") == s  # any token order
    assert parse_mesh_spec("6,6,12:g8:gz8") == parse_mesh_spec("6,6,12:g8")
    assert discretisation_key("6,6,12:g8:gz8") == discretisation_key("6,6,12:g8") == "6,6,12:g8"
    assert discretisation_key("6,6,12:gz1") == "6,6,12"
    g = parse_mesh_spec("6,6,12:gz8")
    assert (g.grading, g.grading_z, g.key) == (1.0, 8.0, "6,6,12:gz8")
    keys = {discretisation_key(f"6,6,12:g8{t}:hex27") for t in ("", ":gz4", ":gz2", ":gz1")}
    assert len(keys) == 4
    assert discretisation_key("converged:gz4") == "15,15,30:g16:gz4:hex27"
    # MeshSpec built directly is normalised the same way; replace() keeps the z ratio
    assert MeshSpec((6, 6, 12), "eighth", 8.0, "hex8", 8.0) == MeshSpec((6, 6, 12), "eighth", 8.0)
    assert MeshSpec((6, 6, 12), "eighth", 8.0, "hex8", 8.0).grading_z is None
    assert replace(s, symmetry="quarter").grading_z == 8.0


def test_file_names_from_keys_stay_unique(tmp_path):
    names = {
        record_path(tmp_path, spec).name
        for spec in ("6,6,12:g16:gz8:hex27", "6,6,12:g16:hex27", "6,6,12:gz8:hex27")
    }
    assert names == {"6x6x12_g16_gz8_hex27.json", "6x6x12_g16_hex27.json", "6x6x12_gz8_hex27.json"}


def test_anisotropic_specs_take_the_elements_gci_order():
    assert gci_order("6,6,12:g8:hex27") == GCI_ORDERS["hex27 g8"]
    assert gci_order("6,6,12:g8:gz8:hex27") == GCI_ORDERS["hex27 g8"]
    assert gci_order("6,6,12:g8:gz4:hex27") == GCI_ORDERS["hex27"]
    assert gci_order("6,6,12:g4:gz8:hex27") == GCI_ORDERS["hex27"]


def test_unknown_token_lists_gz():
    with pytest.raises(ValueError, match=r"gzR \(R >= 1\)"):
        parse_mesh_spec("coarse:hex20")


def test_cli_refuses_a_bad_gz_with_exit_2_and_one_line(capsys):
    assert main(["forward", "--mesh", "2,2,4:g4:gz0.5"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert "--mesh" in err and "gz0.5" in err and ">= 1" in err


def _solve(spec: str):
    """Linear-compression at its reference, 0.5 mm in one step, the eighth model of ``spec``."""
    case = CASES["linear-compression"]
    resp = run(
        discretisation(spec),
        case_material(case, case.reference),
        Loading(0.5, 1),
        FORWARD_SETTINGS,
    )
    assert resp.converged
    return resp


def test_the_plate_ratio_changes_the_response_and_an_equal_one_does_not():
    points = np.array([[y, z] for y in (10.0, 40.0, 70.0) for z in (20.0, 75.0, 130.0)])
    iso, aniso = _solve("2,2,4:g4"), _solve("2,2,4:g4:gz2")
    assert discretisation("2,2,4:g4:gz4") is discretisation("2,2,4:g4")  # one cached model
    same = run(
        discretise(parse_mesh_spec("2,2,4:g4:gz4").mesh, symmetry="eighth"),
        case_material(CASES["linear-compression"], CASES["linear-compression"].reference),
        Loading(0.5, 1),
        FORWARD_SETTINGS,
    )
    uh_i, uv_i = iso.front_face(points)
    uh_a, uv_a = aniso.front_face(points)
    uh_s, uv_s = same.front_face(points)
    assert np.array_equal(uh_s, uh_i) and np.array_equal(uv_s, uv_i)
    assert np.array_equal(same.reaction_kN, iso.reaction_kN)
    # a coarser grading toward the plates moves the front face and the force measurably
    assert np.abs(uh_a - uh_i).max() > 0.02 * np.abs(uh_i).max()  # 7 %
    assert abs(aniso.reaction_kN[-1] / iso.reaction_kN[-1] - 1) > 0.01  # 1.9 %

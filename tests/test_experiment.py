"""A real test's files: any rectangular specimen in the FE model, machine-log loading, the
experiment file and its import into the objective's Dataset."""

from __future__ import annotations

import json

import numpy as np
import pytest

from problems.fe.mesh import SIZE_MM, parse_mesh_spec, quarter_size
from problems.fe.newton import Loading, MachineLoading
from problems.inverse import layout
from problems.inverse.cases import get_case
from problems.inverse.data import DataSettings, default_path, load
from problems.inverse.forward import FEForwardModel, discretisation


# --- any rectangular specimen -------------------------------------------------------------------
def test_default_specimen_is_the_old_cube_and_data_hashes_are_unchanged():
    assert quarter_size((150, 150, 150)) == SIZE_MM == (75.0, 75.0, 150.0)
    old = parse_mesh_spec("coarse").mesh
    assert np.array_equal(discretisation("coarse").full_mesh.nodes, old.nodes)
    path = default_path("linear-compression", "model-error")
    doc = json.loads(path.read_text())
    ds = load(path)
    assert ds.hash == doc["hash"] and "specimen_mm" not in doc["settings"]
    assert "levels_mm" not in DataSettings().to_dict()
    with pytest.raises(ValueError, match="specimen_mm"):
        DataSettings(specimen_mm=(100.0, -1.0, 100.0))


def test_prism_frictionless_elastic_response_is_exact():
    """A 100 x 100 x 300 mm prism between frictionless plates, elastic: F = E A delta / H and the
    face's lateral displacement nu delta / H y, on the eighth model of its quarter."""
    case = get_case("linear-compression")
    delta = 0.01  # mm: elastic
    pts = np.array([[10.0, 30.0], [45.0, 150.0], [50.0, 290.0]])
    model = FEForwardModel(
        case, "4,4,12", Loading(delta, 2, "frictionless"), pts, specimen_mm=(100.0, 100.0, 300.0)
    )
    r = model(case.reference)
    assert r.ok
    E, nu = case.reference[0], case.fixed["nu"]
    u_h, u_v, force = layout.unstack(r.values, 2, 3)
    eps = delta / 300.0
    assert force[-1] == pytest.approx(E * 100.0 * 100.0 * eps / 1e3, rel=1e-9)
    assert np.allclose(u_h[-1], nu * eps * pts[:, 0], rtol=1e-8)
    assert np.allclose(u_v[-1], -eps * pts[:, 1], rtol=1e-8)


def test_machine_levels_equal_steps_bit_for_bit_and_uneven_levels():
    case = get_case("linear-compression")
    pts = np.array([[40.0, 60.0]])
    a = FEForwardModel(case, "2,2,4", Loading(1.5, 3), pts)(case.reference)
    b = FEForwardModel(case, "2,2,4", MachineLoading([0.5, 1.0, 1.5]), pts)(case.reference)
    assert np.array_equal(a.values, b.values)
    uneven = MachineLoading([0.2, 0.9, 1.5])
    r = FEForwardModel(case, "2,2,4", uneven, pts).response(case.reference)
    assert np.allclose(r.snapshots_mm, [0.2, 0.9, 1.5], rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="strictly increasing"):
        MachineLoading([0.5, 0.4])

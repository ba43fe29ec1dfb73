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


# --- the experiment file and its import ---------------------------------------------------------
from problems.inverse.experiment import (  # noqa: E402
    ExperimentFileError,
    face_affine,
    force_sigma_kN,
    import_experiment,
    load_experiment,
    rigid_basis,
    rigid_fit,
    rigid_free_model,
    sha256,
)
from problems.inverse.lab import curve_summary, lab_case  # noqa: E402
from problems.inverse.virtual_experiment import VirtualTest, write_virtual_experiment  # noqa: E402

TRUTH = (33000.0, 37.0, 0.87, 13.5, 23.0, 1350.0)  # linear-compression, not its reference


def test_rigid_fit_recovers_a_known_motion():
    rng = np.random.default_rng(3)
    y, z = rng.uniform(-50, 50, 200), rng.uniform(0, 100, 200)
    sign = np.where(y < 0, -1.0, 1.0)
    B = rigid_basis(y, z, sign)
    field = rng.normal(0, 0.01, 400)  # any deformation
    motion = np.array([0.0123, -0.0456, 3.2e-4])
    w = 1.0 / rng.uniform(1e-3, 3e-3, 400) ** 2
    got = rigid_fit(B, field + B @ motion, w) - rigid_fit(B, field, w)
    assert np.allclose(got, motion, rtol=0, atol=1e-10)
    # in the folded layout the rotation field is that of the true positions
    assert np.allclose(sign * B[:200, 2], -(z - z.mean()))


def test_face_calibration_from_origin_and_from_corners_agree():
    A1, c1 = face_affine("px", 100.0, 80.0, mm_per_px=0.05, origin=[300.0, 2400.0])
    corners = [[300, 2400], [2300, 2400], [2300, 800], [300, 800]]
    A2, c2 = face_affine("px", 100.0, 80.0, corners=corners)
    assert np.allclose(A1, A2, atol=1e-12) and c2["corner_residual_mm"] < 1e-9
    assert c2["mm_per_unit"] == pytest.approx(0.05)
    assert np.allclose(A1 @ [2300.0, 800.0, 1.0], [100.0, 80.0])


@pytest.fixture(scope="module")
def consistent(tmp_path_factory):
    """A virtual 100 mm cube made on the inverse mesh itself with negligible DIC noise, a rigid
    drift and a class 0.5 load cell: the import must give the model's own response."""
    out = tmp_path_factory.mktemp("ve")
    t = VirtualTest(
        "linear-compression",
        TRUTH,
        data_mesh="4,4,8",
        noise_px=(1e-6, 2e-6),
        drift_mm=(0.05, -0.03),
        drift_rad=3e-4,
        load_cell_class=0.5,
        force_step_kN=0.001,
    )
    return write_virtual_experiment(t, out, "consistent")


def test_import_removes_the_drift_and_matches_the_model(consistent):
    exp = load_experiment(consistent)
    ds = import_experiment(exp)
    assert ds.settings.specimen_mm == (100.0, 100.0, 100.0)
    assert ds.points.shape == (400, 2) and np.all(ds.points[:, 0] >= 0)
    assert ds.meta["dropped_off_face"] == 484 - 400
    case = get_case("linear-compression")
    fe = FEForwardModel(case, "4,4,8", ds.settings.loading, ds.points, specimen_mm=(100,) * 3)
    model = rigid_free_model(fe, ds)
    r = model(np.array(TRUTH))
    n = ds.u_h.size
    assert np.abs(r.values[: 2 * n] - ds.values[: 2 * n]).max() < 2e-6  # mm: CSV rounding
    rel = np.abs(r.values[2 * n :] / ds.reaction_kN - 1)
    assert rel.max() < 0.005 + 1e-6  # within the class 0.5 error
    assert np.allclose(ds.std_force_kN, 0.005 / np.sqrt(3) * ds.reaction_kN, rtol=1e-3)
    files = ds.meta["files_sha256"]
    assert files["machine_log"]["machine_log.csv"] == sha256(consistent.parent / "machine_log.csv")
    assert len(files["dic"]) == 8 and "dic/image_08.csv" in files["dic"]
    # the projected Jacobian is the Jacobian of the projected model
    rj = model(np.array(TRUTH), jacobian=True)
    assert rj.jacobian.shape == (2 * n + 8, 6)


def test_lab_case_from_the_test_itself(consistent):
    ds = import_experiment(load_experiment(consistent))
    s = curve_summary(ds)
    assert s["E_MPa"] == pytest.approx(TRUTH[0], rel=0.15)
    for name in ("linear-compression", "hyperbolic-tension", "exponent-shear"):
        case, ref = lab_case(name, ds, s), get_case(name)
        assert np.all(case.lower <= case.start) and np.all(case.start <= case.upper)
        assert not np.any(np.isclose(case.start, ref.reference, rtol=1e-6))
    lin = lab_case("linear-compression", ds, s)
    assert np.all(lin.lower <= TRUTH) and np.all(np.array(TRUTH) <= lin.upper)


def test_bad_experiment_file_lists_every_error(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text(
        '[specimen]\nwidth_mm = -100\ndepth_mm = 100\nheight_mm = "x"\nplatens = "coulomb"\n'
        '[camera]\nunits = "inch"\norigin = [1, 2]\n'
        '[loading]\nlog = "nope.csv"\nforce_unit = "lbf"\nload_cell_class = 4\n'
        '[dic]\nfiles = "dic/*.csv"\n[extra]\n'
    )
    with pytest.raises(ExperimentFileError) as exc:
        load_experiment(f)
    errs = exc.value.errors
    text = "\n".join(errs)
    for needle in (
        "[specimen] width_mm = -100",
        "[specimen] height_mm = 'x'",
        "Coulomb friction is not supported",
        "[camera] units = 'inch'",
        "[loading] log = 'nope.csv'",
        "[loading] force_unit = 'lbf'",
        "[loading] load_cell_class = 4",
        "[loading] displacement_column: missing",
        "[dic] files = 'dic/*.csv': no file matches",
        "unknown table [extra]",
    ):
        assert needle in text, needle
    assert all("\n" not in e for e in errs) and len(errs) >= 10


def test_force_sigma_from_the_class_and_the_resolution():
    s = force_sigma_kN([100.0, 0.0], 1.0, 0.01)
    assert s[0] == pytest.approx(np.hypot(1.0 / np.sqrt(3), 0.01 / np.sqrt(12)))
    assert s[1] == pytest.approx(0.01 / np.sqrt(12))
    with pytest.raises(ValueError, match="force_resolution"):
        force_sigma_kN([0.0], 1.0, 0.0)


def test_mm_export_gives_the_px_export_dataset(consistent, tmp_path):
    """The same measurement exported in mm (the face's frame, y up, origin at its bottom-left
    corner) imports to the same Dataset as the px export with its corner calibration."""
    exp = load_experiment(consistent)
    ds_px = import_experiment(exp)
    A, c = exp.affine[:, :2], exp.affine[:, 2]
    (tmp_path / "dic").mkdir()
    for f in exp.dic_files:
        rows = np.loadtxt(f, delimiter=",", skiprows=1)
        P = rows[:, :2] @ A.T + c
        U = rows[:, 2:4] @ A.T
        S = rows[:, 4] * exp.calibration["mm_per_unit"]
        out = np.column_stack([P, U, S])
        np.savetxt(tmp_path / "dic" / f.name, out, delimiter=",", header="X,Y,U,V,S", comments="")
    text = consistent.read_text()
    start, end = text.index("[camera]"), text.index("[loading]")
    text = text[:start] + '[camera]\nunits = "mm"\norigin = [0.0, 0.0]\nroi_margin_mm = 1.0\n\n'
    text += consistent.read_text()[end:]
    text = text.replace('log = "machine_log.csv"', f'log = "{consistent.parent}/machine_log.csv"')
    text = text.replace(
        'columns = { x = "x", y = "y", u = "u", v = "v", sigma = "sigma" }',
        'columns = { x = "X", y = "Y", u = "U", v = "V", sigma = "S" }',
    )
    f = tmp_path / "mm.toml"
    f.write_text(text)
    ds_mm = import_experiment(load_experiment(f))
    assert np.allclose(ds_mm.points, ds_px.points, atol=1e-9)
    assert np.abs(ds_mm.u_h - ds_px.u_h).max() < 1e-12, np.abs(ds_mm.u_h - ds_px.u_h).max()
    assert np.abs(ds_mm.u_v - ds_px.u_v).max() < 1e-12
    assert np.allclose(ds_mm.std_u_mm, ds_px.std_u_mm, rtol=1e-9)

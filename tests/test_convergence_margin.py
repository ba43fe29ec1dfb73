"""The plate-margin analysis of the convergence study: the measurement vector's rows of a region
(problems/inverse/layout.py), the linearised bias and noise per margin
(problems/analysis/convergence.py), its summary, overview section and figure
(bench/studies/convergence.py) and the command's ``--plate-margins`` (synthetic, no FE solve)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bench.cli import main
from bench.studies.convergence import (
    PLATE_MARGIN_FIGURE,
    analyse,
    record_path,
    render_overview,
    update_plate_margin,
    write_record,
)
from problems.analysis import convergence as conv
from problems.fe.front_face import measurement_grid
from problems.fe.mesh import discretisation_key
from problems.inverse import layout
from problems.inverse.data import MODEL_ERROR_MESH

CASE = "linear-compression"
X_REF = np.array([3.0e4, 40.0])
NAMES = ["E", "sigma0"]


def test_point_rows_keep_both_components_in_every_snapshot_and_every_force():
    N, m = 2, 3
    rows = layout.point_rows([True, False, True], N)
    u_h, u_v, force = layout.unstack(rows, N, m)
    expected = np.array([[True, False, True]] * N)
    np.testing.assert_array_equal(u_h, expected)
    np.testing.assert_array_equal(u_v, expected)
    assert force.all() and rows.dtype == bool and rows.sum() == 2 * N * 2 + N


def _near_plate_residual(points, n_snapshots, rng, force=False):
    """A residual nonzero only on the u_h and u_v rows of the grid rows z = 5 and 145 mm (and
    on the forces when ``force``)."""
    near = (points[:, 1] < 7.5) | (points[:, 1] > 142.5)
    m = len(points)
    r = np.zeros(layout.size(n_snapshots, m))
    r[~layout.point_rows(~near, n_snapshots)] = rng.normal(size=2 * n_snapshots * near.sum())
    if force:
        r[layout.blocks(n_snapshots, m)["force"]] = rng.normal(size=n_snapshots)
    return r


def test_a_margin_removes_a_bias_that_lives_on_the_rows_nearest_the_plates_exactly():
    rng = np.random.default_rng(3)
    points = measurement_grid(spacing_mm=35.0)  # y = 5, 40; z = 5, 40, 75, 110, 145
    N, m = 2, len(points)
    sd = conv.noise_sd(N, m)
    J = rng.normal(size=(layout.size(N, m), 2)) * sd[:, None] / X_REF[None, :] * 30.0
    dx = np.array([0.02, -0.05])  # a true parameter offset (fractions of X_REF)
    near = _near_plate_residual(points, N, rng)
    residuals = {"near": 1e-3 * near, "shift": J @ (dx * X_REF) + 1e-3 * near}
    out = conv.plate_margin_study(J, residuals, X_REF, points, [0.0, 10.0, 40.0], N, 150.0)
    assert [o["points"] for o in out] == [10, 6, 6]
    W = 1.0 / sd**2
    # margin 0: the closed-form Gauss-Newton step of the whole vector
    step = -np.linalg.solve(J.T @ (W[:, None] * J), J.T @ (W * residuals["near"])) / X_REF
    np.testing.assert_allclose(out[0]["bias"]["near"], step, rtol=1e-9)
    assert np.abs(step).max() > 1e-3
    # 10 mm drops the z = 5 and 145 mm rows: no bias left, and the shift is recovered exactly
    np.testing.assert_allclose(out[1]["bias"]["near"], 0.0, atol=1e-12)
    np.testing.assert_allclose(out[1]["bias"]["shift"], -dx, rtol=1e-9)
    # noise sd: sqrt diag (J^T W J)^-1 on the kept rows, relative
    keep = layout.point_rows((points[:, 1] > 7.5) & (points[:, 1] < 142.5), N)
    cov = np.linalg.inv(J[keep].T @ (W[keep, None] * J[keep]))
    np.testing.assert_allclose(out[1]["sd"], np.sqrt(np.diag(cov)) / X_REF, rtol=1e-9)
    assert np.all(out[1]["sd"] > out[0]["sd"])  # fewer points, more noise


def test_the_force_is_kept_whatever_the_margin():
    rng = np.random.default_rng(4)
    points = measurement_grid(spacing_mm=35.0)
    N, m = 1, len(points)
    J = rng.normal(size=(layout.size(N, m), 2)) * conv.noise_sd(N, m)[:, None] / X_REF * 30.0
    r = np.zeros(layout.size(N, m))
    r[-1] = 1.0  # 1 kN off in the force only
    out = conv.plate_margin_study(J, {"f": r}, X_REF, points, [0.0, 10.0], N, 150.0)
    assert np.abs(out[1]["bias"]["f"]).max() > 1e-3  # the force's residual still acts


def _records(tmp_path=None):
    """A synthetic study: family 2/3/4,..:g8:hex27 and the data mesh, one snapshot on the
    default grid, a linear model J whose meshes miss the data by h^2 times a residual on the
    grid rows nearest the plates only."""
    rng = np.random.default_rng(5)
    points = measurement_grid()
    N, m = 1, len(points)
    sd = conv.noise_sd(N, m)
    J = rng.normal(size=(layout.size(N, m), 2)) * sd[:, None] / X_REF * 30.0
    near = 1e-3 * _near_plate_residual(points, N, rng)
    data = J @ X_REF + 1.0
    specs = ["2,2,4:g8:hex27", "3,3,6:g8:hex27", "4,4,8:g8:hex27", MODEL_ERROR_MESH]
    records = {}
    for k, spec in enumerate(specs):
        h = 30.0 / (k + 2)
        is_data = spec == MODEL_ERROR_MESH
        records[spec] = {
            "schema": 1,
            "case": CASE,
            "mesh": spec,
            "key": discretisation_key(spec),
            "element": "hex27",
            "grading": 8.0,
            "elements": 10 * (k + 1),
            "dofs": 100 * (k + 1),
            "h_mm": h,
            "ok": True,
            "message": "",
            "cpu_s": 0.1,
            "wall_s": 0.1,
            "names": NAMES,
            "reference": X_REF.tolist(),
            "n_snapshots": N,
            "n_points": m,
            "values": (data + (0.0 if is_data else h**2 / 100.0) * near).tolist(),
            "jacobian": None if is_data else J.tolist(),
        }
    return records, J, near, sd


def test_summary_overview_and_figure_of_the_plate_margin(tmp_path):
    records, J, near, sd = _records()
    families = {"hex27 g8": list(records)}
    summary, _ = analyse(CASE, families, [], records, (0.0, 10.0, 20.0))
    pm = summary["plate_margin"]
    assert pm["margins_mm"] == [0.0, 10.0, 20.0] and pm["points"] == [406, 378, 322]
    assert list(pm["meshes"]) == ["2,2,4:g8:hex27", "3,3,6:g8:hex27", "4,4,8:g8:hex27"]
    coarse = pm["meshes"]["2,2,4:g8:hex27"]
    assert list(coarse["corrected_pct"]) == ["3,3,6:g8:hex27", "4,4,8:g8:hex27"]
    assert pm["meshes"]["4,4,8:g8:hex27"]["corrected_pct"] == {}  # the data mesh is no hifi
    h = 15.0
    expected = 100.0 * conv.linearised_bias(J, h**2 / 100.0 * near, sd, X_REF)
    assert [coarse["untreated_pct"][0][n] for n in NAMES] == pytest.approx(expected, rel=1e-4)
    for margin in (1, 2):  # the bias lived on the z = 5 and 145 mm rows only
        assert max(abs(v) for v in coarse["untreated_pct"][margin].values()) < 1e-9
    h_fine = 10.0  # the correction's limit with 3,3,6: its own residual
    corrected = coarse["corrected_pct"]["3,3,6:g8:hex27"][0]["E"]
    assert corrected == pytest.approx(expected[0] * h_fine**2 / h**2, rel=1e-4)
    assert coarse["sd_pct"][2]["E"] > coarse["sd_pct"][0]["E"] > 0
    # the overview's section and its figure
    folder = tmp_path / "hex27-g8" / CASE
    folder.mkdir(parents=True)
    (folder / "convergence.json").write_text(json.dumps(summary))
    (folder / "extrapolated.json").write_text(json.dumps({"values": [0.0]}))
    text = render_overview(tmp_path).read_text()
    section = text.split("## Measurement region: the plate margin")[1].split("\n## ")[0]
    assert "### 2,2,4:g8:hex27, corrected (correction with 3,3,6:g8:hex27)" in section
    assert "### 4,4,8:g8:hex27, corrected" not in section
    worst = max(expected, key=abs)
    cell = f"{NAMES[list(expected).index(worst)]} {worst:+.2f} % (sd "
    assert f"| {CASE} | {cell}" in section
    assert "| 0 mm | 10 mm | 20 mm |" in section
    assert (tmp_path / PLATE_MARGIN_FIGURE).stat().st_size > 5000


@pytest.mark.filterwarnings("ignore:Data has no positive values")  # convergence.png: no errors
def test_render_redoes_the_margins_from_the_records_and_checks_the_option(tmp_path, capsys):
    records, *_ = _records()
    folder = tmp_path / CASE
    summary, _ = analyse(CASE, {"hex27 g8": list(records)}, [], records, ())
    assert "plate_margin" not in summary  # no margins: no analysis
    folder.mkdir()
    (folder / "convergence.json").write_text(json.dumps(summary))
    for spec, rec in records.items():
        write_record(record_path(folder, spec), rec)
    code = main(["convergence", CASE, "--out", str(folder), "--render", "--plate-margins", "15,0"])
    assert code == 0, capsys.readouterr().err
    pm = json.loads((folder / "convergence.json").read_text())["plate_margin"]
    assert pm["margins_mm"] == [0.0, 15.0] and pm["points"] == [406, 350]
    # a missing record: one line naming it
    record_path(folder, "3,3,6:g8:hex27").unlink()
    with pytest.raises(ValueError, match="3x3x6_g8_hex27.json: the mesh record is missing"):
        update_plate_margin(folder, (0.0,))


@pytest.mark.parametrize(
    "value, words",
    [
        ("80", "--plate-margins: 80 is out of range: must be in [0, 75) mm"),
        ("-5,10", "--plate-margins: -5 is out of range: must be in [0, 75) mm"),
        ("10,,20", "--plate-margins: '10,,20' is malformed"),
        ("ten", "--plate-margins: 'ten' is not a number"),
    ],
)
def test_bad_plate_margins_are_one_line_errors(value, words, capsys, tmp_path):
    code = main(["convergence", CASE, "--out", str(tmp_path), f"--plate-margins={value}"])
    err = capsys.readouterr().err
    assert code == 2 and words in err and len(err.strip().splitlines()) == 1, err

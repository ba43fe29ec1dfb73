"""The rounding floor of the model-error data (:func:`bench.studies.convergence.add_rounding`)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bench.studies.convergence import (
    add_rounding,
    analyse,
    read_json,
    record_path,
    update_plate_margin,
    write_record,
)
from problems.analysis import convergence as conv
from problems.inverse import layout
from problems.inverse.data import MODEL_ERROR_MESH, _round, rounded, tier_settings
from tests.test_convergence_margin import NAMES, X_REF, _records


def test_rounded_is_the_data_modules_rounding_in_the_measurement_layout():
    settings = tier_settings("model-error", snapshots=2)
    m = len(settings.points)
    rng = np.random.default_rng(3)
    u_h, u_v = rng.normal(0, 0.3, (2, m)), rng.normal(0, 0.3, (2, m))
    force = rng.normal(500.0, 50.0, 2)
    got = rounded(layout.stack(u_h, u_v, force), settings)
    want = layout.stack(_round(u_h, 1e-3), _round(u_v, 1e-3), _round(force, 0.1))
    assert np.array_equal(got, want)
    assert np.abs(got[-2:] - force).max() <= 0.05 and np.abs(got[-2:] - force).max() > 0
    with pytest.raises(ValueError, match="does not fit 2 snapshots"):
        rounded(np.zeros(5), settings)


def _linear_study():
    """The synthetic linear study of the plate-margin tests, its data mesh's response made
    off-grid so that rounding moves it."""
    records, J, near, sd = _records()
    data = records[MODEL_ERROR_MESH]
    data["values"] = (np.asarray(data["values"]) + 0.123456e-3).tolist()
    return records, J, sd


def test_the_floor_of_a_linear_model_is_the_least_squares_step_of_the_rounding_residual():
    records, J, sd = _linear_study()
    summary, _ = analyse("linear-compression", {"hex27 g8": list(records)}, [], records, ())
    exact = np.asarray(records[MODEL_ERROR_MESH]["values"])
    settings = tier_settings("model-error", snapshots=1)
    r = exact - rounded(exact, settings)
    # closed form: dx = -(J^T W J)^-1 J^T W r
    W = np.diag(sd**-2.0)
    dx = -np.linalg.solve(J.T @ W @ J, J.T @ W @ r)
    floor = [summary["rounding_floor_pct"][n] for n in NAMES]
    assert floor == pytest.approx(100.0 * dx / X_REF, rel=1e-8)
    assert max(abs(v) for v in floor) > 1e-4  # rounding does move the estimate
    assert summary["rounding_floor_mesh"] == "4,4,8:g8:hex27"  # the finest with a Jacobian
    assert max(summary["rounding_floor_spread_pct"].values()) < 1e-9  # one linear model
    # superposition: bias against the rounded data = bias against the exact data + floor
    for row in summary["meshes"]:
        if "rounded_data_bias_pct" in row:
            for n in NAMES:
                want = row["data_bias_pct"][n] + summary["rounding_floor_pct"][n]
                assert row["rounded_data_bias_pct"][n] == pytest.approx(want, rel=1e-8, abs=1e-10)


def test_the_spread_is_the_largest_difference_with_another_jacobian():
    records, J, sd = _linear_study()
    other = np.array(J) * np.array([1.0, 1.1])  # the second parameter's sensitivity 10 % larger
    records["2,2,4:g8:hex27"]["jacobian"] = other.tolist()
    summary, _ = analyse("linear-compression", {"hex27 g8": list(records)}, [], records, ())
    exact = np.asarray(records[MODEL_ERROR_MESH]["values"])
    r = exact - rounded(exact, tier_settings("model-error", snapshots=1))
    f0 = conv.linearised_bias(J, r, sd, X_REF)
    f1 = conv.linearised_bias(other, r, sd, X_REF)
    spread = [summary["rounding_floor_spread_pct"][n] for n in NAMES]
    assert spread == pytest.approx(100.0 * np.abs(f1 - f0), rel=1e-8)
    assert spread[1] > 0


def test_no_rounding_no_floor():
    records, J, sd = _linear_study()
    exact = np.asarray(records[MODEL_ERROR_MESH]["values"])
    settings = tier_settings("model-error", snapshots=1, resolution_um=0, force_resolution_kN=0)
    assert np.array_equal(rounded(exact, settings), exact)
    floor, spread = conv.rounding_floor([J, 2.0 * J], exact, rounded(exact, settings), sd, X_REF)
    assert np.all(floor == 0.0) and np.all(spread == 0.0)


def test_the_study_without_jacobians_adds_no_floor():
    records, J, sd = _linear_study()
    for r in records.values():
        r["jacobian"] = None
    summary, _ = analyse("linear-compression", {"hex27 g8": list(records)}, [], records, ())
    assert "rounding_floor_pct" not in summary
    assert not any("rounded_data_bias_pct" in r for r in summary["meshes"])
    assert add_rounding(summary, records) is summary


def test_render_adds_the_floor_from_the_records_and_keeps_the_summary_without_them(tmp_path):
    records, J, sd = _linear_study()
    summary, _ = analyse("linear-compression", {"hex27 g8": list(records)}, [], records, ())
    floor = summary.pop("rounding_floor_pct")
    (tmp_path / "convergence.json").write_text(json.dumps(summary))
    assert update_plate_margin(tmp_path, ()) is None  # no records: the summary stays
    for spec, rec in records.items():
        write_record(record_path(tmp_path, spec), rec)
    assert update_plate_margin(tmp_path, ()) == tmp_path / "convergence.json"
    assert read_json(tmp_path / "convergence.json")["rounding_floor_pct"] == pytest.approx(floor)
    text = (tmp_path / "convergence.md").read_text()
    assert "## The rounding floor of the model-error data (%)" in text
    worst = max(floor.values(), key=abs)
    assert f"| rounding floor | {floor['E']:+.2f} | {floor['sigma0']:+.2f} |" in text
    assert worst != 0.0


def test_the_shipped_model_error_data_are_fixed_points_of_the_rounding():
    """The shipped data set of a case is already rounded in the units rounded() assumes (mm,
    kN): rounding it again, or after a shift below half a step, gives it back."""
    from problems.inverse.data import get_data

    settings = tier_settings("model-error", "6,6,12:g8:hex27")
    values = get_data("exponent-tension", settings).values
    assert np.abs(rounded(values, settings) - values).max() < 1e-12
    shifted = values + 0.4e-3  # 0.4 um on a displacement, 0.0004 kN on a force
    assert np.abs(rounded(shifted, settings) - values).max() < 1e-12
    assert np.abs(rounded(values + 0.6e-3, settings) - values).max() > 0.9e-3

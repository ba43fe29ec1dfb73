"""``femubench calibrate``: the shipped example imported and calibrated briefly, resumption,
consistent data recovered, bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import bench.calibration as cal
from bench.calibration import CalibrationSettings, calibrate
from bench.cli import main
from problems.inverse.experiment import import_experiment, load_experiment
from problems.inverse.virtual_experiment import VirtualTest, write_virtual_experiment
from tests.support import assert_shipped_calibration_is_of

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "suites" / "experiments" / "cube100"
#: the parameters that made the example (linear-compression on the fine mesh)
EXAMPLE_TRUTH = np.array([34000.0, 38.0, 0.9, 12.0, 24.0, 1500.0])


def _short_copy(tmp_path: Path) -> Path:
    """The example's experiment file with absolute paths, four images and a tiny inverse mesh."""
    text = (EXAMPLE / "experiment.toml").read_text()
    text = text.replace('log = "machine_log.csv"', f'log = "{EXAMPLE / "machine_log.csv"}"')
    text = text.replace('files = "dic/image_*.csv"', f'files = "{EXAMPLE}/dic/image_*.csv"')
    text = text.replace('mesh = "coarse"', 'mesh = "3,3,6"\nimages = [1, 4, 8]\nbudget = 8')
    f = tmp_path / "short.toml"
    f.write_text(text)
    return f


def test_shipped_example_is_small_and_imports():
    size = sum(p.stat().st_size for p in EXAMPLE.rglob("*") if p.is_file())
    assert size < 1_000_000
    ds = import_experiment(load_experiment(EXAMPLE / "experiment.toml"))
    assert ds.points.shape == (400, 2) and ds.meta["dropped_off_face"] == 84
    assert len(ds.snapshots_mm) == 8 and ds.snapshots_mm[-1] == pytest.approx(0.7)
    assert ds.settings.specimen_mm == (100.0, 100.0, 100.0)
    # the DIC noise declared (0.01-0.03 px at 0.05 mm/px) is what the sigma column says
    assert 0.5e-3 < ds.std_u_mm.mean() < 1.5e-3


def test_short_calibration_of_the_example_and_resume(tmp_path, monkeypatch):
    exp = _short_copy(tmp_path)
    out = tmp_path / "out"
    settings = CalibrationSettings("3,3,6", 8, check_mesh="")
    models = ["linear-compression", "hyperbolic-compression"]
    rep = calibrate(
        exp, out, models=models, settings=settings, progress=lambda s: None, figures=False
    )
    lin = rep["variants"]["linear-compression"]
    assert lin["ok"] and len(lin["std"]) == 6 and lin["birge_ratio"] >= 1.0
    assert abs(lin["x"][0] / EXAMPLE_TRUTH[0] - 1) < 0.15  # E on a 27-element eighth
    assert {r["variant"] for r in rep["ranking"]} == set(models)
    assert rep["import"]["images"] == 3 and rep["import"]["points_used"] == 400
    f = np.array(rep["force_kN"])
    assert np.abs(np.array(lin["model_force_kN"]) / f - 1).max() < 0.15  # coarse model
    doc = json.loads((out / "report.json").read_text())
    assert doc["format"] == cal.FORMAT and "AIC" in (out / "report.md").read_text()

    # resumable: nothing is rerun when the results are there
    def boom(*a, **k):
        raise AssertionError("rerun")

    monkeypatch.setattr(cal, "calibrate_variant", boom)
    said = []
    again = calibrate(exp, out, models=models, settings=settings, progress=said.append)
    assert sum("done before" in s for s in said) == 2
    assert again["variants"]["linear-compression"]["x"] == lin["x"]
    for name in ("report.md", "report.json", "force_displacement.png", "residuals.png"):
        assert (out / name).stat().st_size > 0


def test_consistent_virtual_experiment_is_recovered(tmp_path):
    """Data made on the inverse mesh itself (no discretisation error), small DIC noise and a
    class 0.5 load cell: every parameter within 1 %, and within its 95 % interval."""
    truth = np.array([31000.0, 33.0, 0.88, 11.0, 21.5, 1300.0])
    t = VirtualTest(
        "linear-compression",
        tuple(truth),
        data_mesh="3,3,6",
        levels_mm=(0.05, 0.15, 0.3, 0.5),
        noise_px=(0.002, 0.004),
        load_cell_class=0.5,
        force_step_kN=0.001,
        seed=5,
    )
    exp = write_virtual_experiment(t, tmp_path / "ve", "consistent")
    # data made on the inverse mesh on purpose (the optimiser alone, as the consistent tier):
    # drop the [virtual] record that would refuse it, as a real test has none
    exp.write_text(exp.read_text().split("[virtual]")[0])
    rep = calibrate(
        exp,
        tmp_path / "out",
        models=["linear-compression"],
        settings=CalibrationSettings("3,3,6", 30, check_mesh=""),
        progress=lambda s: None,
        figures=False,
    )
    v = rep["variants"]["linear-compression"]
    x = np.array(v["x"])
    assert np.abs(x / truth - 1).max() < 0.01, x / truth - 1
    lo, hi = np.array(v["ci95_lower"]), np.array(v["ci95_upper"])
    assert np.sum((lo <= truth) & (truth <= hi)) >= 5


def test_cli_bad_file_and_bad_out(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text('[specimen]\nwidth_mm = 0\n[camera]\nunits = "px"\norigin = [0, 0]\n')
    assert main(["calibrate", str(bad)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("femubench calibrate: error: experiment file")
    assert any("[specimen] width_mm = 0: must be > 0" in e for e in err)
    assert any("[camera] mm_per_px: missing" in e for e in err)
    assert len(err) >= 8
    assert main(["calibrate", str(EXAMPLE / "experiment.toml"), "--out", str(EXAMPLE)]) == 2
    assert "outputs never go among the inputs" in capsys.readouterr().err
    assert main(["calibrate", str(EXAMPLE / "experiment.toml"), "--models", "linear-nope"]) == 2
    assert "--models 'linear-nope'" in capsys.readouterr().err


def test_iterated_correction_removes_the_discretisation_bias(tmp_path):
    """Data made on mesh 6,6,12, inverse mesh 3,3,6: uncorrected, the parameters are biased by
    the inverse mesh's discretisation error; the iterated correction with a finer mesh that is
    not the data's (5,5,10: the honesty rule, enforced) removes most of the bias."""
    truth = np.array([31000.0, 33.0, 0.88, 11.0, 21.5, 1300.0])
    t = VirtualTest(
        "linear-compression",
        tuple(truth),
        data_mesh="6,6,12",
        levels_mm=(0.05, 0.15, 0.3, 0.5),
        noise_px=(0.002, 0.004),
        load_cell_class=0.5,
        force_step_kN=0.001,
        seed=6,
    )
    exp = write_virtual_experiment(t, tmp_path / "ve", "biased")
    errors = {}
    for corr in ("none", "iterated"):
        rep = calibrate(
            exp,
            tmp_path / corr,
            models=["linear-compression"],
            settings=CalibrationSettings("3,3,6", 30, check_mesh="5,5,10", correction=corr),
            progress=lambda s: None,
            figures=False,
        )
        v = rep["variants"]["linear-compression"]
        errors[corr] = np.abs(np.array(v["x"]) / truth - 1).max()
        assert v["n_evals"] > sum(r["n_evals"] for r in v["correction_rounds"])
    # measured: largest relative error 0.55 uncorrected, 0.16 corrected
    assert errors["none"] > 0.1 and errors["iterated"] < errors["none"] / 3, errors
    assert rep["discretisation"]["rms_sigma"] > 0
    # the discretisation band (default with a correction): from the untreated and the corrected
    # estimate, added to the Laplace half-width, in report.json and report.md; here it covers
    # the truth the Laplace intervals alone miss
    x, u = np.array(v["x"]), np.array(v["band_abs"])
    assert v["band"]["method"] == "gci" and v["band"]["fine_mesh"] == "5,5,10"
    assert np.all(u > 0) and np.all(np.array(v["ci95_upper"]) > np.array(v["ci95_laplace_upper"]))
    assert np.all(np.abs(x - truth) <= 1.96 * np.array(v["std"]) + u)
    assert "band U" in (tmp_path / "iterated" / "report.md").read_text()
    saved = json.loads((tmp_path / "iterated" / "report.json").read_text())
    assert saved["variants"]["linear-compression"]["band_percent"] == v["band_percent"]
    # the untreated fit is kept: the first identification's cost, chi2 on the raw data (no 1/2),
    # as one evaluation of the objective there gives it; the ranking of one variant has a band
    # and nothing behind the first
    from problems.inverse.experiment import import_experiment, load_experiment
    from problems.inverse.lab import curve_summary, lab_case

    data = import_experiment(load_experiment(exp))
    ev = cal.objective_for(data, lab_case("linear-compression", data, curve_summary(data)), "3,3,6")
    chi2_u = ev.evaluate(ev.to_scaled(np.array(v["x_untreated"]))).cost
    assert v["chi2_untreated"] == pytest.approx(chi2_u, rel=1e-9)
    assert v["aic_untreated"] == pytest.approx(chi2_u + 12) and chi2_u > v["chi2"]
    assert rep["ranking_band"]["method"] == "gci" and rep["ranking_band"]["warning"] is None


def test_shipped_calibration_matches_the_example():
    """results/calibration/cube100 is keyed by the example as it imports today: rerunning the
    command there resumes (reads every variant) instead of recomputing — on a machine whose
    arithmetic imports it bit for bit; elsewhere its chi2 holds on today's import."""
    from problems.inverse.lab import curve_summary, lab_case

    out = ROOT / "results" / "calibration" / "cube100"
    exp = load_experiment(EXAMPLE / "experiment.toml")
    data = import_experiment(exp)
    summary = curve_summary(data)
    settings = CalibrationSettings(exp.mesh, exp.budget)
    report = json.loads((out / "report.json").read_text())
    assert len(report["variants"]) == 9
    if assert_shipped_calibration_is_of(
        out, data, lab_case("linear-compression", data, summary), settings
    ):
        for name in exp.models:
            done = json.loads((out / "variants" / f"{name}.json").read_text())
            assert done["key"] == cal.variant_key(data, lab_case(name, data, summary), settings)
    assert report["ranking"][0]["variant"].startswith("linear-")


def test_a_variant_key_names_the_discretisation_a_preset_stands_for_today():
    """``converged`` is re-pointable: a variant calibrated with it is keyed by the mesh it names
    today, so a re-pointed preset is never served another mesh's result."""
    from problems.inverse.lab import curve_summary, lab_case

    exp = load_experiment(EXAMPLE / "experiment.toml")
    data = import_experiment(exp)
    case = lab_case("linear-compression", data, curve_summary(data))

    def key(mesh):
        return cal.variant_key(data, case, CalibrationSettings(mesh, exp.budget))

    assert key("converged") == key("15,15,30:g16:hex27") != key("12,12,24:g8:hex27")
    assert key("converged:quarter") == key("15,15,30:g16:hex27:quarter")
    assert key(exp.mesh) != key("converged")


def test_data_mesh_is_never_a_calibration_mesh(tmp_path, capsys):
    """A virtual experiment records its data mesh; --mesh or --check-mesh (auto too) on it is
    refused in one line with exit code 2, before any model run."""
    exp = tmp_path / "ve" / "experiment.toml"
    exp.parent.mkdir()
    text = _short_copy(tmp_path).read_text() + '\n[virtual]\ndata_mesh = "paper"\n'
    exp.write_text(text)
    assert load_experiment(exp).data_mesh == "paper"
    for argv, option in (
        (["--mesh", "14,14,26"], "--mesh 14,14,26"),
        (["--mesh", "coarse"], "--check-mesh auto (= paper)"),
        (["--mesh", "3,3,6", "--check-mesh", "paper"], "--check-mesh paper"),
    ):
        code = main(["calibrate", str(exp), "--out", str(tmp_path / "o"), *argv])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and option in err[0], err
        assert "made this virtual experiment's data" in err[0]
    bad = tmp_path / "ve" / "bad.toml"
    bad.write_text(text.replace('data_mesh = "paper"', 'data_mesh = "nope"'))
    assert main(["calibrate", str(bad)]) == 2
    assert "[virtual] data_mesh" in capsys.readouterr().err

"""The plate margin of a calibration: the ``auto`` rule, its validation (CLI, experiment file),
the coverage study's keys (old records read as margin 0), and the points it leaves out."""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pytest

import bench.calibration_coverage as cov
from bench.calibration_coverage import CoverageSettings
from bench.cli import main
from problems.inverse.build import auto_plate_margin_mm, resolve_plate_margin
from problems.inverse.experiment import ExperimentFileError, import_experiment, load_experiment


def test_auto_is_a_tenth_of_the_smallest_dimension():
    assert auto_plate_margin_mm(150, 150, 150) == pytest.approx(15.0)
    assert auto_plate_margin_mm(100, 100, 100) == pytest.approx(10.0)
    assert auto_plate_margin_mm(100, 100, 300) == pytest.approx(10.0)
    assert auto_plate_margin_mm(200, 80, 160) == pytest.approx(8.0)
    assert resolve_plate_margin("auto", (150, 150, 150)) == pytest.approx(15.0)
    assert resolve_plate_margin(7, (100, 100, 100)) == 7.0
    with pytest.raises(ValueError, match=r"0 <= margin < 50 mm \(or auto\)"):
        resolve_plate_margin(50.0, (100, 100, 100))


def test_coverage_keys_margin_zero_as_before_and_other_margins_apart():
    base = CoverageSettings(
        "hyperbolic-compression", 10, "12,12,24:g8:hex27", "6,6,12:g8:hex27",
        correction="one-point", check_mesh="auto",
    )  # fmt: skip
    # the key of the shipped hyperbolic-compression study's experiment 0 (before the option; its
    # data mesh is converged's until stop 38)
    assert base.calibration_key(0) == "a91ba9f5859f5370"
    auto = dataclasses.replace(base, plate_margin_mm="auto")
    ten = dataclasses.replace(base, plate_margin_mm=10)
    keys = {s.calibration_key(0) for s in (base, auto, ten)} | {s.key(0) for s in (base, auto, ten)}
    assert len(keys) == 6  # a rerun never mixes margins
    assert base.data_key(0) == auto.data_key(0) == ten.data_key(0)  # the data are shared
    assert [auto.margin_mm(sp) for sp in auto.specimens] == [10.0, 15.0, 10.0]
    assert ten.plate_margin_mm == 10.0 and ten.to_dict()["plate_margin_mm"] == 10.0
    # records before the option read as margin 0, per specimen too
    old = {"specimen_mm": [100.0] * 3, "ok": True, "error_percent": [1.0, -3.0]}
    new = {"specimen_mm": [100.0] * 3, "ok": True, "error_percent": [1.0, 0.5]}
    new |= {"plate_margin_mm": 10.0, "true_first_aic": True, "all_covered": True}
    assert cov.record_margin(old) == 0.0 and cov.record_margin(new) == 10.0
    (g,) = cov.per_specimen([old, new])
    assert (g["n"], g["all_within_target"], g["true_first_aic"], g["all_covered"]) == (2, 1, 1, 1)
    assert g["plate_margin_mm"] == [0.0, 10.0]


@pytest.mark.parametrize(
    "value, said",
    [
        ("x", "argument --plate-margin-mm: 'x' is not a number; or auto"),
        ("-1", "argument --plate-margin-mm: -1 is out of range: must be >= 0 mm; or auto"),
        ("50", "--plate-margin-mm 50.0: plate_margin_mm = 50.0 is out of range: 0 <= margin < 50"),
    ],
)
@pytest.mark.parametrize("command", ["calibrate-coverage", "calibrate"])
def test_bad_margin_is_one_line_exit_2(tmp_path, capsys, value, said, command):
    argv = [command, "--plate-margin-mm", value, "--out", str(tmp_path / "o")]
    if command == "calibrate":  # the shipped 100 mm cube
        argv.insert(
            1,
            str(Path(__file__).resolve().parents[1] / "suites/experiments/cube100/experiment.toml"),
        )
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and said in err[0], err
    assert not (tmp_path / "o").exists()


@pytest.fixture(scope="module")
def cube(tmp_path_factory):
    """A copy of the shipped example (a virtual 100 mm cube, DIC step 5 mm): no FE run."""
    root = Path(__file__).resolve().parents[1] / "suites" / "experiments" / "cube100"
    out = tmp_path_factory.mktemp("ve") / "cube100"
    shutil.copytree(root, out)
    return out / "experiment.toml"


def test_margin_leaves_the_near_plate_points_out_with_a_count(cube, tmp_path, monkeypatch):
    exp = load_experiment(cube)
    plain = import_experiment(exp)
    assert exp.plate_margin_mm == 0.0 and "dropped_plate_margin" not in plain.meta
    # the experiment file's "auto": 10 mm on the 100 mm cube
    text = cube.read_text().replace("[calibration]\n", '[calibration]\nplate_margin_mm = "auto"\n')
    auto_file = cube.parent / "auto.toml"
    auto_file.write_text(text)
    auto = load_experiment(auto_file)
    assert auto.plate_margin_mm == pytest.approx(10.0)
    ds = import_experiment(auto)
    z = plain.points[:, 1]
    near = (z < 10.0 - 1e-9) | (z > 90.0 + 1e-9)
    assert near.sum() > 0 and len(ds.points) == len(plain.points) - near.sum()
    assert ds.meta["dropped_plate_margin"] == near.sum() and ds.meta["plate_margin_mm"] == 10.0
    assert ds.meta["dropped_off_face"] == plain.meta["dropped_off_face"]
    assert ds.hash != plain.hash  # a calibration of another margin never reads these results
    # a bad value in the file: one line naming the field
    auto_file.write_text(text.replace('"auto"', '"some"'))
    with pytest.raises(
        ExperimentFileError, match="plate_margin_mm = 'some': a number of mm or \"auto\""
    ):
        load_experiment(auto_file)

    # calibrate(plate_margin_mm=...) overrides the file's: the objective gets the fewer points
    import bench.calibration as cal
    import problems.inverse.experiment as experiment

    seen = []

    def spy(e):
        seen.append(e.plate_margin_mm)
        raise RuntimeError("stop")

    monkeypatch.setattr(experiment, "import_experiment", spy)
    for value in ("auto", 20, None):
        with pytest.raises(RuntimeError, match="stop"):
            cal.calibrate(
                cube, tmp_path / "c", models=["linear-compression"], plate_margin_mm=value
            )
    assert seen == [10.0, 20.0, 0.0]
    with pytest.raises(ValueError, match="--plate-margin-mm 60"):
        cal.calibrate(cube, tmp_path / "c", plate_margin_mm=60)
    assert np.all(np.abs(ds.points[:, 1] - 50.0) <= 40.0 + 1e-9)

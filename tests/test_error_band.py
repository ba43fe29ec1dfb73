"""The discretisation error band of a calibration (grid convergence index of the untreated and
the corrected estimate): the formula on a two-mesh case of known order, its order against the
shipped convergence study, the widened intervals and the report's table, bad option values."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bench.calibration import CalibrationSettings, _parameter_table, with_error_band
from bench.calibration_coverage import CoverageSettings, render_summary, summarise
from bench.cli import main
from problems.analysis.convergence import (
    GCI_ORDERS,
    GCI_SAFETY,
    gci_band,
    gci_order,
    refinement_ratio,
)

P = GCI_ORDERS["hex27 g8"]  # the default inverse model's family

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "suites" / "experiments" / "cube100" / "experiment.toml"


def test_gci_band_of_a_two_mesh_case_of_known_order():
    """q(h) = q0 + C h^p with p = 2 on h = 1.5 and 1: with the true order and no safety factor
    the band is the finer estimate's exact error; the shipped (smaller) order and safety factor
    make it wider, never narrower."""
    q0, c = np.array([10.0, -3.0, 200.0]), np.array([0.4, -0.02, 8.0])
    qc, qf = q0 + c * 1.5**2, q0 + c * 1.0**2
    exact = np.abs(qf - q0)
    assert gci_band(qc, qf, 1.5, order=2.0, safety=1.0) == pytest.approx(exact, rel=1e-12)
    band = gci_band(qc, qf, 1.5, P)
    # 3 |qf - qc| / (1.5^1.13 - 1) = 5.16 |qf - qc| = 5.16 x 1.25 x exact
    assert band == pytest.approx(GCI_SAFETY / (1.5**P - 1) * 1.25 * exact, rel=1e-12)
    assert np.all(band > 6.4 * exact) and np.all(band < 6.5 * exact)
    with pytest.raises(ValueError, match="ratio > 1"):
        gci_band(qc, qf, 1.0, P)


def test_refinement_ratio_from_the_mesh_specs():
    assert refinement_ratio("6,6,12:g8:hex27", "9,9,18:g8:hex27") == pytest.approx(1.5)
    assert refinement_ratio("coarse", "paper") == pytest.approx((14 * 14 * 26 / 432) ** (1 / 3))
    with pytest.raises(ValueError, match="is not finer"):
        refinement_ratio("9,9,18:g8:hex27", "6,6,12:g8:hex27")


def test_band_orders_are_conservative_against_the_shipped_studies():
    """Each family's band order is no larger than any order the shipped studies of that family
    observed (field and force, every triple), and within 0.01 of the smallest."""
    smallest = {}
    for f in (ROOT / "results/studies/convergence").rglob("convergence.json"):
        for name, fam in json.loads(f.read_text())["families"].items():
            o = [v for v in fam["orders_field_all"] + fam["orders_force_all"] if v == v]
            smallest[name] = min([*o, smallest.get(name, np.inf)])
    assert set(smallest) == {"hex27 g8", "hex27 g4", "hex8 g4"}
    for family, mesh in (("hex27 g8", "6,6,12:g8:hex27"), ("hex27 g4", "5,5,10:g4:hex27"),
                         ("hex8 g4", "coarse")):  # fmt: skip
        assert smallest[family] - 0.01 <= gci_order(mesh) <= smallest[family], family
    assert gci_order("6,6,12:g8:hex27") == 1.13 and GCI_SAFETY == 3.0


def _result(**extra) -> dict:
    return {
        "ok": True,
        "names": ["E", "H"],
        "units": ["MPa", "MPa"],
        "start": [30000.0, 1000.0],
        "x": [30000.0, 1200.0],
        "std": [30.0, 6.0],
        "std_percent": [0.1, 0.5],
        "ci95_lower": [30000.0 - 58.8, 1200.0 - 11.76],
        "ci95_upper": [30000.0 + 58.8, 1200.0 + 11.76],
        "fine_mesh": "9,9,18:g8:hex27",
        "x_untreated": [30300.0, 1180.0],
    } | extra


def test_error_band_widens_the_interval_and_is_stated_in_the_table():
    s = CalibrationSettings("6,6,12:g8:hex27", 10, check_mesh="auto", correction="one-point")
    v = with_error_band(_result(), s)
    u = np.array(v["band_abs"])
    k = GCI_SAFETY / (1.5**P - 1)
    assert u == pytest.approx([k * 300.0, k * 20.0])
    assert v["band_percent"] == pytest.approx(100 * u / np.array([30000.0, 1200.0]))
    assert v["ci95_upper"][1] == pytest.approx(1200.0 + 11.76 + k * 20.0)
    assert v["ci95_lower"][0] == pytest.approx(30000.0 - 58.8 - k * 300.0)
    assert v["ci95_laplace_upper"] == _result()["ci95_upper"]
    assert v["band"] | {"ratio": 1.5} == {
        "method": "gci", "order": P, "safety": GCI_SAFETY, "ratio": pytest.approx(1.5),
        "inverse_mesh": "6,6,12:g8:hex27", "fine_mesh": "9,9,18:g8:hex27",
    }  # fmt: skip
    text = "\n".join(_parameter_table(v))
    assert "band U" in text and "untreated (inverse mesh)" in text
    assert f"| {k * 20.0:.4g} |" in text and "p = 1.13" in text
    # turned off, or no correction ran: the Laplace interval alone, and the table says why
    off = with_error_band(_result(), CalibrationSettings(
        "6,6,12:g8:hex27", 10, correction="one-point", error_band="none"))  # fmt: skip
    assert off["ci95_upper"] == _result()["ci95_upper"] and "band_abs" not in off
    plain = with_error_band(_result(x_untreated=None), CalibrationSettings("coarse", 10))
    assert plain["band"]["method"] == "none" and "no correction ran" in plain["band"]["reason"]
    assert "no discretisation band: no correction ran" in "\n".join(_parameter_table(plain))


def test_coverage_key_keeps_studies_without_a_correction():
    a = CoverageSettings(n=1)
    b = CoverageSettings(n=1, error_band="none")
    assert a.key(0) == b.key(0)  # no correction: the band changes nothing
    c = CoverageSettings(n=1, inverse_mesh="6,6,12:g8:hex27", data_mesh="converged",
                         correction="one-point", check_mesh="auto")  # fmt: skip
    d = CoverageSettings(n=1, inverse_mesh="6,6,12:g8:hex27", data_mesh="converged",
                         correction="one-point", check_mesh="auto", error_band="none")  # fmt: skip
    assert c.key(0) != d.key(0) and c.calibration_settings().fine_mesh == "9,9,18:g8:hex27"
    # the band's constants key the record, not the calibration folder (rescored without runs)
    assert c.calibration_key(0) != c.key(0) and d.calibration_key(0) == d.key(0)
    assert a.key(0) == a.calibration_key(0)
    assert "check mesh `auto = 9,9,18:g8:hex27`" in render_summary(summarise(c, []))


@pytest.mark.parametrize(
    "argv, said",
    [
        (["--error-band", "wide"], "--error-band"),
        (["--correction", "two-point"], "--correction"),
        (["--correction", "one-point", "--check-mesh", "none"], "--correction one-point needs"),
    ],
)
def test_calibrate_bad_option_is_one_line_exit_2(tmp_path, capsys, argv, said):
    assert main(["calibrate", str(EXAMPLE), "--out", str(tmp_path / "o"), *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and said in err[0], err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "argv, said",
    [
        (["--error-band", "wide"], "--error-band"),
        (["--correction", "one-point", "--inverse-mesh", "3,3,6", "--check-mesh", "auto"],
         "--correction one-point needs a finer mesh"),
        (["--data-mesh", "9,9,18:g8:hex27", "--inverse-mesh", "6,6,12:g8:hex27",
          "--correction", "one-point", "--check-mesh", "auto"], "--check-mesh auto: the data"),
    ],
)  # fmt: skip
def test_coverage_bad_option_is_one_line_exit_2(tmp_path, capsys, argv, said):
    assert main(["calibrate-coverage", *argv, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and said in err[0], err

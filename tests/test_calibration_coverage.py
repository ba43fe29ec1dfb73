"""``femubench calibrate-coverage`` on a tiny configuration: records, scores, summary, resume,
and the honesty rule on its meshes."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

import bench.calibration_coverage as cov
from bench.calibration_coverage import CoverageSettings, draw_test, run_coverage
from bench.cli import main
from problems.fe.presets import spell_out

TINY = [
    "--n", "2", "--data-mesh", "4,4,8", "--inverse-mesh", "3,3,6",
    "--models", "linear-compression,hyperbolic-compression", "--budget", "8",
    "--strains", "0.0005,0.002,0.005", "--spacing", "10",
    "--specimens", "100x100x100,100x100x200",
]  # fmt: skip


def test_tiny_study_scores_resumes_and_summarises(tmp_path, capsys, monkeypatch):
    out, work = tmp_path / "cov", tmp_path / "work"
    assert main(["calibrate-coverage", *TINY, "--out", str(out), "--work", str(work)]) == 0
    assert "true variant first 2/2 (AIC)" in capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    assert summary["n_done"] == 2 and summary["true_first_aic"] == 2
    recs = [json.loads((out / "experiments" / f"e{i:03d}.json").read_text()) for i in range(2)]
    for r in recs:
        truth, x = np.array(r["truth"]), np.array(r["x"])
        assert np.allclose(r["error_percent"], 100 * (x / truth - 1))
        assert abs(r["error_percent"][0]) < 10  # E, even on a 3,3,6 inverse mesh
        lo, hi = np.array(r["ci95_lower"]), np.array(r["ci95_upper"])
        assert r["covered"] == ((lo <= truth) & (truth <= hi)).tolist()
        # the truth is drawn in the middle half of the box; the levels scale with the height
        assert r["levels_mm"][-1] == pytest.approx(0.005 * r["specimen_mm"][2])
    assert {tuple(r["specimen_mm"]) for r in recs} <= {(100.0,) * 3, (100.0, 100.0, 200.0)}
    covered = sum(c for r in recs for c in r["covered"])
    assert sum(p["covered"] for p in summary["parameters"].values()) == covered
    assert "| E |" in (out / "summary.md").read_text()

    # resumable: nothing is recomputed when the records are there
    def boom(*a, **k):
        raise AssertionError("rerun")

    monkeypatch.setattr("bench.calibration.calibrate", boom)
    said = []
    s = CoverageSettings(
        "linear-compression", 2, "4,4,8", "3,3,6",
        ("linear-compression", "hyperbolic-compression"), 8, 0,
        ((100.0, 100.0, 100.0), (100.0, 100.0, 200.0)), (0.0005, 0.002, 0.005), 10.0,
    )  # fmt: skip
    again = run_coverage(s, out, work=work, progress=said.append)
    assert sum("done before" in m for m in said) == 2 and again["n_done"] == 2
    # a range of the experiments runs (here: finds) those alone; its summary covers every record
    said = []
    part = run_coverage(s, out, work=work, progress=said.append, indices=range(1, 2))
    assert said[0].startswith("experiment 1: done before") and part["n_done"] == 2
    assert sum("done before" in m for m in said) == 1

    # a study differing in the calibration alone reuses the virtual experiments' data
    monkeypatch.undo()
    monkeypatch.setattr(
        "problems.inverse.virtual_experiment.write_virtual_experiment",
        lambda *a, **k: pytest.fail("data remade"),
    )
    argv = [*TINY, "--out", str(tmp_path / "cov2"), "--work", str(work)]
    argv[argv.index("--budget") + 1] = "6"
    assert main(["calibrate-coverage", *argv]) == 0

    # a record scored otherwise (e.g. other band constants) is rescored from the calibration
    # folder, no variant rerun, its wall time carried over
    rec0 = out / "experiments" / "e000.json"
    stale = json.loads(rec0.read_text()) | {"key": "stale", "wall_s": 1000.0}
    rec0.write_text(json.dumps(stale))
    said = []
    run_coverage(s, out, work=work, progress=said.append)
    again = json.loads(rec0.read_text())
    assert again["key"] == s.key(0) and 1000.0 <= again["wall_s"] < 1100.0
    assert sum("identifying" in m for m in said) == 0 and sum("done before" in m for m in said) == 3

    # a record older than the calibration key (none stored) on the same experiment: carried too
    stale = json.loads(rec0.read_text()) | {"key": "older", "wall_s": 2000.0}
    del stale["calibration_key"]
    rec0.write_text(json.dumps(stale))
    run_coverage(s, out, work=work, progress=said.append)
    again = json.loads(rec0.read_text())
    assert again["key"] == s.key(0) and 2000.0 <= again["wall_s"] < 2100.0
    # ... but not when the record is of another experiment (another draw)
    other = json.loads(rec0.read_text()) | {"key": "other", "seed": -1, "wall_s": 3000.0}
    del other["calibration_key"]
    rec0.write_text(json.dumps(other))
    run_coverage(s, out, work=work, progress=said.append)
    assert json.loads(rec0.read_text())["wall_s"] < 1000.0


def test_draws_differ_and_stay_in_the_middle_of_the_box():
    s = CoverageSettings(n=3)
    tests = [draw_test(s, i) for i in range(3)]
    from problems.inverse.cases import get_case

    case = get_case(s.variant)
    lo, hi = np.asarray(case.lower), np.asarray(case.upper)
    for t in tests:
        u = (np.array(t.x) - lo) / (hi - lo)
        assert np.all((u >= cov.DRAW_LOW) & (u <= cov.DRAW_HIGH))
        assert t.data_mesh == "paper"
    assert len({t.x for t in tests}) == 3 and len({t.seed for t in tests}) == 3
    assert s.models == ("linear-compression", "hyperbolic-compression", "exponent-compression")


@pytest.mark.parametrize(
    "argv, said",
    [
        (["--data-mesh", "coarse", "--inverse-mesh", "6,6,12"], "--data-mesh coarse: the same"),
        (["--data-mesh", "3,3,6", "--inverse-mesh", "4,4,8"], "is not finer than --inverse-mesh"),
        (["--data-mesh", "paper", "--check-mesh", "14,14,26"], "--check-mesh 14,14,26: the data"),
        (["--data-mesh", "nope"], "--data-mesh 'nope'"),
        (["--variant", "linear-nope"], "--variant 'linear-nope' is unknown"),
        (["--specimens", "100x100"], "WIDTHxDEPTHxHEIGHT"),
        (["--strains", "0.002,0.001"], "--strains"),
        (["--noise-scale", "-1"], "--noise-scale -1.0: a number >= 0"),
        (["--n", "2", "--experiments", "1-2"], "--experiments '1-2': I-J or I with 0 <= I <= J"),
        (["--experiments", "x"], "--experiments 'x': I-J or I"),
        (["--noise-scale", "nan"], "--noise-scale: 'nan' is not a finite number"),
    ],
)
def test_bad_input_is_one_line_exit_2(tmp_path, capsys, argv, said):
    assert main(["calibrate-coverage", *argv, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and said in err[0], err


def test_summary_of_one_model_does_not_claim_a_ranking():
    s = CoverageSettings(models=("linear-compression",), n=1)
    rec = {
        "index": 0, "ok": True, "specimen_mm": [100.0] * 3, "truth": [1.0] * 6,
        "error_percent": [1.0, -3.0, 0.5, 0.1, 2.5, -1.0], "covered": [True] * 5 + [False],
        "all_covered": False, "true_first_aic": True, "true_first_evidence": True,
        "ranking_aic": ["linear-compression"], "model_probability": 1.0, "rms_sigma": 1.1,
        "birge_ratio": 1.1, "wall_s": 3.0,
    }  # fmt: skip
    summary = cov.summarise(s, [rec])
    assert summary["parameters"]["beta"]["within_target"] == 0
    assert summary["parameters"]["E"]["within_target"] == 1 and summary["all_within_target"] == 0
    assert summary["parameters"]["H"]["covered"] == 0 and summary["all_covered"] == 0
    text = cov.render_summary(summary)
    assert "model selection not assessed" in text and "ranked first" not in text


def test_gaussian_efficient_reference_is_the_gaussian_share_within_the_target():
    """Noise sd 2 % of the truth (std 4 % of the estimate / 1.02 widened by a Birge ratio 2):
    P(|N(0, 2)| <= 2) = erf(1/sqrt 2) = 0.6827; sd 1 %: 0.9545; the Šidák bound multiplies
    them, the upper bound takes the least; 2 of 2 experiments with chance 0.6827^2."""
    s = CoverageSettings(models=("linear-compression",), n=2)
    base = {
        "ok": True, "specimen_mm": [100.0] * 3, "truth": [1.0] * 6, "covered": [True] * 6,
        "all_covered": True, "true_first_aic": True, "ranking_aic": ["linear-compression"],
        "model_probability": 1.0, "rms_sigma": 1.0, "wall_s": 1.0,
    }  # fmt: skip
    recs = [  # std_percent is % of the estimate, x = truth (1 + error/100)
        base | {"index": 0, "birge_ratio": 2.0, "error_percent": [2.0, 0.5, 0, 0, 0, 0],
                "std_percent": [4.0 / 1.02, 2.0 / 1.005, 1e-3, 1e-3, 1e-3, 1e-3]},
        base | {"index": 1, "birge_ratio": 1.0, "error_percent": [-6.0, 0.5, 0, 0, 0, 0],
                "std_percent": [2.0 / 0.94, 1.0 / 1.005, 1e-3, 1e-3, 1e-3, 1e-3]},
    ]  # fmt: skip
    summary = cov.summarise(s, recs)
    p1, p2 = 0.682689492, 0.954499736
    assert summary["parameters"]["E"]["within_target_noise_limit"] == pytest.approx(2 * p1)
    assert summary["parameters"]["beta"]["within_target_noise_limit"] == pytest.approx(2 * p2)
    lo, hi = summary["all_within_target_noise_limit"]
    assert lo == pytest.approx(2 * p1 * p2) and hi == pytest.approx(2 * p1)
    assert summary["all_within_target_noise_sd"] == pytest.approx((2 * p1 * (1 - p1)) ** 0.5)
    assert summary["all_within_target_noise_target_chance"] == pytest.approx(p1**2)
    # errors in sd units: E 1 and -3 -> rms sqrt(5); the largest per experiment 1 and 3
    assert summary["parameters"]["E"]["rms_error_over_sd"] == pytest.approx(5**0.5)
    assert [e["max_error_over_sd"] for e in summary["experiments"]] == pytest.approx([1.0, 3.0])
    text = cov.render_summary(summary)
    assert "1.3–1.4 expected, sd 0.7; at least 2 of 2 with chance 0.47" in text
    assert "| E | 4 | 6 | 1 of 2 (1.4) | 2.2 |" in text
    # a study of scaled noise (e.g. the noise-free twins) states no reference of the noise
    twins = cov.summarise(CoverageSettings(models=("linear-compression",), noise_scale=0), recs)
    assert "all_within_target_noise_limit" not in twins
    assert "Gaussian-efficient" not in cov.render_summary(twins)
    assert "noise-free twins" in cov.render_summary(twins)


def test_count_at_least_is_the_poisson_binomial_tail():
    assert cov.count_at_least([0.5, 0.5], 1) == pytest.approx(0.75)
    assert cov.count_at_least([0.5, 0.5], 2) == pytest.approx(0.25)
    assert cov.count_at_least([0.9, 0.2, 0.5], 2) == pytest.approx(0.9 * 0.2 + 0.9 * 0.5 * 0.8
                                                                   + 0.1 * 0.2 * 0.5)  # fmt: skip


def test_shipped_studies_keep_their_record_keys():
    """The options added since (plate margin, noise scale) and the spelling out of mesh presets
    leave the keys of the shipped studies made without them (read from their stored settings, a
    ``converged`` there as 12,12,24:g8:hex27): their records resume, not rerun."""
    root = Path(__file__).resolve().parents[1] / "results" / "calibration" / "coverage"
    checked = 0
    for name in (
        "hyperbolic-compression-hex27",
        "hyperbolic-compression-hex27-margin",
        "linear-compression",
    ):
        st = json.loads((root / name / "summary.json").read_text())["settings"]
        s = cov.settings_from_dict(st)
        rec = json.loads((root / name / "experiments" / "e000.json").read_text())
        assert s.key(0) == rec["key"]
        assert s.calibration_key(0) == rec.get("calibration_key", rec["key"])  # none: the same
        checked += 1
    assert checked == 3


def test_noise_free_twin_is_the_data_without_its_noise(tmp_path, monkeypatch):
    """``noise_scale`` 0: the same DIC points, sigma and log as the noisy experiment, the
    displacements less exactly the noise draws (in sigma units ~N(0, 1)), the forces without the
    load-cell error; the data and calibration keys change only when the scale is not 1."""
    from problems.inverse import virtual_experiment as ve

    class Resp:  # a stand-in data model: a smooth face field and forces, no FE run
        reaction_kN = np.array([100.0, 180.0])

        @staticmethod
        def front_face(pts):
            y, z = pts[:, 0], pts[:, 1]
            return np.array([1e-3 * y, 2e-3 * y]), np.array([-1e-3 * z, -2e-3 * z])

    monkeypatch.setattr(ve, "_data_response", lambda test, name: Resp())
    base = dict(variant="linear-compression", x=(1.0,) * 6, levels_mm=(0.1, 0.2), seed=3)
    ve.write_virtual_experiment(ve.VirtualTest(**base), tmp_path / "noisy", "n")
    ve.write_virtual_experiment(ve.VirtualTest(**base, noise_scale=0.0), tmp_path / "twin", "t")
    for k in (1, 2):
        a = np.loadtxt(tmp_path / f"noisy/dic/image_0{k}.csv", delimiter=",", skiprows=1)
        b = np.loadtxt(tmp_path / f"twin/dic/image_0{k}.csv", delimiter=",", skiprows=1)
        assert np.array_equal(a[:, [0, 1, 4]], b[:, [0, 1, 4]])  # points and sigma
        z = (a[:, 2:4] - b[:, 2:4]) / a[:, 4:5]
        assert 0.9 < z.std() < 1.1 and abs(z.mean()) < 0.1
    la = np.genfromtxt(tmp_path / "noisy/machine_log.csv", delimiter=",", names=True)
    lb = np.genfromtxt(tmp_path / "twin/machine_log.csv", delimiter=",", names=True)
    assert np.array_equal(la["displacement_mm"], lb["displacement_mm"])
    f_twin = lb["force_kN"][3::4]  # the images' rows: the data model's force, rounded
    assert f_twin == pytest.approx([100.0, 180.0], abs=0.005)
    assert not np.allclose(la["force_kN"][3::4], f_twin, atol=0.05)
    s1 = CoverageSettings(variant="linear-compression", n=1)
    s0 = CoverageSettings(variant="linear-compression", n=1, noise_scale=0.0)
    assert s1.data_key(0) == CoverageSettings(variant="linear-compression", n=3).data_key(0)
    assert s0.data_key(0) != s1.data_key(0) and s0.key(0) != s1.key(0)
    assert draw_test(s0, 0).noise_scale == 0.0 and draw_test(s0, 0).x == draw_test(s1, 0).x


def test_noise_free_twin_of_the_images_route_has_no_camera_noise(tmp_path, monkeypatch):
    """``noise_scale`` 0 on the images route: the camera's noise is scaled too (the images are the
    rendered intensities, quantised), while 1 adds its ``noise_grey`` (2 grey levels)."""
    from problems.dic.imageio import read_image
    from problems.inverse import virtual_experiment as ve

    class Resp:
        reaction_kN = np.array([100.0, 180.0])

    flat = np.full((40, 60), 0.5)  # a stand-in for the rendered speckle: no FE run, no render
    monkeypatch.setattr(ve, "_data_response", lambda test, name: Resp())
    monkeypatch.setattr(
        ve, "render_virtual_images", lambda t, im, r: (ve._camera(t, im), [flat] * 3)
    )
    base = dict(variant="linear-compression", x=(1.0,) * 6, levels_mm=(0.1, 0.2), seed=3)
    grey = {}
    for scale in (1.0, 0.0):
        test = ve.VirtualTest(**base, noise_scale=scale)
        ve.write_virtual_images(test, tmp_path / f"s{scale:g}", "n", ve.VirtualImages())
        grey[scale] = read_image(tmp_path / f"s{scale:g}" / "images" / "image_02.png")
    assert np.ptp(grey[0.0]) == 0  # 0.5 of 255, rounded: one grey level everywhere
    assert 1.6 < np.std(grey[1.0]) < 2.4  # the camera's 2 grey levels


def test_presets_are_stored_and_keyed_as_discretisations(tmp_path):
    """``converged`` in a mesh option is stored and hashed as its spec today; plain meshes keep
    the keys they had (pinned from the code before the change); a stored block saying
    ``converged`` (made before stop 38) reads as 12,12,24:g8:hex27, with its records' keys, and is
    not resumed by a study on today's ``converged``."""
    from problems.fe.presets import SPEC_PRESETS

    new = CoverageSettings("hyperbolic-compression", 10, "converged", "6,6,12:g8:hex27",
                           correction="one-point", check_mesh="auto")  # fmt: skip
    assert new.data_mesh == SPEC_PRESETS["converged"] == "15,15,30:g16:hex27"
    assert new.to_dict()["data_mesh"] == "15,15,30:g16:hex27"
    spelled = dataclasses.replace(new, data_mesh="15,15,30:g16:hex27")
    assert new.key(0) == spelled.key(0) and new.data_key(0) == spelled.data_key(0)
    assert spell_out("converged:quarter") == "15,15,30:g16:hex27:quarter"
    assert draw_test(new, 0).data_mesh == "15,15,30:g16:hex27"
    # plain meshes: the keys of before (the shipped linear-compression study's e000 key)
    plain = CoverageSettings("linear-compression", 10, "fine", "coarse", check_mesh="paper")
    assert (plain.data_key(0), plain.key(0)) == ("58d338c6c79c5688", "4ae61433429369fd")
    hex27 = CoverageSettings("hyperbolic-compression", 10, "paper", "6,6,12:g8:hex27",
                             correction="one-point", check_mesh="auto")  # fmt: skip
    assert (hex27.data_key(3), hex27.calibration_key(3), hex27.key(3)) == (
        "e19e1cdfb1c0f21b", "d341f07f12e4dc0f", "33e8c471b066acfc")  # fmt: skip
    # a legacy block: converged as it was, the keys of its records; today's converged differs
    old = cov.settings_from_dict(new.to_dict() | {"data_mesh": "converged"})
    assert old.data_mesh == "12,12,24:g8:hex27"
    assert (old.data_key(0), old.calibration_key(0), old.key(0)) == (
        "c9ba18ba0573f2bd", "a91ba9f5859f5370", "a6b528696fedd87b")  # fmt: skip
    assert new.data_key(0) != old.data_key(0) and new.key(0) != old.key(0)
    assert "`converged` (= `12,12,24:g8:hex27` until stop 38)" in cov.render_summary(
        cov.summarise(old, []) | {"settings": old.to_dict() | {"data_mesh": "converged"}}
    )
    # ... and its out is not resumed with today's converged: refused before any run, untouched
    out = tmp_path / "legacy"
    out.mkdir()
    stored = json.dumps({"settings": old.to_dict() | {"data_mesh": "converged"}})
    (out / "summary.json").write_text(stored)
    with pytest.raises(ValueError) as err:
        run_coverage(new, out, progress=pytest.fail)
    assert str(err.value) == (
        f"--data-mesh 15,15,30:g16:hex27 (converged today): --out {out} holds a study made with "
        "converged (= 12,12,24:g8:hex27 until stop 38), another discretisation; allowed: "
        "--data-mesh 12,12,24:g8:hex27 (resumes it) or another --out")  # fmt: skip
    assert (out / "summary.json").read_text() == stored and sorted(out.iterdir()) == [
        out / "summary.json"]  # fmt: skip
    argv = ["--variant", "hyperbolic-compression", "--inverse-mesh", "6,6,12:g8:hex27",
            "--correction", "one-point", "--check-mesh", "auto", "--out", str(out)]  # fmt: skip
    assert main(["calibrate-coverage", "--data-mesh", "converged", *argv]) == 2
    assert (out / "summary.json").read_text() == stored
    cov.check_same_meshes(old, out)  # the legacy mesh spelled out resumes it
    cov.check_same_meshes(dataclasses.replace(old, data_mesh="converged"), tmp_path / "none")

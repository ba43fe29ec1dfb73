"""The mesh convergence study: observed order, Richardson extrapolation, linearised bias
(problems/analysis/convergence.py) and the resumable study and its command
(bench/studies/convergence.py, bench/commands/convergence.py) on tiny meshes."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from bench.cli import main
from bench.studies.convergence import (
    family_specs,
    read_record,
    record_path,
    render_convergence,
    run_convergence,
)
from problems.analysis import convergence as conv

CASE = "linear-compression"
FAMILY = {"hex8 g4": ["2,2,4:g4", "3,3,6:g4", "4,4,8:g4"]}


def test_observed_order_and_richardson_recover_a_power_law_on_unequal_ratios():
    h = np.array([25.0, 15.0, 10.7])
    q_inf, C = np.array([3.0, -1.0, 2.0]), np.array([0.5, 0.2, -0.3])
    for p in (0.7, 1.0, 2.0):
        q = q_inf + C * h[:, None] ** p
        assert conv.observed_order(h, q) == pytest.approx(p, abs=1e-8)
        assert conv.observed_order(h, q[:, 0]) == pytest.approx(p, abs=1e-8)
        np.testing.assert_allclose(conv.richardson(h[1], h[2], q[1], q[2], p), q_inf, atol=1e-10)
    assert math.isnan(conv.observed_order(h, [1.0, 2.0, 1.5]))  # oscillating: no order
    with pytest.raises(ValueError, match="must decrease"):
        conv.observed_order(h[::-1], [1.0, 2.0, 3.0])


def test_extrapolate_uses_separate_orders_for_the_field_and_the_force():
    N, m = 2, 3
    h = np.array([20.0, 12.0, 8.0, 6.0])
    exact = np.arange(1.0, 2 * N * m + N + 1)
    shape = np.linspace(0.1, 1.0, len(exact))
    v = exact[None] + shape[None] * np.where(
        np.arange(len(exact)) < 2 * N * m, h[:, None], h[:, None] ** 2
    )
    out = conv.extrapolate(h, v, N, m)
    assert out["order_field"] == pytest.approx(1.0, abs=1e-8)
    assert out["order_force"] == pytest.approx(2.0, abs=1e-8)
    assert len(out["orders_field_all"]) == 2
    np.testing.assert_allclose(out["values"], exact, atol=1e-9)
    err = conv.errors(v[-1], exact, N, m)
    assert out["finest_error_sigma"] == pytest.approx(err["rms_sigma"])
    assert err["force_last_pct"] == pytest.approx(100 * shape[-1] * 36.0 / exact[-1])


def test_a_family_is_asymptotic_when_its_last_two_orders_agree():
    assert conv.asymptotic([1.68, 1.68], [1.69, 1.44])
    assert not conv.asymptotic([0.70, 2.86], [1.44, 1.36])  # the field order jumps
    assert not conv.asymptotic([1.5], [1.5])  # one triple: unknown
    assert not conv.asymptotic([1.5, math.nan], [1.5, 1.5])


def test_the_reference_is_the_best_asymptotic_family():
    from bench.studies.convergence import analyse

    N, m = 1, 1
    exact = np.array([1.0, 2.0, 100.0])
    J = np.eye(3)[:, :2]

    def rec(spec, h, p, c):
        return {
            "mesh": spec,
            "ok": True,
            "h_mm": h,
            "values": (exact + c * h**p).tolist(),
            "n_snapshots": N,
            "n_points": m,
            "names": ["a", "b"],
            "reference": [1.0, 1.0],
            "jacobian": J.tolist(),
            "element": "hex8",
            "grading": 1.0,
            "elements": 1,
            "dofs": 1,
            "message": "",
            "cpu_s": 0.0,
            "wall_s": 0.0,
        }

    hs = [8.0, 6.0, 4.0, 3.0]
    records = {f"a{h}": rec(f"a{h}", h, 1.0, 0.01) for h in hs}  # clean order 1
    # a family whose finest is nearer but whose orders disagree (pre-asymptotic)
    jumpy = dict(zip(hs, [0.9, 0.1, 0.05, 0.001]))
    for h in hs:
        records[f"b{h}"] = rec(f"b{h}", h, 1.0, 0.0)
        records[f"b{h}"]["values"] = (exact + jumpy[h]).tolist()
    families = {"clean": [f"a{h}" for h in hs], "jumpy": [f"b{h}" for h in hs]}
    summary, ref = analyse("x", families, [], records)
    assert summary["families"]["clean"]["asymptotic"]
    assert not summary["families"]["jumpy"]["asymptotic"]
    assert summary["reference_family"] == "clean"
    np.testing.assert_allclose(ref, exact, atol=1e-9)


def test_linearised_bias_is_the_gauss_newton_step_of_a_linear_model():
    rng = np.random.default_rng(1)
    J = rng.normal(size=(40, 3))
    x_ref, x_true = np.array([3e4, 35.0, 0.85]), np.array([3.1e4, 33.0, 0.9])
    sd = np.where(np.arange(40) < 30, conv.SIGMA_DISPLACEMENT_MM, conv.SIGMA_FORCE_KN)
    data = J @ x_true
    dz = conv.linearised_bias(J, J @ x_ref - data, sd, x_ref)
    np.testing.assert_allclose(dz, (x_true - x_ref) / x_ref, rtol=1e-9)


def test_family_specs():
    assert family_specs((6, 10), 4.0, "hex8") == ["6,6,12:g4", "10,10,20:g4"]
    assert family_specs((6, 10), 1.0, "hex27") == ["3,3,6:hex27", "5,5,10:hex27"]
    with pytest.raises(ValueError, match="odd"):
        family_specs((5,), 4.0, "hex27")


def test_study_on_tiny_meshes_resumes_and_recomputes_a_torn_record(tmp_path):
    seen = []
    folder = run_convergence(
        CASE, FAMILY, ["3,3,6"], tmp_path, lambda r, reused: seen.append(reused)
    )
    assert seen == [False] * 4
    summary = json.loads((folder / "convergence.json").read_text())
    fam = summary["families"]["hex8 g4"]
    assert summary["reference_family"] == "hex8 g4" and 0.3 < fam["order_force"] < 4
    rows = {r["mesh"]: r for r in summary["meshes"]}
    assert set(rows) == {"2,2,4:g4", "3,3,6:g4", "4,4,8:g4", "3,3,6"}
    # refining reduces the error against the extrapolation; grading beats uniform at equal size
    assert (
        rows["4,4,8:g4"]["rms_sigma"]
        < rows["3,3,6:g4"]["rms_sigma"]
        < rows["2,2,4:g4"]["rms_sigma"]
    )
    for key in ("rms_sigma", "force_last_pct"):
        assert 0 < rows["3,3,6:g4"][key] < rows["3,3,6"][key]
    assert set(rows["4,4,8:g4"]["bias_pct"]) == {"E", "beta", "K", "psi", "sigma0", "H"}
    assert all(r["cpu_s"] >= 0 and r["wall_s"] > 0 for r in rows.values())
    assert "| 4,4,8:g4 | 128 |" in (folder / "convergence.md").read_text()
    assert render_convergence(folder).stat().st_size > 1000
    # a torn record is recomputed, the others reused
    torn = record_path(folder, "3,3,6:g4")
    torn.write_text(torn.read_text()[:-200])
    assert read_record(torn, CASE, "3,3,6:g4") is None
    seen.clear()
    run_convergence(CASE, FAMILY, ["3,3,6"], tmp_path, lambda r, reused: seen.append(reused))
    assert seen == [True, False, True, True]
    again = json.loads((folder / "convergence.json").read_text())
    assert again["meshes"][2]["rms_sigma"] == pytest.approx(rows["4,4,8:g4"]["rms_sigma"])


@pytest.mark.parametrize(
    "argv, words",
    [
        (["--sizes", "6,4,8"], "--sizes: '6,4,8' is out of range"),
        (["--sizes", "6,10"], "at least three increasing"),
        (["--grading", "0.5"], "--grading: '0.5' is out of range"),
        (["--elements", "hex20"], "'hex20' is unknown; allowed: hex8, hex27"),
        (["--elements", "hex27", "--sizes", "5,7,9"], "--sizes 5,7,9: hex27 families need even"),
        (["--compare", "6,6"], "--compare: mesh '6,6' is unknown"),
        (["--compare", "coarse", "6,6,12:g16:gz8", "6,6,12:g16:gz8:eighth"], "give each mesh once"),
        (["--sizes", "6,10,14", "--compare", "10,10,20:g4"], "the same discretisation as 10,10,20"),
        (["--no-compare", "--plain", "14,14,28"], "--plain 14,14,28: not a mesh of this study"),
    ],
)
def test_bad_options_are_one_line_errors(argv, words, capsys, tmp_path):
    code = main(["convergence", CASE, "--out", str(tmp_path), *argv])
    err = capsys.readouterr().err
    assert code == 2 and words in err and len(err.strip().splitlines()) == 1, err


def test_unknown_and_analytic_cases_are_refused(capsys, tmp_path):
    assert main(["convergence", "nope", "--out", str(tmp_path)]) == 2
    assert "nope" in capsys.readouterr().err
    assert main(["convergence", "analytic-linear", "--out", str(tmp_path)]) == 2
    assert "needs an FE case" in capsys.readouterr().err

"""The discretisation band of the model ranking (bench/calibration.py ``ranking_band``): the GCI
rule on a ranking checkable by hand, its warning and report lines, no band without a
correction; the coverage scores with it; the untreated fit of a variant file written before
it was kept, computed once (``backfill_untreated``)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bench.calibration import (
    CalibrationSettings,
    _ranking_band_lines,
    backfill_untreated,
    ranking_band,
)
from bench.calibration_coverage import CoverageSettings, render_summary, score, summarise
from problems.analysis.convergence import GCI_ORDERS, GCI_SAFETY

K = GCI_SAFETY / (1.5 ** GCI_ORDERS["hex27 g8"] - 1)  # 5.16: 6,6,12:g8 -> 9,9,18:g8
ONE_POINT = CalibrationSettings("6,6,12:g8:hex27", 10, check_mesh="auto", correction="one-point")
NAMES = ("exponent-compression", "hyperbolic-compression", "linear-compression")


def _ranked(aic, aic_untreated, fine="9,9,18:g8:hex27"):
    """Results and ranking rows of three variants with these (corrected, untreated) AICs."""
    results = {
        n: {"ok": True, "aic": a, "fine_mesh": fine} | ({} if u is None else {"aic_untreated": u})
        for n, a, u in zip(NAMES, aic, aic_untreated)
    }
    ranking = [
        {"variant": n, "aic": a, "delta_aic": a - min(aic)}
        for n, a in sorted(zip(NAMES, aic), key=lambda t: t[1])
    ]
    return ranking, results


def test_ranking_band_by_the_gci_rule_and_its_warning():
    # dAIC 3.2 and 50 behind the first; untreated 13.2 and 45: |3.2 - 13.2| = 10 -> U = 51.6
    # (not resolved), |50 - 45| = 5 -> U = 25.8 < 50 (resolved)
    ranking, results = _ranked((100.0, 103.2, 150.0), (120.0, 133.2, 165.0))
    band = ranking_band(ranking, results, ONE_POINT)
    first, second, third = ranking
    assert first["resolved"] is None and first["band_delta_aic"] is None
    assert second["delta_aic_untreated"] == pytest.approx(13.2)
    assert second["band_delta_aic"] == pytest.approx(10.0 * K) == pytest.approx(51.6, abs=0.05)
    assert second["resolved"] is False
    assert third["band_delta_aic"] == pytest.approx(5.0 * K) and third["resolved"] is True
    assert band["method"] == "gci" and band["order"] == 1.13 and band["safety"] == 3.0
    assert band["ratio"] == pytest.approx(1.5) and band["fine_mesh"] == "9,9,18:g8:hex27"
    assert band["probabilities_conditional"] is True
    assert band["warning"] == (
        "exponent-compression vs hyperbolic-compression: dAIC 3.2 within the discretisation "
        "band 51.6: not resolved by this inverse model; refine the inverse mesh or use "
        "--correction iterated"
    )
    text = "\n".join(_ranking_band_lines({"ranking": ranking, "ranking_band": band}))
    assert "| hyperbolic-compression | 3.2 | 13.2 | 51.6 | NO |" in text
    assert "| linear-compression | 50 | 45 | 25.8 | yes |" in text
    assert "conditional on the inverse model" in text and "Warning: exponent" in text
    # the untreated ranking agreeing closely: resolved, no warning, probabilities as they are
    ranking, results = _ranked((100.0, 103.2, 150.0), (120.0, 123.4, 171.0))
    band = ranking_band(ranking, results, ONE_POINT)
    assert ranking[1]["band_delta_aic"] == pytest.approx(0.2 * K) and ranking[1]["resolved"]
    assert band["warning"] is None and not band["probabilities_conditional"]
    text = "\n".join(_ranking_band_lines({"ranking": ranking, "ranking_band": band}))
    assert "Warning" not in text and "| yes |" in text and "| NO |" not in text
    # already iterated: the advice is the mesh alone
    ranking, results = _ranked((100.0, 103.2, 150.0), (120.0, 133.2, 165.0))
    it = CalibrationSettings("6,6,12:g8:hex27", 10, check_mesh="auto", correction="iterated")
    assert ranking_band(ranking, results, it)["warning"].endswith("refine the inverse mesh")


@pytest.mark.parametrize(
    "fine, untreated, settings, reason",
    [
        ("", (None,) * 3, CalibrationSettings("coarse", 10), "no correction ran: one estimate"),
        ("9,9,18:g8:hex27", (1.0, 2.0, 3.0), CalibrationSettings(
            "6,6,12:g8:hex27", 10, correction="one-point", error_band="none"), "turned off"),
        ("9,9,18:g8:hex27", (1.0, float("inf"), 3.0), ONE_POINT,
         "no finite untreated fit of hyperbolic-compression"),
    ],
)  # fmt: skip
def test_no_ranking_band_without_two_estimates(fine, untreated, settings, reason):
    ranking, results = _ranked((100.0, 103.2, 150.0), untreated, fine=fine)
    band = ranking_band(ranking, results, settings)
    assert band["method"] == "none" and reason in band["reason"]
    assert all(r["resolved"] is None and r["band_delta_aic"] is None for r in ranking)
    assert not band["probabilities_conditional"]
    text = "\n".join(_ranking_band_lines({"ranking": ranking, "ranking_band": band}))
    assert f"No discretisation band of the ranking: {band['reason']}" in text


def _report(delta_hyp, band_hyp, first="hyperbolic-compression"):
    """A report whose true variant (hyperbolic-compression) is ``first`` or second at
    ``delta_hyp`` behind the first, with the ranking band ``band_hyp`` there (None: no band)."""
    other = "exponent-compression"
    rows = [{"variant": first, "delta_aic": 0.0, "resolved": None, "band_delta_aic": None}]
    second = other if first != other else "hyperbolic-compression"
    rows.append(
        {
            "variant": second,
            "delta_aic": delta_hyp if first == other else 30.0,
            "band_delta_aic": band_hyp,
            "resolved": None if band_hyp is None else bool(
                (delta_hyp if first == other else 30.0) > band_hyp),
        }
    )  # fmt: skip
    for i, r in enumerate(rows):
        r |= {"log_evidence": -float(i), "model_probability": 1.0 - i}
    v = {
        "ok": True, "names": ["E"], "x": [101.0], "ci95_lower": [99.0], "ci95_upper": [103.0],
        "std_percent": [1.0], "birge_ratio": 1.0, "rms_sigma": 1.0, "n_evals": 10,
    }  # fmt: skip
    return {
        "variants": {"hyperbolic-compression": v, other: v},
        "ranking": rows,
        "ranking_band": {"method": "none" if band_hyp is None else "gci"},
    }


def test_coverage_counts_first_or_not_resolved(monkeypatch):
    truth = [100.0]
    cases = {
        "first": _report(None, 50.0),  # first: both counts
        "within": _report(3.2, 41.9, first="exponent-compression"),  # second, not resolved
        "outside": _report(28.2, 20.0, first="exponent-compression"),  # second, resolved
        "no band": _report(3.2, None, first="exponent-compression"),  # no correction
    }
    scored = {k: score(truth, "hyperbolic-compression", r) for k, r in cases.items()}
    assert [scored[k]["true_first_aic"] for k in cases] == [True, False, False, False]
    assert [scored[k]["true_first_or_unresolved_aic"] for k in cases] == [
        True, True, False, False]  # fmt: skip
    assert scored["within"]["true_delta_aic"] == 3.2
    assert scored["within"]["true_band_delta_aic"] == 41.9
    assert "ranking_band" not in scored["no band"]
    # the summary: both counts, the band's share; one variant, names E
    monkeypatch.setattr(
        "problems.inverse.cases.get_case", lambda name: type("C", (), {"names": ("E",)})
    )
    s = CoverageSettings.__new__(CoverageSettings)
    object.__setattr__(s, "to_dict", lambda: {
        "variant": "hyperbolic-compression", "data_mesh": "converged",
        "inverse_mesh": "6,6,12:g8:hex27", "correction": "one-point", "check_mesh": "",
        "budget": 40, "models": list(NAMES), "specimens": [[100.0] * 3], "seed": 0})  # fmt: skip
    object.__setattr__(s, "variant", "hyperbolic-compression")
    recs = [
        scored[k] | {"index": i, "specimen_mm": [100.0] * 3, "truth": truth, "wall_s": 1.0}
        for i, k in enumerate(("first", "within", "outside"))
    ]
    summary = summarise(s, recs)
    assert summary["true_first_aic"] == 1 and summary["true_first_or_unresolved_aic"] == 2
    assert summary["n_ranking_band"] == 3
    text = render_summary(summary)
    assert "- true variant ranked first: 1 of 3 by AIC" in text
    assert "not resolved from the first at this discretisation" in text
    assert ": 2 of 3 by AIC" in text
    assert "| 3.2 (41.9, not resolved) |" in text and "| 28.2 (20) |" in text
    # an old record without the field (no band: no correction) counts as first or not
    old = {k: v for k, v in recs[0].items() if k != "true_first_or_unresolved_aic"}
    assert summarise(s, [old])["true_first_or_unresolved_aic"] == 1


class _Stub:
    """An evaluator on the raw data: chi2 = sum(x^2) (scaled = physical), counted."""

    def __init__(self):
        self.n = 0

    def to_scaled(self, x):
        return np.asarray(x, float)

    def evaluate(self, z):
        self.n += 1
        return type("E", (), {"cost": float(np.sum(z**2)), "usable": True})


def test_old_variant_file_gets_its_untreated_chi2_once(tmp_path):
    path = tmp_path / "variants" / "hyperbolic-compression.json"
    path.parent.mkdir()
    old = {"key": "k1", "ok": True, "x": [1.0, 2.0], "x_untreated": [3.0, 4.0], "chi2": 20.0}
    path.write_text(json.dumps(old))
    stub = _Stub()
    new = backfill_untreated(path, json.loads(path.read_text()), lambda: stub)
    assert stub.n == 1 and new["chi2_untreated"] == 25.0 and new["aic_untreated"] == 29.0
    stored = json.loads(path.read_text())
    assert stored == old | {"chi2_untreated": 25.0, "aic_untreated": 29.0}  # key kept
    assert not list(path.parent.glob("*.tmp*"))  # atomic: no temporary left

    def no_run():
        raise AssertionError("evaluated again")

    assert backfill_untreated(path, stored, no_run) == stored  # done once
    # no correction ran (no untreated optimum), or a failed variant: nothing to compute
    plain = {"ok": True, "x": [1.0], "x_untreated": None}
    assert backfill_untreated(tmp_path / "none.json", plain, no_run) == plain
    failed = {"ok": False, "x_untreated": [1.0]}
    assert backfill_untreated(tmp_path / "none.json", failed, no_run) == failed
    assert not (tmp_path / "none.json").exists()

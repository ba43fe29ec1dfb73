"""The posterior study on a surrogate: derived exponent coefficient, the summary.json format the
report reads, the rendering from files alone (a quick, unconverged chain on a cheap surrogate)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bench.studies.posterior import exponent_a, exponent_a_gradient, render_posterior, run_posterior
from problems.inverse.cases import get_case
from problems.surrogate import save
from tests.test_surrogate_identify import fake_surrogate

KEYS = {"case", "tier", "n_samples", "tau", "tau_multiple", "mean", "sd", "q025", "q975"}
KEYS |= {"laplace_sd", "names"}


def test_exponent_a_matches_the_case_derivation_and_its_gradient():
    case = get_case("exponent-shear")
    rng = np.random.default_rng(0)
    X = case.lower + rng.random((3, 6)) * (case.upper - case.lower)
    a = exponent_a(case, X)
    for x, ai in zip(X, a):
        assert ai == pytest.approx(case.material_parameters(x)["a"], rel=1e-12)
    g = exponent_a_gradient(case, X[0])
    h = 1e-6 * np.abs(X[0])
    fd = [(exponent_a(case, (X[0] + h[i] * np.eye(6)[i])[None])[0] - a[0]) / h[i] for i in range(6)]
    np.testing.assert_allclose(g, fd, rtol=1e-4, atol=1e-12)
    assert exponent_a(get_case("linear-shear"), X) is None


def test_posterior_study_writes_the_summary_the_report_reads(tmp_path):
    folder = tmp_path / "sur"
    save(fake_surrogate(), folder)
    res = run_posterior(
        "linear-compression",
        surrogate=str(folder),
        n_walkers=16,
        chunk=100,
        max_steps=200,
        fe_budget=1,
        out=tmp_path / "post",
    )
    doc = json.loads((tmp_path / "post" / "summary.json").read_text())
    assert KEYS <= set(doc)
    assert doc["case"] == "linear-compression" and doc["tier"] == "consistent"
    assert doc["names"] == list(get_case("linear-compression").names)
    assert doc["n_samples"] == 16 * (200 - 60)
    for n in doc["names"]:
        assert doc["q025"][n] <= doc["mean"][n] <= doc["q975"][n]
        assert doc["sd"][n] > 0 and doc["laplace_sd"][n] > 0 and doc["tau"][n] > 0
    assert doc["tau_multiple"] == pytest.approx(140 / max(doc["tau"].values()))
    assert res.summary["converged"] == (doc["tau_multiple"] >= 50)
    paths = render_posterior(tmp_path / "post")
    assert all(p.stat().st_size > 1000 for p in paths)

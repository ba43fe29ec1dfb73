"""Posterior panel inputs: the posterior study's summary.json (read leniently) and MCMC records
(a derived from the chain), widths table and figure."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from bench.report import posterior as P
from bench.report.figures import posterior_figure
from problems.inverse.cases import get_case

EXP = "exponent-shear"


def write_summary(folder, case, *, as_lists: bool):
    c = get_case(case)
    names = list(c.names)
    ref = dict(zip(names, c.reference))
    mean = {n: ref[n] * 1.01 for n in names}
    sd = {n: ref[n] * 0.02 for n in names}
    q025 = {n: ref[n] * 0.95 for n in names}
    q975 = {n: ref[n] * 1.07 for n in names}
    lsd = {n: ref[n] * 0.025 for n in names}

    def conv(d):
        return [d[n] for n in names] if as_lists else d

    s = {
        "case": case,
        "tier": "consistent",
        "names": names,
        "n_samples": 4000,
        "tau": conv({n: 20.0 for n in names}),
        "tau_multiple": 60.0,
        "mean": conv(mean),
        "sd": conv(sd),
        "q025": conv(q025),
        "q975": conv(q975),
        "laplace_sd": conv(lsd),
        "unexpected": {"whatever": 1},
    }
    d = folder / case
    d.mkdir(parents=True)
    (d / "summary.json").write_text(json.dumps(s))


@pytest.mark.parametrize("as_lists", [True, False])
def test_summary_rows_normalised_widths(tmp_path, as_lists):
    write_summary(tmp_path, "linear-compression", as_lists=as_lists)
    post = P.posterior_frame(folders=[tmp_path])
    e = post.set_index("parameter").loc["E"]
    assert e["source"] == "posterior study" and e["tier"] == "consistent"
    assert e["mean_n"] == pytest.approx(1.01)
    assert (e["q025_n"], e["q975_n"]) == (pytest.approx(0.95), pytest.approx(1.07))
    assert e["width95_pct"] == pytest.approx(12.0)
    assert e["laplace_width_pct"] == pytest.approx(10.0)  # 4 sd = 4 x 2.5 %
    assert e["laplace_lo_n"] == pytest.approx(1.01 - 0.05)
    assert e["tau_multiple"] == pytest.approx(60.0)
    w = P.width_table(post)
    assert w.loc[0, "E"] == "12 (10)" and w.loc[0, "paper: err a (%)"] == "–"


def test_broken_summary_is_skipped(tmp_path):
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "summary.json").write_text("{not json")
    (tmp_path / "y").mkdir()
    (tmp_path / "y" / "summary.json").write_text("[1, 2]")
    assert P.posterior_frame(folders=[tmp_path, tmp_path / "missing"]).empty


def mcmc_record(case, seed, n_steps, *, rng):
    c = get_case(case)
    ref = np.asarray(c.reference, float)
    n_w = 8
    chain = ref * (1 + 0.01 * rng.standard_normal((n_steps, n_w, len(ref))))
    burn = n_steps // 4
    flat = chain[burn:].reshape(-1, len(ref))
    names = list(c.names)
    return {
        "config_hash": f"h{seed}",
        "config": {"case": case, "method": "mcmc", "seed": seed, "tier": "consistent"},
        "result": {
            "parameter_names": names,
            "extra": {
                "n_steps": n_steps,
                "burn": burn,
                "n_walkers": n_w,
                "mean": dict(zip(names, flat.mean(0))),
                "std": dict(zip(names, flat.std(0, ddof=1))),
                "q2.5": dict(zip(names, np.percentile(flat, 2.5, 0))),
                "q97.5": dict(zip(names, np.percentile(flat, 97.5, 0))),
                "autocorr_time": dict(zip(names, [5.0] * len(names))),
                "chain": chain.tolist(),
            },
        },
    }, flat


def test_mcmc_records_longest_chain_and_a_from_the_chain():
    rng = np.random.default_rng(3)
    short, _ = mcmc_record(EXP, 0, 40, rng=rng)
    long, flat = mcmc_record(EXP, 1, 120, rng=rng)
    lm = {"config": {"case": EXP, "method": "lm"}, "result": {}}
    post = P.posterior_frame(records=[short, long, lm])
    assert set(post["source"]) == {"mcmc run (fe, seed 1, 1 of 2)"}
    c = get_case(EXP)
    a = np.array([c.material_parameters(x)["a"] for x in flat])
    ra = post.set_index("parameter").loc["a"]
    assert ra["mean"] == pytest.approx(a.mean())
    assert ra["q975"] == pytest.approx(np.percentile(a, 97.5))
    a_ref = c.material_parameters(c.reference)["a"]
    assert ra["width95_pct"] == pytest.approx(
        100 * (np.percentile(a, 97.5) - np.percentile(a, 2.5)) / a_ref
    )
    assert math.isnan(ra["laplace_width_pct"])
    assert post.set_index("parameter").loc["E", "tau_multiple"] == pytest.approx((120 - 30) / 5.0)
    w = P.width_table(post)
    assert w.loc[0, "paper: err a (%)"] == "11–46"


def test_posterior_figure_is_written(tmp_path):
    write_summary(tmp_path / "post", EXP, as_lists=False)
    rng = np.random.default_rng(0)
    rec, _ = mcmc_record(EXP, 0, 60, rng=rng)
    post = P.posterior_frame(records=[rec], folders=[tmp_path / "post"])
    assert set(post["source"]) == {"posterior study", "mcmc run (fe, seed 0, 1 of 1)"}
    p = posterior_figure(EXP, post, tmp_path / "fig")
    assert p.is_file() and p.stat().st_size > 5000


def test_summary_laplace_at_the_fe_optimum_and_a_beyond_names(tmp_path):
    c = get_case(EXP)
    names = list(c.names)
    ref = dict(zip(names, c.reference))
    a_ref = c.material_parameters(c.reference)["a"]
    s = {
        "case": EXP,
        "tier": "model-error",
        "names": names,
        "mean": {**{n: ref[n] for n in names}, "a": 1.1 * a_ref},
        "q025": {**{n: 0.9 * ref[n] for n in names}, "a": 0.8 * a_ref},
        "q975": {**{n: 1.1 * ref[n] for n in names}, "a": 1.4 * a_ref},
        "laplace_sd": {**{n: 0.01 * ref[n] for n in names}, "a": 0.1 * a_ref},
        "fe_optimum": {**{n: 1.02 * ref[n] for n in names}, "a": 1.2 * a_ref},
        "surrogate": {"name": "default"},
    }
    (tmp_path / EXP).mkdir()
    (tmp_path / EXP / "summary.json").write_text(json.dumps(s))
    post = P.posterior_frame(folders=[tmp_path]).set_index("parameter")
    assert post.loc["E", "laplace_lo_n"] == pytest.approx(1.0)  # 1.02 - 2 x 0.01
    assert post.loc["a", "width95_pct"] == pytest.approx(60.0)
    assert post.loc["a", "laplace_hi_n"] == pytest.approx(1.4)  # 1.2 + 2 x 0.1
    assert post.loc["a", "source"] == "posterior study (surrogate)"


def test_a_from_a_chain_kept_in_an_npz_file(tmp_path):
    rng = np.random.default_rng(5)
    rec, flat = mcmc_record(EXP, 0, 50, rng=rng)
    extra = rec["result"]["extra"]
    chain = np.asarray(extra.pop("chain"))
    c = get_case(EXP)
    scale = np.asarray(c.reference, float)
    np.savez(tmp_path / "chain.npz", chain=chain / scale, scale=scale, names=np.array(c.names))
    extra["chain_path"] = str(tmp_path / "chain.npz")
    post = P.posterior_frame(records=[rec]).set_index("parameter")
    a = np.array([c.material_parameters(x)["a"] for x in flat])
    assert post.loc["a", "q025"] == pytest.approx(np.percentile(a, 2.5))

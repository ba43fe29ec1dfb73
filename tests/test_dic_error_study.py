"""The DIC error-correlation study (bench/perf/dic_errors.py): its statistics recover a known
correlation structure from synthetic realisations."""

from __future__ import annotations

import numpy as np

from bench.perf.dic_errors import analyse, markdown


def test_analyse_recovers_the_shared_reference_term_and_overlap():
    # 8 x 8 points on a 7 px grid, 3 snapshots, 400 realisations; each point's error is a term
    # shared by every snapshot (the reference image's) plus one per snapshot, of equal variance
    # (rho = 1/2); the points are independent
    rng = np.random.default_rng(0)
    K, N, side, step, s = 400, 3, 8, 7, 0.01
    X, Y = np.meshgrid(np.arange(side) * step + 20.0, np.arange(side) * step + 20.0)
    pts = np.column_stack([X.ravel(), Y.ravel()])
    n = len(pts)
    recs = []
    for _ in range(K):
        ref = rng.standard_normal((n, 2))
        E = np.sqrt(0.5) * (ref[None] + rng.standard_normal((N, n, 2)))
        recs.append(
            {
                "u": s * E[..., 0],
                "v": s * E[..., 1],
                "std_u": np.full((N, n), s),
                "std_v": np.full((N, n), 0.8 * s),
                "converged": np.ones((N, n), bool),
                "noise": np.full(N, 2.0),
            }
        )
    t = {
        "step": np.array(step),
        "points": pts,
        "noise_grey": np.array(2.0),
        "u": np.zeros((N, n)),
        "v": np.zeros((N, n)),
        "converged": np.ones((N, n), bool),
    }
    res = analyse(t, recs, subset=21)
    a = res["rho_between_snapshots"]
    assert abs(a["both"]["mean"] - 0.5) < 0.02
    assert a["sampling_sd"] > 0
    # independent points: no neighbour correlation; the overlap is 2/3 at one step
    first = res["neighbours"][0]
    assert first["direction"] == "x" and first["spacing_px"] == 7
    assert abs(first["overlap_fraction"] - 2 / 3) < 1e-3
    assert abs(first["same_snapshot_u"]) < 0.03
    # sigma ratio: u's sigma is right, v's is 0.8 of the truth
    assert abs(res["sigma_ratio"]["u"]["median"] - 1.0) < 0.03
    assert abs(res["sigma_ratio"]["v"]["median"] - 1.25) < 0.04
    assert f"| u | {a['u']['mean']:.3f} |" in markdown(res)


def test_noise_model_summary_scores_the_intervals():
    from bench.perf.dic_noise_model import markdown as nm_markdown
    from bench.perf.dic_noise_model import summarise

    truth = [10.0, 2.0]
    rng = np.random.default_rng(4)
    recs = []
    for r in range(200):
        rec = {"realisation": r, "names": ["a", "b"]}
        for rho, sd in ((0.5, [0.1, 0.02]), (0.0, [0.05, 0.02])):
            # a is biased by 1 sd (a systematic part), its spread is 0.1 with either model
            x = [10.1 + 0.1 * rng.standard_normal(), 2.0 + 0.02 * rng.standard_normal()]
            rec[str(rho)] = {"x": x, "std": sd, "chi2": 110.0, "n_data": 100}
        recs.append(rec)
    noise_free = {"0.5": {"x": [10.1, 2.0]}, "0.0": {"x": [10.1, 2.0]}}
    res = summarise(recs, truth, noise_free)
    a, b = res["parameters"]["a"], res["parameters"]["b"]
    assert a["sd_ratio_rho05_over_rho0"] == 2.0 and b["sd_ratio_rho05_over_rho0"] == 1.0
    assert abs(a["rho=0.5"]["empirical_sd_over_laplace_sd"] - 1.0) < 0.15
    assert abs(a["rho=0"]["empirical_sd_over_laplace_sd"] - 2.0) < 0.3
    assert a["rho=0.5"]["noise_free_error_in_sd"] == 1.0
    # around the truth the bias costs coverage; around the noise-free estimate it is ~95 %
    assert 150 < a["rho=0.5"]["covered_95"] < 185
    assert 180 < a["rho=0.5"]["covered_95_noise_free"] < 198
    assert a["rho=0"]["covered_95_noise_free"] < 150  # half the true sd: too narrow
    assert res["chi2_per_datum_rho=0.5"] == 1.1
    assert abs(a["spread_ratio_rho05_over_rho0"] - 1.0) < 0.2
    assert "| a | 2.000 |" in nm_markdown(res, "m")

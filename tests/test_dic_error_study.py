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

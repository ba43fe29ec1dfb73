"""Correlation of the images route's DIC errors: between snapshots, between neighbours.

    nice python bench/perf/dic_errors.py [--k 40] [--step 7] [--work results/tmp/dic-errors]
                                         [--out results/calibration/dic-errors]

On the shipped images example (suites/experiments/cube100-images: its speckle, its FE field of
``12,12,24:g4:hex27``, its drift, camera noise of 2 grey levels, the experiment file's subset,
calibration and ROI) the noise-free images are rendered once, then ``--k`` independent camera
noise realisations of the reference AND of every deformed image are correlated by the images
route's IC-GN (every image against the one reference, each started from the previous one's
solution) on a grid of ``--step`` px (finer than the subset, so that neighbours overlap). The
error of a point is its displacement minus that of the noise-free (8-bit rounded) images' own
correlation: the camera noise's part of the error, what the objective's covariance describes.
Printed and written (``<out>/dic_errors.json`` and ``.md``):

(a) per point and direction, the correlation between its errors in two snapshots (over the
    realisations), averaged over the snapshot pairs: mean and spread over the points, and the
    snapshot-pair matrix averaged over the points;
(b) the correlation between two points of one snapshot (and of two different snapshots) as a
    function of their spacing along x, y and the diagonal, in px and in subset sides, next to
    the subsets' overlap fraction;
(c) the empirical standard deviation of each point's error over the realisations divided by
    the IC-GN sigma (averaged over the realisations).

Resumable: the noise-free images and correlation (``truth.npz``) and every realisation
(``real_NNN.npz``) are kept in ``--work``; a rerun computes only what is missing.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from problems.io.atomic import atomic_savez, atomic_write_text  # noqa: E402

EXAMPLE = ROOT / "suites" / "experiments" / "cube100-images" / "experiment.toml"
#: the example's virtual test (docs/calibrating.md, "The images example")
EXAMPLE_X = (34000.0, 38.0, 0.9, 12.0, 24.0, 1500.0)
EXAMPLE_LEVELS = (0.05, 0.15, 0.3, 0.45, 0.6, 0.7)


def correlate(exp, points, images):
    """IC-GN of ``images[1:]`` against ``images[0]`` (uint8) at ``points`` (n, 2) px, as the
    images route does: (u, v, std_u, std_v, converged) each (N, n), grey noise per image (N,)."""
    from problems.dic.correlate import Correlator

    corr = Correlator(images[0], points, exp.correlation)
    out, noise, prev = [], [], None
    for img in images[1:]:
        res = corr.correlate(img, initial=prev)
        if np.any(res.converged):
            prev = res
        out.append([res.u, res.v, res.std_u, res.std_v, res.converged.astype(float)])
        noise.append(float(res.noise_sigma))
    u, v, su, sv, ok = (np.array(a) for a in zip(*out))
    return u, v, su, sv, ok.astype(bool), np.array(noise)


def truth(work: Path, step: int, mesh: str):
    """The noise-free images' correlation (cached in ``work/truth.npz``) and the experiment."""
    from problems.dic.speckle import acquire
    from problems.inverse.experiment import load_experiment, subset_grid
    from problems.inverse.virtual_experiment import VirtualTest, render_virtual_images

    exp = load_experiment(EXAMPLE)
    path = work / "truth.npz"
    if path.exists():
        t = dict(np.load(path))
        if int(t["step"]) == step:
            return exp, t
    test = VirtualTest(
        "linear-compression", EXAMPLE_X, levels_mm=EXAMPLE_LEVELS, data_mesh=mesh, seed=1
    )
    t0 = time.perf_counter()
    camera, intensities = render_virtual_images(test)
    print(f"data model and noise-free images: {time.perf_counter() - t0:.0f} s", flush=True)
    images = [acquire(i, camera.bit_depth, 0.0) for i in intensities]
    pts, on, _ = subset_grid(exp, images[0].shape, step)
    u, v, su, sv, ok, _ = correlate(exp, pts[on], images)
    t = {
        "step": np.array(step),
        "points": pts[on],
        "intensity": np.array(intensities, dtype=np.float64),
        "noise_grey": np.array(camera.noise_sigma),
        "bit_depth": np.array(camera.bit_depth),
        "u": u,
        "v": v,
        "converged": ok,
    }
    atomic_savez(path, compressed=False, **t)
    return exp, t


def realisation(work: Path, exp, t, r: int) -> dict:
    """Realisation ``r``: new camera noise in every image (reference included), correlated;
    cached in ``work/real_NNN.npz``."""
    from problems.dic.speckle import acquire

    path = work / f"real_{r:03d}.npz"
    if path.exists():
        return dict(np.load(path))
    bits, sig = int(t["bit_depth"]), float(t["noise_grey"])
    images = [
        acquire(i, bits, sig, np.random.default_rng([2026, r, k]))
        for k, i in enumerate(t["intensity"])
    ]
    u, v, su, sv, ok, noise = correlate(exp, t["points"], images)
    rec = {"u": u, "v": v, "std_u": su, "std_v": sv, "converged": ok, "noise": noise}
    atomic_savez(path, compressed=False, **rec)
    return rec


def _corr(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Correlation over axis 0 (the realisations) of ``a`` and ``b``, elementwise."""
    a = a - a.mean(axis=0)
    b = b - b.mean(axis=0)
    return (a * b).sum(axis=0) / np.sqrt((a * a).sum(axis=0) * (b * b).sum(axis=0))


def _spread(x: np.ndarray) -> dict:
    x = np.asarray(x, float).ravel()
    return {
        "mean": round(float(np.mean(x)), 4),
        "sd": round(float(np.std(x)), 4),
        "p5": round(float(np.percentile(x, 5)), 4),
        "median": round(float(np.median(x)), 4),
        "p95": round(float(np.percentile(x, 95)), 4),
    }


def analyse(t: dict, recs: list[dict], subset: int) -> dict:
    """The figures (a), (b), (c) of the module docstring from the realisations ``recs``."""
    K = len(recs)
    ok = t["converged"].all(axis=0) & np.all([r["converged"].all(axis=0) for r in recs], axis=0)
    # errors (K, N, n, 2): u then v, px
    E = np.stack([np.stack([r["u"] - t["u"], r["v"] - t["v"]], axis=-1) for r in recs])[:, :, ok]
    S = np.stack([np.stack([r["std_u"], r["std_v"]], axis=-1) for r in recs])[:, :, ok]
    _, N, n, _ = E.shape
    # (a) between snapshots, per point and direction
    pairs = [(j, k) for j in range(N) for k in range(j + 1, N)]
    C = np.zeros((N, N, n, 2))
    for j in range(N):
        for k in range(N):
            C[j, k] = _corr(E[:, j], E[:, k])
    rho_point = np.mean([C[j, k] for j, k in pairs], axis=0)  # (n, 2)
    # the spread of a mean of pair correlations at K draws if rho were the same everywhere:
    # the same statistic on split halves differs by sampling alone
    half = K // 2
    if half >= 5:
        Ca = np.mean([_corr(E[:half, j], E[:half, k]) for j, k in pairs], axis=0)
        Cb = np.mean([_corr(E[half:, j], E[half:, k]) for j, k in pairs], axis=0)
        sampling_sd = float(np.std(Ca - Cb) / np.sqrt(2) * np.sqrt(half / K))
    else:
        sampling_sd = float("nan")
    uv = _corr(E[..., 0], E[..., 1])  # (N, n): u-v of one point in one snapshot
    # (b) neighbours: grid indices of the points
    P = t["points"][ok]
    step = int(t["step"])
    ij = np.rint((P - P.min(axis=0)) / step).astype(int)
    index = {tuple(p): i for i, p in enumerate(ij)}
    neighbours = []
    for name, (dx, dy) in (("x", (1, 0)), ("y", (0, 1)), ("diagonal", (1, 1))):
        for d in range(1, 7):
            a, b = [], []
            for i, p in enumerate(ij):
                q = index.get((p[0] + d * dx, p[1] + d * dy))
                if q is not None:
                    a.append(i)
                    b.append(q)
            if not a:
                continue
            a, b = np.array(a), np.array(b)
            same = _corr(E[:, :, a], E[:, :, b])  # (N, pairs, 2)
            cross = np.mean([_corr(E[:, j, a], E[:, k, b]) for j, k in pairs], axis=0)
            sx, sy = d * dx * step, d * dy * step
            overlap = max(0.0, 1 - sx / subset) * max(0.0, 1 - sy / subset)
            neighbours.append(
                {
                    "direction": name,
                    "spacing_px": round(float(np.hypot(sx, sy)), 2),
                    "spacing_over_subset": round(float(np.hypot(sx, sy) / subset), 3),
                    "overlap_fraction": round(overlap, 3),
                    "pairs": int(len(a)),
                    "same_snapshot_u": round(float(same[..., 0].mean()), 4),
                    "same_snapshot_v": round(float(same[..., 1].mean()), 4),
                    "other_snapshot_u": round(float(cross[..., 0].mean()), 4),
                    "other_snapshot_v": round(float(cross[..., 1].mean()), 4),
                }
            )
    # (c) empirical sd against the IC-GN sigma
    ratio = E.std(axis=0, ddof=1) / S.mean(axis=0)  # (N, n, 2)
    z = E / S
    return {
        "realisations": K,
        "snapshots": N,
        "points": n,
        "points_dropped": int((~ok).sum()),
        "grid_step_px": step,
        "subset_px": subset,
        "grey_noise_true": float(t["noise_grey"]),
        "grey_noise_estimated_mean": round(float(np.mean([r["noise"] for r in recs])), 4),
        "error_rms_px": round(float(np.sqrt(np.mean(E**2))), 5),
        "rho_between_snapshots": {
            "u": _spread(rho_point[:, 0]),
            "v": _spread(rho_point[:, 1]),
            "both": _spread(rho_point),
            "sampling_sd": round(sampling_sd, 4),
            "pair_matrix": C.mean(axis=(2, 3)).round(3).tolist(),
        },
        "rho_u_v_same_point": _spread(uv),
        "neighbours": neighbours,
        "sigma_ratio": {
            "u": _spread(ratio[..., 0]),
            "v": _spread(ratio[..., 1]),
            "rms_error_over_sigma": round(float(np.sqrt(np.mean(z**2))), 4),
        },
    }


def markdown(res: dict) -> str:
    """A short md summary of :func:`analyse`'s figures."""
    a, c = res["rho_between_snapshots"], res["sigma_ratio"]
    lines = [
        "# DIC error correlation on the images example",
        "",
        "`nice python bench/perf/dic_errors.py` (suites/experiments/cube100-images: its speckle, "
        "FE field, drift, 2 grey levels of camera noise, subset "
        f"{res['subset_px']} px); {res['realisations']} noise realisations of the reference and "
        f"the {res['snapshots']} images, {res['points']} points on a {res['grid_step_px']} px "
        "grid; error = correlated − the noise-free images' correlation "
        f"(rms {res['error_rms_px']} px).",
        "",
        "## (a) One point, two snapshots",
        "",
        "| | mean ρ | sd over points | 5 % | median | 95 % |",
        "|---|---|---|---|---|---|",
    ]
    for key in ("u", "v", "both"):
        s = a[key]
        lines.append(
            f"| {key} | {s['mean']:.3f} | {s['sd']:.3f} | {s['p5']:.3f} | {s['median']:.3f} | "
            f"{s['p95']:.3f} |"
        )
    lines += [
        "",
        f"Sampling sd of a point's ρ at {res['realisations']} realisations (split halves): "
        f"{a['sampling_sd']:.3f}. u–v of one point: mean {res['rho_u_v_same_point']['mean']:.3f}."
        f" Grey noise estimated by IC-GN: {res['grey_noise_estimated_mean']:.2f} (true "
        f"{res['grey_noise_true']:g}).",
        "",
        "Snapshot-pair matrix (mean over points and u, v):",
        "",
    ]
    for row in a["pair_matrix"]:
        lines.append("    " + " ".join(f"{v:5.2f}" for v in row))
    lines += [
        "",
        "## (b) Two points, by spacing",
        "",
        "| direction | spacing px | / subset | overlap | same snapshot u, v "
        "| other snapshot u, v |",
        "|---|---|---|---|---|---|",
    ]
    for r in res["neighbours"]:
        lines.append(
            f"| {r['direction']} | {r['spacing_px']:g} | {r['spacing_over_subset']:.2f} | "
            f"{r['overlap_fraction']:.2f} | {r['same_snapshot_u']:.3f}, {r['same_snapshot_v']:.3f}"
            f" | {r['other_snapshot_u']:.3f}, {r['other_snapshot_v']:.3f} |"
        )
    lines += [
        "",
        "## (c) Empirical sd / IC-GN sigma",
        "",
        f"u: median {c['u']['median']:.3f} (5–95 %: {c['u']['p5']:.3f}–{c['u']['p95']:.3f}); "
        f"v: median {c['v']['median']:.3f} ({c['v']['p5']:.3f}–{c['v']['p95']:.3f}); "
        f"rms error / sigma {c['rms_error_over_sigma']:.3f}.",
        "",
    ]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--k", type=int, default=40, help="noise realisations (>= 10)")
    ap.add_argument("--step", type=int, default=7, help="grid step of the points, px")
    ap.add_argument("--mesh", default="12,12,24:g4:hex27", help="the example's data mesh")
    ap.add_argument("--work", default=str(ROOT / "results" / "tmp" / "dic-errors"))
    ap.add_argument("--out", default=str(ROOT / "results" / "calibration" / "dic-errors"))
    args = ap.parse_args(argv)
    if args.k < 10:
        ap.error(f"--k {args.k}: at least 10 realisations are needed")
    if args.step < 1:
        ap.error(f"--step {args.step}: must be >= 1 px")
    from threadpoolctl import threadpool_limits

    work, out = Path(args.work), Path(args.out)
    work.mkdir(parents=True, exist_ok=True)
    with threadpool_limits(limits=1):
        exp, t = truth(work, args.step, args.mesh)
        recs = []
        for r in range(args.k):
            t0 = time.perf_counter()
            recs.append(realisation(work, exp, t, r))
            print(f"realisation {r + 1}/{args.k}: {time.perf_counter() - t0:.1f} s", flush=True)
    res = analyse(t, recs, exp.correlation.subset)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "dic_errors.json", json.dumps(res, indent=1) + "\n")
    md = markdown(res)
    atomic_write_text(out / "dic_errors.md", md)
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())

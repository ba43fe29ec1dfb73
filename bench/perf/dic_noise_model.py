"""The images route's noise model: Laplace intervals with and without the snapshot correlation.

    nice python bench/perf/dic_noise_model.py [--k 40] [--mesh 3,3,6:hex27] [--work ...]
                                              [--out results/calibration/dic-errors]

A virtual images experiment of the shipped example's test (100 mm cube, linear-compression at
the example's parameters, its six load steps, drift, camera, speckle and 2 grey levels of camera
noise) is made on ``--mesh``, which is also the inverse model: the data have no discretisation
error, so what is left is the measurement's noise and what is judged is the noise model alone
(a fast mesh of quadratic elements, so that the field the DIC sees is smooth: fine for that,
and no statement on the inverse model's accuracy). The
noise-free images are rendered once; each of ``--k`` realisations draws new camera noise in the
reference and in every image and a new load-cell error in the machine log, imports the images
(IC-GN against the one reference) and identifies the variant with ``lm`` from the test's own
start (bench.calibration.calibrate_variant), twice on the same data: with the Dataset's
``snapshot_rho`` = 0.5 (the images route's default, the IC-GN model) and with 0 (independent
snapshots, the model before). Per parameter it prints the ratio of the Laplace sds (0.5 over 0),
the ratio of the estimates' spreads over the realisations (0.5 over 0: the efficiency of the
weighting), the spread against each Laplace sd, and the coverage of
the 95 % intervals (Laplace from the exact Jacobian, without the Birge widening) of the truth
and of the estimate from the noise-free images (the systematic part, the same in every
realisation: what the noise model is not about). Resumable:
one record per realisation in ``--work``; ``<out>/noise_model.{json,md}``.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from bench.perf.dic_errors import EXAMPLE_LEVELS, EXAMPLE_X  # noqa: E402
from problems.io.atomic import atomic_savez, atomic_write_text  # noqa: E402

RHOS = (0.5, 0.0)


def setup(work: Path, mesh: str):
    """The virtual test, its folder (experiment file, first log) and the noise-free images
    (cached in ``work/truth.npz``)."""
    import problems.inverse.virtual_experiment as ve

    test = ve.VirtualTest(
        "linear-compression", EXAMPLE_X, levels_mm=EXAMPLE_LEVELS, data_mesh=mesh, seed=1
    )
    folder = work / "experiment"
    path = work / "truth.npz"
    resp = ve._data_response(test, "noise-model")
    if not path.exists() or not (folder / "experiment.toml").exists():
        ve.write_virtual_images(test, folder, "noise-model")
        camera, intensities = ve.render_virtual_images(test, resp=resp)
        bits, noise = camera.bit_depth, camera.noise_sigma
        atomic_savez(
            path, compressed=False, intensity=np.array(intensities), bits=bits, noise=noise
        )
    return test, folder, resp, dict(np.load(path))


def realisation(work: Path, test, folder: Path, resp, truth: dict, r: int, mesh: str, budget: int):
    """Realisation ``r``: new images and log, imported, identified with both rho; its record
    (cached in ``work/real_NNN.json``). ``r = -1``: the noise-free images and log (8-bit
    rounding and the log's force step only), whose estimate is the systematic part of every
    realisation's (cached in ``work/noise_free.json``)."""
    from bench.calibration import CalibrationSettings, calibrate_variant
    from problems.dic.imageio import write_image
    from problems.dic.speckle import acquire
    from problems.inverse.experiment import import_experiment, load_experiment
    from problems.inverse.lab import lab_case
    from problems.inverse.virtual_experiment import _write_log

    path = work / ("noise_free.json" if r < 0 else f"real_{r:03d}.json")
    if path.exists():
        return json.loads(path.read_text())
    names = ["reference.png"] + [f"image_{k:02d}.png" for k in range(1, len(test.levels_mm) + 1)]
    bits, sig = int(truth["bits"]), float(truth["noise"]) if r >= 0 else 0.0
    for k, (name, inten) in enumerate(zip(names, truth["intensity"])):
        img = acquire(inten, bits, sig, np.random.default_rng([7, max(r, 0), k]))
        tmp = folder / "images" / f".{name}.tmp.png"
        os.replace(write_image(tmp, img), folder / "images" / name)
    log_test = test if r >= 0 else dataclasses.replace(test, load_cell_class=0.0)
    _write_log(log_test, resp.reaction_kN, folder, np.random.default_rng([7, max(r, 0), 99]))
    ds = import_experiment(load_experiment(folder / "experiment.toml"))
    case = lab_case(test.variant, ds)
    settings = CalibrationSettings(mesh, budget, check_mesh="")
    rec = {"realisation": r, "names": list(case.names)}
    for rho in RHOS:
        t0 = time.perf_counter()
        out = calibrate_variant(dataclasses.replace(ds, snapshot_rho=rho), case, settings)
        rec[str(rho)] = {
            "x": out["x"],
            "std": out["std_noise_only"],
            "chi2": out["chi2"],
            "n_data": out["n_data"],
            "rms_sigma_blocks": out["rms_sigma_blocks"],
            "n_evals": out["n_evals"],
            "status": out["status"],
            "wall_s": round(time.perf_counter() - t0, 1),
        }
    atomic_write_text(path, json.dumps(rec) + "\n")
    return rec


def summarise(recs: list[dict], truth_x, noise_free: dict) -> dict:
    """Per parameter: Laplace sd ratio (rho 0.5 over 0), empirical sd of the estimates over the
    realisations against each Laplace sd, coverage of the 95 % intervals of the truth and of
    the noise-free images' estimate (the systematic part, rendering and DIC), that estimate's
    error in Laplace sds; chi2 / n."""
    names = recs[0]["names"]
    x0 = np.asarray(truth_x, float)
    out = {"realisations": len(recs), "parameters": {}}
    X = {rho: np.array([r[str(rho)]["x"] for r in recs]) for rho in RHOS}
    S = {rho: np.array([r[str(rho)]["std"] for r in recs]) for rho in RHOS}
    for i, n in enumerate(names):
        row = {
            "sd_ratio_rho05_over_rho0": round(float(np.mean(S[0.5][:, i] / S[0.0][:, i])), 4),
            "spread_ratio_rho05_over_rho0": round(
                float(np.std(X[0.5][:, i], ddof=1) / np.std(X[0.0][:, i], ddof=1)), 4
            ),
        }
        for rho in RHOS:
            xs = noise_free[str(rho)]["x"][i]
            z = (X[rho][:, i] - x0[i]) / S[rho][:, i]
            zs = (X[rho][:, i] - xs) / S[rho][:, i]
            row[f"rho={rho:g}"] = {
                "mean_error_percent": round(float(np.mean(X[rho][:, i] / x0[i] - 1) * 100), 4),
                "noise_free_error_in_sd": round(float((xs - x0[i]) / np.mean(S[rho][:, i])), 3),
                "empirical_sd_over_laplace_sd": round(
                    float(np.std(X[rho][:, i], ddof=1) / np.mean(S[rho][:, i])), 3
                ),
                "rms_z": round(float(np.sqrt(np.mean(z**2))), 3),
                "covered_95": int(np.sum(np.abs(z) <= 1.96)),
                "rms_z_noise_free": round(float(np.sqrt(np.mean(zs**2))), 3),
                "covered_95_noise_free": int(np.sum(np.abs(zs) <= 1.96)),
            }
        out["parameters"][n] = row
    for rho in RHOS:
        chi = [r[str(rho)]["chi2"] / r[str(rho)]["n_data"] for r in recs]
        out[f"chi2_per_datum_rho={rho:g}"] = round(float(np.mean(chi)), 4)
        xs = np.asarray(noise_free[str(rho)]["x"], float)
        for key, ref in (("", x0), ("_noise_free", xs)):
            out[f"all_covered{key}_rho={rho:g}"] = int(
                sum(np.all(np.abs((X[rho][k] - ref) / S[rho][k]) <= 1.96) for k in range(len(recs)))
            )
    return out


def markdown(res: dict, mesh: str) -> str:
    """A short md table of :func:`summarise`."""
    K = res["realisations"]
    lines = [
        "# Noise model of the images route: with and without the snapshot correlation",
        "",
        f"`nice python bench/perf/dic_noise_model.py --mesh {mesh}`: {K} camera-noise (and "
        f"load-cell) realisations of the images example's test, data and inverse model on "
        f"`{mesh}` (no discretisation error: the noise model alone is judged), `lm` from the "
        "test's start; Laplace sds from the exact Jacobian, no Birge widening.",
        "",
        "Covered: the 95 % interval holds the truth; (nf): holds the noise-free images' "
        "estimate, whose error (nf err, in Laplace sds) is the rendering's and the DIC's "
        "systematic part, the same in every realisation.",
        "",
        "| parameter | Laplace sd ratio ρ 0.5 / 0 | spread ratio ρ 0.5 / 0 | spread / Laplace sd, "
        f"ρ = 0.5 | ρ = 0 | nf err (sd) | covered (of {K}), ρ = 0.5 | ρ = 0 | covered (nf), "
        "ρ = 0.5 | ρ = 0 |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for n, row in res["parameters"].items():
        a, b = row["rho=0.5"], row["rho=0"]
        lines.append(
            f"| {n} | {row['sd_ratio_rho05_over_rho0']:.3f} | "
            f"{row['spread_ratio_rho05_over_rho0']:.2f} | "
            f"{a['empirical_sd_over_laplace_sd']:.2f} | {b['empirical_sd_over_laplace_sd']:.2f} | "
            f"{a['noise_free_error_in_sd']:+.1f} | {a['covered_95']} | {b['covered_95']} | "
            f"{a['covered_95_noise_free']} | {b['covered_95_noise_free']} |"
        )
    lines += [
        "",
        f"Every interval covering the truth: {res['all_covered_rho=0.5']} of {K} (ρ = 0.5), "
        f"{res['all_covered_rho=0']} of {K} (ρ = 0); the noise-free estimate: "
        f"{res['all_covered_noise_free_rho=0.5']} and {res['all_covered_noise_free_rho=0']}. "
        f"χ²/n: {res['chi2_per_datum_rho=0.5']:.3f} (ρ = 0.5), "
        f"{res['chi2_per_datum_rho=0']:.3f} (ρ = 0).",
        "",
    ]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--k", type=int, default=40, help="noise realisations (>= 3)")
    ap.add_argument("--mesh", default="3,3,6:hex27", help="data and inverse mesh")
    ap.add_argument("--budget", type=int, default=40, help="lm evaluations per fit")
    ap.add_argument("--work", default=str(ROOT / "results" / "tmp" / "dic-noise-model"))
    ap.add_argument("--out", default=str(ROOT / "results" / "calibration" / "dic-errors"))
    args = ap.parse_args(argv)
    if args.k < 3:
        ap.error(f"--k {args.k}: at least 3 realisations are needed")
    from threadpoolctl import threadpool_limits

    work = Path(args.work) / args.mesh.replace(":", "_").replace(",", "-")
    work.mkdir(parents=True, exist_ok=True)
    recs = []
    with threadpool_limits(limits=1):
        test, folder, resp, truth = setup(work, args.mesh)
        noise_free = realisation(work, test, folder, resp, truth, -1, args.mesh, args.budget)
        for r in range(args.k):
            t0 = time.perf_counter()
            recs.append(realisation(work, test, folder, resp, truth, r, args.mesh, args.budget))
            print(f"realisation {r + 1}/{args.k}: {time.perf_counter() - t0:.0f} s", flush=True)
    res = summarise(recs, test.x, noise_free) | {"mesh": args.mesh, "budget": args.budget}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "noise_model.json", json.dumps(res, indent=1) + "\n")
    md = markdown(res, args.mesh)
    atomic_write_text(out / "noise_model.md", md)
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The experiment file's images route against its CSV route on the shipped images example.

    python bench/perf/images_route.py [--mesh 12,12,24:g4:hex27]

Reruns the example's data model (suites/experiments/cube100-images, about 2.5 min), writes the
same FE run as a DIC export (``write_virtual_experiment``: same scale 0.2 mm/px, synthetic noise
0.01-0.03 px per point) into a temporary folder, imports both, and prints per route: the import
time (s), the points, the error of the imported displacements against the data model's field at
the same points with the rigid motion removed alike (rms and max in px, rms in sigma units per
block u_h, u_v), the median sigma (px) and the mean correlation of a point's errors between
consecutive images. Figures in docs/calibrating.md.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

import problems.inverse.virtual_experiment as ve  # noqa: E402
from problems.inverse.experiment import (  # noqa: E402
    import_experiment,
    load_experiment,
    rigid_basis,
    rigid_fit,
)

EXAMPLE = ROOT / "suites" / "experiments" / "cube100-images" / "experiment.toml"


def errors(ds, resp) -> tuple[np.ndarray, np.ndarray]:
    """(N, 2 m) imported minus true displacements (mm) and their sigma, rigid motion removed
    from the truth by the import's own weighted projection."""
    fh, fv = resp.front_face(ds.points)
    sign = np.array(ds.meta["fold_sign"])
    B = rigid_basis(sign * ds.points[:, 0], ds.points[:, 1], sign)
    E, S = [], []
    for k in range(ds.u_h.shape[0]):
        s = np.concatenate([ds.std_u_mm[0, k], ds.std_u_mm[1, k]])
        u = np.concatenate([fh[k], fv[k]])
        truth = u - B @ rigid_fit(B, u, 1 / s**2)
        E.append(np.concatenate([ds.u_h[k], ds.u_v[k]]) - truth)
        S.append(s)
    return np.array(E), np.array(S)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mesh", default="12,12,24:g4:hex27", help="the example's data mesh")
    args = ap.parse_args()
    test = ve.VirtualTest(
        "linear-compression",
        (34000.0, 38.0, 0.9, 12.0, 24.0, 1500.0),
        levels_mm=(0.05, 0.15, 0.3, 0.45, 0.6, 0.7),
        data_mesh=args.mesh,
        seed=1,
        mm_per_px=0.2,
        corner_px=(16.0, 516.0),
    )
    resp = ve._data_response(test, "truth")
    with tempfile.TemporaryDirectory() as tmp:
        ve._data_response = lambda t, name: resp  # the same FE run makes the export
        routes = {"images": EXAMPLE, "csv": ve.write_virtual_experiment(test, tmp, "cube100-csv")}
        for route, path in routes.items():
            t0 = time.perf_counter()
            exp = load_experiment(path)
            ds = import_experiment(exp)
            dt = time.perf_counter() - t0
            px = exp.calibration["mm_per_unit"]
            E, S = errors(ds, resp)
            m = len(ds.points)
            row = {
                "import_s": round(dt, 3),
                "points": m,
                "rms_px": float(np.sqrt(np.mean(E**2)) / px),
                "max_px": float(np.abs(E).max() / px),
                "rms_sigma_h": float(np.sqrt(np.mean((E[:, :m] / S[:, :m]) ** 2))),
                "rms_sigma_v": float(np.sqrt(np.mean((E[:, m:] / S[:, m:]) ** 2))),
                "rms_sigma": float(np.sqrt(np.mean((E / S) ** 2))),
                "median_sigma_px": float(np.median(S) / px),
                "mean_error_px_per_image": (np.mean(E, axis=1) / px).round(5).tolist(),
                "error_correlation_between_images": float(
                    np.mean([np.corrcoef(E[k], E[k + 1])[0, 1] for k in range(len(E) - 1)])
                ),
            }
            print(route, json.dumps(row), flush=True)


if __name__ == "__main__":
    main()

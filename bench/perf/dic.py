"""DIC benchmark: correlation speed, translation accuracy, rendering time (one core).

    python bench/perf/dic.py [--quick]

Prints
* subsets/s for 21 x 21 px subsets on 1000 x 1000 px rendered images (step 10 grid over the
  face, ~9 000 subsets), for the first image (FFT seeds + reliability-guided propagation)
  and for a next snapshot started from the previous solution, per available back-end;
* bias and standard deviation of u and v for rigid Fourier-shifted translations 0..1 px in
  0.1 px steps: float images without noise, 8-bit without noise, 8-bit with sigma = 2;
* the time to render a 1000 x 1000 px reference and deformed image.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import numpy as np  # noqa: E402

from problems.dic import _kernels  # noqa: E402
from problems.dic.correlate import Correlator, DICConfig, grid_points  # noqa: E402
from problems.dic.pipeline import pixel_displacement  # noqa: E402
from problems.dic.speckle import (  # noqa: E402
    CameraConfig,
    SpeckleConfig,
    face_pattern,
    render_face,
)
from problems.dic.synthetic import translation_study  # noqa: E402


def bulge(delta):
    def f(y, z):
        return 0.2 * delta * y / 150 * (1 + 0.5 * np.sin(np.pi * z / 150)), -delta * z / 150 + 0 * y

    return f


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repetitions")
    args = ap.parse_args()
    reps = 1 if args.quick else 3

    cam, sp = CameraConfig(), SpeckleConfig()
    pat = face_pattern(sp, cam, 0)
    render_face(cam, sp, pat, None, 0)  # warm-up (numba compilation)
    t = time.perf_counter()
    ref = render_face(cam, sp, pat, None, 1)
    t_ref = time.perf_counter() - t
    t = time.perf_counter()
    d1 = render_face(cam, sp, pat, pixel_displacement(bulge(0.3), cam), 2)
    t_def = time.perf_counter() - t
    d2 = render_face(cam, sp, pat, pixel_displacement(bulge(0.6), cam), 3)
    print(
        f"rendering {cam.shape[1]} x {cam.shape[0]} px (1000 x 1000 px face, {len(pat.sigma)} "
        f"speckles, {cam.supersample}x{cam.supersample} supersampling, back-end "
        f"{_kernels.DEFAULT_BACKEND}):"
    )
    print(f"  reference {t_ref:.2f} s, deformed {t_def:.2f} s")

    x0, x1, y0, y1 = (int(round(v)) for v in cam.face_box_px)
    pts = grid_points(ref.shape, 21, 10, (x0 + 5, y0 + 5, x1 - 5, y1 - 5))
    print(f"\ncorrelation speed, {len(pts)} subsets of 21 x 21 px, step 10 px, bicubic, one core:")
    for backend in _kernels.AVAILABLE:
        cfg = DICConfig(backend=backend)
        corr = Correlator(ref, pts, cfg)
        corr.correlate(d1)  # warm-up
        best1 = best2 = np.inf
        for _ in range(reps):
            t = time.perf_counter()
            r1 = corr.correlate(d1)
            best1 = min(best1, time.perf_counter() - t)
            t = time.perf_counter()
            r2 = corr.correlate(d2, initial=r1)
            best2 = min(best2, time.perf_counter() - t)
        t = time.perf_counter()
        Correlator(ref, pts, cfg)
        t_setup = time.perf_counter() - t
        print(
            f"  {backend:6s} first image (seeds + propagation): {len(pts) / best1:8.0f} subsets/s "
            f"({r1.iterations.mean():.1f} iterations, {r1.converged.mean():.1%} converged)"
        )
        print(
            f"  {backend:6s} next snapshot from previous:       {len(pts) / best2:8.0f} subsets/s "
            f"({r2.iterations.mean():.1f} iterations, {r2.converged.mean():.1%} converged); "
            f"reference set-up {t_setup:.2f} s"
        )

    print(
        "\nrigid translation (Fourier shift 0..1 px step 0.1 in x and y), 256 x 256 px, subset 21, "
        "step 10:"
    )
    cases = [
        ("float, no noise", 0.0, None),
        ("8-bit, no noise", 0.0, 8),
        ("8-bit, sigma = 2", 2.0, 8),
    ]
    for order in (3, 5):
        for name, sigma, bits in cases:
            st = translation_study(noise_sigma=sigma, bit_depth=bits, config=DICConfig(order=order))
            w = st.worst
            print(
                f"  order {order}, {name:17s}: max|bias| u {w['max |bias u|']:.5f} v "
                f"{w['max |bias v|']:.5f} px; max std u {w['max std u']:.5f} v "
                f"{w['max std v']:.5f} px; predicted std {np.mean(st.est_std_u):.5f} px "
                f"({st.n_points} points)"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Throughput of the Drucker-Prager material update: points per second for 40 000 points.

    python bench/perf/material_update.py [--points N] [--repeat R]

For each form and hardening: 40 000 points already on their yield surface (one plastic step from
zero, mostly compression and shear as in the cube test) get a further increment that keeps almost
all of them plastic; the best of R timed updates is reported, with the elastic throughput (tiny
increments from the same states) for comparison. Run single-threaded for comparable figures:
OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from problems.materials.drucker_prager import make_material
from problems.materials.verification import typical_parameters


def _states(mat, n, rng):
    """n points on the surface after one plastic step (compression-biased random strains)."""
    s0 = mat.law.sigma0
    de = rng.normal(size=(3 * n, 6)) * 3.0 * s0 / mat.E
    de[:, :3] -= 1.5 * s0 / mat.E
    first = mat.update(de, np.zeros((3 * n, 6)), mat.initial_state(3 * n))
    keep = np.flatnonzero(first.ok & (first.state[:, 0] > 0))[:n]
    return first.stress[keep], first.state[keep]


def _best(fn, repeat):
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=40_000)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    n = args.points
    rng = np.random.default_rng(0)
    print(f"{'variant':24} {'plastic':>8} {'apex':>6} {'ok':>6} {'plastic pts/s':>14} {'elastic pts/s':>14}")
    for form in ("linear", "hyperbolic", "exponent"):
        for hardening in ("compression", "shear", "tension"):
            mat = make_material(form, hardening, typical_parameters(form, hardening))
            sig, st = _states(mat, n, rng)
            # continued loading: 5 % more of the current stress plus noise keeps points plastic
            de = np.linalg.solve(mat.stiffness, 0.05 * sig.T).T + rng.normal(size=(n, 6)) * 1e-3 * mat.law.sigma0 / mat.E
            t_pl, up = _best(lambda: mat.update(de, sig, st), args.repeat)
            plastic = up.state[:, 0] > st[:, 0]
            apex = np.all(up.stress[:, 3:] == 0, axis=1) & np.all(up.stress[:, :3] == up.stress[:, [0]], axis=1) & plastic
            unload = -0.2 * de  # 1 % elastic unloading
            t_el, _ = _best(lambda: mat.update(unload, sig, st), args.repeat)
            print(f"{form + '-' + hardening:24} {plastic.mean():8.1%} {apex.mean():6.1%} {up.ok.mean():6.1%} "
                  f"{n / t_pl:14,.0f} {n / t_el:14,.0f}")


if __name__ == "__main__":
    main()

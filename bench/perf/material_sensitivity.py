"""Cost of the Drucker-Prager parameter sensitivities (DDM) relative to the update itself.

    python -m bench.perf.material_sensitivity [--points N] [--repeat R]

For each form and hardening, N points (default 10^5) already on their yield surface (one
plastic step from zero, compression-biased random strains) get a further increment that keeps
almost all of them plastic; both ``update`` and ``sensitivity`` (with random non-zero history
derivatives dstress_old, dstate_old and ddeps, as in a global DDM) are timed in the same run,
best of R, and their ratio printed; the same for elastic unloading. The first line is the time
of the first calls of the process (numba compilation or cache load). Run single-threaded for
comparable figures: OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1.

The elastic ratio is large because the elastic update is almost free, and at 10^5 points it is
dominated by first touching the fresh output arrays (n, P, 6) and (n, P, 7): above glibc's 32 MB
mmap threshold every call page-faults them in (compare ``--points 80000``).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from problems.materials.drucker_prager import FORMS, make_material
from problems.materials.hardening import HARDENINGS
from problems.materials.verification import typical_parameters


def _surface_states(mat, n, rng):
    """n points on the yield surface after one plastic step (compression-biased random strains)."""
    s0 = mat.law.sigma0
    de = rng.normal(size=(4 * n, 6)) * 3.0 * s0 / mat.E
    de[:, :3] -= 1.5 * s0 / mat.E
    first = mat.update(de, np.zeros((4 * n, 6)), mat.initial_state(4 * n))
    keep = np.flatnonzero(first.ok & (first.state[:, 0] > 0))[:n]
    return first.stress[keep], first.state[keep]


def _best(fn, repeat):
    """(best wall time in s, last result) of ``repeat`` calls."""
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def _ratio(mat, de, sig, st, history, repeat):
    """(update time, sensitivity time, fraction of points whose eqps grew)."""
    t_up, up = _best(lambda: mat.update(de, sig, st), repeat)
    t_se, _ = _best(lambda: mat.sensitivity(de, sig, st, up, *history), repeat)
    return t_up, t_se, np.mean(up.state[:, 0] > st[:, 0])


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=100_000)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    n = args.points
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    for form in ("linear", "hyperbolic"):  # every compiled variant: cone and von Mises section
        mat = make_material(form, "compression", typical_parameters(form, "compression"))
        de = np.array([[-1e-2, 0, 0, 0, 0, 0]])
        sig, st = np.zeros((1, 6)), mat.initial_state(1)
        P = len(mat.parameter_names)
        mat.sensitivity(
            de,
            sig,
            st,
            mat.update(de, sig, st),
            np.zeros((1, P, 6)),
            np.zeros((1, P, 7)),
            np.zeros((1, P, 6)),
        )
    print(f"first calls (numba compile or cache load): {time.perf_counter() - t0:.2f} s")
    print(
        f"times in s (best of {args.repeat}); points: on the surface, of {n} requested; P "
        "parameters"
    )
    print(
        f"{'variant':24} {'points':>7} {'P':>2} {'plastic':>8} {'update':>8} {'sens.':>8} "
        f"{'ratio':>6}   {'elastic: update':>15} {'sens.':>8} {'ratio':>6}"
    )
    for form in FORMS:
        for hardening in HARDENINGS:
            mat = make_material(form, hardening, typical_parameters(form, hardening))
            P = len(mat.parameter_names)
            sig, st = _surface_states(mat, n, rng)
            m = len(sig)
            history = (
                rng.normal(size=(m, P, 6)),
                rng.normal(size=(m, P, 7)) * 1e-4,
                rng.normal(size=(m, P, 6)) * 1e-5,
            )
            # continued loading: 5 % more of the current stress plus noise keeps points plastic
            de = (
                np.linalg.solve(mat.stiffness, 0.05 * sig.T).T
                + rng.normal(size=(m, 6)) * 1e-3 * mat.law.sigma0 / mat.E
            )
            t_up, t_se, plastic = _ratio(mat, de, sig, st, history, args.repeat)
            # 1 % elastic unloading
            e_up, e_se, _ = _ratio(mat, -0.2 * de, sig, st, history, args.repeat)
            print(
                f"{form + '-' + hardening:24} {m:7d} {P:2d} {plastic:8.1%} {t_up:8.3f} {t_se:8.3f} "
                f"{t_se / t_up:6.2f}   {e_up:15.3f} {e_se:8.3f} {e_se / e_up:6.2f}"
            )


if __name__ == "__main__":
    main()

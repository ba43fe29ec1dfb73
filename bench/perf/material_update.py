"""Throughput of the Drucker-Prager material update: points per second for 40 000 points.

    python -m bench.perf.material_update [--points N] [--repeat R]

For each form and hardening: 40 000 points already on their yield surface (one plastic step from
zero, mostly compression and shear as in the cube test) get a further increment that keeps almost
all of them plastic; the best of R timed updates is reported, with the elastic throughput (tiny
increments from the same states) for comparison, and the mean number of local Jacobians formed
per smooth plastic point (1 = the start was already converged: one check, then the final step
with the tangent). The first line is the time of the very first update of the process: it
compiles the numba kernels (about 10 s of CPU, once per machine and version of
``problems/materials/_kernels.py``) or loads them from numba's cache. Run single-threaded for
comparable figures: OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from problems.materials import _kernels
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


def _jacobians_per_point(mat, de, sig, st):
    """Mean local Jacobians per smooth (non-apex) plastic point of this update."""
    sig_tr = np.ascontiguousarray(sig + de @ mat.stiffness.T)
    scale = np.maximum(mat.law.sigma0, np.abs(sig_tr).max(axis=1))
    *_, apex, jac = _kernels.plastic_return(
        mat._kernel_params,
        mat.yield_function.kernel_params,
        mat.potential.kernel_params,
        sig_tr,
        np.ascontiguousarray(st[:, 0]),
        scale,
    )
    smooth = ~apex & (jac > 0)
    return jac[smooth].mean() if smooth.any() else float("nan")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=40_000)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    n = args.points
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    for form in ("linear", "hyperbolic"):  # every compiled variant: cone and von Mises section
        mat = make_material(form, "compression", typical_parameters(form, "compression"))
        mat.update(np.array([[-1e-2, 0, 0, 0, 0, 0]]), np.zeros((1, 6)), mat.initial_state(1))
    print(f"first update (numba compile or cache load): {time.perf_counter() - t0:.2f} s")
    print(
        f"{'variant':24} {'plastic':>8} {'apex':>6} {'ok':>6} {'J/pt':>5} {'plastic pts/s':>14} "
        f"{'elastic pts/s':>14}"
    )
    for form in ("linear", "hyperbolic", "exponent"):
        for hardening in ("compression", "shear", "tension"):
            mat = make_material(form, hardening, typical_parameters(form, hardening))
            sig, st = _states(mat, n, rng)
            # continued loading: 5 % more of the current stress plus noise keeps points plastic
            de = (
                np.linalg.solve(mat.stiffness, 0.05 * sig.T).T
                + rng.normal(size=(n, 6)) * 1e-3 * mat.law.sigma0 / mat.E
            )
            t_pl, up = _best(lambda: mat.update(de, sig, st), args.repeat)
            plastic = up.state[:, 0] > st[:, 0]
            apex = (
                np.all(up.stress[:, 3:] == 0, axis=1)
                & np.all(up.stress[:, :3] == up.stress[:, [0]], axis=1)
                & plastic
            )
            unload = -0.2 * de  # 1 % elastic unloading
            t_el, _ = _best(lambda: mat.update(unload, sig, st), args.repeat)
            jac = _jacobians_per_point(mat, de[plastic], sig[plastic], st[plastic])
            print(
                f"{form + '-' + hardening:24} {plastic.mean():8.1%} {apex.mean():6.1%} "
                f"{up.ok.mean():6.1%} {jac:5.2f} {n / t_pl:14,.0f} {n / t_el:14,.0f}"
            )


if __name__ == "__main__":
    main()

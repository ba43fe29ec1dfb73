"""Benchmark (not a test): the 27-node Q2-P1 hexahedron against the 8-node B-bar hexahedron at
equal degrees of freedom, for one plastic case; cost and accuracy measured in the same run.

    OMP_NUM_THREADS=1 python -m bench.perf.hex27 [--case linear-compression] [--pairs 6,8,12]
                                                 [--grading 1] [--reference 12] [--repeat 2]
                                                 [--json PATH]

Each pair is an 8-node n x n x 2n quarter mesh and the 27-node (n/2) x (n/2) x n mesh with the
same nodes (so the same dofs), both solved as the eighth model, uniform or graded (``--grading R``:
the mesh spec token ``gR``, the same for every mesh and the reference). For each: the CPU
time (process clock, best of ``--repeat``, the two elements alternating so both see the same
machine load) of the default plastic run (1.5 mm in 10 snapshots, friction plates,
FORWARD_SETTINGS) and of the same run with exact sensitivities of every material parameter
(response + Jacobian), where the time went (assembly, material, factorisation, solve: wall s of
the best run), and the errors against a fine reference (the 27-node ``--reference`` R x R x 2R
mesh, same grading): plate force at 1.5 mm (%) and the RMS front-face error over the 14 x 29
grid, both components and all snapshots, in units of sigma = 1 um / sqrt(12) (the data's rounding
error).
Printed: one row per mesh and, per pair, the ratios 27-node / 8-node of time and errors.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from problems.fe.front_face import front_face_operator, measurement_grid
from problems.fe.mesh import parse_mesh_spec
from problems.fe.newton import Loading, discretise, run
from problems.inverse.cases import CASES, get_case
from problems.inverse.forward import FORWARD_SETTINGS, case_material

SIGMA_MM = 1e-3 / np.sqrt(12.0)  # one displacement value's rounding error, mm
LOADING = Loading(1.5, 10)


def measured(resp, points) -> dict:
    """Front-face fields (N, m) mm and plate forces (N,) kN of a response."""
    W = front_face_operator(resp.mesh, points)
    return {
        "u_h": resp.displacements[:, :, 1] @ W.T,
        "u_v": resp.displacements[:, :, 2] @ W.T,
        "force": resp.reaction_kN,
    }


def errors(m: dict, ref: dict) -> dict:
    """Force error at the last snapshot, %, and RMS front-face error in sigma units."""
    d = np.concatenate([(m["u_h"] - ref["u_h"]).ravel(), (m["u_v"] - ref["u_v"]).ravel()])
    return {
        "force_pct": 100.0 * (m["force"][-1] / ref["force"][-1] - 1.0),
        "rms_sigma": float(np.sqrt(np.mean(d**2)) / SIGMA_MM),
    }


def timed(disc, material, sensitivities) -> tuple[float, object]:
    """CPU seconds of one run and its response (the discretisation is built beforehand)."""
    t = time.process_time()
    resp = run(disc, material, LOADING, FORWARD_SETTINGS, sensitivities=sensitivities)
    if not resp.converged:
        raise SystemExit(f"run did not converge: {resp.message}")
    return time.process_time() - t, resp


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--case", default="linear-compression", choices=sorted(CASES))
    ap.add_argument("--pairs", default="6,8,12", help="8-node n of each pair (even): n x n x 2n")
    ap.add_argument("--grading", type=float, default=1.0, help="gR of every mesh (1: uniform)")
    ap.add_argument("--reference", type=int, default=12, help="27-node reference R x R x 2R")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--json", type=Path, help="write the rows as JSON here (atomically)")
    args = ap.parse_args(argv)
    pairs = [int(t) for t in args.pairs.split(",")]
    if any(n < 2 or n % 2 for n in pairs):
        print(f"--pairs {args.pairs!r}: each n must be an even whole number >= 2")
        return 2
    if not (np.isfinite(args.grading) and args.grading >= 1.0):
        print(f"--grading {args.grading!r}: a number >= 1 (largest / smallest element length)")
        return 2
    grading = f":g{args.grading:g}"

    def mesh(n, element):
        return parse_mesh_spec(f"{n},{n},{2 * n}{grading}:{element}").mesh

    case = get_case(args.case)
    material = case_material(case, case.reference)
    points = measurement_grid()

    t = time.perf_counter()
    R = args.reference
    ref_resp = run(
        discretise(mesh(R, "hex27"), symmetry="eighth"),
        material,
        LOADING,
        FORWARD_SETTINGS,
    )
    if not ref_resp.converged:
        raise SystemExit(f"reference did not converge: {ref_resp.message}")
    ref = measured(ref_resp, points)
    print(
        f"{args.case}: reference 27-node {R}x{R}x{2 * R}{grading} ({ref_resp.mesh.n_dofs} dofs "
        "quarter), "
        f"force {ref['force'][-1]:.2f} kN at 1.5 mm, {time.perf_counter() - t:.1f} s wall"
    )
    print(
        f"{'mesh':>16} {'dofs':>6} {'run s':>7} {'run+J s':>8} {'J/run':>6} {'asm':>6} {'mat':>6} "
        f"{'fact':>6} {'solve':>6} {'force %':>8} {'RMS sigma':>9}"
    )
    rows = []
    for n in pairs:
        meshes = {
            "8-node": mesh(n, "hex8"),
            "27-node": mesh(n // 2, "hex27"),
        }
        discs = {k: discretise(m, symmetry="eighth") for k, m in meshes.items()}
        best = {k: [np.inf, np.inf, None] for k in meshes}
        for _ in range(args.repeat):
            for k, disc in discs.items():
                for j, sens in enumerate((False, True)):
                    cpu, resp = timed(disc, material, sens)
                    if cpu < best[k][j]:
                        best[k][j] = cpu
                        if not sens:
                            best[k][2] = resp
        pair = {}
        for k, m in meshes.items():
            run_s, jac_s, resp = best[k]
            tm = resp.timing
            row = {
                "element": k,
                "mesh": "x".join(map(str, m.shape)),
                "dofs": m.n_dofs,
                "run_cpu_s": run_s,
                "run_jacobian_cpu_s": jac_s,
                **{key: tm[key] for key in ("assembly_s", "material_s", "factor_s", "solve_s")},
                **errors(measured(resp, points), ref),
            }
            rows.append(row)
            pair[k] = row
            print(
                f"{k + ' ' + row['mesh']:>16} {row['dofs']:>6} {run_s:7.2f} {jac_s:8.2f} "
                f"{jac_s / run_s:6.2f} {tm['assembly_s']:6.2f} {tm['material_s']:6.2f} "
                f"{tm['factor_s']:6.2f} {tm['solve_s']:6.2f} {row['force_pct']:+8.3f} "
                f"{row['rms_sigma']:9.2f}"
            )
        a, b = pair["27-node"], pair["8-node"]
        print(
            f"{'27/8 ratio':>16} {'':>6} {a['run_cpu_s'] / b['run_cpu_s']:7.2f} "
            f"{a['run_jacobian_cpu_s'] / b['run_jacobian_cpu_s']:8.2f} {'':>6} "
            f"{a['assembly_s'] / b['assembly_s']:6.2f} {a['material_s'] / b['material_s']:6.2f} "
            f"{a['factor_s'] / max(b['factor_s'], 1e-9):6.2f} "
            f"{a['solve_s'] / b['solve_s']:6.2f} "
            f"{abs(a['force_pct'] / b['force_pct']):8.3f} {a['rms_sigma'] / b['rms_sigma']:9.3f}"
        )
    if args.json:
        payload = {
            "case": args.case,
            "reference": f"27-node {R}x{R}x{2 * R}{grading}",
            "grading": args.grading,
            "reference_force_kN": float(ref["force"][-1]),
            "omp_num_threads": os.environ.get("OMP_NUM_THREADS"),
            "rows": rows,
        }
        args.json.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=args.json.parent, suffix=".tmp")
        with os.fdopen(fd, "w") as fh:
            json.dump(payload, fh, indent=1)
        os.replace(tmp, args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Comparison (2): the quarter cube between friction plates, femubench against OpenSees bbarBrick on
the same mesh and load steps, trying the OpenSees solution strategies in turn.

Displacements in mm, forces in kN (whole specimen), stresses in MPa.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bench.crosscheck.mapping import opensees_parameters, tension_cutoff_I1
from bench.crosscheck.opensees_box import BASELINE, CURES, opensees_box, summarise_log
from bench.crosscheck.reference import (
    DELTA_MM,
    femubench_box,
    femubench_material,
    mapped,
    pointwise_relative_difference,
    relative_difference,
)

#: front-face points (y, z) mm reported one by one
FRONT_POINTS = np.array([[37.5, 75.0], [75.0, 75.0], [75.0, 140.0], [37.5, 10.0]])


def cube(p: dict, mesh_spec: str, steps: int, all_strategies: bool, log_dir: Path) -> dict:
    """The quarter cube between friction plates: femubench vs OpenSees bbarBrick on the same mesh.

    Every OpenSees attempt is compared with femubench at the same increments (``substeps`` per
    snapshot): both integrate the same equations by backward Euler, so converged answers must
    agree to the solvers' tolerances whatever tangent each Newton uses."""
    from problems.fe.front_face import front_face_operator, measurement_grid
    from problems.fe.mesh import parse_mesh

    mesh = parse_mesh(mesh_spec)
    mat = femubench_material(p)
    osp = opensees_parameters(**mapped(p))
    W_pts = front_face_operator(mesh, FRONT_POINTS)
    W_grid = front_face_operator(mesh, measurement_grid())
    x1 = mesh.face("x1")

    def fields(u):
        """u_h, u_v at the named points and on the 406-point grid, and u_x (bulge) on the front
        face."""
        if len(u) == 0:
            return {
                k: np.zeros((0,)) for k in ("uh_pts", "uv_pts", "uh_grid", "uv_grid", "bulge_max")
            }
        return {
            "uh_pts": u[:, :, 1] @ W_pts.T,
            "uv_pts": u[:, :, 2] @ W_pts.T,
            "uh_grid": u[:, :, 1] @ W_grid.T,
            "uv_grid": u[:, :, 2] @ W_grid.T,
            "bulge_max": u[:, x1, 0].max(axis=1),
        }

    ours_by_substeps: dict[int, dict] = {}

    def ours(substeps: int) -> dict:
        if substeps not in ours_by_substeps:
            resp, wall = femubench_box(mesh, mat, DELTA_MM, steps, "friction", substeps)
            ours_by_substeps[substeps] = {
                "substeps": substeps,
                "snapshots_mm": resp.snapshots_mm,
                "reaction_kN": resp.reaction_kN,
                **fields(resp.displacements),
                "converged": resp.converged,
                "message": resp.message,
                "wall_s": wall,
                "increments": resp.increments,
                "iterations": resp.iterations,
                "cuts": resp.cuts,
                "residual_history_last": resp.residual_history[-1] if resp.residual_history else [],
                "residual_history": resp.residual_history,
                "max_eqps": resp.state[:, :, 0].max(axis=1) if len(resp.state) else np.zeros(0),
                "max_I1": resp.stress[:, :, :3].sum(axis=2).max(axis=1)
                if len(resp.stress)
                else np.zeros(0),
            }
        return ours_by_substeps[substeps]

    ours(1)
    attempts = []
    for strategy in (BASELINE,) + CURES:
        r = opensees_box(mesh, osp, DELTA_MM, steps, "friction", strategy=strategy, log_dir=log_dir)
        n = len(r.snapshots_mm)
        f = fields(r.displacements)
        ref = ours(strategy.substeps) if r.converged else ours_by_substeps[1]
        m = min(n, len(ref["snapshots_mm"]))
        diffs = {}
        if m:
            diffs = {
                "femubench_substeps": ref["substeps"],
                "snapshots_compared": m,
                "force": pointwise_relative_difference(r.reaction_kN[:m], ref["reaction_kN"][:m]),
                "u_h_grid": relative_difference(f["uh_grid"][:m], ref["uh_grid"][:m]),
                "u_v_grid": relative_difference(f["uv_grid"][:m], ref["uv_grid"][:m]),
                "bulge_max": pointwise_relative_difference(
                    f["bulge_max"][:m], ref["bulge_max"][:m]
                ),
            }
        attempts.append(
            {
                "strategy": r.strategy,
                "substeps": strategy.substeps,
                "converged": r.converged,
                "snapshots_mm": r.snapshots_mm,
                "reaction_kN": r.reaction_kN,
                **f,
                "wall_s": r.wall_s,
                "failure": r.failure,
                "log": summarise_log(r.log),
                "differences": diffs,
                "step_iterations": r.step_iterations,
                "norms_last_step": r.step_norms[-1] if r.step_norms else [],
                "step_norms_all": r.step_norms,
                "norms_first_step": r.step_norms[0] if r.step_norms else [],
                "max_I1": (r.stress[:, :, :3].sum(axis=2).max(axis=1) if n else np.zeros(0)),
            }
        )
        if r.converged and not all_strategies:
            break
    out = {
        "psi": p["psi"],
        "mesh": mesh.info(),
        "femubench": ours_by_substeps[1],
        "femubench_runs": list(ours_by_substeps.values()),
        "opensees": attempts,
        "tension_cutoff_I1": tension_cutoff_I1(osp),
        "front_points": FRONT_POINTS,
    }
    out["plot"] = plot_data(out)
    return out


def plot_data(cb: dict) -> dict:
    """What the cube figure shows of the first converged OpenSees attempt, beside femubench at the
    same increments: u_h (mm) along the front face at y = 70 mm against z (mm) at the last common
    snapshot, and the Newton residuals (relative to the first) of the step OpenSees needed most
    iterations for.
    Empty when no attempt converged."""
    good = [a for a in cb["opensees"] if a["converged"]]
    if not good:
        return {}
    a = good[0]
    ref = next(o for o in cb["femubench_runs"] if o["substeps"] == a["substeps"])
    m = min(len(a["snapshots_mm"]), len(ref["snapshots_mm"])) - 1
    grid_z = np.arange(5.0, 145.0 + 1e-9, 5.0)  # measurement grid: z fastest, 29 z values per y
    nz = grid_z.size
    k = int(np.argmax(a["step_iterations"]))
    nrm = np.asarray(a["step_norms_all"][k], float)
    hist = np.asarray(ref["residual_history"][k] if len(ref["residual_history"]) > k else [], float)
    return {
        "strategy": a["strategy"],
        "at_mm": float(ref["snapshots_mm"][m]),
        "z_mm": grid_z,
        "u_h_femubench": np.asarray(ref["uh_grid"][m])[-nz:],
        "u_h_opensees": np.asarray(a["uh_grid"][m])[-nz:],
        "step": k + 1,
        "residuals_opensees": nrm / nrm[0] if nrm.size else nrm,
        "residuals_femubench": hist / hist[0] if hist.size else hist,
    }

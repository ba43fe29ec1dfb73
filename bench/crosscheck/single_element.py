"""Comparison (1): one 150 mm brick under frictionless uniaxial compression to 1.5 mm, in
femubench's FE (1 x 1 x 1), its material-point driver, the closed form and OpenSees
(bbarBrick and stdBrick).

Stresses in MPa (compression positive), strains dimensionless (lateral: expansion positive).
"""

from __future__ import annotations

from pathlib import Path

from bench.crosscheck.mapping import opensees_parameters
from bench.crosscheck.opensees_box import opensees_box, summarise_log
from bench.crosscheck.reference import (
    DELTA_MM,
    SIZE_MM,
    femubench_box,
    femubench_material,
    mapped,
    material_point_uniaxial,
    pointwise_relative_difference,
    uniaxial_closed_form,
)


def single_element(p: dict, steps: int, log_dir: Path) -> dict:
    """One 150 mm brick, frictionless plates, 1.5 mm: femubench FE (1x1x1), material point,
    closed form and OpenSees (bbarBrick and stdBrick)."""
    from problems.fe.mesh import box_mesh

    mesh = box_mesh(1, 1, 1, size_mm=(SIZE_MM, SIZE_MM, SIZE_MM))
    mat = femubench_material(p)
    osp = opensees_parameters(**mapped(p))
    resp, wall_fe = femubench_box(mesh, mat, DELTA_MM, steps, "frictionless")
    if not resp.converged:
        raise RuntimeError(f"femubench single element failed: {resp.message}")
    strain = resp.snapshots_mm / SIZE_MM
    x1 = mesh.face("x1")
    ours = {
        "stress": -resp.stress[:, 0, 2],
        "lateral": resp.displacements[:, x1, 0].mean(axis=1) / SIZE_MM,
        "eqps": resp.state[:, 0, 0],
    }
    mp_s, mp_l, mp_e = material_point_uniaxial(mat, strain)
    cf_s, cf_l = uniaxial_closed_form(strain, **mapped(p))
    out = {
        "psi": p["psi"],
        "strain": strain,
        "femubench": ours,
        "wall_femubench_s": wall_fe,
        "material_point": {"stress": mp_s, "lateral": mp_l, "eqps": mp_e},
        "closed_form": {"stress": cf_s, "lateral": cf_l},
        "opensees": {},
        "differences": {},
    }
    for element in ("bbarBrick", "stdBrick"):
        r = opensees_box(
            mesh,
            osp,
            DELTA_MM,
            steps,
            "frictionless",
            element=element,
            quarter=False,
            log_dir=log_dir,
        )
        n = len(r.snapshots_mm)
        os_s = -r.stress[:, 0, 2]
        os_l = r.displacements[:, x1, 0].mean(axis=1) / SIZE_MM
        out["opensees"][element] = {
            "converged": r.converged,
            "stress": os_s,
            "lateral": os_l,
            "force_stress": r.force_N / SIZE_MM**2,
            "wall_s": r.wall_s,
            "step_iterations": r.step_iterations,
            "failure": r.failure,
            "log": summarise_log(r.log),
        }
        out["differences"][element] = {
            "snapshots_compared": n,
            "stress_vs_femubench": pointwise_relative_difference(os_s, ours["stress"][:n]),
            "lateral_vs_femubench": pointwise_relative_difference(os_l, ours["lateral"][:n]),
            "stress_vs_closed_form": pointwise_relative_difference(os_s, cf_s[:n]),
            "lateral_vs_closed_form": pointwise_relative_difference(os_l, cf_l[:n]),
            "reaction_vs_element_stress": pointwise_relative_difference(
                r.force_N / SIZE_MM**2, os_s
            ),
        }
    out["differences"]["femubench"] = {
        "stress_vs_closed_form": pointwise_relative_difference(ours["stress"], cf_s),
        "lateral_vs_closed_form": pointwise_relative_difference(ours["lateral"], cf_l),
        "stress_vs_material_point": pointwise_relative_difference(ours["stress"], mp_s),
        "lateral_vs_material_point": pointwise_relative_difference(ours["lateral"], mp_l),
        "eqps_vs_abs_eps_pl_11": pointwise_relative_difference(
            ours["eqps"], strain - ours["stress"] / p["E"], floor=1e-12
        ),
    }
    return out

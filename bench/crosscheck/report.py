"""The cross-check's report: JSON form (``opensees_dp.json``, without the per-point grids and
per-step residual histories) and the tables printed to the console."""

from __future__ import annotations

import numpy as np

from bench.crosscheck.reference import pointwise_relative_difference, relative_difference

#: the report's file name in the output folder
REPORT_FILE = "opensees_dp.json"


def jsonable(x):
    """``x`` with numpy arrays and numbers as JSON values (non-finite floats as null)."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, (np.floating, float)):
        return None if not np.isfinite(x) else float(x)
    if isinstance(x, np.integer):
        return int(x)
    return x


_BULKY = ("uh_grid", "uv_grid", "step_norms_all", "residual_history")


def slim(x):
    """The report without the per-point grids and per-step residual histories (only the printed
    tables use them; the figures' share is in each cube's ``plot``)."""
    if isinstance(x, dict):
        return {k: slim(v) for k, v in x.items() if k not in _BULKY}
    if isinstance(x, list):
        return [slim(v) for v in x]
    return x


def print_report(report: dict) -> None:
    """Print the mapping, the single-element and cube comparisons and the tangent audit."""
    print(f"openseespy {report['openseespy']}  |  total wall time {report['wall_s']:.1f} s")
    print("\nParameter mapping (femubench linear, K = 1 -> OpenSees DruckerPrager):")
    for m in report["mappings"]:
        osp = m["opensees"]
        print(
            f"  psi = {m['psi']:>4g} deg: "
            + "  ".join(f"{k}={v:.6g}" for k, v in osp.items())
            + f"  | tension cutoff I1 = {m['tension_cutoff_I1']:.4g} MPa"
        )
    print("\nSingle element (150 mm, frictionless, 1.5 mm): max pointwise relative difference")
    print(
        f"  {'psi':>4} {'model':22} {'axial stress':>13} {'lateral strain':>15} "
        f"{'final sigma MPa':>16} {'final eps_lat':>14}"
    )
    for se in report["single_element"]:
        d = se["differences"]
        print(
            f"  {se['psi']:>4g} {'femubench vs closed':22} "
            f"{d['femubench']['stress_vs_closed_form']:13.2e} "
            f"{d['femubench']['lateral_vs_closed_form']:15.2e} "
            f"{se['femubench']['stress'][-1]:16.4f} {se['femubench']['lateral'][-1]:14.6e}"
        )
        print(
            f"  {se['psi']:>4g} {'femubench vs mat.point':22} "
            f"{d['femubench']['stress_vs_material_point']:13.2e} "
            f"{d['femubench']['lateral_vs_material_point']:15.2e}"
        )
        for el, o in se["opensees"].items():
            dd = d[el]
            print(
                f"  {se['psi']:>4g} {'OpenSees ' + el + ' vs fem.':22} "
                f"{dd['stress_vs_femubench']:13.2e} {dd['lateral_vs_femubench']:15.2e} "
                f"{o['stress'][-1]:16.4f} {o['lateral'][-1]:14.6e}  ({sum(o['step_iterations'])} "
                f"Newton iterations in {len(o['step_iterations'])} "
                f"steps){'' if o['converged'] else '  (FAILED: ' + str(o['failure']) + ')'}"
            )
    for cb in report.get("cube", []):
        print(
            f"\nQuarter cube {cb['mesh']['nx']}x{cb['mesh']['ny']}x{cb['mesh']['nz']}, friction "
            f"plates, psi = {cb['psi']:g} deg (OpenSees tension cutoff at I1 = "
            f"{cb['tension_cutoff_I1']:.4g} MPa)"
        )
        for o in cb["femubench_runs"]:
            print(
                f"  femubench, {o['substeps']:3d} increment(s)/snapshot: "
                f"{'converged' if o['converged'] else 'FAILED ' + o['message']}, F = "
                f"{o['reaction_kN'][-1]:.3f} kN at {o['snapshots_mm'][-1]:.3g} mm, "
                f"{o['increments']} increments, {o['iterations']} iterations, {o['wall_s']:.1f} s, "
                f"max I1 {o['max_I1'].max():.3g} MPa"
            )
        for a in cb["opensees"]:
            head = f"  OpenSees [{a['strategy']}]: "
            its = a["step_iterations"]
            if a["converged"]:
                d = a["differences"]
                print(
                    head + f"converged, {len(its)} steps, {sum(its)} iterations (max "
                    f"{max(its)}/step), {a['wall_s']:.1f} s, F = {a['reaction_kN'][-1]:.3f} "
                    "kN;\n      max rel. diff. vs femubench at the same increments: force "
                    f"{d['force']:.2e}, u_h grid {d['u_h_grid']:.2e}, u_v grid "
                    f"{d['u_v_grid']:.2e}, bulge {d['bulge_max']:.2e}"
                )
            else:
                fl = a["failure"]
                print(
                    head + f"FAILED at snapshot {fl['snapshot']} (step {fl['top_mm_from']:.4g} -> "
                    f"{fl['top_mm_to']:.4g} mm) after {fl['iterations']} iterations, "
                    f"{sum(its)} in all, {a['wall_s']:.1f} s;\n      norms "
                    f"{' '.join('%.2g' % v for v in fl['first_norms'])} ... "
                    f"{' '.join('%.2g' % v for v in fl['last_norms'][-3:])}; "
                    f"{len(a['snapshots_mm'])} snapshots done; OpenSees log: "
                    f"{a['log']['first'][:2]}"
                )
        good = [a for a in cb["opensees"] if a["converged"]]
        if good:
            a = good[0]
            ref = next(o for o in cb["femubench_runs"] if o["substeps"] == a["substeps"])
            m = min(len(a["snapshots_mm"]), len(ref["snapshots_mm"]))
            print(
                f"  front-face points at {ref['snapshots_mm'][m - 1]:.3g} mm, femubench "
                f"({ref['substeps']} incr./snapshot) / OpenSees [{a['strategy']}] (y, z mm: u_h, "
                "u_v mm):"
            )
            for i, (y, z) in enumerate(cb["front_points"]):
                print(
                    f"    ({y:5.1f}, {z:5.1f}): u_h {ref['uh_pts'][m - 1][i]:+.6f} / "
                    f"{a['uh_pts'][m - 1][i]:+.6f}   u_v {ref['uv_pts'][m - 1][i]:+.6f} / "
                    f"{a['uv_pts'][m - 1][i]:+.6f}"
                )
            o1 = cb["femubench"]
            n1 = len(o1["snapshots_mm"])
            print(
                f"  step-size effect (femubench {n1} vs {ref['substeps'] * n1} increments): force "
                f"{pointwise_relative_difference(o1['reaction_kN'], ref['reaction_kN']):.2e}, u_h "
                f"grid {relative_difference(o1['uh_grid'], ref['uh_grid']):.2e}"
            )
    if report.get("tangent_audit"):
        print(
            "\nOpenSees material tangent (psi = 35) vs the derivative of its own stress (one "
            "element, homogeneous strain), max |dC| / max |C|:"
        )
        for t in report["tangent_audit"]:
            print(
                f"  {t['state']:30}: OpenSees tangent {t['opensees_vs_fd']:.2e}, consistent "
                f"formula {t['consistent_formula_vs_fd']:.2e}; OpenSees = formula with the "
                f"returned ||s|| to {t['returned_norm_formula_vs_opensees']:.2e}; stress vs "
                f"re-derived return {t['stress_difference']:.1e}"
            )

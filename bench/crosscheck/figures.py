"""Figures of the OpenSees cross-check, drawn from ``opensees_dp.json`` alone (style:
:mod:`bench.plotting`; one colour per dilatancy angle, and each model also differs by line or
marker).

* ``single_element.png``: axial stress (MPa) and lateral strain (1e-3) against the axial shortening
  (1e-3) of the single element: closed form, femubench FE, femubench material point, OpenSees.
* ``cube.png`` (when the cube ran): plate force (kN) against plate displacement (mm); u_h (mm)
  along the front face at y = 70 mm; Newton residuals of the hardest step against the iteration.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from bench.crosscheck.report import REPORT_FILE
from bench.plotting import COLOURS, integer_axis, log_axis, pyplot, row, save


def render_crosscheck(folder) -> list[Path]:
    """Draw the figures of ``folder/opensees_dp.json`` into ``folder``; returns their paths."""
    folder = Path(folder)
    path = folder / REPORT_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{path} does not exist: run `femubench crosscheck` first")
    report = json.loads(path.read_text())
    paths = [single_element_figure(report["single_element"], folder / "single_element.png")]
    if report.get("cube"):
        paths.append(cube_figure(report["cube"], folder / "cube.png"))
    return paths


def _arr(values) -> np.ndarray:
    return np.asarray(values if values is not None else [], dtype=float)


def single_element_figure(single: list[dict], path) -> Path:
    """Stress and lateral strain against shortening, one colour per dilatancy angle."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=row(2, 4.2))
    for c, se in zip(COLOURS, single):
        e = 1e3 * _arr(se["strain"])
        e0 = np.r_[0.0, e]
        lab = rf"$\psi$ = {se['psi']:g}°"
        for ax, key in zip(axes, ("stress", "lateral")):
            scale = 1.0 if key == "stress" else 1e3
            ax.plot(
                e0,
                scale * np.r_[0.0, _arr(se["closed_form"][key])],
                "-",
                color=c,
                lw=3,
                alpha=0.3,
                label=f"closed form, {lab}",
            )
            ax.plot(
                e0,
                scale * np.r_[0.0, _arr(se["femubench"][key])],
                "-",
                color=c,
                lw=1.2,
                label=f"femubench FE 1x1x1, {lab}",
            )
            ax.plot(
                e0, scale * np.r_[0.0, _arr(se["material_point"][key])], ":", color="black", lw=1
            )
            for mk, (el, o) in zip(("o", "x"), se["opensees"].items()):
                y = _arr(o[key])
                ax.plot(
                    e[: y.size][::3],
                    scale * y[::3],
                    mk,
                    color=c,
                    ms=5,
                    mfc="none",
                    label=f"OpenSees {el}, {lab}",
                )
    for ax in axes:
        ax.set_xlabel("axial shortening (1e-3)")
    axes[0].set_ylabel("axial stress, compression (MPa)")
    axes[1].set_ylabel("lateral strain (1e-3)")
    axes[0].legend()
    axes[0].set_title("single element, uniaxial compression")
    axes[1].set_title("dilatancy (dotted: femubench material point)")
    fig.tight_layout()
    return save(fig, path)


def cube_figure(cubes: list[dict], path) -> Path:
    """Force-displacement, front-face profile and Newton convergence of the quarter cube."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=row(3, 4.6))
    for c, cb in zip(COLOURS, cubes):
        lab = rf"$\psi$ = {cb['psi']:g}°"
        ours = cb["femubench"]
        axes[0].plot(
            np.r_[0, _arr(ours["snapshots_mm"])],
            np.r_[0, _arr(ours["reaction_kN"])],
            "-",
            color=c,
            label=f"femubench, {lab}",
        )
        for a in cb["opensees"]:
            if len(a["snapshots_mm"]):
                axes[0].plot(
                    _arr(a["snapshots_mm"]),
                    _arr(a["reaction_kN"]),
                    "o" if a["converged"] else "D",
                    color=c,
                    mfc="none",
                    ms=7 if a["converged"] else 5,
                    label="OpenSees "
                    f"[{a['strategy']}]{'' if a['converged'] else ' (failed after)'}, {lab}",
                )
        pd = cb.get("plot") or {}
        if not pd:
            continue
        axes[1].plot(
            _arr(pd["u_h_femubench"]), _arr(pd["z_mm"]), "-", color=c, label=f"femubench, {lab}"
        )
        axes[1].plot(
            _arr(pd["u_h_opensees"]),
            _arr(pd["z_mm"]),
            "o",
            color=c,
            mfc="none",
            label=f"OpenSees, {lab}",
        )
        axes[1].set_title(
            f"front face y = 70 mm at {pd['at_mm']:.3g} mm (both at OpenSees's converged step "
            "size)",
            fontsize=8,
        )
        nrm, hist = _arr(pd["residuals_opensees"]), _arr(pd["residuals_femubench"])
        if nrm.size:
            axes[2].plot(
                np.arange(1, nrm.size + 1),
                nrm,
                "o-",
                color=c,
                mfc="none",
                label=f"OpenSees [{pd['strategy']}], step {pd['step']}, {lab}",
            )
        if hist.size:
            axes[2].plot(
                np.arange(1, hist.size + 1),
                hist,
                "s-",
                color=c,
                label=f"femubench, step {pd['step']}, {lab}",
            )
    axes[0].set_xlabel("plate displacement (mm)")
    axes[0].set_ylabel("plate force, whole cube (kN)")
    axes[0].set_title("quarter cube, friction plates")
    axes[0].legend(fontsize=6)
    axes[1].set_xlabel("$u_h = u_y$ (mm)")
    axes[1].set_ylabel("z (mm)")
    if axes[1].lines:
        axes[1].legend()
    axes[2].set_xlabel("Newton iteration (-)")
    axes[2].set_ylabel("residual / first residual (-)")
    axes[2].set_title("convergence rate")
    if axes[2].lines:
        log_axis(axes[2], "y")
        axes[2].legend(fontsize=6)
    integer_axis(axes[2], "x")
    fig.tight_layout()
    return save(fig, path)

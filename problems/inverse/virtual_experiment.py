"""Virtual experiments: the files a laboratory would have, written from an FE run.

:func:`write_virtual_experiment` runs the FE model of a rectangular specimen (a *data* mesh, finer
than any inverse model) at chosen parameters and writes what a lab brings to
``femubench calibrate``: an experiment file, a machine log (plate displacement and force with
load-cell noise, rows between the images too) and one DIC export per image in pixels, as a
camera slightly rotated against the face sees it, with per-point correlation noise (and its
sigma), a small in-plane rigid drift of the specimen, and points off the face (the platens and
the background). See docs/calibrating.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from problems.fe.newton import MachineLoading
from problems.inverse.cases import get_case
from problems.inverse.experiment import PLATENS


@dataclass(frozen=True)
class VirtualTest:
    """What makes a virtual experiment (lengths mm, forces kN, angles rad unless named).

    variant, x      : the Drucker-Prager variant (a case name) and its identified parameters
    width_mm, depth_mm, height_mm, platens : the specimen (width: the face the camera sees)
    levels_mm       : plate displacement at each image
    data_mesh       : the FE mesh that makes the data (a spec, e.g. ``fine``)
    mm_per_px, rotation_deg, corner_px : the camera: scale, rotation of the image against the
                      face, image position of the face's bottom-left corner (image y down)
    spacing_mm      : DIC grid step; the grid overhangs the face by one step (off-face points)
    noise_px        : (low, high) range of the per-point DIC standard deviation, px
    drift_mm, drift_rad : rigid in-plane drift at the last image (translation h, v; rotation),
                      growing linearly with the image index
    load_cell_class : ISO 7500-1 class of the force (uniform error within +-class % of reading)
    force_step_kN   : the log's force resolution
    seed            : of every random draw
    """

    variant: str
    x: tuple[float, ...]
    width_mm: float = 100.0
    depth_mm: float = 100.0
    height_mm: float = 100.0
    platens: str = "bonded"
    levels_mm: tuple[float, ...] = (0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7)
    data_mesh: str = "fine"
    mm_per_px: float = 0.05
    rotation_deg: float = 0.4
    corner_px: tuple[float, float] = (300.0, 2400.0)
    spacing_mm: float = 5.0
    noise_px: tuple[float, float] = (0.01, 0.03)
    drift_mm: tuple[float, float] = (0.02, -0.015)
    drift_rad: float = 1e-4
    load_cell_class: float = 1.0
    force_step_kN: float = 0.01
    seed: int = 0


def write_virtual_experiment(test: VirtualTest, out_dir: str | Path, name: str) -> Path:
    """Run the FE model of ``test`` and write ``experiment.toml``, ``machine_log.csv`` and
    ``dic/image_NN.csv`` into ``out_dir``; returns the experiment file. RuntimeError when the
    data model does not converge."""
    from problems.inverse.forward import FEForwardModel

    out = Path(out_dir)
    (out / "dic").mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(test.seed)
    case = get_case(test.variant)
    W, D, H = test.width_mm, test.depth_mm, test.height_mm
    loading = MachineLoading(test.levels_mm, PLATENS[test.platens])
    model = FEForwardModel(case, test.data_mesh, loading, specimen_mm=(D, W, H))
    resp = model.response(np.asarray(test.x, float))
    if not resp.converged:
        raise RuntimeError(f"the data model of {name} failed: {resp.message}")
    # DIC grid over the face and one step beyond (the platens, the background)
    h = test.spacing_mm
    s_grid = np.arange(-h / 2, W + h, h)
    z_grid = np.arange(-h / 2, H + h, h)
    S, Z = (a.ravel() for a in np.meshgrid(s_grid, z_grid, indexing="ij"))
    on = (S >= 0) & (S <= W) & (Z >= 0) & (Z <= H)
    y = S - W / 2
    sign = np.where(y < 0, -1.0, 1.0)
    pts = np.column_stack([np.abs(y[on]), Z[on]])
    fh, fv = resp.front_face(pts)  # (N, m_on) folded face
    N = len(test.levels_mm)
    u_s, u_z = np.zeros((N, len(S))), np.zeros((N, len(S)))
    u_s[:, on], u_z[:, on] = sign[on] * fh, fv
    # off the face: the bottom platen stays, the top one moves down, the background stays
    top = Z > H
    u_z[:, top] = -np.asarray(test.levels_mm)[:, None]
    frac = (np.arange(N) + 1) / N
    sc, zc = W / 2, H / 2
    th, tv = (frac * d for d in test.drift_mm)
    om = frac * test.drift_rad
    u_s += th[:, None] - om[:, None] * (Z - zc)
    u_z += tv[:, None] + om[:, None] * (S - sc)
    # camera: image (px, y down) -> face mm is [s, z] = A [x, y] + c
    a = math.radians(test.rotation_deg)
    k = test.mm_per_px
    A = k * np.array([[math.cos(a), math.sin(a)], [math.sin(a), -math.cos(a)]])
    Ainv = np.linalg.inv(A)
    c = -A @ np.asarray(test.corner_px, float)
    P = (np.column_stack([S, Z]) - c) @ Ainv.T
    sigma_px = rng.uniform(*test.noise_px, size=len(S))
    corners = (np.array([[0, 0], [W, 0], [W, H], [0, H]], float) - c) @ Ainv.T
    for i in range(N):
        U = np.column_stack([u_s[i], u_z[i]]) @ Ainv.T
        U += rng.normal(0.0, 1.0, U.shape) * sigma_px[:, None]
        rows = ["x,y,u,v,sigma"] + [
            f"{p[0]:.4f},{p[1]:.4f},{u[0]:.5f},{u[1]:.5f},{s:.4g}"
            for p, u, s in zip(P, U, sigma_px)
        ]
        (out / "dic" / f"image_{i + 1:02d}.csv").write_text("\n".join(rows) + "\n")
    # machine log: images plus three rows between each, force with a uniform class error
    q = test.load_cell_class / 100.0
    levels = np.concatenate([[0.0], test.levels_mm])
    force = np.concatenate([[0.0], resp.reaction_kN])
    lines = ["time_s,displacement_mm,force_kN,image"]
    t = 0.0
    for i in range(1, N + 1):
        for j in range(4):
            f_ = (j + 1) / 4
            d = levels[i - 1] + f_ * (levels[i] - levels[i - 1])
            f = force[i - 1] + f_ * (force[i] - force[i - 1])
            f *= 1.0 + rng.uniform(-q, q)
            f = round(f / test.force_step_kN) * test.force_step_kN
            t += 1.0
            image = f"image_{i:02d}" if j == 3 else ""
            lines.append(f"{t:.1f},{d:.5f},{f:.3f},{image}")
    (out / "machine_log.csv").write_text("\n".join(lines) + "\n")
    corner_text = ", ".join(f"[{x:.3f}, {y:.3f}]" for x, y in corners)
    toml = f"""# A virtual experiment, written by problems/inverse/virtual_experiment.py from the FE
# model of variant {test.variant} on mesh {test.data_mesh} (never an inverse mesh) at
# {", ".join(f"{n} = {v:g}" for n, v in zip(case.names, test.x))}.
[experiment]
name = "{name}"
description = "virtual {W:g} x {D:g} x {H:g} mm specimen, {test.platens} platens"

[specimen]
width_mm = {W:g}
depth_mm = {D:g}
height_mm = {H:g}
platens = "{test.platens}"

[camera]
face = "front"
units = "px"
corners = [{corner_text}]
roi_margin_mm = 1.0

[loading]
log = "machine_log.csv"
displacement_column = "displacement_mm"
force_column = "force_kN"
image_column = "image"
displacement_unit = "mm"
force_unit = "kN"
load_cell_class = {test.load_cell_class:g}
force_resolution = {test.force_step_kN:g}

[dic]
files = "dic/image_*.csv"
columns = {{ x = "x", y = "y", u = "u", v = "v", sigma = "sigma" }}

[calibration]
mesh = "coarse"
models = "all"
"""
    path = out / "experiment.toml"
    path.write_text(toml)
    return path

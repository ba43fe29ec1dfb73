"""Virtual experiments: the files a laboratory would have, written from an FE run.

:func:`write_virtual_experiment` runs the FE model of a rectangular specimen (a *data* mesh, finer
than any inverse model) at chosen parameters and writes what a lab brings to
``femubench calibrate``: an experiment file, a machine log (plate displacement and force with
load-cell noise, rows between the images too) and one DIC export per image in pixels, as a
camera slightly rotated against the face sees it, with per-point correlation noise (and its
sigma), a small in-plane rigid drift of the specimen, and points off the face (the platens and
the background). :func:`write_virtual_images` writes the same test as speckle images instead
of a DIC export (the experiment file's ``[images]`` route): a reference and one image per load
step, rendered by femubench's speckle renderer from the FE field with camera noise and the drift.
See docs/calibrating.md.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from problems.fe.newton import MachineLoading
from problems.inverse.cases import get_case
from problems.inverse.experiment import PLATENS
from problems.io.atomic import atomic_write_text


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
    noise_scale     : multiplies every noise draw (the DIC points', the load cell's, the camera's)
                      while the declared sigma and load-cell class stay: 0 makes the noise-free
                      twin of the experiment (the same draws otherwise), whose calibration error
                      is the inverse model's alone
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
    noise_scale: float = 1.0


def _data_response(test: VirtualTest, name: str):
    """The data model's FE response of ``test`` (RuntimeError when it does not converge)."""
    from problems.inverse.forward import FEForwardModel

    case = get_case(test.variant)
    loading = MachineLoading(test.levels_mm, PLATENS[test.platens])
    specimen = (test.depth_mm, test.width_mm, test.height_mm)
    model = FEForwardModel(case, test.data_mesh, loading, specimen_mm=specimen)
    resp = model.response(np.asarray(test.x, float))
    if not resp.converged:
        raise RuntimeError(f"the data model of {name} failed: {resp.message}")
    return resp


def _drift(test: VirtualTest, k: int, s_mm, z_mm):
    """Rigid in-plane drift (u_s, u_z) mm of image ``k`` (1-based) at face points (s, z) mm:
    growing linearly to ``drift_mm`` and ``drift_rad`` (about the face's centre) at the last."""
    frac = k / len(test.levels_mm)
    om = frac * test.drift_rad
    u_s = frac * test.drift_mm[0] - om * (np.asarray(z_mm) - test.height_mm / 2)
    u_z = frac * test.drift_mm[1] + om * (np.asarray(s_mm) - test.width_mm / 2)
    return u_s, u_z


def _write_log(test: VirtualTest, reaction_kN, out: Path, rng) -> None:
    """``machine_log.csv``: the images' rows and three rows between each, the force with a
    uniform load-cell error within +-class % and rounded to the log's step."""
    q = test.load_cell_class / 100.0
    N = len(test.levels_mm)
    levels = np.concatenate([[0.0], test.levels_mm])
    force = np.concatenate([[0.0], reaction_kN])
    lines = ["time_s,displacement_mm,force_kN,image"]
    t = 0.0
    for i in range(1, N + 1):
        for j in range(4):
            f_ = (j + 1) / 4
            d = levels[i - 1] + f_ * (levels[i] - levels[i - 1])
            f = force[i - 1] + f_ * (force[i] - force[i - 1])
            f *= 1.0 + test.noise_scale * rng.uniform(-q, q)
            f = round(f / test.force_step_kN) * test.force_step_kN
            t += 1.0
            image = f"image_{i:02d}" if j == 3 else ""
            lines.append(f"{t:.1f},{d:.5f},{f:.3f},{image}")
    atomic_write_text(out / "machine_log.csv", "\n".join(lines) + "\n")


def _write_toml(test: VirtualTest, out: Path, name: str, camera: str, measurement: str) -> Path:
    """``experiment.toml`` of ``test`` with the ``[camera]`` keys and the measurement table
    (``[dic]`` or ``[images]``, header included) given as TOML text."""
    case = get_case(test.variant)
    W, D, H = test.width_mm, test.depth_mm, test.height_mm
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
{camera}
[loading]
log = "machine_log.csv"
displacement_column = "displacement_mm"
force_column = "force_kN"
image_column = "image"
displacement_unit = "mm"
force_unit = "kN"
load_cell_class = {test.load_cell_class:g}
force_resolution = {test.force_step_kN:g}

{measurement}
[calibration]
mesh = "coarse"
models = "all"

[virtual]
data_mesh = "{test.data_mesh}"
"""
    return atomic_write_text(out / "experiment.toml", toml)


def write_virtual_experiment(test: VirtualTest, out_dir: str | Path, name: str) -> Path:
    """Run the FE model of ``test`` and write ``experiment.toml``, ``machine_log.csv`` and
    ``dic/image_NN.csv`` into ``out_dir``; returns the experiment file. RuntimeError when the
    data model does not converge."""
    out = Path(out_dir)
    (out / "dic").mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(test.seed)
    W, H = test.width_mm, test.height_mm
    resp = _data_response(test, name)
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
    for k in range(N):
        ds, dz = _drift(test, k + 1, S, Z)
        u_s[k] += ds
        u_z[k] += dz
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
        U += rng.normal(0.0, 1.0, U.shape) * (test.noise_scale * sigma_px[:, None])
        rows = ["x,y,u,v,sigma"] + [
            f"{p[0]:.4f},{p[1]:.4f},{u[0]:.5f},{u[1]:.5f},{s:.4g}"
            for p, u, s in zip(P, U, sigma_px)
        ]
        atomic_write_text(out / "dic" / f"image_{i + 1:02d}.csv", "\n".join(rows) + "\n")
    _write_log(test, resp.reaction_kN, out, rng)
    corner_text = ", ".join(f"[{x:.3f}, {y:.3f}]" for x, y in corners)
    camera = f'units = "px"\ncorners = [{corner_text}]\nroi_margin_mm = 1.0\n'
    dic = (
        '[dic]\nfiles = "dic/image_*.csv"\n'
        'columns = { x = "x", y = "y", u = "u", v = "v", sigma = "sigma" }\n'
    )
    return _write_toml(test, out, name, camera, dic)


@dataclass(frozen=True)
class VirtualImages:
    """The camera and the speckle of an images virtual experiment (femubench's renderer,
    :mod:`problems.dic.speckle`; the camera's axes along the face's, image y down).

    mm_per_px   : scale on the specimen, mm per pixel (the face must span whole pixels)
    margin_px   : background band around the face, px
    bit_depth   : 8 or 16 (PNG)
    noise_grey  : Gaussian camera noise, grey levels of the bit depth
    speckle_mm  : nominal speckle diameter, mm (3 to 5 px correlate best)
    supersample : sub-samples per pixel and direction when rendering
    map_step    : the inverse mapping solved every map_step px (interpolated between)
    subset, step: the DIC settings written to the experiment file's ``[images]``, px
    """

    mm_per_px: float = 0.2
    margin_px: int = 16
    bit_depth: int = 8
    noise_grey: float = 2.0
    speckle_mm: float = 0.8
    supersample: int = 3
    map_step: int = 2
    subset: int = 21
    step: int = 21


def _camera(test: VirtualTest, images: VirtualImages):
    """The camera of ``test``'s images (ValueError when the face is not whole pixels)."""
    from problems.dic.speckle import CameraConfig

    W, H, p = test.width_mm, test.height_mm, images.mm_per_px
    pixels = (round(W / p), round(H / p))
    if not (abs(pixels[0] * p - W) < 1e-9 * W and abs(pixels[1] * p - H) < 1e-9 * H):
        raise ValueError(f"mm_per_px = {p:g}: the {W:g} x {H:g} mm face is not whole pixels")
    return CameraConfig(
        pixels=pixels,
        face_mm=(W, H),
        margin_px=images.margin_px,
        bit_depth=images.bit_depth,
        noise_sigma=images.noise_grey,
        supersample=images.supersample,
        map_step=images.map_step,
    )


def render_virtual_images(test: VirtualTest, images: VirtualImages | None = None, resp=None):
    """The noise-free images of ``test`` (:func:`write_virtual_images` before the camera's noise):
    ``(camera, intensities)``, the reference's then each image's full-scale fractions (float
    arrays, rows x cols) of the face deformed by the FE field plus ``test``'s rigid drift.
    ``resp``: the data model's response when already computed (else it is run)."""
    from problems.dic.pipeline import pixel_displacement
    from problems.dic.speckle import SpeckleConfig, face_pattern, render_face_intensity

    images = images or VirtualImages()
    W, p = test.width_mm, images.mm_per_px
    camera = _camera(test, images)
    speckle = SpeckleConfig(size_mm=images.speckle_mm)
    resp = resp if resp is not None else _data_response(test, "the virtual images")

    def snapshot(k: int):
        def field(y, z):  # the quarter face (y >= 0, mm) of snapshot k
            shape = np.shape(y)
            fh, fv = resp.front_face(np.column_stack([np.ravel(y), np.ravel(z)]))
            return fh[k].reshape(shape), fv[k].reshape(shape)

        face = pixel_displacement(field, camera)

        def disp(X, Y):  # px: the FE field plus the drift of image k + 1
            ux, uy = face(X, Y)
            y, z = camera.px_to_mm(X, Y)
            ds, dz = _drift(test, k + 1, y + W / 2, z)
            return ux + ds / p, uy - dz / p

        return disp

    pattern = face_pattern(speckle, camera, test.seed)
    intensities = [
        render_face_intensity(camera, speckle, pattern, None if k == 0 else snapshot(k - 1))
        for k in range(len(test.levels_mm) + 1)
    ]
    return camera, intensities


def write_virtual_images(
    test: VirtualTest, out_dir: str | Path, name: str, images: VirtualImages | None = None
) -> Path:
    """Run the FE model of ``test`` and write ``experiment.toml`` (the ``[images]`` route),
    ``machine_log.csv`` and ``images/reference.png``, ``images/image_NN.png``: speckle images of
    the face (:class:`VirtualImages`) deformed by the FE field of each image plus ``test``'s
    rigid drift, with camera noise; returns the experiment file. The calibration is the face's
    bottom-left corner in the image and the scale (``test``'s camera rotation, corner and DIC
    noise are those of the CSV route and not used here)."""
    from problems.dic.imageio import write_image
    from problems.dic.speckle import acquire

    images = images or VirtualImages()
    out = Path(out_dir)
    (out / "images").mkdir(parents=True, exist_ok=True)
    W, p = test.width_mm, images.mm_per_px
    _camera(test, images)  # a bad scale is refused before the FE run
    resp = _data_response(test, name)
    camera, intensities = render_virtual_images(test, images, resp)
    names = ["reference.png"] + [f"image_{k:02d}.png" for k in range(1, len(test.levels_mm) + 1)]
    for k, fname in enumerate(names):
        rng = np.random.default_rng([test.seed, 1, k])
        img = acquire(intensities[k], camera.bit_depth, test.noise_scale * camera.noise_sigma, rng)
        tmp = out / "images" / f".{fname}.tmp.png"  # written whole, then renamed
        os.replace(write_image(tmp, img), out / "images" / fname)
    _write_log(test, resp.reaction_kN, out, np.random.default_rng(test.seed))
    x0, y0 = camera.mm_to_px(-W / 2, 0.0)
    camera_text = (
        f'units = "px"\norigin = [{float(x0):.3f}, {float(y0):.3f}]\nmm_per_px = {p:g}\n'
        "roi_margin_mm = 1.0\n"
    )
    measurement = (
        '[images]\nreference = "images/reference.png"\nfiles = "images/image_*.png"\n'
        f"subset = {images.subset}\nstep = {images.step}\n"
    )
    return _write_toml(test, out, name, camera_text, measurement)

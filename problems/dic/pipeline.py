"""The DIC route of the inverse problem: render, correlate, report front-face displacements.

``measure_front_face`` takes one displacement field per snapshot (a callable on the quarter
model's half of the front face), renders the reference and the deformed images of the full
face with a seeded speckle pattern, correlates them with IC-GN and returns the measured
displacements, with their DIC standard deviations, at the requested measurement grid.

Where the displacements are measured: one subset is centred at the pixel nearest to each
grid point's image position (no DIC grid + interpolation), and its first-order shape carries
the result to the exact point (``u + u_x dx + u_y dy``, ``|dx|, |dy| <= 0.5 px``; the covariance
is propagated the same way). With the default camera (0.15 mm/px) the grid points 5 mm from an
edge lie 33 px inside the face, so a 21 px subset stays 23 px clear of the edge; the camera
also renders a background margin (24 px) around the face so that the moving specimen edges
stay in view. Subsets that would reach outside the image raise a ValueError.

Points whose correlation fails are flagged (``converged = False``) and carry NaN values and
NaN standard deviations.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, Iterator, Sequence

import numpy as np

from problems.dic.correlate import Correlator, DICConfig, DICResult
from problems.dic.imageio import write_image
from problems.dic.speckle import CameraConfig, SpeckleConfig, face_pattern, render_face
from problems.dic.warp import mirror_quarter_field

Field = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


@dataclass
class DICMeasurement:
    """Front-face displacements measured by DIC at ``m`` grid points for ``N`` snapshots.

    u_h, u_v     : (N, m) mm; horizontal = u_y (to +y), vertical = u_z (up positive)
    std_h, std_v : (N, m) mm; DIC standard deviations (NaN where not converged)
    cov_hv       : (N, m) mm^2; covariance of u_h and u_v at the same point
    converged    : (N, m) bool
    zncc         : (N, m) final ZNCC
    iterations   : (N, m) IC-GN iterations
    noise_sigma  : (N,) grey-level noise estimated from the residuals of each image pair
    points_mm    : (m, 2) [y, z] the requested quarter grid points
    points_px    : (m, 2) their image coordinates (x right, y down)
    centres_px   : (m, 2) the integer subset centres used
    camera, speckle, dic, seed : everything needed to regenerate the images (with the fields)
    image_paths  : written images (reference first), empty if none were written
    subsets_path : the panels of the Fig.-2-like subset figure (``dic_subsets.npz``), if written
    """

    u_h: np.ndarray
    u_v: np.ndarray
    std_h: np.ndarray
    std_v: np.ndarray
    cov_hv: np.ndarray
    converged: np.ndarray
    zncc: np.ndarray
    iterations: np.ndarray
    noise_sigma: np.ndarray
    points_mm: np.ndarray
    points_px: np.ndarray
    centres_px: np.ndarray
    camera: CameraConfig
    speckle: SpeckleConfig
    dic: DICConfig
    seed: int
    image_paths: tuple[str, ...] = ()
    subsets_path: str | None = None
    meta: dict = field(default_factory=dict)

    def covariance(self) -> np.ndarray:
        """(N, m, 2, 2) covariance of (u_h, u_v) per point, mm^2 (NaN where not converged)."""
        c = np.empty(self.u_h.shape + (2, 2))
        c[..., 0, 0] = self.std_h**2
        c[..., 1, 1] = self.std_v**2
        c[..., 0, 1] = c[..., 1, 0] = self.cov_hv
        return c

    def setup(self) -> dict:
        """JSON-serialisable configuration (camera, speckle, DIC, seed) of this measurement."""
        return {
            "camera": asdict(self.camera),
            "speckle": asdict(self.speckle),
            "dic": asdict(self.dic),
            "seed": int(self.seed),
            "n_snapshots": int(self.u_h.shape[0]),
            "image_paths": list(self.image_paths),
        }


def pixel_displacement(field_quarter: Field, camera: CameraConfig):
    """Turn a quarter field in mm into ``u(X, Y) -> (u_x, u_y)`` in reference image pixels.

    Image x is +y and image y is -z, so ``u_x = u_y / p`` and ``u_y(image) = -u_z / p``.
    """
    w, h = camera.face_mm
    full = mirror_quarter_field(field_quarter, w / 2, h)
    p = camera.pixel_mm

    def disp(X: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        y, z = camera.px_to_mm(X, Y)
        uy, uz = full(y, z)
        return uy / p, -uz / p

    return disp


def render_images(
    fields: Sequence[Field], camera: CameraConfig, speckle: SpeckleConfig, seed: int
) -> Iterator[np.ndarray]:
    """The reference image, then one deformed image per field (deterministic in ``seed``).

    Pattern: ``default_rng([seed, 0])``; grey-level noise of image k (0 = reference):
    ``default_rng([seed, 1, k])``.
    """
    pattern = face_pattern(speckle, camera, seed)
    yield render_face(camera, speckle, pattern, None, np.random.default_rng([seed, 1, 0]))
    for k, f in enumerate(fields, start=1):
        yield render_face(
            camera,
            speckle,
            pattern,
            pixel_displacement(f, camera),
            np.random.default_rng([seed, 1, k]),
        )


def _check_grid(points: np.ndarray, camera: CameraConfig) -> np.ndarray:
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) == 0:
        raise ValueError(f"grid_points_mm must have shape (m, 2) [y, z], got {pts.shape}")
    w, h = camera.face_mm
    bad = (
        (pts[:, 0] < 0)
        | (pts[:, 0] > w / 2)
        | (pts[:, 1] < 0)
        | (pts[:, 1] > h)
        | ~np.all(np.isfinite(pts), 1)
    )
    if np.any(bad):
        k = int(np.flatnonzero(bad)[0])
        raise ValueError(
            f"{int(bad.sum())} grid point(s) lie outside the quarter face y in [0, {w / 2:g}], "
            f"z in [0, {h:g}] mm, e.g. {pts[k].tolist()}"
        )
    return pts


def _figure_points(points_mm: np.ndarray, face: tuple[float, float]) -> list[int]:
    w, h = face
    targets = [(0.1 * w, 0.95 * h), (0.25 * w, 0.5 * h), (0.45 * w, 0.5 * h), (0.25 * w, 0.05 * h)]
    out: list[int] = []
    for t in targets:
        k = int(np.argmin(np.sum((points_mm - t) ** 2, axis=1)))
        if k not in out:
            out.append(k)
    return out


def measure_front_face(
    fields: Sequence[Field],
    grid_points_mm: np.ndarray,
    camera: CameraConfig = CameraConfig(),
    speckle: SpeckleConfig = SpeckleConfig(),
    dic: DICConfig = DICConfig(),
    seed: int = 0,
    image_dir: str | Path | None = None,
    progress: bool = False,
    figure: bool = True,
) -> DICMeasurement:
    """Render, correlate and measure the front-face displacements of every snapshot.

    fields         : one callable per snapshot, ``field(y_mm, z_mm) -> (u_y_mm, u_z_mm)`` on the
                     quarter face (y >= 0); mirrored to the full face (u_y odd, u_z even)
    grid_points_mm : (m, 2) [y, z] measurement points in the quarter, mm
    camera, speckle, dic : configurations; seed : pattern and noise seed
    image_dir      : if given, the images are written there as 8/16-bit PackBits TIFFs
                     (``reference.tif``, ``deformed_001.tif``, ...), with ``dic_setup.json``
                     and, if ``figure``, ``dic_subsets.npz``: the panels of the Fig.-2-like subset
                     figure of the last snapshot (:mod:`problems.dic.subsets`; drawn to
                     ``dic_subsets.png`` by :func:`bench.dic_figures.render_subsets`)
    progress       : tqdm progress bar over the snapshots

    Each snapshot's correlation starts from the previous snapshot's solution.
    """
    fields = list(fields)
    if not fields:
        raise ValueError("no displacement fields (snapshots) given")
    pts_mm = _check_grid(grid_points_mm, camera)
    xq, yq = camera.mm_to_px(pts_mm[:, 0], pts_mm[:, 1])
    pts_px = np.column_stack([xq, yq])
    outdir = Path(image_dir) if image_dir is not None else None
    if outdir is not None:
        outdir.mkdir(parents=True, exist_ok=True)

    N, m = len(fields), len(pts_mm)
    p = camera.pixel_mm
    u_h, u_v, s_h, s_v, c_hv, zn = (np.full((N, m), np.nan) for _ in range(6))
    conv = np.zeros((N, m), dtype=bool)
    its = np.zeros((N, m), dtype=np.int64)
    sig = np.full(N, np.nan)
    paths: list[str] = []
    images = render_images(fields, camera, speckle, seed)
    ref = next(images)
    corr = Correlator(ref, pts_px, dic)
    if outdir is not None:
        paths.append(str(write_image(outdir / "reference.tif", ref, "packbits")))
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=N, desc="DIC snapshots", unit="img")
    prev: DICResult | None = None
    last = None
    for k, img in enumerate(images):
        if outdir is not None:
            paths.append(str(write_image(outdir / f"deformed_{k + 1:03d}.tif", img, "packbits")))
        res = corr.correlate(img, initial=prev)
        u, v, cov = res.at(xq, yq)
        u_h[k], u_v[k] = u * p, -v * p
        s_h[k], s_v[k] = np.sqrt(cov[:, 0, 0]) * p, np.sqrt(cov[:, 1, 1]) * p
        c_hv[k] = -cov[:, 0, 1] * p * p
        conv[k], zn[k], its[k], sig[k] = res.converged, res.zncc, res.iterations, res.noise_sigma
        prev = res if np.any(res.converged) else prev
        last = (img, res)
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()

    meas = DICMeasurement(
        u_h=u_h,
        u_v=u_v,
        std_h=s_h,
        std_v=s_v,
        cov_hv=c_hv,
        converged=conv,
        zncc=zn,
        iterations=its,
        noise_sigma=sig,
        points_mm=pts_mm,
        points_px=pts_px,
        centres_px=corr.points.copy(),
        camera=camera,
        speckle=speckle,
        dic=dic,
        seed=int(seed),
        image_paths=tuple(paths),
    )
    if outdir is not None:
        if figure and last is not None and np.any(last[1].converged):
            from problems.dic.subsets import subset_figure_data

            idx = _figure_points(pts_mm, camera.face_mm)
            labels = [f"y = {pts_mm[i, 0]:g}, z = {pts_mm[i, 1]:g} mm" for i in idx]
            panels = subset_figure_data(
                ref,
                last[0],
                last[1],
                idx,
                dic.subset,
                dic.order,
                labels=labels,
                title=f"DIC subsets, snapshot {N}",
            )
            meas.subsets_path = str(panels.save(outdir / "dic_subsets.npz"))
        (outdir / "dic_setup.json").write_text(json.dumps(meas.setup(), indent=2))
    return meas

"""Speckle patterns, their analytic rendering, and the camera (geometry, noise, bit depth).

Pattern model
-------------
A speckle pattern is a set of ``K`` Gaussian blobs painted on the specimen. At a reference
point ``X`` the blob field is ``G(X) = sum_k A_k exp(-|X - X_k|^2 / (2 s_k^2))`` and the
grey level is

    I(X) = bright - (bright - dark) * (1 - exp(-G(X)))          (inside the specimen face)
    I(X) = background                                            (outside)

``1 - exp(-G)`` is a smooth saturation: overlapping speckles never go darker than ``dark``
and the image is C-infinity in ``X``, so no interpolation bias is baked into the images.
Optical/paint blur of standard deviation ``b`` is applied analytically to each blob
(``s_k^2 -> s_k^2 + b^2``, ``A_k -> A_k s_k^2 / (s_k^2 + b^2)``), i.e. to ``G`` before the
saturation.

Nominal speckle size ``D`` is the full width at half maximum of a blob (``s = D / 2.3548``);
the number of speckles is ``density * area / (pi D^2 / 4)``; sizes vary log-normally with
coefficient of variation ``size_cv``; positions are uniform (Poisson) and seeded.

Rendering
---------
Every pixel is the mean of ``n x n`` sub-samples (``supersample``), each evaluated exactly at
its reference position (for a deformed image: from :mod:`problems.dic.warp`). Blobs are
"splatted": each blob is evaluated on the sub-samples within ``5 s_eff`` of its (deformed)
centre, on a disc of super-grid offsets, and the contributions summed with ``bincount``.

Camera
------
The camera looks at the full front face (``y`` to the right, ``z`` up) with square pixels;
``pixels`` pixels span the face and a ``margin_px`` band of background surrounds it so the
moving specimen edges stay in view. Grey-level noise is additive Gaussian (``noise_sigma``
grey levels of the output bit depth) followed by rounding and clipping to 8 or 16 bits.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from problems.dic import _kernels
from problems.dic.warp import inverse_map, supersample_displacement

FWHM_PER_SIGMA = 2.0 * np.sqrt(2.0 * np.log(2.0))  # 2.3548
CUTOFF_SIGMAS = 5.0  # blob truncation radius: A exp(-12.5) < 1e-5 of full scale


@dataclass(frozen=True)
class SpeckleConfig:
    """The painted pattern (lengths in mm on the specimen).

    size_mm    : nominal speckle diameter (FWHM of one blob)
    density    : fraction of the face covered by nominal discs (0 < density <= 1.5); the
                 default 0.32 gives about half the face darker than mid-grey
    size_cv    : coefficient of variation of the speckle size (log-normal)
    contrast   : dark level = bright * (1 - contrast), 0 < contrast <= 1
    blur_mm    : Gaussian blur (std) of paint edges and optics
    bright     : white paint level, fraction of the full grey-level scale
    amplitude  : blob amplitude A (darkness of an isolated blob centre is 1 - exp(-A))
    background : grey level outside the specimen, fraction of full scale
    """

    size_mm: float = 0.75
    density: float = 0.32
    size_cv: float = 0.2
    contrast: float = 0.75
    blur_mm: float = 0.1
    bright: float = 0.8
    amplitude: float = 2.0
    background: float = 0.05

    def __post_init__(self):
        if not self.size_mm > 0:
            raise ValueError(f"speckle size_mm = {self.size_mm!r} must be > 0")
        if not 0 < self.density <= 1.5:
            raise ValueError(f"speckle density = {self.density!r} must be in (0, 1.5]")
        if not 0 < self.contrast <= 1:
            raise ValueError(f"speckle contrast = {self.contrast!r} must be in (0, 1]")
        if not (self.blur_mm >= 0 and self.size_cv >= 0 and self.amplitude > 0):
            raise ValueError("speckle blur_mm and size_cv must be >= 0 and amplitude > 0")
        if not (0 < self.bright <= 1 and 0 <= self.background <= 1):
            raise ValueError("speckle bright must be in (0, 1] and background in [0, 1]")


@dataclass(frozen=True)
class CameraConfig:
    """The camera: geometry, sampling and sensor.

    pixels      : (columns, rows) of pixels spanning the face (square pixels)
    face_mm     : (width along y, height along z) of the full front face
    margin_px   : background band around the face, pixels on each side
    bit_depth   : 8 or 16
    noise_sigma : Gaussian grey-level noise, grey levels of the output bit depth
    supersample : n x n sub-samples per pixel when rendering
    map_step    : solve the inverse mapping every map_step pixels (1 = every pixel)
    """

    pixels: tuple[int, int] = (1000, 1000)
    face_mm: tuple[float, float] = (150.0, 150.0)
    margin_px: int = 24
    bit_depth: int = 8
    noise_sigma: float = 2.0
    supersample: int = 3
    map_step: int = 1

    def __post_init__(self):
        cols, rows = self.pixels
        if cols < 8 or rows < 8:
            raise ValueError(f"camera pixels = {self.pixels!r}: need at least 8 x 8")
        w, h = self.face_mm
        if not abs(w / cols - h / rows) <= 1e-9 * (w / cols):
            raise ValueError(
                f"camera pixels {self.pixels} over a face of {self.face_mm} mm are not square"
            )
        if self.bit_depth not in (8, 16):
            raise ValueError(f"camera bit_depth = {self.bit_depth!r}: use 8 or 16")
        if self.noise_sigma < 0 or self.margin_px < 0 or self.supersample < 1 or self.map_step < 1:
            raise ValueError(
                "camera noise_sigma and margin_px must be >= 0, supersample and map_step >= 1"
            )

    @property
    def pixel_mm(self) -> float:
        """Pixel size on the specimen, mm/px."""
        return self.face_mm[0] / self.pixels[0]

    @property
    def shape(self) -> tuple[int, int]:
        """Image shape (rows, cols) including the margins."""
        return (self.pixels[1] + 2 * self.margin_px, self.pixels[0] + 2 * self.margin_px)

    @property
    def max_level(self) -> int:
        return 2**self.bit_depth - 1

    def mm_to_px(self, y: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Face coordinates (y right, z up; mm) -> image coordinates (x right, y down; px)."""
        p, m = self.pixel_mm, self.margin_px
        x = m - 0.5 + (np.asarray(y, float) + self.face_mm[0] / 2) / p
        yi = m - 0.5 + (self.face_mm[1] - np.asarray(z, float)) / p
        return x, yi

    def px_to_mm(self, x: np.ndarray, yi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Image coordinates (px) -> face coordinates (y, z; mm)."""
        p, m = self.pixel_mm, self.margin_px
        y = (np.asarray(x, float) - m + 0.5) * p - self.face_mm[0] / 2
        z = self.face_mm[1] - (np.asarray(yi, float) - m + 0.5) * p
        return y, z

    @property
    def face_box_px(self) -> tuple[float, float, float, float]:
        """(x0, x1, y0, y1): the face's edges in image coordinates."""
        m = self.margin_px
        return (m - 0.5, m - 0.5 + self.pixels[0], m - 0.5, m - 0.5 + self.pixels[1])


@dataclass(frozen=True)
class SpecklePattern:
    """Gaussian blobs: centres (K, 2) as (x, y), standard deviations (K,), amplitudes (K,).

    Units are whatever the caller uses (mm on the face, or pixels once mapped to an image).
    """

    centres: np.ndarray
    sigma: np.ndarray
    amplitude: np.ndarray

    @classmethod
    def random(
        cls,
        extent: tuple[float, float, float, float],
        size: float,
        density: float = 0.5,
        size_cv: float = 0.2,
        amplitude: float = 2.0,
        rng: np.random.Generator | int | None = 0,
        periodic: bool = False,
    ) -> "SpecklePattern":
        """Uniformly placed blobs in ``extent = (x0, x1, y0, y1)``.

        ``periodic=True`` adds the images of the blobs near the borders shifted by the extent,
        so that the rendered pattern tiles seamlessly (for Fourier-shift tests).
        """
        rng = np.random.default_rng(rng)
        x0, x1, y0, y1 = extent
        w, h = x1 - x0, y1 - y0
        if not (w > 0 and h > 0 and size > 0):
            raise ValueError(f"speckle extent {extent} and size {size} must be positive")
        n = int(round(density * w * h / (np.pi * size**2 / 4)))
        c = np.column_stack([x0 + w * rng.random(n), y0 + h * rng.random(n)])
        s = size / FWHM_PER_SIGMA
        if size_cv > 0:
            sg = np.sqrt(np.log1p(size_cv**2))
            sig = s * np.exp(sg * rng.standard_normal(n) - sg**2 / 2)
        else:
            sig = np.full(n, s)
        amp = np.full(n, float(amplitude))
        if periodic:
            reach = CUTOFF_SIGMAS * sig.max() * 2
            cs, ss, aa = [c], [sig], [amp]
            for dx in (-w, 0.0, w):
                for dy in (-h, 0.0, h):
                    if dx == 0.0 and dy == 0.0:
                        continue
                    cc = c + [dx, dy]
                    near = (
                        (cc[:, 0] > x0 - reach)
                        & (cc[:, 0] < x1 + reach)
                        & (cc[:, 1] > y0 - reach)
                        & (cc[:, 1] < y1 + reach)
                    )
                    cs.append(cc[near]), ss.append(sig[near]), aa.append(amp[near])
            c, sig, amp = np.concatenate(cs), np.concatenate(ss), np.concatenate(aa)
        return cls(c, sig, amp)

    def transformed(
        self, scale: tuple[float, float], offset: tuple[float, float]
    ) -> "SpecklePattern":
        """Pattern in new coordinates ``x' = offset + scale * x`` (per axis;
        |scale_x| = |scale_y|)."""
        sx, sy = scale
        if not np.isclose(abs(sx), abs(sy)):
            raise ValueError("the pattern can only be mapped with a uniform scale")
        c = np.column_stack(
            [offset[0] + sx * self.centres[:, 0], offset[1] + sy * self.centres[:, 1]]
        )
        return SpecklePattern(c, self.sigma * abs(sx), self.amplitude)

    def blurred(self, blur: float) -> "SpecklePattern":
        """Analytic Gaussian blur of std ``blur`` applied to every blob."""
        if blur <= 0:
            return self
        s2 = self.sigma**2 + blur**2
        return SpecklePattern(self.centres, np.sqrt(s2), self.amplitude * self.sigma**2 / s2)


def blob_field(
    pattern: SpecklePattern,
    shape: tuple[int, int],
    supersample: int,
    approx_centres: np.ndarray,
    Ux: np.ndarray | None = None,
    Uy: np.ndarray | None = None,
    chunk_elems: int = 2_000_000,
    backend: str | None = None,
) -> np.ndarray:
    """``G`` at the ``n x n`` sub-samples of every pixel (super-grid of shape ``(H n, W n)``).

    The reference position of super-grid point ``(R, C)`` is ``X = x(C) - Ux[R, C]``,
    ``Y = y(R) - Uy[R, C]`` with ``x(C) = (C + 1/2)/n - 1/2`` (``Ux = Uy = None``: undeformed).
    approx_centres : (K, 2) where each blob appears in the image (deformed position, px);
                     only sub-samples within the blob's cut-off disc (+1 px slack) around it
                     are evaluated. Differences are formed relative to the blob's nearest
                     super-grid point, so single precision is exact to ~1e-6 px.
    backend        : 'numpy' (chunked gather + bincount), 'numba' (compiled loop) or None
                     (numba when installed); both evaluate the same sums.
    """
    n = supersample
    Hs, Ws = shape[0] * n, shape[1] * n

    def radius(sig: float) -> int:
        return int(np.ceil((CUTOFF_SIGMAS * sig + 1.0) * n))

    K = pattern.sigma.size
    if K == 0:
        return np.zeros((Hs, Ws))
    C = np.rint((approx_centres[:, 0] + 0.5) * n - 0.5).astype(np.int64)
    R = np.rint((approx_centres[:, 1] + 0.5) * n - 0.5).astype(np.int64)
    if backend == "numba" or (backend is None and _kernels.DEFAULT_BACKEND == "numba"):
        return _kernels.splat_numba(
            (Hs, Ws),
            Ux,
            Uy,
            C,
            R,
            pattern.centres,
            pattern.sigma,
            pattern.amplitude,
            n,
            CUTOFF_SIGMAS,
        )
    rho_max = radius(pattern.sigma.max())
    pad = 2 * rho_max  # blob centres up to rho_max outside + their window
    Hp, Wp = Hs + 2 * pad, Ws + 2 * pad
    deformed = Ux is not None
    if deformed:
        Up = np.zeros((2, Hp, Wp), dtype=np.float32)
        Up[:, pad : pad + Hs, pad : pad + Ws] = (Ux, Uy)
        Upx, Upy = Up[0].ravel(), Up[1].ravel()
    G = np.zeros(Hp * Wp)
    keep = (C >= -rho_max) & (C <= Ws - 1 + rho_max) & (R >= -rho_max) & (R <= Hs - 1 + rho_max)
    # size classes (few window radii), each swept in row order so that a chunk touches a strip
    sig = pattern.sigma
    rad = np.ceil((CUTOFF_SIGMAS * sig + 1.0) * n).astype(np.int64)
    classes = np.unique(np.minimum(rho_max, 2 * ((rad + 1) // 2)))  # even radii
    cls_of = np.searchsorted(classes, np.minimum(rho_max, rad))
    for ci, rho in enumerate(classes):
        members = np.flatnonzero(keep & (cls_of == ci))
        if members.size == 0:
            continue
        members = members[np.argsort(R[members], kind="stable")]
        dr, dc = np.mgrid[-rho : rho + 1, -rho : rho + 1]
        disc = dr**2 + dc**2 <= rho**2
        off = (dr[disc] * Wp + dc[disc]).astype(np.int64)
        ofx = (dc[disc] / n).astype(np.float32)
        ofy = (dr[disc] / n).astype(np.float32)
        m = max(1, chunk_elems // off.size)
        for j in range(0, members.size, m):
            sel = members[j : j + m]
            base = (R[sel] + pad) * Wp + C[sel] + pad
            idx = base[:, None] + off[None, :]
            # blob centre relative to its nearest super-grid point
            ax = ((C[sel] + 0.5) / n - 0.5 - pattern.centres[sel, 0]).astype(np.float32)
            ay = ((R[sel] + 0.5) / n - 0.5 - pattern.centres[sel, 1]).astype(np.float32)
            dx = ax[:, None] + ofx[None, :]
            dy = ay[:, None] + ofy[None, :]
            if deformed:
                dx -= Upx[idx]
                dy -= Upy[idx]
            inv = (0.5 / sig[sel] ** 2).astype(np.float32)
            q = (dx * dx + dy * dy) * inv[:, None]
            w = np.exp(-q) * pattern.amplitude[sel].astype(np.float32)[:, None]
            lo = int(base.min() - rho * Wp - rho)
            hi = int(base.max() + rho * Wp + rho + 1)
            G[lo:hi] += np.bincount((idx - lo).ravel(), weights=w.ravel(), minlength=hi - lo)
    return G.reshape(Hp, Wp)[pad : pad + Hs, pad : pad + Ws]


def render(
    pattern: SpecklePattern,
    shape: tuple[int, int],
    *,
    displacement=None,
    supersample: int = 3,
    bright: float = 0.8,
    dark: float = 0.2,
    background: float = 0.05,
    face_box: tuple[float, float, float, float] | None = None,
    map_step: int = 1,
) -> np.ndarray:
    """Render a (possibly deformed) image, grey levels as fractions of full scale.

    pattern      : blobs in reference *pixel* coordinates (x right, y down), blur included
    shape        : (rows, cols)
    displacement : None (reference image) or ``u(X, Y) -> (u_x, u_y)`` in px, reference coords
    face_box     : (x0, x1, y0, y1) of the painted region in reference px; outside it the
                   scene shows ``background``. None: the pattern covers the whole image.
    """
    n = int(supersample)
    if displacement is None:
        ux = uy = None
        approx = pattern.centres
    else:
        ux, uy = inverse_map(displacement, shape, map_step=map_step)
        du, dv = displacement(pattern.centres[:, 0], pattern.centres[:, 1])
        approx = pattern.centres + np.column_stack([du, dv])
    if ux is None:
        Ux = Uy = None
    else:
        Ux, Uy = supersample_displacement(ux, uy, n)
    G = blob_field(pattern, shape, n, approx, Ux, Uy)
    # I = bright - (bright - dark) (1 - exp(-G)) = dark + (bright - dark) exp(-G), in place
    np.negative(G, out=G)
    np.exp(G, out=G)
    G *= bright - dark
    G += dark
    if face_box is not None:
        x0, x1, y0, y1 = face_box
        d = (np.arange(n) + 0.5) / n - 0.5
        xs = (np.arange(shape[1])[:, None] + d[None, :]).ravel()
        ys = (np.arange(shape[0])[:, None] + d[None, :]).ravel()
        if Ux is None:
            G[(ys < y0) | (ys > y1), :] = background
            G[:, (xs < x0) | (xs > x1)] = background
        else:
            X = xs[None, :].astype(np.float32) - Ux
            Y = ys[:, None].astype(np.float32) - Uy
            outside = (X < x0) | (X > x1) | (Y < y0) | (Y > y1)
            G[outside] = background
    rows, cols = shape
    return G.reshape(rows * n, cols, n).sum(axis=2).reshape(rows, n, cols).sum(axis=1) / (n * n)


def acquire(
    intensity: np.ndarray,
    bit_depth: int = 8,
    noise_sigma: float = 0.0,
    rng: np.random.Generator | int | None = None,
) -> np.ndarray:
    """Sensor: full-scale fractions -> noisy, rounded, clipped ``uint8``/``uint16`` grey levels."""
    if bit_depth not in (8, 16):
        raise ValueError(f"bit_depth = {bit_depth!r}: use 8 or 16")
    top = 2**bit_depth - 1
    v = np.asarray(intensity, dtype=float) * top
    if noise_sigma > 0:
        v = v + noise_sigma * np.random.default_rng(rng).standard_normal(v.shape)
    return np.clip(np.rint(v), 0, top).astype(np.uint8 if bit_depth == 8 else np.uint16)


def face_pattern(speckle: SpeckleConfig, camera: CameraConfig, seed: int) -> SpecklePattern:
    """The seeded pattern painted on the front face, in reference image pixels (blur included).

    The pattern is drawn in mm on the face (independent of the camera resolution), then mapped
    to pixels: ``x = m - 1/2 + (y + W/2)/p``, ``y_img = m - 1/2 + (H - z)/p``.
    """
    w, h = camera.face_mm
    pad = 3 * speckle.size_mm  # blobs straddling the edges are painted too (cut by the face box)
    mm = SpecklePattern.random(
        (-w / 2 - pad, w / 2 + pad, -pad, h + pad),
        speckle.size_mm,
        speckle.density,
        speckle.size_cv,
        speckle.amplitude,
        rng=np.random.default_rng([seed, 0]),
    )
    p, m = camera.pixel_mm, camera.margin_px
    px = mm.transformed((1 / p, -1 / p), (m - 0.5 + w / 2 / p, m - 0.5 + h / p))
    return px.blurred(speckle.blur_mm / p)


def render_face_intensity(
    camera: CameraConfig,
    speckle: SpeckleConfig,
    pattern: SpecklePattern,
    displacement_px=None,
) -> np.ndarray:
    """The noise-free image of the face as full-scale fractions (float, rows x cols), the
    reference if ``displacement_px`` is None; :func:`acquire` makes the camera's image of it."""
    dark = speckle.bright * (1.0 - speckle.contrast)
    return render(
        pattern,
        camera.shape,
        displacement=displacement_px,
        supersample=camera.supersample,
        bright=speckle.bright,
        dark=dark,
        background=speckle.background,
        face_box=camera.face_box_px,
        map_step=camera.map_step,
    )


def render_face(
    camera: CameraConfig,
    speckle: SpeckleConfig,
    pattern: SpecklePattern,
    displacement_px=None,
    noise_rng: np.random.Generator | int | None = None,
) -> np.ndarray:
    """One camera image of the face (``uint8``/``uint16``), reference if ``displacement_px`` is
    None."""
    img = render_face_intensity(camera, speckle, pattern, displacement_px)
    return acquire(img, camera.bit_depth, camera.noise_sigma, noise_rng)


__all__ = [
    "SpeckleConfig",
    "CameraConfig",
    "SpecklePattern",
    "blob_field",
    "render",
    "acquire",
    "face_pattern",
    "render_face",
    "render_face_intensity",
]

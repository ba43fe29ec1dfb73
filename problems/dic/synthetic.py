"""Synthetic test images and the rigid sub-pixel translation study (used by tests and bench/perf).

``speckle_image`` renders a *periodic* speckle pattern so that ``fourier_shift`` (a phase ramp
in the Fourier domain: exact band-limited translation) produces no wrap-around artefacts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from problems.dic.correlate import Correlator, DICConfig, grid_points
from problems.dic.speckle import SpecklePattern, acquire, render


def speckle_image(
    size: int = 256,
    speckle_px: float = 5.0,
    density: float = 0.32,
    blur_px: float = 0.67,
    seed: int = 0,
    bright: float = 0.8,
    dark: float = 0.2,
    supersample: int = 3,
) -> np.ndarray:
    """A periodic ``size x size`` speckle image, grey levels as fractions of full scale (float)."""
    pat = SpecklePattern.random(
        (-0.5, size - 0.5, -0.5, size - 0.5), speckle_px, density, 0.2, 2.0, rng=seed, periodic=True
    )
    return render(
        pat.blurred(blur_px), (size, size), supersample=supersample, bright=bright, dark=dark
    )


def fourier_shift(image: np.ndarray, dx: float, dy: float) -> np.ndarray:
    """Translate a periodic image by ``(dx, dy)`` px (content moves right/down for positive
    values)."""
    ky = np.fft.fftfreq(image.shape[0])[:, None]
    kx = np.fft.fftfreq(image.shape[1])[None, :]
    F = np.fft.fft2(image)
    return np.real(np.fft.ifft2(F * np.exp(-2j * np.pi * (kx * dx + ky * dy))))


@dataclass
class TranslationStudy:
    shifts: np.ndarray  # (S,) imposed shift, px (same in x and y)
    bias_u: np.ndarray  # (S,) mean(u) - shift
    bias_v: np.ndarray
    std_u: np.ndarray  # (S,) std over points
    std_v: np.ndarray
    est_std_u: np.ndarray  # (S,) RMS of the predicted std(u)
    est_std_v: np.ndarray
    converged: np.ndarray  # (S,) fraction converged
    n_points: int

    @property
    def worst(self) -> dict:
        return {
            "max |bias u|": float(np.max(np.abs(self.bias_u))),
            "max |bias v|": float(np.max(np.abs(self.bias_v))),
            "max std u": float(np.max(self.std_u)),
            "max std v": float(np.max(self.std_v)),
        }


def translation_study(
    noise_sigma: float = 0.0,
    bit_depth: int | None = 8,
    size: int = 256,
    shifts: np.ndarray | None = None,
    config: DICConfig = DICConfig(),
    seed: int = 0,
    speckle_px: float = 5.0,
) -> TranslationStudy:
    """Correlate Fourier-shifted copies of a speckle image (shift ``s`` in x and in y).

    noise_sigma : grey-level noise (of the bit depth's scale) added to every image
    bit_depth   : 8 or 16: images are quantised; None: float grey levels in 0..255, no rounding
    """
    shifts = (
        np.round(np.arange(0.0, 1.0001, 0.1), 10) if shifts is None else np.asarray(shifts, float)
    )
    base = speckle_image(size, speckle_px=speckle_px, seed=seed)
    rng = np.random.default_rng([seed, 99])

    def camera(img):
        if bit_depth is None:
            return img * 255.0 + (
                noise_sigma * rng.standard_normal(img.shape) if noise_sigma > 0 else 0.0
            )
        return acquire(img, bit_depth, noise_sigma, rng)

    ref = camera(base)
    m = 3 * config.subset // 2
    pts = grid_points(ref.shape, config.subset, config.step, (m, m, size - m, size - m))
    corr = Correlator(ref, pts, config)
    out = {k: [] for k in ("bu", "bv", "su", "sv", "eu", "ev", "c")}
    for s in shifts:
        r = corr.correlate(camera(fourier_shift(base, s, s)))
        c = r.converged
        out["bu"].append(np.mean(r.u[c]) - s)
        out["bv"].append(np.mean(r.v[c]) - s)
        out["su"].append(np.std(r.u[c]))
        out["sv"].append(np.std(r.v[c]))
        out["eu"].append(np.sqrt(np.mean(r.std_u[c] ** 2)))
        out["ev"].append(np.sqrt(np.mean(r.std_v[c] ** 2)))
        out["c"].append(np.mean(c))
    a = {k: np.array(v) for k, v in out.items()}
    return TranslationStudy(
        shifts, a["bu"], a["bv"], a["su"], a["sv"], a["eu"], a["ev"], a["c"], len(pts)
    )

"""Reading and writing grey-level images: TIFF (any compression tifffile reads, e.g. PackBits),
PNG and BMP, 8- or 16-bit.

``read_image`` returns a 2-D ``uint8``/``uint16`` array (float TIFFs are returned as float64).
Colour images are converted to grey (ITU-R 601 luma) with a rounded result in the same
bit depth; alpha channels are dropped. ``write_image`` picks the format from the suffix.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

READ_SUFFIXES = (".tif", ".tiff", ".png", ".bmp")
WRITE_SUFFIXES = (".tif", ".tiff", ".png", ".bmp")


def _to_grey(a: np.ndarray, path: Path) -> np.ndarray:
    if a.ndim == 3 and a.shape[-1] in (3, 4):
        dt = a.dtype
        rgb = a[..., :3].astype(float)
        grey = rgb @ np.array([0.299, 0.587, 0.114])
        a = np.rint(grey).astype(dt) if np.issubdtype(dt, np.integer) else grey
    elif a.ndim == 3 and a.shape[-1] in (1, 2):  # grey (+ alpha)
        a = a[..., 0]
    if a.ndim != 2:
        raise ValueError(
            f"{path}: expected a single grey-level image, got an array of shape {a.shape}"
        )
    if a.dtype == np.uint8 or a.dtype == np.uint16:
        return a
    if a.dtype == np.bool_:
        return a.astype(np.uint8) * 255
    if np.issubdtype(a.dtype, np.integer):
        if a.min() < 0 or a.max() > 65535:
            raise ValueError(
                f"{path}: integer grey levels outside 0..65535 ({a.dtype}) are not supported"
            )
        return a.astype(np.uint16)
    if np.issubdtype(a.dtype, np.floating):
        return a.astype(np.float64)
    raise ValueError(f"{path}: unsupported pixel type {a.dtype}")


def read_image(path: str | Path) -> np.ndarray:
    """Read a grey-level TIFF/PNG/BMP image as a 2-D array (uint8, uint16 or float64)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"image file not found: {path}")
    suffix = path.suffix.lower()
    if suffix not in READ_SUFFIXES:
        raise ValueError(
            f"{path}: unsupported image format {suffix or '(none)'}; use TIFF, PNG or BMP"
        )
    if suffix in (".tif", ".tiff"):
        import tifffile

        try:
            a = tifffile.imread(path)
        except Exception as exc:  # corrupt or unsupported TIFF
            raise ValueError(f"{path}: cannot read TIFF ({exc})") from exc
        if a.ndim == 3 and a.shape[0] > 4 and a.shape[-1] not in (1, 2, 3, 4):
            raise ValueError(
                f"{path}: multi-page TIFF with {a.shape[0]} pages; give one image per file"
            )
    else:
        from PIL import Image, UnidentifiedImageError

        try:
            with Image.open(path) as im:
                if im.mode == "P":
                    im = im.convert("RGB")
                elif im.mode == "I;16B":
                    im = im.convert("I;16")
                a = np.array(im)
                mode = im.mode
        except UnidentifiedImageError as exc:
            raise ValueError(f"{path}: not a readable {suffix[1:].upper()} image") from exc
        except Exception as exc:
            # truncated or corrupt data (Pillow raises OSError, SyntaxError, ...)
            raise ValueError(
                f"{path}: cannot read {suffix[1:].upper()} image ({' '.join(str(exc).split())})"
            ) from exc
        if mode == "I":  # 16-bit PNGs open as 32-bit integers
            a = a.astype(np.int64)
    return _to_grey(a, path)


def write_image(path: str | Path, image: np.ndarray, compression: str | None = None) -> Path:
    """Write a 2-D ``uint8``/``uint16`` image; format from the suffix (BMP: 8-bit only).

    compression : for TIFF, e.g. 'packbits', 'zlib' or None (uncompressed)
    """
    path = Path(path)
    a = np.asarray(image)
    if a.ndim != 2:
        raise ValueError(f"{path}: can only write 2-D grey-level images, got shape {a.shape}")
    if a.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"{path}: write uint8 or uint16 grey levels, got {a.dtype}")
    suffix = path.suffix.lower()
    if suffix not in WRITE_SUFFIXES:
        raise ValueError(
            f"{path}: unsupported image format {suffix or '(none)'}; use .tif, .png or .bmp"
        )
    path.parent.mkdir(parents=True, exist_ok=True)
    if suffix in (".tif", ".tiff") and compression and compression.lower() == "packbits":
        from PIL import Image  # tifffile needs imagecodecs to encode PackBits; Pillow does not

        Image.fromarray(a).save(path, compression="packbits")
    elif suffix in (".tif", ".tiff"):
        import tifffile

        tifffile.imwrite(path, a, compression=compression, photometric="minisblack")
    else:
        from PIL import Image

        if suffix == ".bmp" and a.dtype != np.uint8:
            raise ValueError(
                f"{path}: BMP holds 8-bit grey levels only; use TIFF or PNG for 16 bits"
            )
        Image.fromarray(a).save(path)
    return path

"""A real test's files -> the objective's :class:`~problems.inverse.data.Dataset`.

A laboratory test is described by an *experiment file* (TOML, docs/calibrating.md): the specimen
(any rectangular prism), the platens, the face the camera sees and its calibration, the machine
log (plate displacement and force at each image, declared units, load-cell accuracy) and the DIC
export (one CSV per image with named columns x, y, u, v and optional sigma, in px or mm) or the
images themselves (``[images]``: a reference and one image per load step, correlated here by
femubench's IC-GN DIC, :func:`correlate_images`, into the same per-point form).
:func:`load_experiment` validates it and reports *all* errors at once, one line each naming the
field (:class:`ExperimentFileError`); :func:`import_experiment` turns the files into a Dataset:

1. the machine log's rows of the images give the plate displacement (the snapshots of a
   :class:`~problems.fe.newton.MachineLoading`) and the force with its standard deviation from
   the load cell's accuracy: an ISO 7500-1 class q (0.5, 1, 2, 3: relative accuracy error within
   q % of the reading) or an accuracy in % of reading, read as a uniform error over +-q %, i.e.
   sigma_F = q / 100 / sqrt(3) |F|, combined with the log's resolution step r (r / sqrt 12);
2. each DIC point's reference position (px or mm of the export) is mapped to the face's
   coordinates (s, z) mm, s from the face's left edge, z up from the bottom platen, by the
   calibration (``mm_per_px`` and the face's bottom-left corner ``origin``, or the four
   ``corners``, fitted by least squares as an affine map); its displacement by the same map's
   linear part; sigma (column or declared) by its scale;
3. points not in every image, with non-finite values, or off the face (closer than
   ``roi_margin_mm`` to an edge) are dropped and counted;
4. the in-plane rigid-body motion (two translations, one rotation about the points' centroid) of
   each image is removed by weighted least squares (weights 1 / sigma^2). The same projection is
   applied to the model's field in the objective (:class:`RigidMotionFree`), so the objective
   compares deformations only: a drift of the camera or of the specimen, or a platen that moves,
   cannot bias the parameters;
5. the face is folded onto the quarter model's: y = s - width / 2, a point at y < 0 is the
   mirror image of (-y, z) with its horizontal displacement negated (the quarter model is exact
   for a rectangular prism between identical platens).

Provenance (the SHA-256 of every file read, the calibration, the counts, the removed motions)
goes into ``Dataset.meta``. Units: mm, kN, MPa.
"""

from __future__ import annotations

import csv
import glob
import hashlib
import math
import os
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from problems.dic.correlate import DICConfig
from problems.fe.newton import MachineLoading
from problems.inverse import layout
from problems.inverse.build import (
    PLATE_MARGIN_TEXT,
    Region,
    auto_plate_margin_mm,
    plate_margin_mask,
)
from problems.inverse.data import EXPERIMENT_TIER, Dataset, DataSettings

#: platen conditions an experiment may declare -> the FE model's plate condition
PLATENS = {"bonded": "friction", "frictionless": "frictionless"}
#: faces the camera may see; all four lateral faces are alike in the quarter model once
#: ``width_mm`` is the horizontal extent of the face seen
FACES = ("front", "back", "left", "right")
UNITS = ("px", "mm")
DISPLACEMENT_UNITS = {"mm": 1.0, "um": 1e-3, "m": 1e3}
FORCE_UNITS = {"N": 1e-3, "kN": 1.0, "MN": 1e3}
#: ISO 7500-1 classes of a testing machine's force-measuring system: relative accuracy error, %
ISO7500_CLASSES = {0.5: 0.5, 1.0: 1.0, 2.0: 2.0, 3.0: 3.0}
#: DIC export columns: role -> default header name (sigma, sigma_u, sigma_v are optional)
COLUMNS = {"x": "x", "y": "y", "u": "u", "v": "v", "sigma": "sigma", "sigma_u": "", "sigma_v": ""}

SECTIONS = {
    "experiment": {"name": "a short name", "description": "free text"},
    "specimen": {
        "width_mm": "horizontal extent of the face the camera sees, mm",
        "depth_mm": "the other horizontal extent, mm",
        "height_mm": "extent along the load, mm",
        "platens": f"{' | '.join(PLATENS)}",
    },
    "camera": {
        "face": f"{' | '.join(FACES)}",
        "units": "px | mm: the units of the DIC export's x, y, u, v (and sigma)",
        "mm_per_px": "scale of px exports, mm per pixel (with origin)",
        "origin": "[x, y] of the face's bottom-left corner in the export's units",
        "corners": "[[x, y] x 4] of the face's corners bottom-left, bottom-right, top-right, "
        "top-left in the export's units (instead of origin and mm_per_px)",
        "y_axis": "down | up: the export's y direction (default: down for px, up for mm)",
        "roi_margin_mm": "points closer than this to an edge of the face are dropped (default 2)",
    },
    "loading": {
        "log": "machine log CSV, relative to the experiment file",
        "displacement_column": "header of the plate displacement",
        "force_column": "header of the force",
        "image_column": "header marking the rows of the images (non-empty); default: every row",
        "displacement_unit": f"{' | '.join(DISPLACEMENT_UNITS)}",
        "force_unit": f"{' | '.join(FORCE_UNITS)}",
        "compression": "positive | negative: the sign of compression in the log (default positive)",
        "zero_displacement": "log displacement of the unloaded reference image (default 0)",
        "load_cell_class": f"ISO 7500-1 class {', '.join(f'{c:g}' for c in ISO7500_CLASSES)}",
        "accuracy_percent": "load-cell accuracy, % of reading (instead of load_cell_class)",
        "force_resolution": "resolution of the logged force, in force_unit (default 0)",
    },
    "dic": {
        "files": "glob pattern or list of CSV files, one per image in the log's order",
        "columns": "table role -> header: x, y, u, v, sigma (or sigma_u, sigma_v)",
        "sigma": "standard deviation of u and v in the export's units when no sigma column",
        "images": "folder of the images (recorded, optional)",
        "snapshot_correlation": "correlation of a point's errors between two images, 0 <= rho "
        "< 1 (default 0: independent; 0.5 when every image was correlated against one reference)",
    },
    "images": {
        "reference": "the reference (undeformed) image: TIFF, PNG or BMP, 8 or 16 bit",
        "files": "glob pattern or list of the deformed images, one per image row of the log",
        "roi": "[x0, y0, x1, y1] px region of the subsets, half-open (default: the face's "
        "bounding box in the reference image)",
        "subset": "subset side, odd px >= 5 (default 21)",
        "step": "grid step of the subset centres, px (default: the subset side, so that "
        "subsets do not overlap and the points' errors are independent)",
        "order": "B-spline interpolation of the deformed images: 3 | 5 (default 3)",
        "zncc_min": "points whose final ZNCC is lower are dropped, in [-1, 1] (default 0.9)",
        "search_radius": "integer search radius of the FFT seed guess, px (default 32)",
        "snapshot_correlation": "correlation of a point's errors between two images, 0 <= rho "
        "< 1 (default 0.5: the reference's noise, equal to an image's, is half of each error "
        "variance; 1/(n + 1) for a reference averaged over n images; 0: independent)",
    },
    "calibration": {
        "mesh": "inverse mesh spec (default coarse)",
        "models": "all, or a list of variants form-hardening",
        "budget": "evaluations of the local method per variant (default 80)",
        "images": "1-based indices of the images used (default all)",
        "plate_margin_mm": f'{PLATE_MARGIN_TEXT} (default 0), or "auto": 10 % of the '
        "specimen's smallest dimension",
    },
    "virtual": {
        "data_mesh": "virtual experiments only: the FE mesh that made the data; never the "
        "inverse or the check mesh of a calibration (the honesty rule)",
    },
}


class ExperimentFileError(ValueError):
    """An invalid experiment file: ``errors`` holds one line per problem, naming the field."""

    def __init__(self, path, errors: list[str]):
        self.errors = list(errors)
        n = len(self.errors)
        head = f"experiment file {path}: {n} error{'s' if n > 1 else ''}:"
        super().__init__("\n".join([head] + [f"  - {e}" for e in self.errors]))


@dataclass(frozen=True)
class Experiment:
    """A validated experiment file (see :data:`SECTIONS` and docs/calibrating.md).

    All paths are absolute. ``specimen_mm`` is the model's (x, y, z) = (depth, width, height).
    ``dic_files`` are the measurement's files per image: the DIC export's CSVs (``route`` csv) or
    the deformed images (``route`` images, with ``reference_image``, the DIC settings
    ``correlation`` and the optional ``roi_px``).
    """

    path: Path
    name: str
    description: str
    width_mm: float
    depth_mm: float
    height_mm: float
    platens: str
    face: str
    units: str
    affine: np.ndarray  # (2, 3): [s, z] = A [x, y] + c, mm
    calibration: dict
    roi_margin_mm: float
    log: Path
    log_columns: dict
    displacement_scale: float  # mm per log unit
    force_scale: float  # kN per log unit
    compression_sign: float
    zero_displacement: float  # log unit
    force_accuracy_percent: float
    force_resolution_kN: float
    dic_files: tuple[Path, ...]
    columns: dict
    sigma: float | None  # export units
    images: Path | None
    mesh: str = "coarse"
    route: str = "csv"  # csv: a DIC export; images: correlated here ([images])
    reference_image: Path | None = None
    correlation: DICConfig | None = None
    roi_px: tuple[int, int, int, int] | None = None
    models: tuple[str, ...] = ()
    budget: int = 80
    use_images: tuple[int, ...] = ()
    plate_margin_mm: float = 0.0
    snapshot_rho: float = 0.0  # correlation of a point's errors between two images
    data_mesh: str = ""  # a virtual experiment's data mesh ("" for a real test)

    @property
    def specimen_mm(self) -> tuple[float, float, float]:
        return (self.depth_mm, self.width_mm, self.height_mm)

    @property
    def plates(self) -> str:
        return PLATENS[self.platens]


# --- reading the experiment file -----------------------------------------------------------------
def _number(sec, key, errors, where, *, default=None, positive=True, required=True):
    if key not in sec:
        if required and default is None:
            errors.append(f"[{where}] {key}: missing ({SECTIONS[where][key]})")
        return default
    v = sec[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        errors.append(f"[{where}] {key} = {v!r}: must be a number")
        return default
    if positive and v <= 0:
        errors.append(f"[{where}] {key} = {v!r}: must be > 0")
        return default
    return float(v)


def _choice(sec, key, allowed, errors, where, default=None):
    v = sec.get(key, default)
    if v is None:
        errors.append(f"[{where}] {key}: missing; allowed: {', '.join(map(str, allowed))}")
        return None
    if v not in allowed:
        errors.append(
            f"[{where}] {key} = {v!r} is unknown; allowed: {', '.join(map(str, allowed))}"
        )
        return None
    return v


def _point(v) -> bool:
    return (
        isinstance(v, list)
        and len(v) == 2
        and all(not isinstance(t, bool) and isinstance(t, (int, float)) for t in v)
    )


def face_affine(
    units: str,
    width_mm: float,
    height_mm: float,
    *,
    mm_per_px: float | None = None,
    origin=None,
    corners=None,
    y_axis: str | None = None,
) -> tuple[np.ndarray, dict]:
    """The map (2, 3) ``[s, z] = A [x, y] + c`` from the export's coordinates to the face's (mm;
    s from the left edge, z up from the bottom platen) and a calibration summary.

    From the four ``corners`` (bottom-left, bottom-right, top-right, top-left, export units): the
    least-squares affine map onto (0, 0), (w, 0), (w, h), (0, h), its corner residual reported in
    mm. Else from ``origin`` (the bottom-left corner) and the scale (``mm_per_px`` for px exports,
    1 for mm) with axes along the export's, y pointing ``y_axis`` (default down for px, up for mm).
    """
    if corners is not None:
        P = np.asarray(corners, float)
        target = np.array([[0.0, 0.0], [width_mm, 0.0], [width_mm, height_mm], [0.0, height_mm]])
        M = np.column_stack([P, np.ones(4)])
        coef, *_ = np.linalg.lstsq(M, target, rcond=None)
        affine = coef.T  # (2, 3)
        residual = float(np.sqrt(np.mean(np.sum((M @ coef - target) ** 2, axis=1))))
        scale = float(math.sqrt(abs(np.linalg.det(affine[:, :2]))))
        return affine, {
            "kind": "corners",
            "corners": P.tolist(),
            "corner_residual_mm": residual,
            "mm_per_unit": scale,
            "rotation_deg": float(math.degrees(math.atan2(affine[1, 0], affine[0, 0]))),
        }
    k = 1.0 if units == "mm" else float(mm_per_px)
    down = (y_axis or ("down" if units == "px" else "up")) == "down"
    sy = -k if down else k
    x0, y0 = map(float, origin)
    affine = np.array([[k, 0.0, -k * x0], [0.0, sy, -sy * y0]])
    return affine, {
        "kind": "origin",
        "origin": [x0, y0],
        "mm_per_unit": k,
        "y_axis": "down" if down else "up",
    }


def _files(sec: dict, where: str, base: Path, errors: list[str], suffixes=None) -> list[Path]:
    """The ``files`` of table ``where``: a glob (sorted) or a list, relative to ``base``;
    ``suffixes``: the allowed file name endings (lower case), if any."""
    files = sec.get("files")
    out: list[Path] = []
    if isinstance(files, str):
        out = sorted(Path(p).resolve() for p in glob.glob(str(base / files)))
        if not out:
            errors.append(f"[{where}] files = {files!r}: no file matches")
    elif isinstance(files, list) and files and all(isinstance(f, str) for f in files):
        out = [(base / f).resolve() for f in files]
        missing = [str(f) for f in files if not (base / f).is_file()]
        if missing:
            errors.append(f"[{where}] files: no such file(s) {', '.join(missing[:3])}")
            out = []
    else:
        errors.append(f"[{where}] files = {files!r}: a glob pattern or a non-empty list of files")
    bad = [p.name for p in out if suffixes and p.suffix.lower() not in suffixes]
    if bad:
        errors.append(
            f"[{where}] files: {', '.join(bad[:3])}: not an image; allowed: {', '.join(suffixes)}"
        )
        out = []
    return out


def _file(sec: dict, key: str, where: str, base: Path, errors: list[str]) -> Path | None:
    """The existing file named by ``key`` of table ``where``, relative to ``base``; None (and an
    error) when it is missing, not a string or no file."""
    name = sec.get(key)
    if not isinstance(name, str):
        errors.append(f"[{where}] {key} = {name!r}: missing or not a file name")
        return None
    path = (base / name).resolve()
    if not path.is_file():
        errors.append(f"[{where}] {key} = {name!r}: no such file {path}")
        return None
    return path


def _parse_images(im: dict, base: Path, errors: list[str]):
    """The ``[images]`` table: (reference image, deformed images, DICConfig, roi or None)."""
    from problems.dic.imageio import READ_SUFFIXES

    ref = im.get("reference")
    reference = _file(im, "reference", "images", base, errors)
    if reference is not None and reference.suffix.lower() not in READ_SUFFIXES:
        errors.append(
            f"[images] reference = {ref!r}: not an image; allowed: {', '.join(READ_SUFFIXES)}"
        )
        reference = None
    files = _files(im, "images", base, errors, READ_SUFFIXES)
    if reference is not None and reference in files:
        errors.append(f"[images] files: the reference {ref!r} is among the deformed images")

    def whole(key, default, low):
        v = im.get(key, default)
        if isinstance(v, bool) or not isinstance(v, int) or v < low:
            errors.append(f"[images] {key} = {v!r}: a whole number >= {low}")
            return default
        return v

    subset = whole("subset", 21, 5)
    if subset % 2 == 0:
        errors.append(f"[images] subset = {subset!r}: the subset side must be odd")
        subset = 21
    step = whole("step", subset, 1)
    search = whole("search_radius", 32, 0)
    order = im.get("order", 3)
    if order not in (3, 5) or isinstance(order, bool):
        errors.append(f"[images] order = {order!r} is unknown; allowed: 3, 5")
        order = 3
    zmin = _number(im, "zncc_min", errors, "images", default=0.9, positive=False)
    if zmin is not None and not -1.0 <= zmin <= 1.0:
        errors.append(f"[images] zncc_min = {zmin!r}: must be in [-1, 1]")
        zmin = 0.9
    roi = im.get("roi")
    if roi is not None:
        if not (
            isinstance(roi, list)
            and len(roi) == 4
            and all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in roi)
        ):
            errors.append(f"[images] roi = {roi!r}: four whole numbers [x0, y0, x1, y1] px >= 0")
            roi = None
        elif not (roi[2] - roi[0] >= subset and roi[3] - roi[1] >= subset):
            errors.append(
                f"[images] roi = {roi!r}: must hold one subset of {subset} px (x1 - x0 and "
                "y1 - y0 >= subset)"
            )
            roi = None
    cfg = DICConfig(subset=subset, step=step, order=order, zncc_min=zmin, search_radius=search)
    return reference, files, cfg, None if roi is None else tuple(roi)


def load_experiment(path: str | Path) -> Experiment:
    """Read and validate an experiment file; :class:`ExperimentFileError` lists every problem
    (one line each, naming the field), FileNotFoundError for a missing file."""
    path = Path(path).resolve()
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise FileNotFoundError(f"experiment file {path} does not exist") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ExperimentFileError(path, [f"not valid TOML: {exc}"]) from None
    return parse_experiment(raw, path)


def parse_experiment(raw: dict, path: Path) -> Experiment:
    """Validate the parsed TOML ``raw`` of the experiment file at ``path`` (relative file names
    are resolved from its folder)."""
    errors: list[str] = []
    base = path.parent
    for key in raw:
        if key not in SECTIONS:
            errors.append(f"unknown table [{key}]; allowed: {', '.join(SECTIONS)}")
    sec = {}
    for name in SECTIONS:
        s = raw.get(name, {})
        if not isinstance(s, dict):
            errors.append(f"[{name}] must be a table")
            s = {}
        for key in s:
            if key not in SECTIONS[name]:
                errors.append(f"[{name}] unknown key {key!r}; allowed: {', '.join(SECTIONS[name])}")
        sec[name] = s
    for name in ("specimen", "camera", "loading"):
        if name not in raw:
            errors.append(f"missing table [{name}]")
    route = "images" if "images" in raw else "csv"
    if "images" in raw and "dic" in raw:
        errors.append(
            "[dic], [images]: give the measurement once: a DIC export ([dic]) or the images "
            "([images]), not both"
        )
    elif "images" not in raw and "dic" not in raw:
        errors.append("missing table [dic] (a DIC export) or [images] (the images)")

    e = sec["experiment"]
    name = e.get("name", path.stem)
    if not isinstance(name, str) or not name or not all(c.isalnum() or c in "-_." for c in name):
        errors.append(f"[experiment] name = {name!r}: letters, digits, '-', '_' and '.' only")
        name = path.stem
    description = str(e.get("description", ""))

    sp = sec["specimen"]
    width = _number(sp, "width_mm", errors, "specimen")
    depth = _number(sp, "depth_mm", errors, "specimen")
    height = _number(sp, "height_mm", errors, "specimen")
    platens = sp.get("platens")
    if platens == "friction" or (isinstance(platens, str) and platens.startswith("coulomb")):
        errors.append(
            f"[specimen] platens = {platens!r}: Coulomb friction is not supported; allowed: "
            f"{', '.join(PLATENS)} (bonded: no slip, the usual idealisation of dry steel platens)"
        )
        platens = None
    else:
        platens = _choice(sp, "platens", tuple(PLATENS), errors, "specimen")

    cam = sec["camera"]
    face = _choice(cam, "face", FACES, errors, "camera", default="front")
    if route == "images":
        units = _choice(cam, "units", ("px",), errors, "camera", default="px")
    else:
        units = _choice(cam, "units", UNITS, errors, "camera")
    y_axis = cam.get("y_axis")
    if route == "images" and y_axis is not None and y_axis != "down":
        errors.append(f"[camera] y_axis = {y_axis!r}: an image's y points down; allowed: down")
        y_axis = None
    elif y_axis is not None and y_axis not in ("down", "up"):
        errors.append(f"[camera] y_axis = {y_axis!r} is unknown; allowed: down, up")
    roi = _number(cam, "roi_margin_mm", errors, "camera", default=2.0, positive=False)
    if roi is not None and roi < 0:
        errors.append(f"[camera] roi_margin_mm = {roi!r}: must be >= 0")
    corners, origin, mm_per_px = cam.get("corners"), cam.get("origin"), None
    if corners is not None:
        if not (isinstance(corners, list) and len(corners) == 4 and all(map(_point, corners))):
            errors.append(f"[camera] corners = {corners!r}: four [x, y] pairs")
            corners = None
        if origin is not None or "mm_per_px" in cam:
            errors.append("[camera] corners: give corners, or origin (and mm_per_px), not both")
    else:
        if origin is None:
            errors.append("[camera] origin: missing (or give corners)")
        elif not _point(origin):
            errors.append(f"[camera] origin = {origin!r}: an [x, y] pair")
            origin = None
        if units == "px":
            mm_per_px = _number(cam, "mm_per_px", errors, "camera")
        elif units == "mm" and "mm_per_px" in cam:
            errors.append("[camera] mm_per_px: only for px exports (units = 'px')")
    affine, calibration = None, {}
    if (
        width
        and height
        and units
        and (corners is not None or (origin is not None and (units == "mm" or mm_per_px)))
    ):
        affine, calibration = face_affine(
            units,
            width,
            height,
            mm_per_px=mm_per_px,
            origin=origin,
            corners=corners,
            y_axis=y_axis if y_axis in ("down", "up") else None,
        )
        if corners is not None and calibration["corner_residual_mm"] > 0.01 * max(width, height):
            errors.append(
                f"[camera] corners: not the corners of a {width:g} x {height:g} mm face (affine "
                f"fit residual {calibration['corner_residual_mm']:.3g} mm)"
            )

    lg = sec["loading"]
    log_path = _file(lg, "log", "loading", base, errors)
    log_columns = {}
    for key in ("displacement_column", "force_column", "image_column"):
        v = lg.get(key)
        if v is None and key != "image_column":
            errors.append(f"[loading] {key}: missing ({SECTIONS['loading'][key]})")
        elif v is not None and not isinstance(v, str):
            errors.append(f"[loading] {key} = {v!r}: a column header (string)")
        else:
            log_columns[key] = v
    du = _choice(lg, "displacement_unit", tuple(DISPLACEMENT_UNITS), errors, "loading")
    fu = _choice(lg, "force_unit", tuple(FORCE_UNITS), errors, "loading")
    comp = _choice(lg, "compression", ("positive", "negative"), errors, "loading", "positive")
    zero = _number(lg, "zero_displacement", errors, "loading", default=0.0, positive=False)
    res = _number(lg, "force_resolution", errors, "loading", default=0.0, positive=False)
    if res is not None and res < 0:
        errors.append(f"[loading] force_resolution = {res!r}: must be >= 0")
    accuracy = None
    if "load_cell_class" in lg and "accuracy_percent" in lg:
        errors.append("[loading] load_cell_class, accuracy_percent: give one, not both")
    elif "load_cell_class" in lg:
        c = lg["load_cell_class"]
        if (
            isinstance(c, bool)
            or not isinstance(c, (int, float))
            or float(c) not in ISO7500_CLASSES
        ):
            errors.append(
                f"[loading] load_cell_class = {c!r} is unknown; allowed (ISO 7500-1): "
                f"{', '.join(f'{k:g}' for k in ISO7500_CLASSES)}"
            )
        else:
            accuracy = ISO7500_CLASSES[float(c)]
    elif "accuracy_percent" in lg:
        accuracy = _number(lg, "accuracy_percent", errors, "loading")
    else:
        errors.append(
            "[loading] load_cell_class: missing (or accuracy_percent): the force's standard "
            "deviation comes from it"
        )

    d = sec["dic"]
    dic_files: list[Path] = []
    columns, sigma, images_path = dict(COLUMNS), None, None
    reference, correlation, roi_px = None, None, None
    if route == "csv":
        dic_files = _files(d, "dic", base, errors)
        cols = d.get("columns", {})
        if not isinstance(cols, dict):
            errors.append("[dic] columns must be a table role = header")
            cols = {}
        for role, header in cols.items():
            if role not in COLUMNS:
                errors.append(
                    f"[dic] columns: unknown role {role!r}; allowed: {', '.join(COLUMNS)}"
                )
            elif not isinstance(header, str):
                errors.append(f"[dic] columns.{role} = {header!r}: a column header (string)")
            else:
                columns[role] = header
        sigma = _number(d, "sigma", errors, "dic", required=False)
        images = d.get("images")
        if images is not None:
            images_path = (base / str(images)).resolve()
            if not images_path.is_dir():
                errors.append(f"[dic] images = {images!r}: no such folder {images_path}")
    else:
        reference, dic_files, correlation, roi_px = _parse_images(sec["images"], base, errors)
    table = "images" if route == "images" else "dic"
    rho = sec[table].get("snapshot_correlation", 0.5 if route == "images" else 0.0)
    if isinstance(rho, bool) or not isinstance(rho, (int, float)) or not 0.0 <= rho < 1.0:
        errors.append(f"[{table}] snapshot_correlation = {rho!r}: must be in [0, 1)")
        rho = 0.0

    c = sec["calibration"]
    mesh = c.get("mesh", "coarse")
    try:
        from problems.fe.mesh import parse_mesh_spec

        parse_mesh_spec(mesh)
    except (ValueError, TypeError) as exc:
        errors.append(f"[calibration] mesh: {exc}")
    models = c.get("models", "all")
    try:
        models = tuple(parse_models(models))
    except ValueError as exc:
        errors.append(f"[calibration] models: {exc}")
        models = ()
    budget = c.get("budget", 80)
    if isinstance(budget, bool) or not isinstance(budget, int) or budget < 2:
        errors.append(f"[calibration] budget = {budget!r}: a whole number >= 2")
        budget = 80
    use = c.get("images", [])
    if not isinstance(use, list) or not all(
        isinstance(i, int) and not isinstance(i, bool) and i >= 1 for i in use
    ):
        errors.append(f"[calibration] images = {use!r}: a list of 1-based image indices")
        use = []
    elif dic_files and any(i > len(dic_files) for i in use):
        errors.append(f"[calibration] images = {use!r}: there are {len(dic_files)} images")
        use = []
    elif len(set(use)) != len(use) or use != sorted(use):
        errors.append(f"[calibration] images = {use!r}: increasing, without repeats")
        use = []
    if c.get("plate_margin_mm") == "auto":  # 10 % of the smallest dimension (build.py)
        margin = auto_plate_margin_mm(width, depth, height) if width and depth and height else 0.0
    elif isinstance(c.get("plate_margin_mm"), str):
        errors.append(
            f'[calibration] plate_margin_mm = {c["plate_margin_mm"]!r}: a number of mm or "auto"'
        )
        margin = 0.0
    else:
        margin = _number(c, "plate_margin_mm", errors, "calibration", default=0.0, positive=False)
    why = margin is not None and height and Region.range_error(margin, height)
    if why:
        errors.append(f"[calibration] {why}")
    data_mesh = sec["virtual"].get("data_mesh", "")
    if data_mesh:
        try:
            parse_mesh_spec(data_mesh)
        except (ValueError, TypeError) as exc:
            errors.append(f"[virtual] data_mesh: {exc}")
    if errors:
        raise ExperimentFileError(path, errors)
    return Experiment(
        path=path,
        name=name,
        description=description,
        width_mm=width,
        depth_mm=depth,
        height_mm=height,
        platens=platens,
        face=face,
        units=units,
        affine=affine,
        calibration=calibration,
        roi_margin_mm=roi,
        log=log_path,
        log_columns=log_columns,
        displacement_scale=DISPLACEMENT_UNITS[du],
        force_scale=FORCE_UNITS[fu],
        compression_sign=1.0 if comp == "positive" else -1.0,
        zero_displacement=zero,
        force_accuracy_percent=accuracy,
        force_resolution_kN=res * FORCE_UNITS[fu],
        dic_files=tuple(dic_files),
        columns=columns,
        sigma=sigma,
        images=images_path,
        mesh=str(mesh),
        models=models,
        budget=int(budget),
        use_images=tuple(use),
        plate_margin_mm=margin,
        snapshot_rho=float(rho),
        route=route,
        reference_image=reference,
        correlation=correlation,
        roi_px=roi_px,
        data_mesh=str(data_mesh),
    )


def parse_models(models) -> list[str]:
    """``"all"``, a comma-separated string or a list of variants ``form-hardening`` -> names
    (ValueError naming the unknown ones)."""
    from problems.inverse.cases import CASES

    if models == "all" or models == ["all"]:
        return list(CASES)
    names = models.split(",") if isinstance(models, str) else models
    if not isinstance(names, list) or not names:
        raise ValueError(f"{models!r}: 'all' or a list of {', '.join(CASES)}")
    names = [str(n).strip() for n in names]
    bad = [n for n in names if n not in CASES]
    if bad:
        raise ValueError(f"{', '.join(bad)} unknown; allowed: all, {', '.join(CASES)}")
    return names


# --- reading the data files ----------------------------------------------------------------------
def sha256(path: Path) -> str:
    """SHA-256 of a file's bytes (hex)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def read_csv(path: Path, wanted: dict[str, str], what: str) -> dict[str, np.ndarray]:
    """Columns ``{role: header}`` of a CSV file with a header row as float arrays (empty cells
    NaN); ValueError naming the file and the missing column or the bad cell."""
    with open(path, newline="", encoding="utf-8-sig") as f:
        reader = csv.reader(f)
        try:
            header = [h.strip() for h in next(reader)]
        except StopIteration:
            raise ValueError(f"{what} {path}: empty file") from None
        rows = [r for r in reader if any(c.strip() for c in r)]
    out = {}
    for role, name in wanted.items():
        if name not in header:
            raise ValueError(
                f"{what} {path}: no column {name!r} ({role}); columns: {', '.join(header)}"
            )
        j = header.index(name)
        vals = np.full(len(rows), np.nan)
        for i, r in enumerate(rows):
            cell = r[j].strip() if j < len(r) else ""
            if cell and cell.lower() != "nan":
                try:
                    vals[i] = float(cell)
                except ValueError:
                    raise ValueError(
                        f"{what} {path}: row {i + 2}, column {name!r}: {cell!r} is not a number"
                    ) from None
        out[role] = vals
    return out


def read_log(exp: Experiment) -> tuple[np.ndarray, np.ndarray]:
    """``(displacement_mm (N,), force_kN (N,))`` at the images from the machine log
    (compression positive, displacement from the reference image)."""
    cols = {"d": exp.log_columns["displacement_column"], "f": exp.log_columns["force_column"]}
    image_col = exp.log_columns.get("image_column")
    if image_col:
        with open(exp.log, newline="", encoding="utf-8-sig") as f:
            reader = csv.reader(f)
            header = [h.strip() for h in next(reader)]
            if image_col not in header:
                raise ValueError(
                    f"machine log {exp.log}: no column {image_col!r} (image_column); columns: "
                    f"{', '.join(header)}"
                )
            j = header.index(image_col)
            marks = [bool(r[j].strip()) for r in reader if any(c.strip() for c in r)]
    data = read_csv(exp.log, cols, "machine log")
    rows = np.flatnonzero(marks) if image_col else np.arange(len(data["d"]))
    d = exp.compression_sign * (data["d"][rows] - exp.zero_displacement) * exp.displacement_scale
    f = exp.compression_sign * data["f"][rows] * exp.force_scale
    if len(rows) != len(exp.dic_files):
        table = "images" if exp.route == "images" else "dic"
        raise ValueError(
            f"machine log {exp.log}: {len(rows)} image rows, but [{table}] files lists "
            f"{len(exp.dic_files)} images"
        )
    if not (np.all(np.isfinite(d)) and np.all(np.isfinite(f))):
        raise ValueError(f"machine log {exp.log}: an image row has no displacement or force")
    return d, f


def force_sigma_kN(force_kN, accuracy_percent: float, resolution_kN: float = 0.0) -> np.ndarray:
    """Standard deviation (kN) of each force: a uniform error within +-``accuracy_percent`` % of
    the reading (an ISO 7500-1 class's relative accuracy error) and the resolution's rounding
    error, combined in quadrature. ValueError when it is zero (a force must have a weight)."""
    f = np.abs(np.asarray(force_kN, float))
    s = np.hypot(accuracy_percent / 100.0 / math.sqrt(3.0) * f, resolution_kN / math.sqrt(12.0))
    if np.any(s <= 0):
        raise ValueError(
            "a force reading of 0 kN has no standard deviation: declare the log's "
            "[loading] force_resolution"
        )
    return s


# --- rigid-body motion ---------------------------------------------------------------------------
def rigid_basis(y_mm, z_mm, fold_sign=None) -> np.ndarray:
    """(2 m, 3) fields of the in-plane rigid motions over points (y, z) mm of the face, in the
    layout ``[u_h (m), u_v (m)]``: translation h, translation v, rotation (rad) about the points'
    centroid. With ``fold_sign`` (m,) the u_h rows are those of the folded face (multiplied by
    it): ``y`` is then the true (unfolded) position."""
    y, z = np.asarray(y_mm, float), np.asarray(z_mm, float)
    m = len(y)
    yc, zc = y - y.mean(), z - z.mean()
    B = np.zeros((2 * m, 3))
    B[:m, 0] = 1.0
    B[m:, 1] = 1.0
    B[:m, 2] = -zc
    B[m:, 2] = yc
    if fold_sign is not None:
        B[:m] *= np.asarray(fold_sign, float)[:, None]
    return B


def rigid_fit(B, u, weights) -> np.ndarray:
    """Weighted least-squares rigid motion (3,) = (t_h mm, t_v mm, rotation rad) of the field
    ``u`` (2 m,) = [u_h, u_v] (or (2 m, k): then (3, k)) with ``weights`` (2 m,) = 1 / sigma^2."""
    w = np.asarray(weights, float)
    BW = B.T * w
    return np.linalg.solve(BW @ B, BW @ u)


@dataclass(frozen=True, eq=False)
class RigidMotionFree:
    """A forward model whose face displacements have their in-plane rigid motion removed per
    snapshot, as the imported data's (weighted least squares, the same basis and weights):
    the objective then compares deformations only. Picklable; Jacobians are projected alike.

    model   : the FE forward model on the dataset's (folded) points
    basis   : (2 m, 3) :func:`rigid_basis` of the points
    weights : (N, 2 m) 1 / sigma^2 per snapshot, [u_h, u_v]
    """

    model: object
    basis: np.ndarray
    weights: np.ndarray

    @property
    def names(self):
        return self.model.names

    @property
    def provides_jacobian(self) -> bool:
        return getattr(self.model, "provides_jacobian", False)

    @property
    def jacobian_cost(self):
        return getattr(self.model, "jacobian_cost", None)

    def check(self, x):
        return self.model.check(x)

    def project(self, values: np.ndarray) -> np.ndarray:
        """The measurement vector (or Jacobian rows) with each snapshot's rigid motion removed."""
        N, m2 = self.weights.shape
        m = m2 // 2
        u_h, u_v, f = layout.unstack(values, N, m)
        out_h, out_v = u_h.copy(), u_v.copy()
        for k in range(N):
            u = np.concatenate([u_h[k], u_v[k]])
            r = u - self.basis @ rigid_fit(self.basis, u, self.weights[k])
            out_h[k], out_v[k] = r[:m], r[m:]
        if np.ndim(values) == 1:
            return layout.stack(out_h, out_v, f)
        k = np.shape(values)[1]
        return np.concatenate([out_h.reshape(-1, k), out_v.reshape(-1, k), f])

    def __call__(self, x, jacobian: bool = False):
        res = self.model(x, jacobian=jacobian) if jacobian else self.model(x)
        if not res.ok:
            return res
        J = None if res.jacobian is None else self.project(res.jacobian)
        return replace(res, values=self.project(res.values), jacobian=J)


# --- the import ----------------------------------------------------------------------------------
def read_dic(exp: Experiment):
    """Per image: (points (m_k, 2) export units, u (m_k, 2) export units, sigma (m_k, 2) mm or
    NaN) and the number of rows with non-finite values."""
    wanted = {r: exp.columns[r] for r in ("x", "y", "u", "v")}
    out, n_nan = [], 0
    for path in exp.dic_files:
        with open(path, newline="", encoding="utf-8-sig") as f:
            header = [h.strip() for h in next(csv.reader(f), [])]
        sig = {}
        if exp.columns["sigma_u"] and exp.columns["sigma_v"]:
            sig = {"su": exp.columns["sigma_u"], "sv": exp.columns["sigma_v"]}
        elif exp.columns["sigma"] in header:
            sig = {"su": exp.columns["sigma"], "sv": exp.columns["sigma"]}
        elif exp.sigma is None:
            raise ValueError(
                f"DIC export {path}: no sigma column ({exp.columns['sigma']!r}) and no "
                "[dic] sigma declared"
            )
        c = read_csv(path, wanted | sig, "DIC export")
        P = np.column_stack([c["x"], c["y"]])
        U = np.column_stack([c["u"], c["v"]])
        S = np.column_stack([c["su"], c["sv"]]) if sig else np.full_like(U, exp.sigma)
        ok = np.all(np.isfinite(P), axis=1) & np.all(np.isfinite(U), axis=1)
        ok &= np.all(np.isfinite(S) & (S > 0), axis=1)
        n_nan += int((~ok).sum())
        out.append((P[ok], U[ok], S[ok]))
    return out, n_nan


def face_to_image(exp: Experiment, face_mm) -> np.ndarray:
    """Face coordinates (m, 2) = (s, z) mm -> the image's (x, y) px: the calibration's inverse."""
    A, c = exp.affine[:, :2], exp.affine[:, 2]
    return (np.asarray(face_mm, float) - c) @ np.linalg.inv(A).T


def subset_grid(exp: Experiment, shape: tuple[int, int], step: int | None = None):
    """The ``[images]`` route's subset centres in a reference image of ``shape`` (rows, cols):
    ``(points (n, 2) px, on (n,) bool, roi)``, the grid of ``step`` px (default ``[images]
    step``) centred in the ROI and which subsets lie entirely on the face, ``roi_margin_mm``
    inside its edges. ValueError (one line) for a ROI off the image or fewer than 4 subsets."""
    from problems.dic.correlate import grid_points

    cfg = exp.correlation
    rows, cols = shape
    W, H, mrg = exp.width_mm, exp.height_mm, exp.roi_margin_mm
    if exp.roi_px is None:
        box = face_to_image(exp, [[0.0, 0.0], [W, 0.0], [W, H], [0.0, H]])
        lo, hi = np.floor(box.min(axis=0)), np.ceil(box.max(axis=0)) + 1
        roi = (max(0, int(lo[0])), max(0, int(lo[1])), min(cols, int(hi[0])), min(rows, int(hi[1])))
        where = f"the face's bounding box {roi} px"
    else:
        roi, where = exp.roi_px, f"[images] roi = {list(exp.roi_px)}"
    try:
        pts = grid_points(shape, cfg.subset, step or cfg.step, roi)
    except ValueError as exc:
        raise ValueError(f"{where} in {exp.reference_image.name}: {exc}") from None
    # a subset (pixels c - h - 1/2 .. c + h + 1/2) must lie on the face, mrg inside its edges
    h = cfg.half + 0.5
    A, c = exp.affine[:, :2], exp.affine[:, 2]
    on = np.ones(len(pts), bool)
    for dx, dy in ((-h, -h), (h, -h), (h, h), (-h, h)):
        f = (pts + [dx, dy]) @ A.T + c
        on &= (f[:, 0] >= mrg) & (f[:, 0] <= W - mrg) & (f[:, 1] >= mrg) & (f[:, 1] <= H - mrg)
    if on.sum() < 4:
        raise ValueError(
            f"{where}: only {int(on.sum())} subsets of {cfg.subset} px lie on the face; check "
            "[camera] and [images]"
        )
    return pts, on, roi


def correlate_images(exp: Experiment):
    """The ``[images]`` route: the deformed images correlated against the reference by
    femubench's IC-GN DIC (:class:`~problems.dic.correlate.Correlator`, each image started from
    the previous one's solution), in the form of :func:`read_dic`.

    Subset centres lie on a grid (``step`` px) in the ROI (default: the face's bounding box in
    the image, from the calibration); subsets not entirely on the face, ``roi_margin_mm`` inside
    its edges, are not correlated (counted). Returns ``(per_image, n_failed, info)``: per image
    (centres (m_k, 2) px, u (m_k, 2) px, sigma (m_k, 2) px from the IC-GN covariance) of the
    converged points, the number of (image, point) pairs that did not converge, and ``info``
    (settings, counts, the images' grey-level noise) for the provenance. ValueError (one line
    naming the file or field) for unreadable, blank or differently sized images.
    """
    from problems.dic.correlate import Correlator, as_grey, check_not_blank
    from problems.dic.imageio import read_image

    cfg = exp.correlation
    ref = as_grey(read_image(exp.reference_image), f"reference image {exp.reference_image}")
    check_not_blank(ref, f"reference image {exp.reference_image}")
    rows, cols = ref.shape
    pts, on, roi = subset_grid(exp, ref.shape)
    corr = Correlator(ref, pts[on], cfg)
    per_image, failed, noise, prev = [], [], [], None
    for path in exp.dic_files:
        img = as_grey(read_image(path), f"image {path}")
        if img.shape != ref.shape:
            raise ValueError(
                f"image {path}: {img.shape[1]} x {img.shape[0]} px, but the reference "
                f"{exp.reference_image.name} is {cols} x {rows} px"
            )
        check_not_blank(img, f"image {path}")
        res = corr.correlate(img, initial=prev)
        ok = res.converged
        if np.any(ok):
            prev = res
        P = corr.points[ok]
        U = np.column_stack([res.u[ok], res.v[ok]])
        S = np.column_stack([res.std_u[ok], res.std_v[ok]])
        per_image.append((P, U, S))
        failed.append(int((~ok).sum()))
        noise.append(float(res.noise_sigma))
    info = {
        "subset_px": cfg.subset,
        "step_px": cfg.step,
        "order": cfg.order,
        "zncc_min": cfg.zncc_min,
        "search_radius_px": cfg.search_radius,
        "roi_px": [int(v) for v in roi],
        "image_px": [cols, rows],
        "subsets_correlated": int(on.sum()),
        "subsets_off_face": int((~on).sum()),
        "not_converged_per_image": failed,
        "grey_noise_per_image": noise,
    }
    return per_image, int(sum(failed)), info


def import_experiment(exp: Experiment) -> Dataset:
    """The Dataset of an experiment (see the module docstring): folded face points (y, z) mm of
    the quarter model, rigid-motion-free displacements and their sigma (mm), the machine's plate
    displacement (mm) and force (kN) at each image with the force's sigma, provenance in
    ``meta``. Raises ValueError (one line naming the file) for unreadable data."""
    d_mm, f_kN = read_log(exp)
    correlation = None
    if exp.route == "images":
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1):  # one BLAS thread: the same images, the same bytes
            per_image, n_nan, correlation = correlate_images(exp)
    else:
        per_image, n_nan = read_dic(exp)
    use = np.array(exp.use_images, int) - 1 if exp.use_images else np.arange(len(per_image))
    # points in every used image, keyed by their reference position
    keys = [{tuple(np.round(p, 6)): i for i, p in enumerate(per_image[k][0])} for k in use]
    common = set(keys[0]).intersection(*keys[1:])
    all_points = set().union(*keys)
    n_partial = len(all_points) - len(common)
    common = sorted(common)
    ref = per_image[use[0]][0][[keys[0][key] for key in common]] if common else np.zeros((0, 2))
    if len(ref) == 0:
        raise ValueError(f"DIC export: no point is in every image ({exp.dic_files[0].parent})")
    A, c = exp.affine[:, :2], exp.affine[:, 2]
    face = ref @ A.T + c  # (m, 2) s, z mm
    order = np.lexsort(np.round(face, 6).T[::-1])  # by s, then z: whatever the export's frame
    ref, face = ref[order], face[order]
    common = [common[i] for i in order]
    W, H, mrg = exp.width_mm, exp.height_mm, exp.roi_margin_mm
    on = (
        (face[:, 0] >= mrg)
        & (face[:, 0] <= W - mrg)
        & (face[:, 1] >= mrg)
        & (face[:, 1] <= H - mrg)
    )
    n_off = int((~on).sum())
    n_margin = 0
    if exp.plate_margin_mm:  # counted apart from the points off the face
        near = on & ~plate_margin_mask(face, exp.plate_margin_mm, H)
        n_margin = int(near.sum())
        on &= ~near
    ref, face = ref[on], face[on]
    common = [key for key, keep in zip(common, on) if keep]
    if len(ref) < 4:
        raise ValueError(f"DIC export: only {len(ref)} points on the face; check [camera]")
    scale = exp.calibration["mm_per_unit"]
    N, m = len(use), len(ref)
    u_h, u_v, std = np.zeros((N, m)), np.zeros((N, m)), np.zeros((2, N, m))
    y = face[:, 0] - W / 2.0
    sign = np.where(y < 0, -1.0, 1.0)
    B = rigid_basis(y, face[:, 1], sign)
    removed = []
    for row, k in enumerate(use):
        P, U, S = per_image[k]
        idx = np.array([keys[row][key] for key in common])
        du = U[idx] @ A.T  # (m, 2) mm: [along s, along z]
        s_mm = S[idx] * scale  # sigma (column or declared) is in the export's units
        u = np.concatenate([sign * du[:, 0], du[:, 1]])
        w = 1.0 / np.concatenate([s_mm[:, 0], s_mm[:, 1]]) ** 2
        motion = rigid_fit(B, u, w)
        r = u - B @ motion
        u_h[row], u_v[row] = r[:m], r[m:]
        std[0, row], std[1, row] = s_mm[:, 0], s_mm[:, 1]
        removed.append([float(v) for v in motion])
    levels = d_mm[use]
    force = f_kN[use]
    loading = MachineLoading(levels, exp.plates)  # validates increasing, > 0
    settings = DataSettings(
        tier=EXPERIMENT_TIER,
        mesh="",
        resolution_um=0.0,
        force_resolution_kN=exp.force_resolution_kN,
        displacement_mm=loading.displacement_mm,
        snapshots=N,
        plates=exp.plates,
        route="dic",
        specimen_mm=exp.specimen_mm,
        levels_mm=loading.levels_mm,
    )

    def rel(p: Path) -> str:
        return os.path.relpath(p, exp.path.parent)

    files = {
        "experiment": {rel(exp.path): sha256(exp.path)},
        "machine_log": {rel(exp.log): sha256(exp.log)},
    }
    if correlation is None:
        files["dic"] = {rel(p): sha256(p) for p in exp.dic_files}
    else:
        files["images"] = {rel(p): sha256(p) for p in (exp.reference_image, *exp.dic_files)}
        n_off += correlation["subsets_off_face"]
    meta = {
        "experiment": exp.name,
        "description": exp.description,
        "files_sha256": files,
        "calibration": exp.calibration,
        "face": exp.face,
        "platens": exp.platens,
        "points_read": len(all_points),
        "dropped_not_in_every_image": n_partial,
        "dropped_off_face": n_off,
        "dropped_non_finite_rows": n_nan,
        "fold_sign": sign.tolist(),
        "face_s_mm": face[:, 0].tolist(),
        "rigid_motion_removed": {"columns": ["t_h_mm", "t_v_mm", "rotation_rad"], "rows": removed},
        "images_used": [int(k) + 1 for k in use],
        "force_accuracy_percent": exp.force_accuracy_percent,
    }
    if exp.plate_margin_mm:  # absent without a margin: the data hashes of studies before stay
        meta["plate_margin_mm"] = exp.plate_margin_mm
        meta["dropped_plate_margin"] = n_margin
    if exp.images is not None:
        meta["images"] = os.path.relpath(exp.images, exp.path.parent)
    if correlation is not None:
        meta["correlation"] = correlation
    if exp.data_mesh:
        meta["data_mesh"] = exp.data_mesh
    return Dataset(
        f"experiment:{exp.name}",
        settings,
        {},
        np.column_stack([np.abs(y), face[:, 1]]),
        np.array(loading.levels_mm),
        u_h,
        u_v,
        force,
        std,
        meta,
        force_sigma_kN(force, exp.force_accuracy_percent, exp.force_resolution_kN),
        exp.snapshot_rho,
    )


def rigid_free_model(fe_model, data: Dataset) -> RigidMotionFree:
    """``fe_model`` (on ``data.points``) with the same rigid-motion removal as the imported
    data."""
    sign = np.array(data.meta["fold_sign"], float)
    B = rigid_basis(sign * data.points[:, 0], data.points[:, 1], sign)
    w = 1.0 / np.concatenate([data.std_u_mm[0], data.std_u_mm[1]], axis=1) ** 2
    return RigidMotionFree(fe_model, B, w)

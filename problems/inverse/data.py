"""Pseudo-experimental data sets: the reference response on a finer mesh, noised and rounded.

One data set is one JSON file (format ``femubench-data/1``) holding the measurements, the
settings that made them and a SHA-256 content hash. The same settings give the same bytes.
The nine default sets ship in ``results/data/`` so that the main job never needs the fine mesh.
"""
from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass, field
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import numpy as np

from problems.inverse.cases import Case, get_case
from problems.fe.newton import Loading
from problems.fe.front_face import measurement_grid

FORMAT = "femubench-data/1"
DATA_DIR = Path(__file__).resolve().parents[2] / "results" / "data"


@dataclass(frozen=True)
class DataSettings:
    """How a data set is made.

    mesh                : mesh of the *data* model (never the inverse model's), default ``fine``
    resolution_um       : displacement rounding step, micrometres (0: no rounding)
    noise_um            : standard deviation of added Gaussian displacement noise, micrometres
    force_resolution_kN : force rounding step, kN (0: no rounding)
    seed                : seed of the noise generator
    displacement_mm, snapshots, plates : the loading
    spacing_mm, margin_mm : the front-face measurement grid
    """

    mesh: str = "fine"
    resolution_um: float = 1.0
    noise_um: float = 0.0
    force_resolution_kN: float = 0.1
    seed: int = 0
    displacement_mm: float = 1.5
    snapshots: int = 10
    plates: str = "friction"
    spacing_mm: float = 5.0
    margin_mm: float = 5.0
    route: str = "fe"

    def __post_init__(self):
        for name in ("resolution_um", "noise_um", "force_resolution_kN"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} = {v!r} is out of range: must be >= 0")
        if self.route not in ("fe", "dic"):
            raise ValueError(f"route = {self.route!r} is unknown; allowed: fe, dic")
        self.loading  # validates displacement, snapshots, plates

    @property
    def loading(self) -> Loading:
        return Loading(self.displacement_mm, self.snapshots, self.plates)

    @property
    def points(self) -> np.ndarray:
        return measurement_grid(self.spacing_mm, self.margin_mm)


@dataclass(frozen=True, eq=False)
class Dataset:
    """Measured front-face displacements (mm) and plate force (kN) with their standard deviations."""

    case: str
    settings: DataSettings
    parameters: dict
    points: np.ndarray          # (m, 2) y, z mm
    snapshots_mm: np.ndarray    # (N,)
    u_h: np.ndarray             # (N, m) mm
    u_v: np.ndarray             # (N, m) mm
    reaction_kN: np.ndarray     # (N,)
    std_u_mm: np.ndarray        # (2, N, m) standard deviation of u_h and u_v, mm
    meta: dict = field(default_factory=dict)

    @property
    def values(self) -> np.ndarray:
        """Measurement vector ``[u_h, u_v, reaction]`` in the forward model's layout."""
        return np.concatenate([self.u_h.ravel(), self.u_v.ravel(), self.reaction_kN])

    def sigma(self, force_kN: float = 1.0) -> np.ndarray:
        """Standard deviations of the measurement vector (diagonal covariance), mm and kN."""
        if not force_kN > 0:
            raise ValueError(f"sigma_force_kN = {force_kN!r} is out of range: must be > 0 kN")
        return np.concatenate([self.std_u_mm.ravel(), np.full(len(self.reaction_kN), force_kN)])

    def to_json(self) -> str:
        doc = self._doc()
        doc["hash"] = _digest(doc)
        return json.dumps(doc, indent=None, separators=(",", ":"), sort_keys=True) + "\n"

    @property
    def hash(self) -> str:
        return _digest(self._doc())

    def _doc(self) -> dict:
        return {
            "format": FORMAT, "case": self.case, "settings": asdict(self.settings), "parameters": self.parameters,
            "points": self.points.tolist(), "snapshots_mm": self.snapshots_mm.tolist(),
            "u_h": self.u_h.tolist(), "u_v": self.u_v.tolist(), "reaction_kN": self.reaction_kN.tolist(),
            "std_u_mm": self.std_u_mm.tolist(), "meta": self.meta,
        }


def _digest(doc: dict) -> str:
    body = {k: v for k, v in doc.items() if k != "hash"}
    return hashlib.sha256(json.dumps(body, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def package_version() -> str:
    try:
        return version("femubench")
    except PackageNotFoundError:
        return "unknown"


def _round(values: np.ndarray, step: float) -> np.ndarray:
    return np.round(values / step) * step if step > 0 else values


def displacement_std_mm(settings: DataSettings) -> float:
    """Standard deviation of one displacement value: uniform rounding error (step/sqrt 12) and noise.

    Unrounded, noise-free data are weighted as if rounded to 1 um (a weight is needed; the
    cost scale is then that of the default data).
    """
    res_mm = (settings.resolution_um or 1.0) * 1e-3
    return math.hypot(res_mm / math.sqrt(12.0), settings.noise_um * 1e-3)


def make_data(case: Case | str, settings: DataSettings | None = None, *, x=None, progress: bool = False,
              **overrides) -> Dataset:
    """Compute a data set: the FE response at ``x`` (default: the case's reference) on ``settings.mesh``.

    Keyword overrides go into :class:`DataSettings` (``make_data(case, mesh="coarse", resolution_um=0)``).
    Raises RuntimeError when the data model itself does not converge.
    """
    from problems.inverse.forward import FEForwardModel

    case = get_case(case) if isinstance(case, str) else case
    settings = DataSettings(**{**asdict(settings or DataSettings()), **overrides})
    x = case.reference if x is None else np.asarray(x, float)
    model = FEForwardModel(case, settings.mesh, settings.loading, settings.points)
    resp = model.response(x, progress=progress)
    if not resp.converged:
        raise RuntimeError(f"data model of {case.name} on mesh {settings.mesh} failed: {resp.message}")
    u_h, u_v = resp.front_face(settings.points)
    if settings.route == "dic":
        return _dic_dataset(case, settings, x, resp)
    rng = np.random.default_rng(settings.seed)
    noise = settings.noise_um * 1e-3
    if noise > 0:
        u_h = u_h + rng.normal(0.0, noise, u_h.shape)
        u_v = u_v + rng.normal(0.0, noise, u_v.shape)
    res = settings.resolution_um * 1e-3
    std = np.full((2,) + u_h.shape, displacement_std_mm(settings))
    return Dataset(case.name, settings, dict(zip(case.names, map(float, x))), settings.points, resp.snapshots_mm,
                   _round(u_h, res), _round(u_v, res), _round(resp.reaction_kN, settings.force_resolution_kN), std,
                   {"package_version": package_version(), "mesh": resp.mesh.info()})


def _dic_dataset(case: Case, settings: DataSettings, x, resp) -> Dataset:
    """The DIC route: render speckle images of the response, correlate them back (see problems.dic)."""
    from problems.dic.route import dic_dataset

    return dic_dataset(case, settings, x, resp)


def save(ds: Dataset, path: str | Path) -> Path:
    """Write ``ds`` atomically as JSON."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(ds.to_json())
    tmp.replace(path)
    return path


def load(path: str | Path) -> Dataset:
    """Read a data set, checking its format and content hash."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"data file {path} is not valid JSON: {exc}") from None
    if doc.get("format") != FORMAT:
        raise ValueError(f"data file {path}: format {doc.get('format')!r} is not {FORMAT!r}")
    if doc.get("hash") != _digest(doc):
        raise ValueError(f"data file {path}: content hash does not match (file modified or truncated)")
    return Dataset(doc["case"], DataSettings(**doc["settings"]), doc["parameters"], np.array(doc["points"]),
                   np.array(doc["snapshots_mm"]), np.array(doc["u_h"]), np.array(doc["u_v"]),
                   np.array(doc["reaction_kN"]), np.array(doc["std_u_mm"]), doc.get("meta", {}))


def default_path(case: str) -> Path:
    """Where the shipped default data set of ``case`` lives."""
    return DATA_DIR / f"{case}.json"


def cached_path(case: str, settings: DataSettings) -> Path:
    """Cache file of a non-default data set, keyed by the settings."""
    key = hashlib.sha256(json.dumps(asdict(settings), sort_keys=True).encode()).hexdigest()[:12]
    return DATA_DIR / "cache" / f"{case}__{key}.json"


def get_data(case: str, settings: DataSettings | None = None, *, progress: bool = False) -> Dataset:
    """The data set of ``case`` for ``settings`` (default: shipped), computed and cached if missing."""
    settings = settings or DataSettings()
    path = default_path(case) if settings == DataSettings() else cached_path(case, settings)
    if path.exists():
        return load(path)
    if progress:
        print(f"computing data for {case} on mesh {settings.mesh} (cached in {path}) ...", flush=True)
    ds = make_data(case, settings, progress=progress)
    save(ds, path)
    return ds

"""Store and load surrogates: ``surrogate.npz`` (arrays) + ``surrogate.json``
(settings, validation, hash).

One surrogate is one folder. The JSON (format ``femubench-surrogate/1``) holds the settings,
cost, selection and validation, the description of the checker, the list of arrays and
``hash``: the SHA-256 of the JSON body (without ``hash``) and of every array (name, dtype,
shape, bytes). :func:`load` recomputes it and refuses a folder whose files were changed after
they were written. ``info["training_hash"]`` identifies the training set and settings.

Names: :func:`load` takes a folder, a ``surrogate.json`` / ``.npz`` path, or a *name* looked up
in a root folder: ``<root>/<name>/``. The root is the ``root`` argument, else
``$FEMUBENCH_SURROGATE_DIR``; the command line uses ``<results root>/surrogates`` (see
``bench.commands.surrogate``). The default name of the surrogate of a case on a mesh is
:func:`default_name` ``(case, mesh)``, e.g. ``linear-compression__coarse``.
"""

from __future__ import annotations

import hashlib
import importlib
import json
import os
import re
import zipfile
from dataclasses import asdict
from pathlib import Path

import numpy as np

from problems.surrogate.model import SurrogateModel
from problems.surrogate.pod import POD
from problems.surrogate.regression import from_stored

FORMAT = "femubench-surrogate/1"
JSON_NAME, NPZ_NAME = "surrogate.json", "surrogate.npz"
#: The build summary written beside them by ``femubench surrogate``.
BUILD_NAME = "build.json"
#: The files of a surrogate folder (anything else in it is not replaced: :func:`save` refuses).
OWN_FILES = (JSON_NAME, NPZ_NAME, BUILD_NAME)
#: environment variable: root folder of named surrogates
SURROGATE_DIR_ENV = "FEMUBENCH_SURROGATE_DIR"


def default_name(case: str, mesh: str) -> str:
    """Folder name of the surrogate of ``case`` on ``mesh``: ``<case>__<mesh>``, mesh characters
    other than letters, digits, ``.``, ``_`` and ``-`` replaced by ``_``
    (``3,3,6`` -> ``3_3_6``)."""
    return f"{case}__{re.sub(r'[^A-Za-z0-9._-]', '_', mesh)}"


def default_root() -> Path | None:
    """``$FEMUBENCH_SURROGATE_DIR`` if set, else None (the caller gives the root)."""
    env = os.environ.get(SURROGATE_DIR_ENV)
    return Path(env).expanduser() if env else None


def resolve(name_or_path: str | Path, root: str | Path | None = None) -> Path:
    """The folder of a stored surrogate: an existing folder or file path, else ``<root>/<name>``."""
    p = Path(name_or_path).expanduser()
    if p.is_file():
        return p.parent
    if p.is_dir():
        return p
    root = Path(root).expanduser() if root is not None else default_root()
    if root is not None and (root / str(name_or_path)).is_dir():
        return root / str(name_or_path)
    where = (
        f" nor in {root}" if root is not None else f" (set {SURROGATE_DIR_ENV} to look names up)"
    )
    raise FileNotFoundError(f"surrogate {str(name_or_path)!r} is neither a folder or file{where}")


def _array_digest(h, arrays: dict[str, np.ndarray]) -> None:
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        if a.dtype.kind == "f":
            a = a.astype("<f8")
        elif a.dtype.kind in "iu":
            a = a.astype("<i8")
        h.update(f"{name}|{a.dtype.str}|{a.shape}|".encode())
        h.update(a.tobytes())


def content_hash(doc: dict, arrays: dict[str, np.ndarray]) -> str:
    """SHA-256 of the JSON body (``hash`` left out) and of the arrays."""
    body = {k: v for k, v in doc.items() if k != "hash"}
    h = hashlib.sha256(json.dumps(body, sort_keys=True, separators=(",", ":")).encode())
    _array_digest(h, arrays)
    return h.hexdigest()


def _checker_spec(checker) -> tuple[dict, dict]:
    """JSON description of the checker and its arrays."""
    if checker is None:
        return {"kind": "none"}, {}
    from problems.inverse.forward import FEForwardModel

    if isinstance(checker, FEForwardModel):
        return (
            {
                "kind": "fe",
                "case": checker.case.name,
                "mesh": checker.mesh,
                "loading": asdict(checker.loading),
            },
            {"checker_points": np.asarray(checker.points, float)},
        )
    cls = type(checker)
    kwargs = checker.to_spec() if hasattr(checker, "to_spec") else {}
    return {"kind": "object", "class": f"{cls.__module__}:{cls.__qualname__}", "kwargs": kwargs}, {}


def _make_checker(spec: dict, arrays: dict):
    kind = spec.get("kind")
    if kind == "none":
        return None
    if kind == "fe":
        from problems.fe.newton import Loading
        from problems.inverse.cases import get_case
        from problems.inverse.forward import FEForwardModel

        return FEForwardModel(
            get_case(spec["case"]),
            spec["mesh"],
            Loading(**spec["loading"]),
            arrays["checker_points"],
        )
    if kind == "object":
        module, _, qualname = spec["class"].partition(":")
        try:
            obj = importlib.import_module(module)
            for part in qualname.split("."):
                obj = getattr(obj, part)
        except (ImportError, AttributeError) as exc:
            raise ValueError(
                f"checker class {spec['class']} cannot be imported ({exc}); pass checker= to load"
            ) from None
        return obj(**spec.get("kwargs", {}))
    raise ValueError(f"checker kind {kind!r} is unknown")


def _json_ready(value):
    from problems.io.jsonio import encode

    return encode(value)


def save(model: SurrogateModel, folder: str | Path, extra=None) -> Path:
    """Write ``model`` (``surrogate.npz`` + ``surrogate.json``) and the text files
    ``extra(size_bytes) -> {name: text}`` (e.g. ``build.json``; ``size_bytes``: the bytes of the
    npz and JSON, ``model.hash`` already set) into ``folder`` as one unit: they are written into a
    temporary folder beside it, which then replaces ``folder`` as a whole
    (:func:`problems.io.atomic.atomic_dir`), so no file of an older surrogate survives and a kill
    leaves the old surrogate or the new one. ValueError when ``folder`` holds files other than a
    surrogate's (:data:`OWN_FILES`). Returns the folder; sets ``model.info["hash"]``."""
    from problems.io.atomic import atomic_dir

    folder = Path(folder)
    foreign = (
        sorted(p.name for p in folder.iterdir() if p.name not in OWN_FILES)
        if (folder.is_dir())
        else []
    )
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"surrogate folder {folder} is a file")
    if foreign:
        raise ValueError(
            f"surrogate folder {folder} holds files that are not a surrogate's "
            f"({', '.join(foreign[:3])}); a surrogate replaces its folder as a whole, give another"
        )
    spec, checker_arrays = _checker_spec(model.checker)
    arrays = {
        "pod_mean": model.pod.mean,
        "pod_scale": model.pod.scale,
        "pod_modes": model.pod.modes,
        "pod_singular_values": model.pod.singular_values,
        "train_z": model.train_z,
        "lower": model.lower,
        "upper": model.upper,
        "design_lower": model.design_box[0],
        "design_upper": model.design_box[1],
        **checker_arrays,
        **{f"reg_{k}": v for k, v in model.regression.arrays().items()},
    }
    if model.hold_out_variance is not None:
        arrays["hold_out_variance"] = model.hold_out_variance
    arrays = {k: np.ascontiguousarray(v) for k, v in arrays.items()}
    info = {k: v for k, v in model.info.items() if k != "hash"}
    doc = _json_ready(
        {
            "format": FORMAT,
            "names": list(model.names),
            "checker": spec,
            "pod": {"tol_sigma": model.pod.tol_sigma, "projection_rms": model.pod.projection_rms},
            "regression": model.regression.settings(),
            "info": info,
            "arrays": {
                k: {"dtype": v.dtype.str, "shape": list(v.shape)} for k, v in arrays.items()
            },
        }
    )
    doc["hash"] = content_hash(doc, arrays)
    with atomic_dir(folder) as tmp:
        with open(tmp / NPZ_NAME, "wb") as fh:
            np.savez(fh, **arrays)
        (tmp / JSON_NAME).write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
        model.info["hash"] = doc["hash"]
        size = sum((tmp / name).stat().st_size for name in (NPZ_NAME, JSON_NAME))
        for name, text in (extra(size) if extra else {}).items():
            (tmp / name).write_text(text, encoding="utf-8")
    return folder


def load(
    name_or_path: str | Path, *, root: str | Path | None = None, checker=None
) -> SurrogateModel:
    """Load a stored surrogate (see the module docstring for names); verifies the content hash.

    checker : object whose ``check`` replaces the stored checker (needed when it cannot be rebuilt)
    Raises ValueError when the files were changed after writing or are not a surrogate.
    """
    folder = resolve(name_or_path, root)
    jpath, npath = folder / JSON_NAME, folder / NPZ_NAME
    for p in (jpath, npath):
        if not p.is_file():
            raise FileNotFoundError(f"{p} is missing: {folder} holds no stored surrogate")
    try:
        doc = json.loads(jpath.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{jpath} is not valid JSON: {exc}") from None
    if doc.get("format") != FORMAT:
        raise ValueError(f"{jpath} has format {doc.get('format')!r}, expected {FORMAT}")
    try:
        with np.load(npath, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, EOFError, OSError, ValueError) as exc:
        raise ValueError(
            f"{npath} is torn ({type(exc).__name__}: {exc}); build the surrogate again"
        ) from None
    if set(arrays) != set(doc.get("arrays", {})):
        raise ValueError(f"{folder}: the arrays of {NPZ_NAME} do not match {JSON_NAME}")
    digest = content_hash(doc, arrays)
    if digest != doc.get("hash"):
        raise ValueError(
            f"{folder}: content hash mismatch (stored {str(doc.get('hash'))[:12]}, computed "
            f"{digest[:12]}): the files were changed after they were written"
        )
    pod_doc = doc["pod"]
    pod = POD(
        arrays["pod_mean"],
        arrays["pod_scale"],
        arrays["pod_modes"],
        arrays["pod_singular_values"],
        float(pod_doc["tol_sigma"]),
        dict(pod_doc["projection_rms"]),
    )
    reg = from_stored(
        {k[4:]: v for k, v in arrays.items() if k.startswith("reg_")}, doc["regression"]
    )
    if checker is None:
        checker = _make_checker(doc["checker"], arrays)
    from problems.io.jsonio import decode

    info = dict(decode(doc["info"]), hash=doc["hash"])
    return SurrogateModel(
        tuple(doc["names"]),
        arrays["lower"],
        arrays["upper"],
        pod,
        reg,
        arrays["train_z"],
        (arrays["design_lower"], arrays["design_upper"]),
        checker,
        arrays.get("hold_out_variance"),
        info,
    )

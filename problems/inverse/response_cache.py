"""A small on-disk cache of expensive FE runs at one point, so that one solve of the model-error
tier's reference mesh serves both the data generator (:func:`problems.inverse.data.make_data`)
and the convergence study (:func:`bench.studies.convergence.solve_mesh`): on the converged
reference (``15,15,30:g16:hex27``, 440-720 CPU s per case without its Jacobian) solving it twice
would double the tier's cost.

An entry is one JSON file in ``<data cache dir>/responses/`` (default
``~/.cache/femubench/data/responses``, see :func:`problems.inverse.user_cache.cache_dir`), keyed
by the *request*: the case, the discretisation key (any spelling of one mesh gives the same
entry), the parameters, the loading (snapshot levels, plates), the measurement grid, the
specimen, the Newton settings and the hash of the code that computes the response
(:func:`code_hash`: the sources of :data:`CODE_SOURCES` but the mesh presets,
:data:`NOT_RESPONSE_CODE`, read once per process). It holds the
measurement vector, the exact Jacobian when the run that made it was asked for one (it costs
~0.5 plain runs more; the data need none, and the study takes the data mesh's run as it is), the
snapshot levels and mesh of the response, and the CPU and wall times of the run. Written
atomically with a SHA-256 of its content; an entry that is torn, edited or of another request is
computed again. Failed runs are not cached. After a change of the FE, material or forward-model
code an entry is not served (its request names another code hash; the stale file stays until the
folder is deleted); ``femubench data --check`` solves afresh (``reuse=False``) whatever the cache
holds.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import json
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from problems.fe.mesh import discretisation_key
from problems.inverse.user_cache import cache_dir
from problems.io import jsonio
from problems.io.atomic import atomic_write_text

SCHEMA = 1

#: the sources that determine a response, as globs under ``problems/``: the FE code, the
#: materials, and the forward model with what it reads (the measurement layout, the cases'
#: materials and fixed parameters)
CODE_SOURCES = (
    "fe/**/*.py",
    "materials/**/*.py",
    "inverse/forward.py",
    "inverse/layout.py",
    "inverse/case.py",
    "inverse/cases.py",
)


#: files matched by :data:`CODE_SOURCES` that compute no response: the mesh presets only name
#: discretisations, and a request holds the spelled-out one (:func:`request`), so re-pointing a
#: preset keeps every entry valid
NOT_RESPONSE_CODE = ("fe/presets.py",)


def code_text(source: str) -> bytes:
    """What of a Python source computes: its syntax tree without docstrings (comments,
    layout and docstrings change no response, so editing them keeps every entry valid); the
    bytes themselves for a file that does not parse. The dump follows the interpreter's AST, so
    another Python minor version hashes differently and solves again (never serves a wrong
    entry)."""
    try:
        tree = ast.parse(source)
    except SyntaxError:
        return source.encode()
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if (
            isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
            and body
            and isinstance(body[0], ast.Expr)
            and isinstance(body[0].value, ast.Constant)
            and isinstance(body[0].value.value, str)
        ):
            node.body = body[1:] or [ast.Pass()]
    return ast.dump(tree).encode()


def sources_hash(root: Path, patterns=CODE_SOURCES, excluded=NOT_RESPONSE_CODE) -> str:
    """SHA-256 (16 hex digits) of the files under ``root`` matched by ``patterns`` and not by
    ``excluded``: their relative paths and :func:`code_text`, in sorted order."""
    h = hashlib.sha256()
    skip = {p for pattern in excluded for p in root.glob(pattern)}
    files = {p for pattern in patterns for p in root.glob(pattern) if p.is_file()} - skip
    for path in sorted(files):
        h.update(path.relative_to(root).as_posix().encode() + b"\0")
        h.update(code_text(path.read_text(encoding="utf-8", errors="surrogateescape")) + b"\0")
    return h.hexdigest()[:16]


@functools.lru_cache(maxsize=1)
def code_hash() -> str:
    """The hash of this checkout's :data:`CODE_SOURCES` (computed once per process)."""
    return sources_hash(Path(__file__).resolve().parents[1])


def folder() -> Path:
    """Where the entries live: ``responses/`` in the data cache directory."""
    return cache_dir() / "responses"


def request(model, x) -> dict:
    """What identifies a run of the FE forward model ``model`` at ``x`` (physical units)."""
    return {
        "schema": SCHEMA,
        "case": model.case.name,
        "key": discretisation_key(model.mesh),
        "x": [float(v) for v in np.asarray(x, float)],
        "plates": model.loading.plates,
        "levels_mm": [float(v) for v in model.loading.snapshots_mm],
        "points": np.asarray(model.points, float).tolist(),
        "specimen_mm": [float(v) for v in model.specimen_mm],
        "newton": asdict(model.settings),
        "code": code_hash(),
    }


def _digest(doc: dict) -> str:
    body = {k: v for k, v in doc.items() if k != "sha256"}
    return hashlib.sha256(jsonio.dumps(body, sort_keys=True).encode()).hexdigest()


def entry_path(req: dict) -> Path:
    """``<folder>/<case>__<key>__<hash of the request>.json``."""
    h = hashlib.sha256(json.dumps(req, sort_keys=True).encode()).hexdigest()[:16]
    key = req["key"].replace(",", "x").replace(":", "_")
    return folder() / f"{req['case']}__{key}__{h}.json"


def lookup(model, x, jacobian: bool = False) -> dict | None:
    """The cached run of ``model`` at ``x`` (see :func:`solve`), or None (also when
    ``jacobian`` asks for a Jacobian the entry lacks)."""
    req = request(model, x)
    try:
        doc = jsonio.loads(entry_path(req).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    if not isinstance(doc, dict) or doc.get("sha256") != _digest(doc) or doc.get("request") != req:
        return None
    if jacobian and doc.get("jacobian") is None:
        return None
    return _arrays(doc) | {"reused": True}


def _arrays(doc: dict) -> dict:
    out = dict(doc)
    for name in ("values", "jacobian", "snapshots_mm"):
        out[name] = None if doc[name] is None else np.asarray(doc[name], float)
    return out


def solve(model, x, *, jacobian: bool = False, reuse: bool = True, progress=None) -> dict:
    """The run of the FE forward model ``model`` at ``x``, from the cache (unless ``reuse`` is
    False) or computed (with the exact Jacobian when ``jacobian``) and stored.

    Returns ``ok``, ``message``, ``values`` (m,) and ``jacobian`` (m, n; None when the run that
    made the entry had none) in the layout and units of the measurement vector, ``snapshots_mm``
    (N,) the response's plate displacements (mm), ``mesh`` (the response mesh's
    :meth:`~problems.fe.mesh.Mesh.info`), ``symmetry``, ``cpu_s``, ``wall_s`` and
    ``plain_wall_s`` (s, of the run that made the entry), ``reused`` (True when read from the
    cache). A failed run (``ok`` False, ``values`` None) is returned, not stored.
    ``progress``: a callable given one line before a run is computed.
    """
    hit = lookup(model, x, jacobian) if reuse else None
    if hit is not None:
        return hit
    if progress is not None:
        progress(f"solving {model.case.name} on {model.mesh} (cached in {folder()}) ...")
    cpu, wall = time.process_time(), time.perf_counter()
    res, resp = model.run_with_response(x, jacobian=jacobian)
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    ok = bool(res.ok and (res.jacobian is not None or not jacobian))
    doc = {
        "request": request(model, x),
        "ok": ok,
        "message": res.message,
        "values": None if res.values is None else res.values,
        "jacobian": res.jacobian,
        "snapshots_mm": None if resp is None else resp.snapshots_mm,
        "mesh": None if resp is None else resp.mesh.info(),
        "symmetry": None if resp is None else resp.symmetry,
        "cpu_s": cpu,
        "wall_s": wall,
        "plain_wall_s": res.plain_wall_s,
    }
    if not ok:
        return doc | {"reused": False}
    doc = jsonio.plain(doc)
    atomic_write_text(entry_path(doc["request"]), jsonio.dumps({**doc, "sha256": _digest(doc)}))
    return _arrays(doc) | {"reused": False}

"""The results store: one JSON record per run under ``DIR/runs/``, written atomically.

A record is keyed by the hash of its :class:`~bench.experiment.spec.RunSpec` (``RunSpec.hash``)
and lives in ``DIR/runs/<hash>.json``. It is written to a temporary file in the same directory
(``.<hash>.<random>.tmp``), flushed, fsync'ed and renamed over the final name with
:func:`os.replace`, so a reader (or a rerun after ``kill -9``) sees either the whole record or
none. Stray ``*.tmp`` files left by a killed writer are ignored by the loaders and removed by
:func:`clean_tmp` (which the runner calls while holding the directory lock).

A record carries ``digest``, the sha256 of its canonical JSON without that field
(:func:`record_digest`); a reader recomputes it, and recomputes the hash of the record's
``config`` (it must be the file name). Records written before digests existed have none and are
read as they are (their config is still checked).

Compact records: a record with a non-empty ``result.history`` is stored as two files, the JSON
without ``result.history`` and the companion ``DIR/runs/<hash>.history.xz`` (format 2): one xz
stream holding a JSON index line ``[[name, dtype, shape], ...]`` and then the bytes of those
numpy arrays. Each history key is one column (``x`` an ``(n, d)`` float64 array,
``<key>.present`` a boolean column when only some evaluations carry the key), stored in the
smallest of several exact encodings, entries ``<key>@<part>``: a column equal bit for bit to the
running minimum of another (``best_cost`` of ``cost``) as that rule (``runmin``); otherwise the
smallest of raw values in the narrowest dtype (``raw``/``f8``), float bytes regrouped by position
(``shuf1``/``shuf2``), integer steps (``delta``, ``drle.v``/``drle.n``), run lengths
(``rle.v``/``rle.n``), runs opening at another column's values (``rleref``); strings as a
vocabulary and codes (``vocab`` + codes). ``_n`` is the number of evaluations, ``_format`` 2.
The JSON names the companion in ``history_file`` (``{"name", "sha256", "n"}``, the sha256 of the
companion's bytes); a companion that is a release artefact may live outside the folder
(docs/artefacts.md, :func:`bench.artefacts.find_companion`). The companion is written first
(atomically), then the JSON; a reader checks the companion's sha256 and rebuilds exactly the
same in-memory record as from a one-file record (the writer decodes it before keeping it).
Format-1 companions (``<hash>.history.npz``, plain ``np.savez_compressed`` columns) are still
read. ``digest`` always covers the whole in-memory
record, history included, ``history_file`` left out: a torn or edited companion fails its
sha256, one that decodes to other values fails the digest; either way the record counts as
unreadable. A history that the columns cannot hold exactly (mixed types per key, ragged ``x``,
``"nan"`` strings among floats) or whose companion would be larger than its JSON (short
histories) stays in the one-file form. ``femubench records compact DIR`` converts one-file and
format-1 records (optionally a subset: ``--track``, ``--tier``, ``--method``, ``--record``,
``--limit``).

A record file that cannot be read as a record (truncated, empty, not JSON, JSON of the wrong
shape, a config that does not hash to the file name, or a content hash that does not match: a
record changed after it was written) counts as missing: the loaders skip it and return it in
:func:`scan_records`'s ``unreadable`` list, and the runner moves it into ``DIR/runs/corrupt/``
(as ``<hash>.json.corrupt-<UTC time>``, see :func:`set_aside_unreadable`) before running its
run again.

Record (JSON object)::

    schema       int, RECORD_SCHEMA
    config_hash  str, sha256 of the run configuration
    config       RunSpec.to_dict()
    suite        name of the suite that produced it
    result       RunResult.to_dict()
    data_hash    str | None, hash of the measured-data file used by the objective
    error        str | None, traceback when the run crashed (result.status == "failed")
    warnings     [str], the distinct warnings the run issued (at most 20)
    versions     {package: version}
    machine      {hostname, platform, python, cpu_count, ...}
    started      ISO-8601 UTC time
    finished     ISO-8601 UTC time
    digest       str, sha256 of the canonical JSON of the record without this field
                 (and without ``history_file``), with ``result.history`` in it
    history_file {name, sha256, n}, only in a compact record (``result.history`` then absent)

A record whose ``data_hash`` differs from the hash of the data set the run would use today (e.g.
another ``FEMUBENCH_DATA_DIR``) is stale: the runner moves it into ``DIR/runs/stale/`` and runs it
again (a record without ``data_hash`` is accepted).
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import time
from io import BytesIO
from pathlib import Path
from typing import Any, Iterator

from problems.io import jsonio
from problems.io.atomic import atomic_write, atomic_write_text

RECORD_SCHEMA = 1
RUNS = "runs"
#: Sub-folder of ``DIR/runs`` holding the unreadable records the runner moved aside.
CORRUPT = "corrupt"
#: Sub-folder of ``DIR/runs`` holding the records made on other data than today's.
STALE = "stale"
#: The record field holding its content hash (:func:`record_digest`).
DIGEST = "digest"
#: The field of a compact record naming its history companion.
HISTORY_FILE = "history_file"
#: File-name suffix of a compact record's history companion (format 2, written today).
HISTORY_SUFFIX = ".history.xz"
#: File-name suffix of a format-1 companion (``np.savez_compressed`` columns), still read.
HISTORY_SUFFIX_V1 = ".history.npz"
#: Keys the ``config`` of a record must have.
CONFIG_KEYS = ("case", "method", "seed", "start", "start_index", "budget")

log = logging.getLogger("femubench.store")

#: Canonical order of the study's parameters (Table 1 rows); others follow alphabetically.
PARAMETER_ORDER = ("E", "beta", "K", "psi", "sigma0", "H", "pt0", "a", "b")


def runs_dir(out_dir: str | Path) -> Path:
    return Path(out_dir) / RUNS


def record_path(out_dir: str | Path, config_hash: str) -> Path:
    return runs_dir(out_dir) / f"{config_hash}.json"


def corrupt_dir(out_dir: str | Path) -> Path:
    return runs_dir(out_dir) / CORRUPT


def _canonical(record: dict[str, Any]) -> str:
    """The canonical JSON of a record without its ``digest`` (what the digest covers)."""
    body = {k: v for k, v in record.items() if k != DIGEST}
    return json.dumps(jsonio.encode(body), sort_keys=True, separators=(",", ":"))


def record_digest(record: dict[str, Any]) -> str:
    """sha256 of the record's canonical JSON, its ``digest`` field left out."""
    return hashlib.sha256(_canonical(record).encode()).hexdigest()


def companion_path(path: str | Path, suffix: str = HISTORY_SUFFIX) -> Path:
    """The history companion ``<hash>.history.xz`` (``suffix``: or the format-1
    ``.history.npz``) of the record file ``<hash>.json``."""
    path = Path(path)
    return path.with_name(path.stem + suffix)


def companion_paths(path: str | Path) -> list[Path]:
    """The history companions of the record file ``path`` that exist (either format)."""
    return [
        c for s in (HISTORY_SUFFIX, HISTORY_SUFFIX_V1) if (c := companion_path(path, s)).is_file()
    ]


#: Format of the history companions written today (2: each column in its smallest lossless
#: encoding, LZMA-compressed; 1: plain ``np.savez_compressed`` columns, still read).
HISTORY_FORMAT = 2
#: Separator of a history key and its encoding part in a format-2 companion's entry names.
_ENC = "@"


def _history_columns(history: list) -> dict[str, Any] | None:
    """The numpy columns of a JSON-decoded ``history`` (list of dicts): ``_n`` and, per key, its
    values (``x`` as ``(n, d)`` float64) and ``<key>.present`` when only some entries carry it;
    None when the columns cannot hold the values exactly (mixed types per key, ragged ``x``)."""
    import numpy as np

    if not history or not all(isinstance(e, dict) for e in history):
        return None
    n = len(history)
    cols: dict[str, Any] = {"_n": np.array(n, dtype=np.int64)}
    for key in sorted({k for e in history for k in e}):
        if key.startswith("_") or key.endswith(".present") or _ENC in key:
            return None
        present = [key in e for e in history]
        values = [e[key] for e in history if key in e]
        kinds = {type(v) for v in values}
        if len(kinds) != 1:
            return None
        kind = kinds.pop()
        try:
            if kind is list:
                arr = np.array(values, dtype=np.float64)
                if arr.ndim != 2 or any(type(a) is not float for v in values for a in v):
                    return None
            elif kind in (bool, int, float, str):
                arr = np.array(values, dtype={bool: np.bool_, int: np.int64}.get(kind, None))
                if kind is float and arr.dtype != np.float64:
                    return None
            else:
                return None
        except (OverflowError, ValueError):
            return None
        cols[key] = arr
        if not all(present):
            cols[key + ".present"] = np.array(present, dtype=np.bool_)
    return cols


def _history_rows(cols) -> list[dict[str, Any]]:
    """The history list of dicts from its numpy columns (keys in sorted order per entry);
    ``cols`` as :func:`_history_columns` makes them, or a companion's entries (either format)."""
    if "_format" in cols:
        cols = _decode_columns(cols)
    n = int(cols["_n"])
    rows: list[dict[str, Any]] = [{} for _ in range(n)]
    for key in sorted(k for k in cols if k != "_n" and not k.endswith(".present")):
        values = cols[key].tolist()
        where = (
            [i for i, p in enumerate(cols[key + ".present"].tolist()) if p]
            if key + ".present" in cols
            else range(n)
        )
        for i, v in zip(where, values, strict=True):
            rows[i][key] = v
    return rows


def _small_int(values, unsigned: bool = False):
    """The integers ``values`` as the narrowest numpy integer array that holds them exactly."""
    import numpy as np

    arr = np.asarray(values, dtype=np.int64)
    kinds = (np.uint8, np.uint16, np.uint32) if unsigned else (np.int8, np.int16, np.int32)
    for dt in kinds:
        info = np.iinfo(dt)
        if arr.size == 0 or (arr.min() >= info.min and arr.max() <= info.max):
            return arr.astype(dt)
    return arr


def _run_starts(arr):
    """Indices where a run of bitwise-equal values (rows of a 2-d array) of ``arr`` begins."""
    import numpy as np

    change = np.ones(len(arr), dtype=bool)
    if len(arr) > 1:
        raw = arr.view(np.uint64) if arr.dtype.kind == "f" else arr
        diff = raw[1:] != raw[:-1]
        change[1:] = diff.reshape(len(arr) - 1, -1).any(axis=1)
    return np.flatnonzero(change)


def _candidates(arr) -> list[dict[str, Any]]:
    """Lossless encodings of the column ``arr`` on its own (each: part name -> array; decoded by
    :func:`_decode_columns`): raw (narrowest dtype; strings as a vocabulary and codes), byte
    regrouped floats, deltas and run lengths."""
    import numpy as np

    base: dict[str, Any] = {}
    if arr.dtype.kind == "U":  # strings: a vocabulary and small codes
        vocab, codes = np.unique(arr, return_inverse=True)
        base, arr = {"vocab": vocab}, _small_int(codes.reshape(-1), unsigned=True)
    out: list[dict[str, Any]] = []
    if arr.dtype.kind == "f":
        out.append({"f8": arr})
        # bytes regrouped by position (exponents together): compresses better
        shuf = np.ascontiguousarray(arr.T).view(np.uint8).reshape(-1, 8).T
        out.append({f"shuf{arr.ndim}": np.ascontiguousarray(shuf)})
    else:
        out.append({**base, "raw": arr if arr.dtype.kind == "b" or base else _small_int(arr)})
        if arr.dtype.kind in "iu" and not base:
            d = np.diff(arr.astype(np.int64), prepend=0)
            s = _run_starts(d)
            out.append({"delta": _small_int(d)})
            lengths = _small_int(np.diff(np.append(s, len(d))), unsigned=True)
            out.append({"drle.v": _small_int(d[s]), "drle.n": lengths})
    if arr.ndim == 1 or arr.dtype.kind == "f":  # rows of x repeat (MCMC: rejected moves)
        s = _run_starts(arr)
        n = _small_int(np.diff(np.append(s, len(arr))), unsigned=True)
        v = arr[s] if arr.dtype.kind in "fb" or base else _small_int(arr[s])
        out.append({**base, "rle.v": v, "rle.n": n})
    return out


def _derived(arr, raws: dict[str, Any]) -> list[dict[str, Any]]:
    """Encodings of the 1-d column ``arr`` that refer to one of the columns ``raws``: its
    running minimum (``runmin``) or run values opening at its values (``rleref``)."""
    import numpy as np

    out: list[dict[str, Any]] = []
    if arr.ndim != 1 or arr.dtype.kind == "U":
        return out
    s = _run_starts(arr)
    n = _small_int(np.diff(np.append(s, len(arr))), unsigned=True)
    for ref, src in raws.items():
        if src.shape != arr.shape or src.dtype != arr.dtype:
            continue
        if arr.dtype.kind == "f" and np.minimum.accumulate(src).tobytes() == arr.tobytes():
            out.append({"runmin": np.array(ref)})
        if src[s].tobytes() == arr[s].tobytes():
            out.append({"rleref.n": n, "rleref.ref": np.array(ref)})
    return out


#: LZMA preset of the companions (6: xz's default; 9 gains < 1 % on histories at ~10x memory).
_PRESET = 6


def _packed_size(parts: dict[str, Any]) -> int:
    """Bytes the parts add to the companion: LZMA-compressed alone, plus ~40 of index each."""
    import lzma

    filters = [{"id": lzma.FILTER_LZMA2, "preset": _PRESET}]
    return sum(
        40 + len(lzma.compress(a.tobytes(), format=lzma.FORMAT_RAW, filters=filters))
        for a in parts.values()
    )


def _encode_columns(cols: dict[str, Any]) -> dict[str, Any]:
    """The companion entries (format 2) of the columns ``cols`` (:func:`_history_columns`):
    ``_n``, ``_format`` and ``<key>@<part>`` arrays. A column that is the running minimum of
    another is stored as that rule (``runmin``); every other one in its smallest encoding, run
    values opening at another column's values by reference (``rleref``). A column only refers
    to one stored as itself."""
    import numpy as np

    raws = {k: v for k, v in cols.items() if k != "_n"}
    chosen = {key: min(_candidates(arr), key=_packed_size) for key, arr in raws.items()}
    referenced: set[str] = set()
    for key, arr in raws.items():
        if key in referenced:
            continue
        free = {k: v for k, v in raws.items() if k != key and not _refers(chosen[k])}
        derived = _derived(arr, free)
        best = next((d for d in derived if "runmin" in d), None)
        if best is None and derived:
            best = min(derived, key=_packed_size)
            if _packed_size(best) >= _packed_size(chosen[key]):
                best = None
        if best is not None:
            chosen[key] = best
            referenced.add(str(best.get("runmin", best.get("rleref.ref"))))
    entries = {"_n": cols["_n"], "_format": np.array(HISTORY_FORMAT, dtype=np.int64)}
    for key, parts in chosen.items():
        entries.update({f"{key}{_ENC}{p}": a for p, a in parts.items()})
    return entries


def _refers(parts: dict[str, Any]) -> bool:
    return "runmin" in parts or "rleref.ref" in parts


def _decode_columns(entries) -> dict[str, Any]:
    """The columns (as :func:`_history_columns`) of a format-2 companion's ``entries``."""
    import numpy as np

    if int(entries["_format"]) != HISTORY_FORMAT:
        raise ValueError(f"history format {int(entries['_format'])} is not {HISTORY_FORMAT}")
    parts: dict[str, dict[str, Any]] = {}
    for name, arr in entries.items():
        if _ENC in name:
            key, part = name.split(_ENC, 1)
            parts.setdefault(key, {})[part] = arr
    cols: dict[str, Any] = {"_n": entries["_n"]}

    def column(key: str, seen=()):
        if key in cols:
            return cols[key]
        if key in seen or key not in parts:
            raise ValueError(f"history column {key!r} missing or circular")
        p = parts[key]
        if "f8" in p or "raw" in p:
            arr = p.get("f8", p.get("raw"))
        elif "shuf1" in p or "shuf2" in p:
            b = p.get("shuf1", p.get("shuf2"))
            arr = np.ascontiguousarray(b.T).view("<f8").reshape(-1)
            if "shuf2" in p:
                arr = arr.reshape(-1, int(entries["_n"])).T.copy()
        elif "runmin" in p:
            arr = np.minimum.accumulate(column(str(p["runmin"]), (*seen, key)))
        elif "delta" in p:
            arr = np.cumsum(p["delta"].astype(np.int64))
        elif "drle.v" in p:
            arr = np.cumsum(np.repeat(p["drle.v"].astype(np.int64), p["drle.n"]))
        elif "rle.v" in p:
            v = p["rle.v"]
            v = v.astype(np.int64) if v.dtype.kind in "iu" else v
            arr = np.repeat(v, p["rle.n"], axis=0)
        elif "rleref.n" in p:
            n = p["rleref.n"].astype(np.int64)
            src = column(str(p["rleref.ref"]), (*seen, key))
            arr = np.repeat(src[np.cumsum(n) - n], n)
        else:
            raise ValueError(f"history column {key!r} has no known encoding ({sorted(p)})")
        if "vocab" in p:
            arr = p["vocab"][arr]
        elif arr.dtype.kind in "iu":
            arr = arr.astype(np.int64)
        cols[key] = arr
        return arr

    for key in parts:
        column(key)
    return cols


def _companion_bytes(entries: dict[str, Any]) -> bytes:
    """A format-2 companion: one xz stream (no check: the record's sha256 covers it) of a JSON
    index line ``[[name, dtype, shape], ...]`` followed by the arrays' bytes in that order."""
    import lzma

    index = [[k, a.dtype.str, list(a.shape)] for k, a in entries.items()]
    head = json.dumps(index, separators=(",", ":")).encode() + b"\n"
    body = b"".join(a.tobytes() for a in entries.values())
    return lzma.compress(head + body, format=lzma.FORMAT_XZ, check=lzma.CHECK_NONE, preset=_PRESET)


def _companion_entries(data: bytes) -> dict[str, Any]:
    """The arrays of a format-2 companion's bytes (ValueError when they do not decode)."""
    import lzma

    import numpy as np

    try:
        raw = lzma.decompress(data, format=lzma.FORMAT_XZ)
    except lzma.LZMAError as exc:
        raise ValueError(str(exc)) from None
    head, sep, body = raw.partition(b"\n")
    if not sep:
        raise ValueError("no index line")
    entries, pos = {}, 0
    for name, dtype, shape in json.loads(head):
        dt = np.dtype(dtype)
        if dt.hasobject:
            raise ValueError(f"entry {name!r} holds objects")
        size = dt.itemsize * math.prod(shape)
        if pos + size > len(body):
            raise ValueError(f"entry {name!r} is cut short")
        entries[name] = np.frombuffer(body, dt, math.prod(shape), pos).reshape(shape)
        pos += size
    if pos != len(body):
        raise ValueError(f"{len(body) - pos} bytes after the last entry")
    return entries


def _history_entries(history) -> dict[str, Any] | None:
    """The format-2 companion entries of a JSON-decoded ``history``, None when they would not
    give back exactly the same list (same canonical JSON, every float bit for bit)."""
    cols = _history_columns(history) if isinstance(history, list) else None
    if cols is None:
        return None
    entries = _encode_columns(cols)
    same = json.dumps(_history_rows(entries), sort_keys=True) == json.dumps(history, sort_keys=True)
    return entries if same else None


def _record_text(record: dict[str, Any]) -> str:
    return json.dumps(record, sort_keys=True, separators=(",", ":")) + "\n"


def write_record(out_dir: str | Path, record: dict[str, Any]) -> Path:
    """Write one record atomically to ``DIR/runs/<config_hash>.json`` with its content hash
    (``digest``, :func:`record_digest`); return its path. A record with a history the columns
    hold exactly is written compact (companion first, see the module doc)."""
    h = record["config_hash"]
    path = record_path(out_dir, h)
    record = {**record, DIGEST: record_digest(record)}
    write_encoded(path, jsonio.encode(record))
    return path


def write_encoded(path: Path, encoded: dict[str, Any]) -> bool:
    """Write the JSON-ready record ``encoded`` (with its ``digest``) to ``path``, compact when
    its history allows; True when compact."""

    result = encoded.get("result")
    entries = _history_entries(result.get("history")) if isinstance(result, dict) else None
    if entries is None:
        atomic_write_text(path, _record_text(encoded))
        for c in companion_paths(path):  # left by an earlier compact record
            c.unlink()
        return False
    data = _companion_bytes(entries)
    if len(data) >= len(json.dumps(result["history"], separators=(",", ":"))):
        atomic_write_text(path, _record_text(encoded))  # small history: one file is smaller
        for c in companion_paths(path):
            c.unlink()
        return False
    comp = companion_path(path)
    atomic_write(comp, lambda fh: fh.write(data))
    body = {**encoded, "result": {k: v for k, v in result.items() if k != "history"}}
    body[HISTORY_FILE] = {
        "name": comp.name,
        "sha256": hashlib.sha256(data).hexdigest(),
        "n": len(result["history"]),
    }
    atomic_write_text(path, _record_text(body))
    companion_path(path, HISTORY_SUFFIX_V1).unlink(missing_ok=True)  # no longer named
    return True


def _inflate(rec, path: Path):
    """Put the companion's history back into a compact record ``rec`` read from ``path``
    (ValueError when the companion is missing, torn or edited). A companion that is not beside
    its record is looked for as a release artefact (:func:`bench.artefacts.find_companion`: the
    surrogate-track companions of the shipped comparison); a listed one in neither place raises
    :class:`bench.artefacts.MissingArtefact` (an OSError, not a ValueError: the record is not
    unreadable, so the loaders stop with its one line rather than skip the record or set it
    aside)."""
    if not isinstance(rec, dict) or HISTORY_FILE not in rec:
        return rec
    import numpy as np

    ref = rec.pop(HISTORY_FILE)
    names = {companion_path(path, s).name: s for s in (HISTORY_SUFFIX, HISTORY_SUFFIX_V1)}
    if not isinstance(ref, dict) or ref.get("name") not in names:
        raise ValueError(f"{HISTORY_FILE} names neither of {', '.join(names)}")
    comp = companion_path(path, names[ref["name"]])
    if not comp.is_file():  # a release artefact out of the tree? (MissingArtefact when listed)
        from bench.artefacts import find_companion

        config = rec.get("config")
        track = config.get("track") if isinstance(config, dict) else None
        comp = find_companion(path, track, comp.name, str(ref.get("sha256"))) or comp
    try:
        data = comp.read_bytes()
    except OSError as exc:
        raise ValueError(f"history companion {comp.name} cannot be read ({exc.strerror})") from None
    if hashlib.sha256(data).hexdigest() != ref.get("sha256"):
        raise ValueError(f"history companion {comp.name} hash mismatch (torn or edited)")
    try:
        if comp.name.endswith(HISTORY_SUFFIX):
            history = _history_rows(_companion_entries(data))
        else:
            with np.load(BytesIO(data), allow_pickle=False) as z:
                history = _history_rows({k: z[k] for k in z.files})
    except (OSError, ValueError, KeyError, TypeError, IndexError) as exc:
        raise ValueError(f"history companion {comp.name} cannot be decoded ({exc})") from None
    if not isinstance(rec.get("result"), dict):
        raise ValueError("'result' missing or not an object")
    rec["result"]["history"] = history
    return rec


def read_record(path: str | Path) -> dict[str, Any]:
    """The record at ``path`` as stored (both forms, the history put back), unchecked."""
    with open(path, encoding="utf-8") as fh:
        return _inflate(json.load(fh), Path(path))


def load_record(path: str | Path) -> dict[str, Any]:
    """Read the record file ``path`` and check its shape; ValueError saying what is wrong."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise ValueError("not UTF-8 text") from None
    except OSError as exc:
        raise ValueError(f"cannot be read ({exc.strerror or exc})") from None
    if not text.strip():
        raise ValueError("empty file")
    try:
        rec = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"not valid JSON (truncated?): {exc}") from None
    rec = _inflate(rec, path)
    check_record(rec, path.stem)
    return rec


def check_record(rec, config_hash: str) -> None:
    """ValueError unless ``rec`` has the shape of a record stored under ``config_hash``."""
    if not isinstance(rec, dict):
        raise ValueError(f"a JSON {type(rec).__name__}, not a record object")
    if rec.get("config_hash") != config_hash:
        raise ValueError(f"config_hash {rec.get('config_hash')!r} does not match the file name")
    config, result = rec.get("config"), rec.get("result")
    if not isinstance(config, dict) or not isinstance(result, dict):
        raise ValueError("'config' or 'result' missing or not an object")
    missing = [k for k in CONFIG_KEYS if k not in config]
    if missing:
        raise ValueError(f"config lacks {', '.join(missing)}")
    from bench.experiment.spec import RunSpec

    try:
        actual = RunSpec.from_dict(config).hash
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"config cannot be read ({type(exc).__name__}: {exc})") from None
    if actual != config_hash:
        raise ValueError(f"config does not match the file name (its hash is {actual[:12]})")
    if DIGEST in rec and rec[DIGEST] != record_digest(rec):
        raise ValueError("content hash mismatch (the record was changed after it was written)")


def has_record(out_dir: str | Path, config_hash: str) -> bool:
    return record_path(out_dir, config_hash).is_file()


def stray_tmp(out_dir: str | Path) -> list[Path]:
    """Temporary files left behind by killed writers."""
    d = runs_dir(out_dir)
    return sorted(d.glob("*.tmp")) if d.is_dir() else []


def clean_tmp(out_dir: str | Path) -> int:
    """Remove stray temporary files; only call while no writer is active (the runner's lock)."""
    n = 0
    for p in stray_tmp(out_dir):
        try:
            p.unlink()
            n += 1
        except FileNotFoundError:
            pass
    return n


def scan_records(out_dir: str | Path) -> tuple[list[dict[str, Any]], list[tuple[Path, str]]]:
    """``(records, unreadable)``: every complete record of ``DIR/runs`` (sorted by hash) and the
    ``(path, reason)`` of every record file that could not be read as a record. Stray ``*.tmp``
    files are ignored and reported."""
    d = runs_dir(out_dir)
    if not d.is_dir():
        return [], []
    tmp = stray_tmp(out_dir)
    if tmp:
        log.warning(
            "ignoring %d stray temporary file(s) in %s (left by an interrupted run)", len(tmp), d
        )
    records, unreadable = [], []
    for p in sorted(d.glob("*.json")):
        try:
            records.append(load_record(p))
        except ValueError as exc:
            unreadable.append((p, str(exc)))
    return records, unreadable


def iter_records(out_dir: str | Path) -> Iterator[dict[str, Any]]:
    """Yield every complete record of ``DIR/runs`` (sorted by hash); unreadable files are skipped
    with a warning, stray ``*.tmp`` files are ignored and reported."""
    records, unreadable = scan_records(out_dir)
    for p, why in unreadable:
        log.warning("skipping unreadable record %s: %s", p, why)
    yield from records


def load_records(out_dir: str | Path) -> list[dict[str, Any]]:
    """All complete records of a results directory."""
    return list(iter_records(out_dir))


def done_hashes(out_dir: str | Path) -> set[str]:
    """Hashes of the runs that have a readable record."""
    return {rec["config_hash"] for rec in scan_records(out_dir)[0]}


def set_aside(path: Path, folder: str = CORRUPT) -> Path:
    """Move the record file ``path`` into ``runs/<folder>/<name>.<folder>-<UTC time>`` (folder
    :data:`CORRUPT` or :data:`STALE`); return the new path."""
    dest_dir = path.parent / folder
    dest_dir.mkdir(exist_ok=True)
    stem = f"{path.name}.{folder}-{time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())}"
    dest, n = dest_dir / stem, 1
    while dest.exists():
        dest, n = dest_dir / f"{stem}-{n}", n + 1
    for comp in companion_paths(path):
        os.replace(comp, dest.with_name(dest.name + comp.name[len(path.stem) :]))
    os.replace(path, dest)
    return dest


def set_aside_unreadable(
    out_dir: str | Path, unreadable: list[tuple[Path, str]] | None = None
) -> list[tuple[Path, Path, str]]:
    """Move every unreadable record of ``DIR/runs`` (``unreadable``: those :func:`scan_records`
    found, default: scanned now) into ``DIR/runs/corrupt/`` (only call while no writer is
    active: the runner's lock); return ``(old path, new path, reason)`` of each."""
    if unreadable is None:
        unreadable = scan_records(out_dir)[1]
    return [(p, set_aside(p), why) for p, why in unreadable]


def set_aside_files(out_dir: str | Path, folder: str = CORRUPT) -> list[Path]:
    """The record files moved aside so far: unreadable ones (``DIR/runs/corrupt/``), or with
    ``folder=STALE`` those made on other data (``DIR/runs/stale/``)."""
    d = runs_dir(out_dir) / folder
    if not d.is_dir():
        return []
    return sorted(
        p
        for p in d.iterdir()
        if p.is_file() and not p.name.endswith((HISTORY_SUFFIX, HISTORY_SUFFIX_V1))
    )


def compact_records(
    out_dir: str | Path,
    *,
    dry_run: bool = False,
    track: str | None = None,
    tier: str | None = None,
    method: str | None = None,
    limit: int | None = None,
    only: list[str] | None = None,
) -> list[tuple[Path, int, int, int]]:
    """Convert the records of ``DIR/runs`` to the compact form of today: one-file records whose
    history the columns hold exactly, and format-1 compact ones (``.history.npz``). Return
    ``(path, bytes before, JSON bytes after, companion bytes after)`` of each converted record
    (before: the JSON and any old companion). Each is written to a temporary name, read back and
    compared with the original (same canonical JSON, or ValueError and nothing replaced), then
    renamed into place (companion first). ``dry_run`` writes into a temporary folder only.
    Unreadable records are left alone. Selection: ``track`` ``"fe"`` (records without a
    ``config.track``) or a track name (e.g. ``"surrogate"``); ``tier``: the data tier
    (``config.tier``, ``"model-error"`` when absent, as :func:`method_label`); ``method``: the
    solver (``config.method``, e.g. ``"mcmc"``); ``only``: record file names or hashes;
    ``limit``: at most that many conversions, in file-name order."""
    import tempfile

    wanted = {Path(o).name.removesuffix(".json") for o in only} if only is not None else None
    out: list[tuple[Path, int, int, int]] = []
    for path in sorted(runs_dir(out_dir).glob("*.json")):
        if limit is not None and len(out) >= limit:
            break
        if wanted is not None and path.stem not in wanted:
            continue
        text = path.read_text(encoding="utf-8")
        try:  # select on the stored JSON first: checking a record costs more than parsing it
            stored = json.loads(text)
            config, ref = stored["config"], stored.get(HISTORY_FILE)
            of_track, of_tier = config.get("track") or "fe", config.get("tier", "model-error")
            of_method = config.get("method")
        except (ValueError, TypeError, KeyError, AttributeError):
            continue  # unreadable: left alone
        if (track is not None and of_track != track) or (tier is not None and of_tier != tier):
            continue
        if method is not None and of_method != method:
            continue
        if isinstance(ref, dict) and str(ref.get("name")).endswith(HISTORY_SUFFIX):
            continue  # compact already
        try:
            rec = load_record(path)
        except ValueError:
            continue
        before = len(text.encode()) + sum(c.stat().st_size for c in companion_paths(path))
        with tempfile.TemporaryDirectory(dir=path.parent, prefix=".compact-") as tmp:
            trial = Path(tmp) / path.name
            if not write_encoded(trial, rec):
                continue
            back = load_record(trial)
            if json.dumps(back, sort_keys=True) != json.dumps(rec, sort_keys=True):
                raise ValueError(f"{path.name}: the compact form does not load back equal")
            comp = companion_path(trial)
            sizes = (trial.stat().st_size, comp.stat().st_size)
            if not dry_run:
                os.replace(comp, companion_path(path))
                os.replace(trial, path)
                companion_path(path, HISTORY_SUFFIX_V1).unlink(missing_ok=True)
        out.append((path, before, *sizes))
    return out


def parameter_order(names) -> list[str]:
    names = list(dict.fromkeys(names))
    known = [n for n in PARAMETER_ORDER if n in names]
    return known + sorted(n for n in names if n not in PARAMETER_ORDER)


def _num(v) -> float:
    if v is None:
        return math.nan
    if isinstance(v, str):
        return {"inf": math.inf, "-inf": -math.inf, "nan": math.nan}.get(v, math.nan)
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def case_facts(name: str) -> tuple[bool, str, float] | None:
    """``(analytic, default treatment, its plate margin in mm)`` of case ``name`` from
    :mod:`problems.inverse.cases`, None for an unknown case (the report passes its frozen table,
    :func:`bench.report.catalogue.case_facts`, instead)."""
    from problems.inverse.cases import all_cases, default_treatment

    case = all_cases().get(name)
    if case is None:
        return None
    if case.is_analytic:
        return True, "none", 0.0
    d = default_treatment(name)
    return False, d.treatment, d.plate_margin_mm


def method_label(config: dict, facts=case_facts) -> str:
    """How a run's method is shown in tables and figures: the solver with its data tier and, when
    there is one, its model-error treatment, finite-difference Jacobian and surrogate track, e.g.
    ``lm (model-error, iterated)``, ``lm (model-error, iterated on 9,9,18:g16:gz8:hex27)`` (a
    high-fidelity mesh named in the configuration), ``lm (consistent, FD forward)``,
    ``cma (consistent, surrogate + FE polish)``. ``facts``: :func:`case_facts` or a function like
    it (what ``default`` stands for)."""
    known = facts(config["case"])
    if known is None or known[0]:  # analytic problems have no data tiers
        return config["method"]
    tags = [config.get("tier", "model-error")]
    treatment = config.get("treatment", "none")
    if treatment == "default":
        margin = f" {known[2]:g} mm" if known[2] else ""
        tags.append(f"default {known[1]}{margin}")
    elif treatment != "none":  # with the high-fidelity mesh when the run names one
        hifi = config.get("hifi_mesh")
        tags.append(f"{treatment} on {hifi}" if hifi else treatment)
    if config.get("jacobian", "exact") != "exact":
        tags.append(f"FD {config['jacobian']}")
    if config.get("track", "fe") == "surrogate":
        tags.append("surrogate + FE polish")
    return f"{config['method']} ({', '.join(tags)})"


def to_frames(out_dir: str | Path, records: list[dict] | None = None, *, facts=case_facts):
    """Load a results directory into two tidy DataFrames ``(runs, history)``.

    ``runs``: one row per run — configuration columns (case, ``method`` = :func:`method_label`,
    ``solver``, ``tier``, ``treatment``, seed, start, start_index, budget, mesh, ``data.<key>``,
    options as JSON), outcome (``forward_equivalents`` of the solver's evaluations, measured;
    ``forward_equivalents_nominal``, what the budget counted, in ``budget_unit``;
    ``charged_equivalents`` of the runs made for it, ``total_equivalents``) (status, success, cost,
    n_evals, ..., wall_s), per parameter ``x.<p>`` (physical), ``xn.<p>`` (x / reference),
    ``err.<p>`` (signed error in percent; NaN where the parameter is inactive) and ``x0.<p>``, plus
    provenance (data_hash, hostname, started, finished, crashed).

    ``history``: one row per history row of each run — config_hash, case, method, seed, start,
    start_index, budget, ``step`` (the row's position in the run's history), ``phase`` (e.g.
    ``polish`` after a surrogate search; empty when the solver gives none), iteration, n_evals,
    cost, best_cost and ``xn.<p>``/``err.<p>``.

    ``facts``: what the method labels take from the cases (:func:`method_label`).
    """
    import numpy as np
    import pandas as pd

    records = load_records(out_dir) if records is None else records
    all_params: list[str] = []
    for rec in records:
        all_params.extend(rec["result"].get("parameter_names", []))
    params = parameter_order(all_params)

    rows, hrows = [], []
    for rec in records:
        cfg, res = rec["config"], rec["result"]
        names = list(res.get("parameter_names", []))
        ref = np.array([_num(v) for v in res.get("reference", [])], float)
        x = np.array([_num(v) for v in res.get("x", [])], float)
        xn = np.array([_num(v) for v in res.get("x_normalised", [])], float)
        x0 = np.array([_num(v) for v in res.get("x0", [])], float)
        key = {
            "config_hash": rec["config_hash"],
            "suite": rec.get("suite"),
            "case": cfg["case"],
            "method": method_label(cfg, facts),
            "seed": int(cfg["seed"]),
            "start": cfg["start"],
            "start_index": int(cfg["start_index"]),
            "budget": int(cfg["budget"]),
        }
        row = dict(key)
        row["solver"] = cfg["method"]
        row["tier"] = cfg.get("tier", "model-error")
        row["treatment"] = cfg.get("treatment", "none")
        row["track"] = cfg.get("track", "fe")
        row["jacobian"] = cfg.get("jacobian", "exact")
        row["polish"] = cfg.get("track", "fe") == "surrogate"
        row["mesh"] = cfg.get("mesh")
        charges = res.get("charges") or {}
        charges = charges.values() if isinstance(charges, dict) else charges
        row["forward_equivalents"] = _num(res.get("forward_equivalents"))
        row["forward_equivalents_nominal"] = _num(
            res.get("forward_equivalents_nominal", res.get("forward_equivalents"))
        )
        row["budget_unit"] = cfg.get("budget_unit", "evaluations")
        row["charged_equivalents"] = sum(_num(c.get("forward_equivalents")) for c in charges)
        row["total_equivalents"] = row["forward_equivalents"] + row["charged_equivalents"]
        for k, v in sorted((cfg.get("data") or {}).items()):
            row[f"data.{k}"] = v
        row["options"] = json.dumps(cfg.get("options") or {}, sort_keys=True)
        row.update(
            {
                "status": res.get("status"),
                "success_solver": bool(res.get("success")),
                "cost": _num(res.get("cost")),
                "n_evals": int(res.get("n_evals") or 0),
                "n_failed": int(res.get("n_failed") or 0),
                "n_infeasible": int(res.get("n_infeasible") or 0),
                "n_cache_hits": int(res.get("n_cache_hits") or 0),
                "n_iterations": int(res.get("n_iterations") or 0),
                "wall_s": _num(res.get("wall_s")),
                "message": res.get("message", ""),
                "crashed": bool(rec.get("error")),
                "data_hash": rec.get("data_hash"),
                "hostname": (rec.get("machine") or {}).get("hostname"),
                "started": rec.get("started"),
                "finished": rec.get("finished"),
                "n_params": len(names),
                "max_abs_err": float(np.max(np.abs(100.0 * (xn - 1.0)))) if len(xn) else math.nan,
            }
        )
        idx = {n: i for i, n in enumerate(names)}
        for p in params:
            i = idx.get(p)
            row[f"x.{p}"] = x[i] if i is not None and i < len(x) else math.nan
            row[f"xn.{p}"] = xn[i] if i is not None and i < len(xn) else math.nan
            row[f"err.{p}"] = 100.0 * (xn[i] - 1.0) if i is not None and i < len(xn) else math.nan
            row[f"x0.{p}"] = x0[i] if i is not None and i < len(x0) else math.nan
        rows.append(row)

        for step, h in enumerate(res.get("history") or []):
            hr = dict(key)
            hr["step"] = step  # the row's position: iterations restart in an FE polish
            hr["phase"] = str(h.get("phase", ""))
            hr["iteration"] = int(h.get("iteration", step))
            hr["n_evals"] = int(h.get("n_evals") or 0)
            hr["cost"] = _num(h.get("cost"))
            hr["best_cost"] = _num(h.get("best_cost", h.get("cost")))
            hx = h.get("x")
            hxn = (
                (np.array([_num(v) for v in hx], float) / ref)
                if hx is not None and len(hx) == len(ref)
                else np.full(len(names), math.nan)
            )
            for p in params:
                i = idx.get(p)
                hr[f"xn.{p}"] = hxn[i] if i is not None else math.nan
                hr[f"err.{p}"] = 100.0 * (hxn[i] - 1.0) if i is not None else math.nan
            hr["max_abs_err"] = float(np.max(np.abs(100.0 * (hxn - 1.0)))) if len(hxn) else math.nan
            hrows.append(hr)

    runs = pd.DataFrame(rows)
    history = pd.DataFrame(hrows)
    sort = ["case", "method", "budget", "seed", "start", "start_index"]
    if len(runs):
        runs = runs.sort_values(sort, kind="stable").reset_index(drop=True)
    if len(history):
        history = history.sort_values(sort + ["step"], kind="stable").reset_index(drop=True)
    runs.attrs["parameters"] = params
    history.attrs["parameters"] = params
    return runs, history


def write_parquet(out_dir: str | Path, dest: str | Path | None = None) -> tuple[Path, Path]:
    """Write ``runs.parquet`` and ``history.parquet`` (default: into ``DIR``); return their
    paths."""
    runs, history = to_frames(out_dir)
    dest = Path(dest) if dest is not None else Path(out_dir)
    dest.mkdir(parents=True, exist_ok=True)
    paths = dest / "runs.parquet", dest / "history.parquet"
    for df, p in zip((runs, history), paths):
        df = df.copy()
        df.attrs = {}
        atomic_write(p, lambda fh, df=df: df.to_parquet(fh, index=False))
    return paths

"""Atomic writes and torn-file handling: the one way femubench writes an artefact.

Every artefact (run record, data set, BAE statistics, surrogate, report) is written to a
temporary name in its final folder, flushed, fsync'ed and renamed over the final name with
:func:`os.replace`, so a reader (or a rerun after ``kill -9`` or a full disk) sees the whole old
file or the whole new one, never half of one. A folder of files that belong together (a
surrogate: npz + JSON + build.json) is written the same way as one unit (:func:`atomic_dir`).

A write that fails (disk full, read-only folder) raises an :class:`OSError` whose message names
the path (``[Errno 28] No space left on device: '/path'``) and leaves no temporary file behind.

A file that cannot be read back (truncated zip, short file, content-hash mismatch) is *torn*:
:func:`set_aside_torn` moves it to ``<name>.torn`` so that the next run rebuilds it (for a cache)
or says exactly which file to rebuild.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

#: Suffix of a torn file moved aside by :func:`set_aside_torn`.
TORN = ".torn"


def _named(exc: OSError, path: Path) -> OSError:
    """``exc`` with ``path`` as its file name (so that its message names the path)."""
    if exc.filename is not None and Path(str(exc.filename)) == path:
        return exc
    return type(exc)(exc.errno, exc.strerror or str(exc), str(path)) if exc.errno else exc


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _mode(path: Path, default: int) -> int:
    """The permissions a replacement of ``path`` gets: those of the file it replaces, else
    ``default`` less the umask (temporary files are created private, 0600/0700)."""
    try:
        return path.stat().st_mode & 0o7777
    except OSError:
        return default & ~_umask()


def fsync_dir(folder: str | Path) -> None:
    """Make a rename in ``folder`` durable (no-op where folders cannot be fsync'ed)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
    except OSError:  # pragma: no cover - platforms without directory fsync
        pass


def atomic_write(path: str | Path, write: Callable, *, binary: bool = True) -> Path:
    """Write ``path`` atomically: ``write(fh)`` fills a temporary file in the same folder (opened
    ``"wb"``, or ``"w"`` UTF-8 with ``binary=False``), which is fsync'ed and renamed over
    ``path``. The folder is created. An OSError (disk full, permission) names ``path``; the
    temporary file is removed. Returns ``path``."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    except OSError as exc:
        raise _named(exc, path) from None
    try:
        os.fchmod(fd, _mode(path, 0o666))
        with (
            os.fdopen(fd, "wb") if binary else os.fdopen(fd, "w", encoding="utf-8", newline="")
        ) as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        if isinstance(exc, OSError):
            raise _named(exc, path) from None
        raise
    fsync_dir(path.parent)
    return path


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically (:func:`atomic_write`)."""
    return atomic_write(path, lambda fh: fh.write(text), binary=False)


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (:func:`atomic_write`)."""
    return atomic_write(path, lambda fh: fh.write(data))


def atomic_savez(path: str | Path, *, compressed: bool = True, **arrays) -> Path:
    """``np.savez_compressed`` (or ``np.savez``) of ``arrays`` to ``path``, atomically. ``path``
    is used as given (numpy would append ``.npz`` to a name without it)."""
    import numpy as np

    save = np.savez_compressed if compressed else np.savez
    return atomic_write(path, lambda fh: save(fh, **arrays))


@contextlib.contextmanager
def atomic_dir(final: str | Path) -> Iterator[Path]:
    """Yield an empty temporary folder beside ``final``; when the block ends without an error the
    folder replaces ``final`` as a whole (an old ``final`` is renamed aside first and removed
    after), so ``final`` always holds one complete set of files. On an error the temporary folder
    is removed and ``final`` is left as it was."""
    final = Path(final)
    try:
        final.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(dir=final.parent, prefix=f".{final.name}.", suffix=".tmp"))
    except OSError as exc:
        raise _named(exc, final) from None
    try:
        tmp.chmod(_mode(final, 0o777))
        yield tmp
        try:
            _replace_dir(tmp, final)
        except OSError as exc:
            raise _named(exc, final) from None
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


def _replace_dir(tmp: Path, final: Path) -> None:
    """fsync the files of ``tmp``, then rename it over ``final`` (see :func:`atomic_dir`)."""
    for p in tmp.rglob("*"):  # the files' contents are durable before the rename
        if p.is_file():
            with open(p, "rb+") as fh:
                os.fsync(fh.fileno())
    old = None
    if final.exists():
        old = Path(tempfile.mkdtemp(dir=final.parent, prefix=f".{final.name}.", suffix=".old"))
        os.replace(final, old / final.name)
    try:
        os.replace(tmp, final)
    except BaseException:
        if old is not None:  # put the old folder back
            os.replace(old / final.name, final)
            shutil.rmtree(old, ignore_errors=True)
        raise
    fsync_dir(final.parent)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def set_aside_torn(path: str | Path) -> Path:
    """Move the torn file (or folder) ``path`` to ``<path>.torn`` (``.torn-1``, ... when taken);
    return the new path."""
    path = Path(path)
    dest, n = path.with_name(path.name + TORN), 1
    while dest.exists():
        dest, n = path.with_name(f"{path.name}{TORN}-{n}"), n + 1
    os.replace(path, dest)
    return dest

"""Torn numba cache files: found when a kernel module is imported, named, removed.

The compiled kernels (``@njit(cache=True)``) are cached by numba in files next to their source
(``__pycache__/<module>.<kernel>-<line>.pyXY.nbi``: the index, ``....N.nbc``: the code) or
wherever its locator puts them. A file torn by a full disk, a kill or a copy used to fail the first
call of the kernel with a bare ``UnpicklingError: pickle data was truncated`` (or ``EOFError``), in
every run, until the file was deleted by hand.

:func:`heal` (called at the end of each kernel module with its ``globals()``) checks the cache
files of the module's cached dispatchers: an index must unpickle (cheap: a version, a time stamp
and a small dict), a data file must be a complete pickle stream (protocol header, final STOP
opcode; unpickling the code itself would cost seconds). A torn file is removed with a
``RuntimeWarning`` naming it; numba then compiles the kernel again and rewrites its cache.
"""

from __future__ import annotations

import glob
import os
import pickle
import warnings


def torn_reason(path: str) -> str | None:
    """Why the numba cache file ``path`` (``.nbi`` or ``.nbc``) is torn, or None if it looks
    whole."""
    try:
        with open(path, "rb") as f:
            if path.endswith(".nbi"):
                pickle.load(f)  # numba's version
                stamp, overloads = pickle.loads(f.read())
                if not isinstance(overloads, dict):
                    return "its index is not a mapping"
                return None
            head = f.read(2)
            f.seek(0, os.SEEK_END)
            size = f.tell()
            f.seek(max(0, size - 1))
            last = f.read(1)
    except FileNotFoundError:
        return None
    except (OSError, EOFError, ValueError, TypeError, pickle.UnpicklingError) as exc:
        return f"{type(exc).__name__}: {exc}"
    if size < 3 or head[:1] != b"\x80" or last != b".":
        return f"an incomplete pickle stream of {size} bytes"
    return None


def cache_files(namespace: dict) -> list[str]:
    """The index and data files of the cached numba dispatchers in ``namespace`` (a module's
    ``globals()``) that exist."""
    files = []
    for obj in list(namespace.values()):
        cache = getattr(obj, "_cache", None)
        index = getattr(getattr(cache, "_cache_file", None), "_index_path", None)
        if not index:
            continue
        pattern = cache._cache_file._data_name_pattern.replace("{number:d}", "*")
        files += [index] if os.path.exists(index) else []
        files += sorted(glob.glob(os.path.join(glob.escape(cache._cache_path), pattern)))
    return files


def heal(namespace: dict) -> list[str]:
    """Remove the torn cache files of the kernels in ``namespace`` (a module's ``globals()``),
    with a RuntimeWarning naming each; returns the removed paths."""
    removed = []
    for path in cache_files(namespace):
        why = torn_reason(path)
        if why is None:
            continue
        try:
            os.remove(path)
        except FileNotFoundError:
            continue
        except OSError as exc:
            raise RuntimeError(
                f"numba cache file {path} is torn ({why}) and cannot be removed ({exc}); delete "
                "it by hand"
            ) from None
        warnings.warn(
            f"numba cache file {path} was torn ({why}): removed, the kernel is compiled again",
            RuntimeWarning,
            stacklevel=2,
        )
        removed.append(path)
    return removed

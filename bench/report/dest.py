"""Where a report may be written: never over its inputs, never over a folder it did not write.

A report replaces its folder as a whole (no stale table survives), so the folder must be one that
a report wrote: :func:`check_dest` refuses the results directory itself, its ``runs/`` folder (or
anything inside it), a folder that holds the results directory or another input, an existing file,
and an existing non-empty folder without the report's marker file :data:`MARKER` (a folder
holding a ``report.md`` and no ``runs/`` is taken as a report written before markers existed).

While a report is written its temporary folders ``.report-tmp-*`` live beside the final folder; the
writer holds :data:`LOCK` there, and :func:`clean_stale` removes the folders a killed report left
behind (:data:`STALE`).
"""

from __future__ import annotations

import fcntl
import re
import shutil
from pathlib import Path

#: The file every report folder holds (written by :func:`mark`).
MARKER = ".femubench-report"
#: Lock file beside the report folder, held while a report is written.
LOCK = ".report-lock"
#: Prefix of the temporary folder of a report being written.
TMP_PREFIX = ".report-tmp-"
#: What a killed report leaves beside its folder: a temporary folder (``.report-tmp-*``, or
#: ``.report-`` + 8 random characters from before that prefix), or the old report it was
#: replacing (``.report-old-<pid>``).
STALE = re.compile(r"\.report-(tmp-.+|old-\d+|[a-z0-9_]{8})")


def _within(path: Path, folder: Path) -> bool:
    return path == folder or folder in path.parents


def is_report_folder(folder: Path) -> bool:
    """True when ``folder`` was written by a report (its marker, or a legacy ``report.md``
    without ``runs/``)."""
    return (folder / MARKER).is_file() or (
        (folder / "report.md").is_file() and not (folder / "runs").exists()
    )


def check_dest(results_dir: str | Path, dest: str | Path, inputs=()) -> None:
    """ValueError (one line naming ``--out``, the path and why) unless ``dest`` may be replaced by
    the report of ``results_dir``; ``inputs``: other folders the report reads (posterior, model
    error), which ``dest`` must not be or hold either."""
    src, out = Path(results_dir).resolve(), Path(dest).resolve()
    why = None
    if out == src:
        why = "is the results directory itself"
    elif _within(out, src / "runs"):
        why = "is the run records' folder (or inside it)"
    elif out in src.parents:
        why = f"holds the results directory {results_dir}"
    else:
        for folder in inputs:
            f = Path(folder).resolve()
            if _within(out, f) or out in f.parents:
                why = f"is (or holds) the input folder {folder}"
                break
    if why is None and out.exists():
        if not out.is_dir():
            why = "is a file"
        elif any(out.iterdir()) and not is_report_folder(out):
            why = f"is a folder that a report did not write (no {MARKER} in it)"
    if why is not None:
        raise ValueError(
            f"--out {dest}: {why}; the report replaces its folder as a whole, so give a new or "
            "empty folder, or one that holds an earlier report"
        )


def mark(folder: str | Path) -> None:
    """Write the marker file into the report folder being built."""
    (Path(folder) / MARKER).write_text(
        "written by 'femubench report'; this folder is replaced by the next report\n",
        encoding="utf-8",
    )


def lock(parent: str | Path):
    """Take the report lock of ``parent`` (waiting for another report writing there) and remove
    the folders a killed report left (:data:`STALE`); return the open lock file (close it to
    release the lock)."""
    parent = Path(parent)
    parent.mkdir(parents=True, exist_ok=True)
    fh = open(parent / LOCK, "a+")
    fcntl.flock(fh.fileno(), fcntl.LOCK_EX)
    clean_stale(parent)
    return fh


def clean_stale(parent: Path) -> list[Path]:
    """Remove the temporary report folders under ``parent`` (call with the lock held); return
    them."""
    stale = [p for p in parent.glob(".report-*") if STALE.fullmatch(p.name) and p.is_dir()]
    for p in stale:
        shutil.rmtree(p, ignore_errors=True)
    return stale

"""Where commands write when the user gives no ``--out``: one results root, never the current
directory.

The root is ``$FEMUBENCH_RESULTS_DIR`` if set; else the ``results/`` folder of the source checkout
this package runs from (the folder holding ``pyproject.toml``); else, for an installed package,
``$XDG_DATA_HOME/femubench/results`` (default ``~/.local/share/femubench/results``).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

RESULTS_DIR_ENV = "FEMUBENCH_RESULTS_DIR"


def results_root() -> Path:
    """The results root (see the module docstring); not created."""
    env = os.environ.get(RESULTS_DIR_ENV)
    if env:
        return Path(env).expanduser().resolve()
    checkout = Path(__file__).resolve().parents[1]
    if (checkout / "pyproject.toml").is_file():
        return checkout / "results"
    data_home = Path(os.environ.get("XDG_DATA_HOME") or "~/.local/share").expanduser()
    return data_home / "femubench" / "results"


def default_dir(*parts: str) -> Path:
    """``results_root() / parts[0] / parts[1] ...``, created."""
    path = results_root().joinpath(*parts)
    path.mkdir(parents=True, exist_ok=True)
    return path


def output_file(text: str) -> str:
    """A file to be written, checked before any work: not an existing directory, its folder an
    existing, writable folder (so that a long computation never ends on an unwritable path)."""
    p = Path(text)
    if not text:
        raise argparse.ArgumentTypeError("empty file name")
    if p.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a directory; give a file name")
    parent = p.parent
    if not parent.exists():
        raise argparse.ArgumentTypeError(f"{text}: folder {parent} does not exist; create it first")
    if not parent.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: {parent} is a file, not a folder")
    if not_writable(p):
        raise argparse.ArgumentTypeError(f"{text} is not writable (permission denied)")
    return text


def not_writable(path) -> bool:
    """True when ``path`` cannot be written: the file exists read-only, or its nearest existing
    folder does not allow creating files (a missing folder is created by the writer)."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        return not os.access(p, os.W_OK)
    folder = next((q for q in (p, *p.parents) if q.exists()), Path("."))
    return folder.is_dir() and not os.access(folder, os.W_OK | os.X_OK)

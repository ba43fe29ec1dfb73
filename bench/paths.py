"""Where commands write when the user gives no ``--out``: one results root, never the current
directory.

The root is ``$FEMUBENCH_RESULTS_DIR`` if set; else the ``results/`` folder of the source checkout
this package runs from (the folder holding ``pyproject.toml``); else, for an installed package,
``$XDG_DATA_HOME/femubench/results`` (default ``~/.local/share/femubench/results``).
"""

from __future__ import annotations

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

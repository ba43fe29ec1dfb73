"""Where femubench keeps what it computes on first use: the user's data cache directory.

Shared by the data sets (:mod:`problems.inverse.data`), the response cache
(:mod:`problems.inverse.response_cache`) and the surrogate training runs, so that none of them
imports another for a path; and where the release artefacts live outside the results folder
(:func:`artefact_dir`).
"""

from __future__ import annotations

import os
from pathlib import Path

#: Environment variable: directory of the cache of computed non-default data sets.
CACHE_DIR_ENV = "FEMUBENCH_CACHE_DIR"


def cache_dir() -> Path:
    """Directory of computed non-default data sets: ``$FEMUBENCH_CACHE_DIR`` if set, else
    ``$XDG_CACHE_HOME/femubench/data`` (default ``~/.cache/femubench/data``)."""
    env = os.environ.get(CACHE_DIR_ENV)
    if env:
        return Path(env).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base).expanduser() / "femubench" / "data"


#: Environment variable: directory of the release artefacts kept outside the source tree.
ARTEFACT_DIR_ENV = "FEMUBENCH_ARTEFACT_DIR"


def artefact_dir() -> Path:
    """Directory of the release artefacts (stored surrogates, BAE statistics) that are not in the
    results folder: ``$FEMUBENCH_ARTEFACT_DIR`` if set, else ``$XDG_CACHE_HOME/femubench/artefacts``
    (default ``~/.cache/femubench/artefacts``); laid out like the results folder
    (``surrogates/<name>/``, ``model_error/<file>.npz``). See :mod:`bench.artefacts`."""
    env = os.environ.get(ARTEFACT_DIR_ENV)
    if env:
        return Path(env).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base).expanduser() / "femubench" / "artefacts"

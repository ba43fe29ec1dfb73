"""Outputs never overwrite inputs: the one check every command runs on its output paths before
any work."""

from __future__ import annotations

import os
from pathlib import Path


def same_file(a: str | Path, b: str | Path) -> bool:
    """True when the paths ``a`` and ``b`` name one file (after resolving links; an existing pair
    is compared by device and inode, so hard links count too)."""
    a, b = Path(a), Path(b)
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return a.resolve() == b.resolve()


def refuse_inputs(option: str, output: str | Path | None, inputs) -> None:
    """ValueError (one line naming ``option``, the path and the input) when ``output`` names one
    of the files ``inputs``; nothing for ``output=None``."""
    if output is None:
        return
    for inp in inputs:
        if inp is not None and same_file(output, inp):
            raise ValueError(
                f"{option} {output}: names the input {inp}; an output never overwrites an input, "
                "give another file name"
            )

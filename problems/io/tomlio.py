"""Reading a TOML input file (a suite, a study plan) with one-line errors naming the file."""

from __future__ import annotations

import tomllib
from pathlib import Path


def read_toml(path: str | Path, what: str) -> tuple[dict, str]:
    """The parsed TOML of the file at ``path`` and its text. ``what`` names the kind of file in
    the errors (e.g. ``"suite"``): FileNotFoundError when it does not exist, ValueError when it is
    binary, not UTF-8 (a leading byte-order mark is accepted) or not valid TOML."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{what} file {str(path)!r} does not exist")
    blob = path.read_bytes()
    if b"\0" in blob:
        raise ValueError(f"{path}: a binary file (NUL bytes), not a TOML {what}")
    try:
        text = blob.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ValueError(
            f"{path}: not UTF-8 text (byte {blob[exc.start]:#04x} at offset {exc.start}); "
            f"save the {what} as UTF-8"
        ) from None
    try:
        return tomllib.loads(text), text
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not valid TOML: {exc}") from None

"""Argument types and shared options of the sub-commands (not a command itself: no ``NAME``).

Every type turns a string into a value or raises :class:`argparse.ArgumentTypeError` with one
line naming the value and what is allowed; argparse prefixes the option (``argument --budget:
0 is out of range: must be a whole number >= 1``) and :mod:`bench.cli` prints that one line
with exit code 2. Nothing here imports more than the standard library at import time, so that
``femubench --help`` stays fast.

Shared options, declared once: :func:`add_mesh_argument` (``--mesh``) and
:func:`add_cluster_arguments` (``--workers`` | ``--scheduler``).

:func:`harden` is the safety net :mod:`bench.cli` applies to every sub-parser: options a command
declared with a bare ``int``/``float`` (or none) get the checked types of :data:`BY_NAME` (by
option name: ``--seed`` >= 0, ``--budget`` >= 1, ``--mesh`` a mesh spec, ``--data`` an existing
file, ...) or at least a whole or finite number, so that no command accepts ``--seed -1``,
``--budget 0``, ``--mesh bogus`` or ``nan``.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from bench.paths import not_writable, output_file  # noqa: F401 (the options' checks)
from problems.fe.presets import SPEC_PRESETS

ArgumentTypeError = argparse.ArgumentTypeError


# --- numbers -----------------------------------------------------------------------------------


def _integer(text: str, minimum: int | None = None, maximum: int | None = None) -> int:
    try:
        value = int(str(text).strip())
    except ValueError:
        try:  # 1e9, 2.0: a whole number in float notation
            number = float(str(text).strip())
        except ValueError:
            number = math.nan
        if not (math.isfinite(number) and number.is_integer()):
            raise ArgumentTypeError(f"{text!r} is not a whole number") from None
        value = int(number)
    if (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
        allowed = (
            f">= {minimum}"
            if maximum is None
            else f"<= {maximum}"
            if minimum is None
            else f"in [{minimum}, {maximum}]"
        )
        raise ArgumentTypeError(f"{value} is out of range: must be a whole number {allowed}")
    return value


def integer(text: str) -> int:
    """Any whole number."""
    return _integer(text)


def positive_int(text: str) -> int:
    """A whole number >= 1 (counts, budgets, workers, steps)."""
    return _integer(text, 1)


def nonneg_int(text: str) -> int:
    """A whole number >= 0 (seeds; counts where 0 is meaningful and documented)."""
    return _integer(text, 0)


def int_at_least(minimum: int):
    """Type: a whole number >= ``minimum``."""

    def check(text: str) -> int:
        return _integer(text, minimum)

    check.__name__ = f"int>={minimum}"
    return check


def int_in(minimum: int, maximum: int):
    """Type: a whole number in ``[minimum, maximum]``."""

    def check(text: str) -> int:
        return _integer(text, minimum, maximum)

    check.__name__ = f"int in [{minimum}, {maximum}]"
    return check


def finite_float(text: str) -> float:
    """A finite number (no nan, inf)."""
    try:
        value = float(str(text).strip())
    except ValueError:
        raise ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise ArgumentTypeError(f"{text!r} is not a finite number")
    return value


def float_in(
    low: float | None = None,
    high: float | None = None,
    *,
    low_open: bool = False,
    high_open: bool = False,
    unit: str = "",
):
    """Type: a finite number in the interval ``low .. high`` (open or closed ends; None: unbounded).

    ``unit`` is printed after the bounds (e.g. ``"um"``).
    """

    def check(text: str) -> float:
        value = finite_float(text)
        bad = (low is not None and (value <= low if low_open else value < low)) or (
            high is not None and (value >= high if high_open else value > high)
        )
        if bad:
            allowed = describe_interval(low, high, low_open, high_open)
            raise ArgumentTypeError(
                f"{value:g} is out of range: must be {allowed}" + (f" {unit}" if unit else "")
            )
        return value

    check.__name__ = "number"
    return check


def describe_interval(low, high, low_open: bool = False, high_open: bool = False) -> str:
    """``"> 0"``, ``">= 0"``, ``"in (0, 1]"`` ..."""
    if high is None:
        return f"{'>' if low_open else '>='} {low:g}"
    if low is None:
        return f"{'<' if high_open else '<='} {high:g}"
    return f"in {'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"


positive_float = float_in(0.0, low_open=True)
nonneg_float = float_in(0.0)


# --- names, lists, files --------------------------------------------------------------------------


def comma_list(item_type, *, what: str = "value"):
    """Type: a non-empty comma-separated list of ``item_type`` values."""

    def check(text: str) -> tuple:
        items = [s.strip() for s in str(text).split(",")]
        if not text.strip() or any(not s for s in items):
            raise ArgumentTypeError(
                f"{text!r} is malformed: a comma-separated list of {what}s, none empty"
            )
        return tuple(item_type(s) for s in items)

    check.__name__ = "list"
    return check


def mesh_spec(text: str) -> str:
    """A mesh spec the FE model accepts (``coarse``, ``paper``, ``fine``, ``NX,NY,NZ``, optionally
    ``:TOKEN``s: ``eighth``/``quarter``, ``gR``, ``gzR``, ``hex8``/``hex27``); returned unchanged
    (checked by problems.fe.mesh.parse_mesh_spec, and refused when its operators cannot fit in
    memory: bench.resources.check_mesh_memory)."""
    from bench.resources import check_mesh_memory
    from problems.fe.mesh import parse_mesh_spec

    try:
        parse_mesh_spec(text)
        check_mesh_memory(text)
    except ValueError as exc:
        raise ArgumentTypeError(str(exc)) from None
    return text


def input_file(text: str) -> str:
    """An existing regular file (not a directory)."""
    p = Path(text)
    if not text:
        raise ArgumentTypeError("empty file name")
    if p.is_dir():
        raise ArgumentTypeError(f"{text} is a directory: it cannot be read as a file")
    if not p.is_file():
        raise ArgumentTypeError(f"{text} does not exist")
    return text


def output_dir(text: str) -> str:
    """A folder to be written into (created if missing): not an existing file."""
    p = Path(text)
    if not text:
        raise ArgumentTypeError("empty folder name")
    for q in (p, *p.parents):
        if q.exists():
            if not q.is_dir():
                raise ArgumentTypeError(f"{text}: {q} is a file, not a folder")
            break
    return text


def study_data(text: str) -> str:
    """``auto``, ``shipped``, ``synthetic`` or the path of an existing data file."""
    if text in ("auto", "shipped", "synthetic"):
        return text
    try:
        return input_file(text)
    except ArgumentTypeError as exc:
        raise ArgumentTypeError(
            f"{exc}; allowed: auto, shipped, synthetic or a data file"
        ) from None


def add_tier_arguments(parser) -> None:
    """``--tier``, ``--correction`` and ``--plate-margin-mm`` of the studies (see
    :func:`bench.studies.study_objective`); they reach ``args.tier``, ``args.correction`` and
    ``args.plate_margin_mm``."""
    parser.add_argument(
        "--tier",
        choices=["consistent", "model-error"],
        default=None,
        help="fit the tier's shipped data set for the inverse mesh: consistent (made with the "
        "inverse mesh itself) or model-error (made on the converged "
        f"{SPEC_PRESETS['converged']}); in place of --data",
    )
    parser.add_argument(
        "--correction",
        choices=["none", "one-point", "bae", "default"],
        default="none",
        help="model-error treatment of the objective (default none; one-point at the default "
        "start; default = the case's default treatment with its plate margin, see `femubench "
        "cases`)",
    )
    add_plate_margin_argument(parser)


def add_plate_margin_argument(parser, default: float | None = 0.0, note: str = "") -> None:
    """``--plate-margin-mm MM`` (:class:`problems.inverse.build.Region`), in args.plate_margin_mm;
    ``note`` ends the help text (after the default)."""
    from problems.fe.mesh import SIZE_MM
    from problems.inverse.build import PLATE_MARGIN_TEXT

    parser.add_argument(
        "--plate-margin-mm",
        type=float_in(0.0, SIZE_MM[2] / 2, high_open=True, unit="mm"),
        default=default,
        metavar="MM",
        help=f"{PLATE_MARGIN_TEXT.replace('this', 'MM').removesuffix(', mm')} (default 0{note})",
    )


def plate_margin_or_auto(text: str):
    """A plate margin of a calibration: a number of mm >= 0, or ``auto``
    (:func:`problems.inverse.build.auto_plate_margin_mm`; the upper bound, half the specimen's
    height, is checked on the specimen)."""
    if text.strip().lower() == "auto":
        return "auto"
    try:
        return float_in(0.0, None, unit="mm")(text)
    except ArgumentTypeError as exc:
        raise ArgumentTypeError(f"{exc}; or auto") from None


def assignments(items, option: str, names=None, *, units: dict | None = None) -> dict[str, float]:
    """``["E=3e4", "nu=0.2"]`` -> ``{"E": 30000.0, "nu": 0.2}``.

    ValueError (one line naming ``option``) for a malformed item, a value that is not a finite
    number, a name not in ``names`` (when given) or a name given twice.
    """
    out: dict[str, float] = {}
    for item in items or []:
        name, sep, value = str(item).partition("=")
        name = name.strip()
        if not sep or not name:
            raise ValueError(f"{option} {item!r} is malformed: expected NAME=VALUE with a number")
        if names is not None and name not in names:
            raise ValueError(
                f"{option} {item!r}: parameter {name!r} is unknown; allowed: {', '.join(names)}"
            )
        try:
            v = float(value)
        except ValueError:
            raise ValueError(f"{option} {item!r}: {value.strip()!r} is not a number") from None
        if not math.isfinite(v):
            raise ValueError(f"{option} {item!r}: {name} must be a finite number")
        if name in out:
            raise ValueError(f"{option}: {name} is given twice")
        out[name] = v
    return out


# --- shared options -------------------------------------------------------------------------------

MESH_HELP = (
    "coarse | paper | fine | xfine | converged | NX,NY,NZ, optionally :TOKENs (:eighth or "
    ":quarter, :gR grading, :gzR grading toward the plates, :hex8 or :hex27; docs/fe_model.md)"
)


def add_mesh_argument(parser, default: str = "coarse", help: str | None = None) -> None:
    """``--mesh`` (checked when parsed; see :func:`mesh_spec`)."""
    parser.add_argument(
        "--mesh",
        type=mesh_spec,
        default=default,
        metavar="MESH",
        help=help or f"FE mesh: {MESH_HELP} (default: {default})",
    )


def add_cluster_arguments(
    parser, *, default_workers: int | None = None, workers_help: str | None = None
) -> None:
    """``--workers N`` (>= 1) or ``--scheduler ADDRESS`` (mutually exclusive).

    ``default_workers`` None means one local Dask worker process per core.
    """
    where = parser.add_mutually_exclusive_group()
    if workers_help is None:
        workers_help = (
            f"Dask worker processes (default {default_workers})"
            if default_workers
            else "local Dask worker processes (default: one per core); 1 runs in-process"
        )
    where.add_argument(
        "--workers", type=positive_int, default=default_workers, metavar="N", help=workers_help
    )
    where.add_argument(
        "--scheduler",
        type=scheduler_address,
        metavar="ADDRESS",
        help="submit to an existing Dask cluster, e.g. tcp://host:8786",
    )


def scheduler_address(text: str) -> str:
    """A Dask scheduler address ``[PROTOCOL://]HOST:PORT`` (tcp, tls, ucx, ws, wss or inproc)."""
    t = str(text).strip()
    if not t:
        raise ArgumentTypeError("empty scheduler address")
    proto, sep, rest = t.partition("://")
    if not sep:
        rest, proto = t, "tcp"
    if proto not in ("tcp", "tls", "inproc", "ucx", "ws", "wss"):
        raise ArgumentTypeError(
            f"{text!r}: protocol {proto!r} is unknown; allowed: tcp://HOST:PORT (or tls, ucx, ws)"
        )
    host, colon, port = rest.rpartition(":")
    valid_port = port.isdigit() and 0 < int(port) < 65536
    if proto != "inproc" and (not colon or not host or not valid_port):
        raise ArgumentTypeError(f"{text!r} is not a scheduler address: expected tcp://HOST:PORT")
    return t


def add_quiet_argument(parser) -> None:
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


# --- the safety net for bare types ----------------------------------------------------------------

#: checked types of options declared without one (or with a bare int/float), by option name
BY_NAME = {
    "seed": nonneg_int,
    "budget": positive_int,
    "workers": positive_int,
    "samples": positive_int,
    "steps": positive_int,
    "snapshots": positive_int,
    "batch": positive_int,
    "walkers": positive_int,
    "mesh": mesh_spec,
    "hifi_mesh": mesh_spec,
    "scheduler": scheduler_address,
    "data": input_file,
    "json": output_file,
    "csv": output_file,
    "plate_margin_mm": nonneg_float,
}
_INT_TYPES = (nonneg_int, positive_int)
_FLOAT_TYPES = (nonneg_float, positive_float)


def harden(parser: argparse.ArgumentParser) -> None:
    """Give the options of ``parser`` that have no checked type one (see the module docstring).

    Positional arguments, flags, options with ``choices`` and options with their own type are left
    alone.
    """
    for action in parser._actions:
        if not action.option_strings or action.choices is not None or action.nargs == 0:
            continue
        checked = BY_NAME.get(action.dest)
        if action.type is int:
            action.type = checked if checked in _INT_TYPES else integer
        elif action.type is float:
            action.type = checked if checked in _FLOAT_TYPES else finite_float
        elif action.type is None and checked not in (None, *_INT_TYPES, *_FLOAT_TYPES):
            action.type = checked

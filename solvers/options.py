"""Declared options of the optimisation methods.

Each adapter declares its options next to its code as ``{name: Option(...)}`` and passes them to
:func:`solvers.base.register`. The declaration is the one source of the option's type, default,
allowed range or names and help text: :func:`solvers.base.resolve_options` validates with it,
suites (bench/experiment/suite.py) check ``[options.<method>]`` with it, ``femubench solvers``
lists it and docs/solver_options.md is generated from it (:func:`markdown`, ``femubench solvers
--markdown``; a test keeps the file current).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

#: the option types: a whole number, a number, true/false, a string, anything (the method checks)
TYPES = ("int", "float", "bool", "str", "any")


@dataclass(frozen=True)
class Option:
    """One option of a method.

    type      : one of :data:`TYPES`
    default   : the value when the option is not given (None: the method chooses, see ``help``)
    help      : what it does, with units
    low, high : the allowed range of a number (None: unbounded); ``low_open``/``high_open``
                exclude the bound itself
    choices   : the allowed strings of a ``str`` option (empty: any string)
    strings   : strings a number option takes besides numbers (``x_scale``: ``"jac"``)
    """

    type: str
    default: Any
    help: str
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    choices: tuple[str, ...] = ()
    strings: tuple[str, ...] = ()

    def __post_init__(self):
        if self.type not in TYPES:
            raise ValueError(f"option type {self.type!r} is unknown; allowed: {', '.join(TYPES)}")

    def error(self, value: Any) -> str | None:
        """Why ``value`` is not allowed (e.g. ``-1 is out of range``; the allowed values are
        :meth:`range_text`), or None. None is allowed only where the default is None; a number is
        finite unless the default is not; an ``int`` a whole number."""
        if value is None:
            return None if self.default is None else f"{value!r} is not allowed"
        if self.type == "any":
            return None
        if self.type == "bool":
            return None if isinstance(value, (bool, np.bool_)) else f"{value!r} is not true/false"
        if self.type == "str":
            if not isinstance(value, str):
                return f"{value!r} is not a string"
            if self.choices and value not in self.choices:
                return f"{value!r} is unknown"
            return None
        if isinstance(value, str):
            if value in self.strings:
                return None
            return f"{value!r} is not a number"
        if not isinstance(value, (int, float, np.integer, np.floating)) or isinstance(
            value, (bool, np.bool_)
        ):
            return f"{value!r} is not a number"
        infinite_default = isinstance(self.default, float) and not math.isfinite(self.default)
        if not math.isfinite(float(value)) and not infinite_default:
            return f"{value!r} is not a finite number"
        if self.type == "int" and float(value) != int(value):
            return f"{value!r} is not a whole number"
        low_ok = self.low is None or (value > self.low if self.low_open else value >= self.low)
        high_ok = self.high is None or (value < self.high if self.high_open else value <= self.high)
        if not (low_ok and high_ok):
            return f"{value!r} is out of range"
        return None

    def range_text(self) -> str:
        """The allowed values in words, e.g. ``a whole number >= 1``, ``in [0, 1)``, ``> 0``."""
        if self.type == "bool":
            return "true or false"
        if self.type == "str":
            return ", ".join(self.choices) if self.choices else "a string"
        if self.type == "any":
            return "see the help"
        what = "a whole number" if self.type == "int" else "a number"
        if self.low is not None and self.high is not None:
            lo, hi = "(" if self.low_open else "[", ")" if self.high_open else "]"
            text = f"{what} in {lo}{self.low:g}, {self.high:g}{hi}"
        elif self.low is not None:
            text = f"{what} {'>' if self.low_open else '>='} {self.low:g}"
        elif self.high is not None:
            text = f"{what} {'<' if self.high_open else '<='} {self.high:g}"
        else:
            text = what
        if self.strings:
            text += f" or {' | '.join(self.strings)}"
        if self.default is None:
            text += " or None"
        return text

    def to_dict(self) -> dict[str, Any]:
        """The JSON form (``femubench solvers --json``)."""
        from problems.io import jsonio

        out: dict[str, Any] = {
            "type": self.type,
            "default": jsonio.plain(self.default),
            "description": self.help,
            "allowed": self.range_text(),
        }
        if self.choices:
            out["choices"] = list(self.choices)
        return out


def count(default: int | None, help: str) -> Option:
    """A whole number >= 1 (a population, a number of iterations or evaluations)."""
    return Option("int", default, help, low=1)


def fraction(default: float | None, help: str, *, high_open: bool = False) -> Option:
    """A probability or share in [0, 1] (``high_open``: [0, 1))."""
    return Option("float", default, help, low=0.0, high=1.0, high_open=high_open)


def positive(default: float | None, help: str) -> Option:
    """A step size or scale > 0."""
    return Option("float", default, help, low=0.0, low_open=True)


def nonnegative(default: float | None, help: str, type: str = "float") -> Option:
    """A tolerance or index >= 0."""
    return Option(type, default, help, low=0.0)


def number(default: float | None, help: str, type: str = "float", **kw) -> Option:
    """Any number (``kw``: the remaining :class:`Option` fields)."""
    return Option(type, default, help, **kw)


def flag(default: bool, help: str) -> Option:
    """True or false."""
    return Option("bool", default, help)


def choice(default: str, help: str, choices: tuple[str, ...] = ()) -> Option:
    """A string, one of ``choices`` when given."""
    return Option("str", default, help, choices=tuple(choices))


def markdown(methods) -> str:
    """docs/solver_options.md: one table of options per method of ``methods`` (name ->
    :class:`~solvers.base.MethodInfo`)."""
    lines = [
        "# Solver options",
        "",
        "Generated from the options each adapter declares (`solvers/options.py`; regenerate with "
        "`femubench solvers --markdown > docs/solver_options.md`, tests/test_solver_options.py "
        "checks it is current). Give them as `--option NAME=VALUE` or in a suite's "
        "`[options.<method>]` table; a value outside the allowed ones stops the run before it "
        "starts. Any other nlopt algorithm also works as `nlopt:<NAME>` with the options of its "
        "kind (local, global, MLSL).",
        "",
    ]
    for name, info in methods.items():
        lines += [f"## `{name}`", "", f"{info.description} ({info.library}, {info.family}).", ""]
        if not info.options:
            lines += ["No options.", ""]
            continue
        lines += ["| option | default | allowed | what |", "|:---|:---|:---|:---|"]
        for key, opt in info.options.items():
            text = opt.help.replace("|", "\\|")
            allowed = opt.range_text().replace("|", "\\|")
            lines.append(f"| `{key}` | `{opt.default!r}` | {allowed} | {text} |")
        lines.append("")
    return "\n".join(lines)

"""NIST StRD nonlinear regression: the 27 certified least-squares problems, both starts.

The Statistical Reference Datasets of NIST's Information Technology Laboratory
(https://www.itl.nist.gov/div898/strd/nls/nls_main.shtml; public domain) give, for each problem,
the data, a model ``y = f(x; b)``, two starting points (start 1 far from the solution, start 2
nearer) and certified values of the parameters, their standard deviations and the residual sum
of squares, computed in 128-bit precision. ``nist_strd.json`` holds them as typed from NIST's
``.dat`` files (floats parse exactly as NIST's decimal text; the test suite checks that the
certified parameters reproduce the certified residual sum of squares for every problem).

Use::

    from problems.benchmarks.nist import problem, user_problem, NAMES
    p = problem("MGH09", start=1)        # a LeastSquaresProblem: R = y - f(x; b), sigma = 1
    up = user_problem("MGH09", start=1)  # + start, certified b and RSS, success at >= 4 digits

The cost is the residual sum of squares itself (``sigma = 1``, in the response's units squared;
``Nelson`` fits ``log y``, as NIST does). Parameters are unbounded (``-inf, inf``) and unscaled
(``reference = 1``: the solvers see ``b`` as it is), so every method gets what a user of the
library called directly would give it. ``problem(..., scaled=True)`` scales ``z = b / |start|``
instead.

Difficulty (NIST's): lower Misra1a Chwirut2 Chwirut1 Lanczos3 Gauss1 Gauss2 DanWood Misra1b;
average Kirby2 Hahn1 Nelson MGH17 Lanczos1 Lanczos2 Gauss3 Misra1c Misra1d Roszman1 ENSO; higher
MGH09 Thurber BoxBOD Rat42 MGH10 Eckerle4 Rat43 Bennett5. NIST's ``Rat43.dat`` states 9 degrees
of freedom for 15 observations and 4 parameters (11); the data are unaffected.
"""

from __future__ import annotations

import functools
import json
import math
from pathlib import Path

import numpy as np

DATA_FILE = Path(__file__).with_name("nist_strd.json")

#: the 27 problems in NIST's order (by difficulty, then as NIST lists them)
NAMES = (
    "Misra1a", "Chwirut2", "Chwirut1", "Lanczos3", "Gauss1", "Gauss2", "DanWood", "Misra1b",
    "Kirby2", "Hahn1", "Nelson", "MGH17", "Lanczos1", "Lanczos2", "Gauss3", "Misra1c", "Misra1d",
    "Roszman1", "ENSO", "MGH09", "Thurber", "BoxBOD", "Rat42", "MGH10", "Eckerle4", "Rat43",
    "Bennett5",
)  # fmt: skip


def _exp3(x, b):
    return b[0] * np.exp(-b[1] * x) + b[2] * np.exp(-b[3] * x) + b[4] * np.exp(-b[5] * x)


def _gauss(x, b):
    return (
        b[0] * np.exp(-b[1] * x)
        + b[2] * np.exp(-((x - b[3]) ** 2) / b[4] ** 2)
        + b[5] * np.exp(-((x - b[6]) ** 2) / b[7] ** 2)
    )


def _rational33(x, b):
    num = b[0] + b[1] * x + b[2] * x**2 + b[3] * x**3
    return num / (1 + b[4] * x + b[5] * x**2 + b[6] * x**3)


def _chwirut(x, b):
    return np.exp(-b[0] * x) / (b[1] + b[2] * x)


def _misra1a(x, b):
    return b[0] * (1 - np.exp(-b[1] * x))


def _enso(x, b):
    w = 2 * np.pi * x
    return (
        b[0]
        + b[1] * np.cos(w / 12)
        + b[2] * np.sin(w / 12)
        + b[4] * np.cos(w / b[3])
        + b[5] * np.sin(w / b[3])
        + b[7] * np.cos(w / b[6])
        + b[8] * np.sin(w / b[6])
    )


#: the model of each problem, ``f(x, b)`` (NIST's formula; x is (m,) or, for Nelson, (m, 2))
MODELS = {
    "Misra1a": _misra1a,
    "Chwirut2": _chwirut,
    "Chwirut1": _chwirut,
    "Lanczos3": _exp3,
    "Gauss1": _gauss,
    "Gauss2": _gauss,
    "DanWood": lambda x, b: b[0] * x ** b[1],
    "Misra1b": lambda x, b: b[0] * (1 - (1 + b[1] * x / 2) ** (-2)),
    "Kirby2": lambda x, b: (b[0] + b[1] * x + b[2] * x**2) / (1 + b[3] * x + b[4] * x**2),
    "Hahn1": _rational33,
    "Nelson": lambda x, b: b[0] - b[1] * x[:, 0] * np.exp(-b[2] * x[:, 1]),  # of log y
    "MGH17": lambda x, b: b[0] + b[1] * np.exp(-x * b[3]) + b[2] * np.exp(-x * b[4]),
    "Lanczos1": _exp3,
    "Lanczos2": _exp3,
    "Gauss3": _gauss,
    "Misra1c": lambda x, b: b[0] * (1 - (1 + 2 * b[1] * x) ** (-0.5)),
    "Misra1d": lambda x, b: b[0] * b[1] * x * (1 + b[1] * x) ** (-1),
    "Roszman1": lambda x, b: b[0] - b[1] * x - np.arctan(b[2] / (x - b[3])) / np.pi,
    "ENSO": _enso,
    "MGH09": lambda x, b: b[0] * (x**2 + x * b[1]) / (x**2 + x * b[2] + b[3]),
    "Thurber": _rational33,
    "BoxBOD": _misra1a,
    "Rat42": lambda x, b: b[0] / (1 + np.exp(b[1] - b[2] * x)),
    "MGH10": lambda x, b: b[0] * np.exp(b[1] / (x + b[2])),
    "Eckerle4": lambda x, b: (b[0] / b[1]) * np.exp(-0.5 * ((x - b[2]) / b[1]) ** 2),
    "Rat43": lambda x, b: b[0] / (1 + np.exp(b[1] - b[2] * x)) ** (1 / b[3]),
    "Bennett5": lambda x, b: b[0] * (b[1] + x) ** (-1 / b[2]),
}


@functools.lru_cache(maxsize=1)
def _table() -> dict:
    data = json.loads(DATA_FILE.read_text())
    if tuple(data) != NAMES:
        raise ValueError(f"{DATA_FILE} holds {list(data)}, expected the 27 NIST problems")
    return data


def record(name: str) -> dict:
    """NIST's record of problem ``name``: ``difficulty``, ``start1``, ``start2``, ``certified``
    (parameters), ``certified_sd``, ``rss`` (certified residual sum of squares), ``residual_sd``,
    ``dof``, ``x``, ``y`` (as typed from the ``.dat`` file)."""
    if name not in NAMES:
        raise ValueError(f"NIST problem {name!r} is unknown; allowed: {', '.join(NAMES)}")
    return _table()[name]


class Curve:
    """The model of one NIST problem as a picklable ``fn(b) -> values`` (m,) at its data's x."""

    def __init__(self, name: str):
        self.name = name
        rec = record(name)
        self.x = np.asarray(rec["x"], float)
        self.n = len(rec["certified"])

    def __call__(self, b) -> np.ndarray:
        with np.errstate(all="ignore"):  # overflow -> inf: a failed point, never a warning
            return MODELS[self.name](self.x, np.asarray(b, float))

    def __reduce__(self):
        return (Curve, (self.name,))


def response(name: str) -> np.ndarray:
    """The fitted response of ``name``: ``y`` (``log y`` for Nelson, as NIST fits it)."""
    y = np.asarray(record(name)["y"], float)
    return np.log(y) if name == "Nelson" else y


def start(name: str, start: int = 1) -> np.ndarray:
    """NIST's start ``1`` (far) or ``2`` (near) of ``name``."""
    if start not in (1, 2):
        raise ValueError(f"start = {start!r} is out of range: 1 (far) or 2 (near)")
    return np.asarray(record(name)[f"start{start}"], float)


def certified(name: str) -> np.ndarray:
    """The certified parameters of ``name``."""
    return np.asarray(record(name)["certified"], float)


def problem(name: str, start: int = 1, scaled: bool = False):
    """NIST problem ``name`` as a :class:`~problems.inverse.problem.LeastSquaresProblem`: residual
    ``y - f(x; b)``, sigma 1, unbounded, ``reference`` 1 (``scaled``: ``|start|``); its start and
    certified values are in ``provenance`` (``nist_start``, ``x0``, ``x_ref``, ``f_min``)."""
    from problems.user import least_squares

    x0 = globals()["start"](name, start)
    curve = Curve(name)
    rec = record(name)
    return least_squares(
        curve,
        response(name),
        np.full(curve.n, -math.inf),
        np.full(curve.n, math.inf),
        reference=np.abs(x0) if scaled else None,
        names=[f"b{i + 1}" for i in range(curve.n)],
        provenance={
            "case": f"nist-{name}-s{start}",
            "nist": name,
            "nist_start": start,
            "difficulty": rec["difficulty"],
            "x0": x0.tolist(),
            "x_ref": rec["certified"],
            "f_min": rec["rss"],
        },
    )


def user_problem(name: str, start: int = 1, scaled: bool = False, digits: float = 4.0):
    """:func:`problem` with what a benchmark needs to judge it (a
    :class:`~problems.user.UserProblem`): NIST's start, the certified parameters and residual
    sum of squares, success when every parameter has ``digits`` correct significant digits."""
    from problems.user import SuccessRule, UserProblem

    p = problem(name, start, scaled)
    return UserProblem(
        p,
        x0=np.asarray(p.provenance["x0"], float),
        f_min=float(p.provenance["f_min"]),
        x_ref=np.asarray(p.provenance["x_ref"], float),
        success=SuccessRule("digits", digits=digits),
        name=f"{name}-s{start}",
        description=f"NIST StRD {name} ({record(name)['difficulty']} difficulty), start {start}",
    )

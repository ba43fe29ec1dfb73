"""A compiled screen of a case's material rule: which points are *clearly* well-posed.

The rule itself is :func:`problems.materials.drucker_prager.validate_parameters` (ranges of the
parameters and the form's condition: linear cone with compression hardening ``tan(beta), tan(psi)
< 3``; hyperbola ``0 < A < S``; exponent ``a > 0`` and ``pt0 > 0``). It builds dictionaries and
messages, about 15 us a point: too slow for a surrogate evaluated in microseconds. The screen
evaluates the same inequalities in compiled code with a relative margin :data:`MARGIN`: a point
it passes satisfies every inequality by more than the margin, so the rule accepts it; every
other point (outside a range, or within the margin of a boundary) is left to the rule, which
decides and says why. So screen + rule classify every point exactly as the rule alone (tested on
all nine cases, inside, on and far outside the boxes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

#: relative margin of the screen's inequalities
MARGIN = 1e-9

#: form conditions the screen knows
NONE, HYPERBOLIC, EXPONENT_FROM_PT0, EXPONENT = 0, 1, 2, 3


@njit(cache=True)
def _clear(x, lo, hi, code, idx, consts) -> bool:
    for j in range(x.size):
        if not (x[j] > lo[j] and x[j] < hi[j]):
            return False
    if code == NONE:
        return True
    q_hat, p_hat = consts[0], consts[1]
    s0 = x[idx[0]]
    S = q_hat * s0
    if code == HYPERBOLIC:
        A = math.tan(math.radians(x[idx[1]])) * (x[idx[2]] + p_hat * s0)
        return A > MARGIN * S and A < S * (1.0 - MARGIN)
    if code == EXPONENT_FROM_PT0:
        pt0, b = x[idx[1]], x[idx[2]]
        num = pt0 + p_hat * s0  # a = num / S^b > 0
        return num > MARGIN * (abs(pt0) + abs(p_hat * s0)) and math.isfinite(num / S**b)
    if code == EXPONENT:
        a, b = x[idx[1]], x[idx[2]]
        aS = a * S**b
        return math.isfinite(aS) and aS - p_hat * s0 > MARGIN * (abs(aS) + abs(p_hat * s0))
    return False


@njit(cache=True)
def screen_points(X, lo, hi, code, idx, consts, out) -> None:
    """``out[k]`` = row k of ``X`` passes the screen."""
    for k in range(X.shape[0]):
        out[k] = _clear(X[k], lo, hi, code, idx, consts)


@dataclass(frozen=True, eq=False)
class Screen:
    """The screen of one case (build it with :meth:`of`): open intervals ``lo < x < hi`` of the
    identified parameters (their ranges narrowed by the margin) and the form's condition."""

    lo: np.ndarray
    hi: np.ndarray
    code: int
    idx: np.ndarray
    consts: np.ndarray

    @classmethod
    def of(cls, case) -> "Screen | None":
        """The screen of ``case`` (a :class:`~problems.inverse.case.Case`), or None when its
        fixed constants are invalid or its parameters are not the ones the screen knows (then
        the rule decides every point)."""
        from problems.inverse.cases import ExponentStrength
        from problems.materials.drucker_prager import (
            _ATAN3_DEG,
            OPTIONAL_PARAMETERS,
            PARAMETER_RANGES,
            validate_parameters,
        )
        from problems.materials.hardening import reference_test

        names = tuple(case.names)
        if case.derive is not None and not isinstance(case.derive, ExponentStrength):
            return None
        try:
            validate_parameters(case.form, case.hardening, case.material_parameters(case.reference))
        except ValueError:
            return None
        if any(k not in OPTIONAL_PARAMETERS for k in case.fixed):
            return None
        lo, hi = [], []
        for n in names:
            if n not in PARAMETER_RANGES:
                return None
            a, b, _, _, _ = PARAMETER_RANGES[n]
            if case.form == "linear" and case.hardening == "compression" and n in ("beta", "psi"):
                b = min(b, _ATAN3_DEG)
            lo.append(a + MARGIN * max(1.0, abs(a)))
            hi.append(b - MARGIN * max(1.0, abs(b)) if math.isfinite(b) else math.inf)
        test = reference_test(case.hardening)
        pos = {n: i for i, n in enumerate(names)}
        if case.form == "hyperbolic":
            code, need = HYPERBOLIC, ("sigma0", "beta", "pt0")
        elif case.form == "exponent" and "pt0" in pos:
            code, need = EXPONENT_FROM_PT0, ("sigma0", "pt0", "b")
        elif case.form == "exponent":
            code, need = EXPONENT, ("sigma0", "a", "b")
        else:
            code, need = NONE, ()
        if any(n not in pos for n in need):
            return None
        return cls(
            np.array(lo),
            np.array(hi),
            code,
            np.array([pos[n] for n in need] or [0], np.int64),
            np.array([test.q_hat, test.p_hat]),
        )

    def __call__(self, X) -> np.ndarray:
        """(q,) bool: the rows of ``X`` (q, n) (physical) that pass the screen."""
        X = np.ascontiguousarray(np.atleast_2d(X), dtype=float)
        out = np.empty(len(X), bool)
        screen_points(X, self.lo, self.hi, self.code, self.idx, self.consts, out)
        return out

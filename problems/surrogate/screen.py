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

Its one user is the surrogate's cost path (:mod:`problems.surrogate.misfit`); the compiled
screen (:func:`problems.surrogate._kernels.screen_points`) lives beside the cost path's kernel that
calls it: numba's cache would not see a change to a kernel of another file.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from problems.surrogate._kernels import (
    EXPONENT,
    EXPONENT_FROM_PT0,
    HYPERBOLIC,
    MARGIN,
    NONE,
    screen_points,
)

__all__ = ["EXPONENT", "EXPONENT_FROM_PT0", "HYPERBOLIC", "MARGIN", "NONE", "Screen"]


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

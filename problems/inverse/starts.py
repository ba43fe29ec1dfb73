"""Start points of an identification: the case's default start or seeded Latin-hypercube starts."""

from __future__ import annotations

import numpy as np

from problems.inverse.case import Case
from problems.inverse.cases import get_case


def feasible_toward_reference(case: Case, x, check) -> np.ndarray:
    """``x`` if ``check(x)`` is None, else the first feasible point on the way back to the
    reference.

    A start can be an ill-posed material (exponent-compression: a sigma0^b < sigma0/3), so it is
    pulled toward the reference by factors 0.9^k until the material is well-posed.
    """
    ref = case.reference
    x = np.asarray(x, float)
    for k in range(60):
        y = ref + 0.9**k * (x - ref)
        if check(y) is None:
            return y
    return ref.copy()


def start_point(
    case: Case | str, kind: str = "default", seed: int = 0, index: int = 0
) -> np.ndarray:
    """Physical start point: the case's default start, or the ``index``-th seeded Latin-hypercube
    start."""
    case = get_case(case) if isinstance(case, str) else case
    if kind == "default":
        x = case.start
    elif kind == "random":
        x = case.random_starts(index + 1, seed)[index]
    else:
        raise ValueError(f"start = {kind!r} is unknown; allowed: default, random")
    if case.is_analytic:
        return x
    from problems.inverse.forward import FEForwardModel

    return feasible_toward_reference(case, x, FEForwardModel(case).check)

"""What any forward model offers the inverse problem: FE, surrogate or analytic alike.

A forward model maps physical parameters ``x`` to a predicted measurement vector ``U_N(x)``
(the layout of the data it is compared with). It is picklable (it is shipped to workers), it
never raises for non-convergence (it returns ``ok=False`` with a message instead), and ``check``
tells cheaply, without running anything heavy, whether ``x`` is a valid point at all.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Protocol, runtime_checkable

import numpy as np


@dataclass(frozen=True)
class ForwardResult:
    """What a forward model returns for one point.

    ok       : False when the model failed (then ``values`` is None and ``message`` says why)
    values   : (m,) predicted measurement vector U_N(x), same layout and units as the data
    message  : why it failed, or a note
    wall_s   : wall time of the evaluation, s
    jacobian : (m, n) dU_N/dx in physical units, when the model computed it (else None)
    plain_wall_s : for a run with a Jacobian, the wall time of its plain part (the same work as a
               run without), s, when the model can tell; the evaluator measures the Jacobian's
               price against it when it has no plain run of its own
    """

    ok: bool
    values: np.ndarray | None
    message: str = ""
    wall_s: float = 0.0
    jacobian: np.ndarray | None = None
    plain_wall_s: float | None = None


@runtime_checkable
class ForwardModel(Protocol):
    """Anything picklable with ``names``, ``check`` and ``__call__``."""

    names: tuple[str, ...]

    def check(self, x: np.ndarray) -> str | None:
        """``None`` if the physical point ``x`` is feasible, else the reason (cheap, no FE)."""
        ...

    def __call__(self, x: np.ndarray) -> ForwardResult:
        """Evaluate at physical ``x``; never raises for non-convergence (``ok=False`` instead)."""
        ...


class RunModel:
    """Picklable call of a model shipped through a mapper: times it, turns exceptions into failures.

    ``with_jacobian`` asks models that offer ``jacobian=True`` for their exact Jacobian.
    """

    def __init__(self, model: ForwardModel, with_jacobian: bool = False):
        self.model = model
        self.with_jacobian = with_jacobian

    def __call__(self, x: np.ndarray) -> ForwardResult:
        t0 = time.perf_counter()
        try:
            x = np.array(x, dtype=float)
            res = self.model(x, jacobian=True) if self.with_jacobian else self.model(x)
        except Exception as exc:  # a crash inside the model must not kill the solver loop
            return ForwardResult(
                False, None, f"model raised {type(exc).__name__}: {exc}", time.perf_counter() - t0
            )
        if not isinstance(res, ForwardResult):
            return ForwardResult(
                False,
                None,
                f"model returned {type(res).__name__}, not ForwardResult",
                time.perf_counter() - t0,
            )
        if not res.wall_s:
            res = replace(res, wall_s=time.perf_counter() - t0)
        return res


def provides_jacobian(model) -> bool:
    """True when ``model`` declares that it computes exact Jacobians
    (``model(x, jacobian=True)``)."""
    return bool(getattr(model, "provides_jacobian", False))

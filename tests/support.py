"""Small helpers shared by the tests (fixtures live in conftest.py)."""
from __future__ import annotations

from problems.inverse.evaluator import Evaluator
from problems.inverse.problem import LeastSquaresProblem


def evaluator(model, data, *, mapper=None, cache=True, **problem):
    """An :class:`Evaluator` over ``LeastSquaresProblem(model, data, **problem)``."""
    return Evaluator(LeastSquaresProblem(model, data, **problem), mapper=mapper, cache=cache)

"""Small helpers shared by the tests (fixtures live in conftest.py)."""

from __future__ import annotations

from problems.inverse.evaluator import Evaluator
from problems.inverse.problem import LeastSquaresProblem


def evaluator(model, data, *, mapper=None, cache=True, free_repeats=False, **problem):
    """An :class:`Evaluator` over ``LeastSquaresProblem(model, data, **problem)``."""
    return Evaluator(
        LeastSquaresProblem(model, data, **problem),
        mapper=mapper,
        cache=cache,
        free_repeats=free_repeats,
    )


def material(form: str, hardening: str, **overrides):
    """A Drucker-Prager material of ``form``/``hardening`` at its typical parameters
    (+ overrides)."""
    from problems.materials.drucker_prager import make_material
    from problems.materials.verification import typical_parameters

    return make_material(form, hardening, {**typical_parameters(form, hardening), **overrides})


#: the nine (form, hardening) variants of the extended Drucker-Prager family
VARIANTS = [
    (f, h)
    for f in ("linear", "hyperbolic", "exponent")
    for h in ("compression", "shear", "tension")
]

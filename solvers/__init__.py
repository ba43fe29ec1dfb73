"""femubench.solvers: one interface over local, global and sampling methods.

>>> from solvers import solve, METHODS
>>> result = solve(objective, "lm", budget=200, seed=0, x0=case.start)

Importing the package registers every adapter in :data:`METHODS`.
"""

from solvers.base import METHODS, MethodInfo, Outcome, Run, find_method, get_method, register, solve
from solvers.result import RunResult

# Importing the adapters registers their methods, in this order (the order of METHODS).
# isort: off
from solvers import (  # noqa: F401
    scipy_,
    gauss_newton,
    pymoo_,
    pyswarms_,
    nlopt_,
    emcee_,
    hybrid,
    cma_,
    bo_,
    nevergrad_,
)
# isort: on

__all__ = [
    "solve",
    "METHODS",
    "RunResult",
    "MethodInfo",
    "Outcome",
    "Run",
    "get_method",
    "find_method",
    "register",
]

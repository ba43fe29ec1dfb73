"""The BBOB functions of COCO (``cocoex``, package ``coco-experiment``) as scalar user problems.

``problem(function, instance, dimension)`` is the entry point ``problems.benchmarks.bbob:problem``
(suites/bbob.toml): f is COCO's ``bbob`` function over the box [-5, 5]^dimension, f_min its known
optimum (``cocoex.BareProblem.best_value``), success ``f - f_min <= target`` (COCO's final target
1e-8 by default), the default start COCO's initial solution (the origin).
"""

from __future__ import annotations

import numpy as np

from problems.user import ScalarProblem, SuccessRule, UserProblem


class BBOBFunction:
    """A picklable BBOB function: the ``cocoex.BareProblem`` is made on first call in each
    process (it cannot be pickled itself). ``function`` 1..24, ``instance`` >= 1."""

    def __init__(self, function: int, instance: int, dimension: int):
        self.function, self.instance, self.dimension = int(function), int(instance), int(dimension)
        self.names = tuple(f"x{i + 1}" for i in range(self.dimension))
        self._fn = None

    def bare(self):
        """The cocoex problem (made once per process)."""
        if self._fn is None:
            import cocoex

            self._fn = cocoex.BareProblem("bbob", self.function, self.dimension, self.instance)
        return self._fn

    def __call__(self, x) -> float:
        return float(self.bare()(np.asarray(x, dtype=float)))

    def __getstate__(self):
        return {**self.__dict__, "_fn": None}


def problem(
    function: int = 1, instance: int = 1, dimension: int = 5, target: float = 1e-8
) -> UserProblem:
    """BBOB function ``function`` (1..24), instance ``instance``, in ``dimension`` D (2, 3, 5,
    10, 20, 40) as a :class:`UserProblem`."""
    if not (isinstance(function, int) and 1 <= function <= 24):
        raise ValueError(f"function = {function!r} is out of range: an integer 1..24")
    if dimension not in (2, 3, 5, 10, 20, 40):
        raise ValueError(f"dimension = {dimension!r} is not a BBOB dimension: 2, 3, 5, 10, 20, 40")
    fn = BBOBFunction(function, instance, dimension)
    bare = fn.bare()
    return UserProblem(
        ScalarProblem(fn, np.full(dimension, -5.0), np.full(dimension, 5.0)),
        x0=np.zeros(dimension),
        f_min=float(bare.best_value()),
        x_ref=np.asarray(bare.best_parameter(), dtype=float),
        success=SuccessRule("f-target", target=float(target)),
        name=str(bare.id),
    )

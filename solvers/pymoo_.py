"""pymoo adapters: ``ga`` (real-coded GA, SBX + polynomial mutation) and ``de``.

The whole population of a generation is one ``Problem._evaluate`` call (``elementwise=False``),
i.e. one :meth:`Evaluator.costs` batch through the mapper. The initial population is a seeded
Latin hypercube (optionally with the start point as its first member). pymoo's own evaluation
count and termination are only a backstop: the objective's budget is the hard cap.
"""

from __future__ import annotations

import numpy as np

from solvers.base import Outcome, Run, isolated_global_rng, lhs, register
from solvers.options import choice, count, flag, fraction, nonnegative, number

POP_OPTIONS = {
    "pop_size": count(40, "population size"),
    "max_generations": count(None, "maximum number of generations (None: until the budget)"),
    "include_x0": flag(False, "put the start point into the initial population"),
}

GA_OPTIONS = {
    **POP_OPTIONS,
    "crossover_prob": fraction(0.9, "SBX crossover probability"),
    "crossover_eta": nonnegative(15.0, "SBX distribution index"),
    "mutation_eta": nonnegative(20.0, "polynomial mutation distribution index"),
    "mutation_prob": fraction(None, "polynomial mutation probability per variable (None: 1/n)"),
}

DE_OPTIONS = {
    **POP_OPTIONS,
    "variant": choice("DE/rand/1/bin", "DE/<selection>/<n_diffs>/<crossover>"),
    "CR": fraction(0.9, "crossover rate"),
    "F": number(0.8, "differential weight"),
}


def _problem(obj, lower, upper):
    from pymoo.core.problem import Problem

    class _ObjectiveProblem(Problem):
        def __init__(self):
            super().__init__(n_var=lower.size, n_obj=1, xl=lower, xu=upper, elementwise=False)

        def _evaluate(self, X, out, *args, **kwargs):
            out["F"] = obj.costs(X)[:, None]

    return _ObjectiveProblem()


def _initial(r: Run) -> np.ndarray:
    X = lhs(int(r.options["pop_size"]), r.lower, r.upper, r.rng(1))
    if r.options["include_x0"]:
        X[0] = np.clip(r.z0, r.lower, r.upper)
    return X


def _minimize(r: Run, algorithm) -> Outcome:
    from pymoo.config import Config
    from pymoo.optimize import minimize

    Config.warnings["not_compiled"] = False
    obj = r.objective
    max_gen = r.options["max_generations"]

    def callback(algorithm):
        opt = algorithm.opt[0]
        r.record(opt.X, float(opt.F[0]), generation=int(algorithm.n_gen))

    termination = ("n_gen", int(max_gen)) if max_gen else ("n_evals", r.budget)
    with isolated_global_rng(r.seed):  # pymoo 0.6.2 uses its own Generator; belt and braces
        res = minimize(
            _problem(obj, r.lower, r.upper),
            algorithm,
            termination,
            seed=r.seed,
            callback=callback,
            verbose=False,
            copy_algorithm=False,
        )
    if obj.remaining == 0 or not max_gen:
        return Outcome("budget", f"evaluation budget spent after {res.algorithm.n_gen} generations")
    return Outcome("max_iterations", f"{max_gen} generations")


@register(
    "ga",
    library="pymoo",
    family="global",
    options=GA_OPTIONS,
    stochastic=True,
    description="real-coded genetic algorithm: tournament selection, SBX crossover, polynomial "
    "mutation",
)
def run_ga(r: Run) -> Outcome:
    from pymoo.algorithms.soo.nonconvex.ga import GA
    from pymoo.operators.crossover.sbx import SBX
    from pymoo.operators.mutation.pm import PM

    o = r.options
    mutation = (
        PM(eta=o["mutation_eta"])
        if o["mutation_prob"] is None
        else PM(eta=o["mutation_eta"], prob=o["mutation_prob"])
    )
    algorithm = GA(
        pop_size=int(o["pop_size"]),
        sampling=_initial(r),
        crossover=SBX(prob=o["crossover_prob"], eta=o["crossover_eta"]),
        mutation=mutation,
        eliminate_duplicates=True,
    )
    return _minimize(r, algorithm)


@register(
    "de",
    library="pymoo",
    family="global",
    options=DE_OPTIONS,
    stochastic=True,
    description="differential evolution",
)
def run_de(r: Run) -> Outcome:
    from pymoo.algorithms.soo.nonconvex.de import DE

    o = r.options
    algorithm = DE(
        pop_size=int(o["pop_size"]),
        sampling=_initial(r),
        variant=o["variant"],
        CR=o["CR"],
        F=o["F"],
    )
    return _minimize(r, algorithm)

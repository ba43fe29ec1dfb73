"""Run one identification: the objective of a spec from the one assembly, the solver, the FE polish.

The experiment side's entry point (``femubench identify``, the runner, the studies): the spec is a
:class:`bench.experiment.spec.RunSpec`; the objective is assembled by
:func:`bench.experiment.objective.prepare`, which checks the honesty rule once. Every run it
triggers is counted in the returned :class:`~solvers.result.RunResult`: the solver's evaluations
(``n_evals``, ``forward_equivalents``) and the runs made on its behalf (``charges``: the
high-fidelity runs of a correction, the BAE statistics, a surrogate's training), and
``provenance`` says where the data and the models came from.
"""

from __future__ import annotations

from bench.experiment.objective import prepare
from bench.experiment.spec import RunSpec

#: options of the FE polish after a run on a surrogate: it starts near the optimum (often on a
#: bound), where a step's relative cost decrease and size are tiny on ill-conditioned
#: (model-error) problems, so only the gradient (gtol), a stalled step or the budget stop it
POLISH_OPTIONS = {"ftol": 1e-15, "xtol": 1e-15}


def jacobian_options(method: str, options: dict, jacobian: str) -> dict:
    """``options`` of ``method`` with the finite-difference ``scheme`` that ``jacobian`` asks
    (methods without a ``scheme`` option, and ``exact``, get them unchanged). A ``scheme`` given
    in the options that contradicts ``jacobian`` raises ValueError."""
    from solvers.base import get_method

    if jacobian == "exact" or "scheme" not in get_method(method).options:
        return dict(options)
    given = options.get("scheme", jacobian)
    if given != jacobian:
        raise ValueError(
            f"option scheme = {given!r} contradicts jacobian = {jacobian!r}; give one of them"
        )
    return {**options, "scheme": jacobian}


def vectorised_mapper():
    """The mapper of objectives on a surrogate: whole batches in one vectorised call."""
    from problems.surrogate.model import VectorisedMapper

    return VectorisedMapper()


def identify(spec: RunSpec, *, mapper=None, dataset=None, observers=()):
    """Run the identification ``spec``; returns the solver's RunResult with totals and provenance.

    ``dataset``: the measured data when the caller prepared it (else ``spec.data``'s).
    ``observers``: callables added to the objective's observers (progress bars). The objective is
    assembled by :func:`bench.experiment.objective.prepare` (which checks the honesty rule).
    """
    from dataclasses import replace

    from problems.inverse.model_error import ITERATED
    from problems.inverse.plausibility import warn_data, warn_result
    from solvers import solve
    from solvers.corrected import solve_iterated

    requested = spec.treatment.name
    asm = prepare(spec, mapper=mapper, dataset=dataset)
    if asm.data is not None:  # wrong units, all zero: before any run (plausibility.py)
        warn_data(asm.data)
    spec, surrogate = asm.spec, asm.surrogate
    built = []  # the objectives on the surrogate (their logs give its evaluations' wall time)

    def run_phase(method, budget, start, options, forward):
        options = jacobian_options(method, options, spec.jacobian)

        def objective_with(correction):
            obj = asm.objective(
                correction,
                forward=forward,
                mapper=None if forward is None else vectorised_mapper(),
                observers=observers,
            )
            if forward is not None:
                built.append(obj)
            return obj

        if spec.treatment.name in ITERATED:
            return solve_iterated(
                objective_with,
                asm.one_point if spec.treatment.name == "iterated" else asm.first_order,
                method,
                budget=budget,
                seed=spec.seed,
                x0=start,
                **options,
            )
        return solve(
            objective_with(asm.correction()),
            method,
            budget=budget,
            seed=spec.seed,
            x0=start,
            **options,
        )

    result = run_phase(spec.method, spec.budget, asm.start(), spec.options, surrogate)
    if surrogate is not None:
        from bench.experiment.surrogate_track import combine

        polished = None
        if spec.polish_budget:
            polished = run_phase("lm", spec.polish_budget, list(result.x), POLISH_OPTIONS, None)
        result = combine(
            result,
            built,
            surrogate,
            spec.surrogate,
            polished,
            polish_charges_repeat=spec.treatment.name in ("one-point", "bae"),
        )
    if asm.case.is_analytic:
        return result
    provenance = {
        **result.provenance,
        "start": spec.start,
        "start_index": spec.start_index,
        "data_file": spec.data.file,
        "treatment": spec.treatment.name,
        "treatment_requested": requested,
        "jacobian": spec.jacobian,
        "bae_samples": spec.treatment.bae_samples if spec.treatment.name == "bae" else None,
    }
    warn_result(asm.case, asm.data, asm.region, result)  # a cost far above the data's size, bounds
    return replace(result, provenance=provenance)

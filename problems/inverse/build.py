"""The inverse problem of a case: the evaluated least-squares problem against a data set."""
from __future__ import annotations

from pathlib import Path

from problems.inverse import layout
from problems.inverse.case import Case
from problems.inverse.cases import get_case
from problems.inverse.data import Dataset, get_data, load
from problems.inverse.evaluator import Evaluator
from problems.inverse.problem import LeastSquaresProblem


def build_objective(case: Case | str, *, mesh: str = "coarse", data: Dataset | str | Path | None = None,
                    mapper=None, sigma_force_kN: float = 1.0, cache: bool = True) -> Evaluator:
    """The evaluator (a solver's objective) of ``case`` with the FE model on ``mesh``.

    data : a :class:`Dataset`, a data-file path, or None for the case's shipped pseudo-experimental
           data. Analytic cases ignore mesh and data.
    sigma_force_kN : standard deviation of the plate force, kN
    """
    from problems.inverse.forward import FEForwardModel

    case = get_case(case) if isinstance(case, str) else case
    if case.is_analytic:
        from problems.inverse.analytic import analytic_objective

        return analytic_objective(case.name, mapper=mapper)
    if data is None:
        data = get_data(case.name)
    elif not isinstance(data, Dataset):
        data = load(data)
    if data.case != case.name:
        raise ValueError(f"data set is for case {data.case!r}, not {case.name!r}")
    model = FEForwardModel(case, mesh, data.settings.loading, data.points)
    problem = LeastSquaresProblem(
        model, data.values, case.lower, case.upper, case.reference, sigma=data.sigma(sigma_force_kN),
        blocks=layout.blocks(len(data.snapshots_mm), len(data.points)),
        provenance={"case": case.name, "data_hash": data.hash, "data_mesh": data.settings.mesh,
                    "inverse_mesh": mesh})
    return Evaluator(problem, mapper=mapper, cache=cache)

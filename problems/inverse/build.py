"""The inverse problem of a case: its objective against a data set, and its start points."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from problems.inverse.cases import Case, get_case
from problems.inverse.data import Dataset, get_data, load


def build_objective(case: Case | str, *, mesh: str = "coarse", data: Dataset | str | Path | None = None,
                    mapper=None, sigma_force_kN: float = 1.0, cache: bool = True):
    """The weighted least-squares objective of ``case`` with the FE model on ``mesh``.

    data : a :class:`Dataset`, a data-file path, or None for the case's shipped pseudo-experimental
           data (made on the ``fine`` mesh). Analytic cases (``analytic-*``) ignore mesh and data.
    """
    from problems.inverse.forward import FEForwardModel, measurement_blocks
    from problems.inverse.objective import Objective

    case = get_case(case) if isinstance(case, str) else case
    if case.name.startswith("analytic-"):
        from problems.inverse.analytic import analytic_objective

        return analytic_objective(case.name, mapper=mapper)
    if data is None:
        data = get_data(case.name)
    elif not isinstance(data, Dataset):
        data = load(data)
    if data.case != case.name:
        raise ValueError(f"data set is for case {data.case!r}, not {case.name!r}")
    model = FEForwardModel(case, mesh, data.settings.loading, data.points)
    obj = Objective(model, data.values, lower=case.lower, upper=case.upper, reference=case.reference,
                    sigma=data.sigma(sigma_force_kN), blocks=measurement_blocks(len(data.snapshots_mm), len(data.points)),
                    mapper=mapper, cache=cache)
    obj.data_hash = data.hash
    return obj


def feasible_toward_reference(case: Case, x, check) -> np.ndarray:
    """``x`` if ``check(x)`` is None, else the first feasible point on the way back to the reference.

    The issue's default start can be ill-posed (exponent-compression: a sigma0^b < sigma0/3), so a
    start is pulled toward the reference by factors 0.9^k until the material is well-posed.
    """
    ref = case.reference
    x = np.asarray(x, float)
    for k in range(60):
        y = ref + 0.9**k * (x - ref)
        if check(y) is None:
            return y
    return ref.copy()


def start_point(case: Case | str, kind: str = "default", seed: int = 0, index: int = 0) -> np.ndarray:
    """Physical start point: the case's default start, or the ``index``-th seeded Latin-hypercube start."""
    case = get_case(case) if isinstance(case, str) else case
    if kind == "default":
        x = case.start
    elif kind == "random":
        x = case.random_starts(index + 1, seed)[index]
    else:
        raise ValueError(f"start kind {kind!r} is unknown; allowed: default, random")
    if case.name.startswith("analytic-"):
        return x
    from problems.inverse.forward import FEForwardModel

    return feasible_toward_reference(case, x, FEForwardModel(case).check)

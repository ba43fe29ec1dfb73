"""NIST StRD certified nonlinear regression problems (problems/benchmarks/nist.py)."""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest

from problems.benchmarks import nist
from problems.inverse.evaluator import Evaluator
from problems.inverse.problem import LeastSquaresProblem
from problems.user import load_problem
from solvers import solve

#: number of parameters and observations of each problem (NIST's headers)
SIZES = {
    "Misra1a": (2, 14), "Chwirut2": (3, 54), "Chwirut1": (3, 214), "Lanczos3": (6, 24),
    "Gauss1": (8, 250), "Gauss2": (8, 250), "DanWood": (2, 6), "Misra1b": (2, 14),
    "Kirby2": (5, 151), "Hahn1": (7, 236), "Nelson": (3, 128), "MGH17": (5, 33),
    "Lanczos1": (6, 24), "Lanczos2": (6, 24), "Gauss3": (8, 250), "Misra1c": (2, 14),
    "Misra1d": (2, 14), "Roszman1": (4, 25), "ENSO": (9, 168), "MGH09": (4, 11),
    "Thurber": (7, 37), "BoxBOD": (2, 6), "Rat42": (3, 9), "MGH10": (3, 16), "Eckerle4": (3, 35),
    "Rat43": (4, 15), "Bennett5": (3, 154),
}  # fmt: skip


def test_all_27_problems_with_both_starts_and_certified_values():
    assert nist.NAMES == tuple(SIZES) and len(nist.NAMES) == 27
    for name, (n, m) in SIZES.items():
        rec = nist.record(name)
        assert len(rec["start1"]) == len(rec["start2"]) == len(rec["certified"]) == n, name
        assert len(rec["certified_sd"]) == n and len(rec["y"]) == len(rec["x"]) == m, name
        assert rec["difficulty"] in ("lower", "average", "higher")
    assert np.asarray(nist.record("Nelson")["x"]).shape == (128, 2)  # two predictors
    assert nist.certified("Misra1a")[0] == 2.3894212918e02  # as typed in NIST's file
    assert nist.record("MGH10")["rss"] == 8.7945855171e01


@pytest.mark.parametrize("name", nist.NAMES)
def test_certified_parameters_reproduce_the_certified_rss(name):
    """The model as typed, at the certified parameters (11 digits), gives NIST's residual sum of
    squares (computed in 128 bits) to 1e-9; Lanczos1, whose RSS 1.4e-25 is below what 11-digit
    parameters can resolve, to 1e-20 of the data's squared norm."""
    p = nist.problem(name)
    ev = Evaluator(p)
    rss = ev.cost(nist.certified(name))
    certified = nist.record(name)["rss"]
    y = nist.response(name)
    if name == "Lanczos1":
        assert rss < 1e-20 * float(y @ y)
    else:
        assert rss == pytest.approx(certified, rel=1e-9)
    # start 1 is worse than start 2 or both are far (the certified point is the best of the three)
    assert rss <= min(ev.cost(nist.start(name, 1)), ev.cost(nist.start(name, 2)))


def test_factory_builds_unbounded_unscaled_problems_named_by_entry_point():
    p = nist.problem("MGH09", start=2)
    assert isinstance(p, LeastSquaresProblem)
    assert np.all(np.isinf(p.lower)) and np.all(np.isinf(p.upper))
    assert np.all(p.reference == 1.0) and p.names == ("b1", "b2", "b3", "b4")
    assert p.provenance["x0"] == [0.25, 0.39, 0.415, 0.39] and p.provenance["nist_start"] == 2
    assert np.allclose(nist.problem("MGH09", scaled=True).reference, [25, 39, 41.5, 39])
    pickle.loads(pickle.dumps(p.model))  # runs on a cluster
    up = load_problem("problems.benchmarks.nist:user_problem", {"name": "BoxBOD", "start": 1})
    assert list(up.x0) == [1.0, 1.0] and up.success.kind == "digits"
    assert up.judge(nist.certified("BoxBOD"), 1168.0, False)["success"]
    bare = load_problem("problems.benchmarks.nist:problem", {"name": "BoxBOD"})
    assert bare.problem.n_params == 2
    with pytest.raises(ValueError, match="start = 3 is out of range"):
        nist.problem("BoxBOD", start=3)
    with pytest.raises(ValueError, match="unknown; allowed: Misra1a"):
        nist.problem("Misra2")
    nelson = Evaluator(nist.problem("Nelson"))
    assert nelson.data[0] == pytest.approx(math.log(nist.record("Nelson")["y"][0]))


def test_a_near_start_is_solved_to_certified_digits():
    from problems.user import correct_digits

    for method in ("lm", "trf", "lm-minpack"):
        ev = Evaluator(nist.problem("Misra1a", 2))
        res = solve(ev, method, budget=200, x0=nist.start("Misra1a", 2))
        assert res.status == "converged" and res.success, (method, res.message)
        assert correct_digits(res.x, nist.certified("Misra1a")) >= 6, method

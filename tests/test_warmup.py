"""The per-process warm-up of the FE forward model (problems/inverse/forward.py ``warm_up``):
numba's JIT compilation is a one-off of the process and must not be charged to a run's first
evaluation (the measured forward-equivalents)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

import problems.inverse.forward as forward
from problems.inverse.cases import get_case
from problems.inverse.evaluator import Evaluator
from problems.inverse.forward import FEForwardModel
from problems.inverse.problem import LeastSquaresProblem


def test_warm_up_runs_once_per_kind_and_changes_nothing(monkeypatch):
    case = get_case("linear-compression")
    model = FEForwardModel(case, "2,2,4")
    x = case.reference
    monkeypatch.setattr(FEForwardModel, "warm_up", lambda self, x, jacobian=False: False)
    cold = model(x, jacobian=True)
    monkeypatch.undo()
    monkeypatch.setattr(forward, "_WARMED", set())
    problem = LeastSquaresProblem(
        model, cold.values * 1.01, lower=0.5 * x, upper=1.5 * x, reference=x, sigma=0.01
    )
    ev = Evaluator(problem)
    got = ev.evaluate(ev.to_scaled(x), with_jacobian=True)  # warms the sensitivity kind up
    assert len(forward._WARMED) == 1 and ev.n_evals == 1 and len(ev.log) == 1
    assert ev.n_jacobian_runs == 1 and ev.nominal_equivalents() == model.jacobian_cost
    # the same answers as without a warm-up, bit for bit
    np.testing.assert_array_equal(got.residual, problem.residual(cold.values)[0])
    np.testing.assert_array_equal(got.jacobian, problem.residual_jacobian(cold.jacobian))
    assert not model.warm_up(x, jacobian=True)  # once per kind
    assert model.warm_up(x) and not model.warm_up(x)  # plain runs are another kind
    other = FEForwardModel(case, "3,3,6")  # same element, symmetry, material: nothing to do
    assert not other.warm_up(x) and len(forward._WARMED) == 2


@pytest.mark.slow
def test_a_cold_numba_cache_is_not_charged(tmp_path):
    """With an empty numba cache the measured forward-equivalents of an exact-Jacobian LM run
    stay near their nominal count (before the warm-up: 78.6 against 10.2)."""
    out = tmp_path / "run.json"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    cmd = [sys.executable, "-m", "bench.cli", "identify", "linear-compression", "--solver", "lm"]
    cmd += ["--tier", "consistent", "--budget", "200", "--json", str(out), "--quiet"]
    subprocess.run(cmd, env=env, check=True, capture_output=True)
    run = json.loads(out.read_text())
    assert run["n_evals"] >= 5 and run["forward_equivalents_nominal"] > 0
    assert run["forward_equivalents"] < 1.5 * run["forward_equivalents_nominal"]

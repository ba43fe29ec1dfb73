"""The ``solvers``, ``identify`` and ``objective`` sub-commands (analytic cases: no FE)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bench.cli import main
from problems.inverse.analytic import ANALYTIC_CASES, analytic_objective
from solvers import METHODS, RunResult, solve


def test_solvers_json_lists_every_method(capsys):
    assert main(["solvers", "--json"]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert {m["name"] for m in listed} == set(METHODS)
    lm = next(m for m in listed if m["name"] == "lm")
    assert (
        lm["library"] == "scipy"
        and lm["family"] == "local"
        and lm["options"]["rel_step"]["default"] is None
    )


def test_solvers_table_filters_by_family(capsys):
    assert main(["solvers", "--family", "sampling"]) == 0
    rows = [line.split()[0] for line in capsys.readouterr().out.splitlines()[1:-1]]
    assert rows == ["mcmc"]


def test_format_identification_table():
    from bench.commands.identify import format_identification

    case = ANALYTIC_CASES["analytic-smooth"]
    res = solve(analytic_objective("analytic-smooth"), "gauss-newton", budget=100, x0=case.start)
    text = format_identification(case, res)
    assert "E " in text and "sigma0" in text and f"forward evaluations {res.n_evals}" in text
    row = next(line for line in text.splitlines() if line.strip().startswith("psi"))
    assert float(row.split()[-1]) == pytest.approx(0.0, abs=1e-3)  # error % of psi
    assert float(row.split()[-3]) == pytest.approx(11.25)  # start


def test_identify_writes_run_result_plus_errors(tmp_path, capsys):
    out = tmp_path / "run.json"
    code = main(
        [
            "identify",
            "analytic-multimodal",
            "--solver",
            "multistart-lm",
            "--budget",
            "250",
            "--seed",
            "1",
            "--option",
            "n_starts=6",
            "--json",
            str(out),
        ]
    )
    assert code == 0
    text = capsys.readouterr().out
    assert "omega" in text and "forward evaluations" in text
    doc = json.loads(out.read_text())
    errors = doc.pop("errors_percent")
    assert doc.pop("package_version") and doc.pop("iterations") == doc["n_iterations"]
    assert doc.pop("warnings") == []  # plausibility warnings (FE cases only)
    assert doc.pop("derived") == {}  # derived parameters (the exponent cases' a) only
    res = RunResult.from_dict(doc)  # the rest is exactly a RunResult
    assert (
        res.n_evals <= 250
        and res.options["n_starts"] == 6
        and res.provenance["case"] == "analytic-multimodal"
    )
    assert errors == pytest.approx(
        {n: 100 * (xn - 1) for n, xn in zip(res.parameter_names, res.x_normalised)}
    )
    assert abs(errors["omega"]) < 1e-3  # found the global minimum


def test_identify_random_start_and_bad_input(capsys):
    assert (
        main(["identify", "analytic-smooth", "--solver", "lm", "--start", "random", "--seed", "3"])
        == 0
    )
    assert main(["identify", "analytic-smooth", "--solver", "nope"]) == 2
    assert "unknown" in capsys.readouterr().err
    assert main(["identify", "analytic-smooth", "--solver", "lm", "--option", "bogus=1"]) == 2


def test_objective_command_prints_cost_split_and_feasibility(capsys):
    assert main(["objective", "analytic-smooth", "--x", "E=31000", "psi=12", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    obj = analytic_objective("analytic-smooth")
    expected = obj.cost(obj.to_scaled([31000, 20, 1500, 12]))
    assert doc["cost"] == pytest.approx(expected, rel=1e-12) and doc["feasible"] and doc["ok"]
    assert doc["split"]["stress"] + doc["split"]["lateral"] == pytest.approx(expected, rel=1e-12)
    assert main(["objective", "analytic-infeasible", "--x", "psi=27"]) == 0
    text = capsys.readouterr().out
    assert "INFEASIBLE" in text and "1e+12" in text
    assert main(["objective", "analytic-smooth", "--x", "F=1"]) == 2
    assert main(["objective", "analytic-smooth", "--x", "E=abc"]) == 2


def test_objective_point_defaults_to_reference():
    from bench.commands.objective import point

    case = ANALYTIC_CASES["analytic-smooth"]
    np.testing.assert_array_equal(point(case, ["H=1000"]), [30000, 20, 1000, 15])

"""Declared solver options (solvers/options.py): validation, listing and docs, one declaration."""

from __future__ import annotations

from pathlib import Path

import pytest

from solvers import METHODS
from solvers.base import register, resolve_options
from solvers.options import Option, count, fraction, markdown, number

DOC = Path(__file__).resolve().parents[1] / "docs" / "solver_options.md"


def test_the_docs_are_generated_from_the_declarations():
    assert DOC.read_text(encoding="utf-8") == markdown(METHODS), (
        "docs/solver_options.md is stale: femubench solvers --markdown > docs/solver_options.md"
    )


@pytest.mark.parametrize(
    "method, name, value, why",
    [
        ("ga", "pop_size", 0, "0 is out of range; allowed: a whole number >= 1"),
        ("ga", "pop_size", 2.5, "2.5 is not a whole number"),
        ("mcmc", "burn_fraction", 1.0, "1.0 is out of range; allowed: a number in [0, 1)"),
        ("lm", "ls_method", "lm", "'lm' is unknown; allowed: dogbox, trf"),
        ("lm", "x_scale", "auto", "'auto' is not a number; allowed: a number > 0 or jac"),
        ("lm", "rel_step", 0.0, "0.0 is out of range; allowed: a number > 0"),
        ("lm", "ftol", None, "None is not allowed"),
        ("sa", "visit", 3.5, "3.5 is out of range; allowed: a number in (1, 3]"),
        ("mcmc", "keep_chain", 1, "1 is not true/false"),
        ("cma", "sigma0", float("nan"), "nan is not a finite number"),
    ],
)
def test_values_outside_the_declaration_are_refused_naming_what_is_allowed(
    method, name, value, why
):
    with pytest.raises(ValueError) as exc:
        resolve_options(METHODS[method], {name: value})
    assert str(exc.value).startswith(f"{method}: option {name} = {why}")


def test_allowed_values_pass_and_defaults_fill_in():
    out = resolve_options(
        METHODS["lm"], {"x_scale": "jac", "max_nfev": None, "ls_method": "trf", "ftol": 1e-8}
    )
    assert out["x_scale"] == "jac" and out["ls_method"] == "trf" and out["max_nfev"] is None
    assert out["gtol"] == METHODS["lm"].options["gtol"].default
    assert resolve_options(METHODS["bo"], {"noise": 1e-4, "cost_scale": "median"})["noise"] == 1e-4
    assert resolve_options(METHODS["pso"], {"ftol": float("-inf")})["ftol"] == float("-inf")


def test_options_must_be_declared():
    with pytest.raises(TypeError, match="not declared as solvers.options.Option"):
        register("undeclared", library="x", family="local", options={"a": (1, "old form")})
    with pytest.raises(ValueError, match="option type 'integer' is unknown"):
        Option("integer", 1, "a count")


def test_the_range_in_words():
    assert count(None, "n").range_text() == "a whole number >= 1 or None"
    assert fraction(0.5, "f").range_text() == "a number in [0, 1]"
    assert number(1.0, "x", low=0.0, low_open=True, high=2.0).range_text() == ("a number in (0, 2]")
    assert METHODS["lm"].options["x_scale"].to_dict()["allowed"] == "a number > 0 or jac"


def test_femubench_solvers_lists_the_declarations(capsys):
    from bench.cli import main

    assert main(["solvers", "--options", "--family", "sampling"]) == 0
    out = capsys.readouterr().out
    assert "burn_fraction" in out and "(allowed: a number in [0, 1))" in out

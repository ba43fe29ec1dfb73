"""Progress bars fed by the evaluator's observer hook, and the running-time warning."""

from __future__ import annotations

import io
from contextlib import redirect_stderr

import pytest

from bench import progress as P
from bench.cli import main


def test_the_bar_counts_every_evaluation_and_shows_the_best_cost():
    from problems.inverse.analytic import analytic_objective
    from solvers import solve

    obj = analytic_objective("analytic-linear")
    err = io.StringIO()
    with redirect_stderr(err):
        with P.EvaluationProgress(obj, desc="t") as bar:
            obj.evaluate([1.1, 1.0, 1.0])  # a phase without budget (e.g. the Laplace step) ...
            solve(obj, "lm", budget=40)  # ... then a budgeted solve (which resets the counters)
            n, total, postfix = bar.bar.n, bar.bar.total, bar.bar.postfix
    assert n == 1 + obj.n_evals and total == 1 + 40  # the total follows the budget once it is set
    assert bar not in obj.observers  # detached on exit
    assert postfix.startswith("best cost")


def test_one_bar_over_several_evaluators():
    from problems.inverse.analytic import analytic_objective

    a, b = analytic_objective("analytic-linear"), analytic_objective("analytic-smooth")
    with redirect_stderr(io.StringIO()):
        with P.EvaluationProgress(total=10) as bar:
            a.observers.append(bar)
            b.observers.append(bar)
            a.evaluate([1.0, 1.0, 1.0])
            b.evaluate(b.to_scaled(b.reference))
            a.evaluate([1.0, 1.0, 1.0])  # a cache hit: charged like every call (docs/objective.md)
            assert bar.bar.n == 3 and a.n_evals == 2 and a.n_repeats == 1


def test_no_bar_without_a_terminal_or_with_quiet(capsys):
    assert not P.enabled(stream=io.StringIO()) and not P.enabled(quiet=True)
    assert main(["identify", "analytic-linear", "--solver", "lm", "--budget", "30"]) == 0
    assert capsys.readouterr().err == ""  # stderr is not a terminal under pytest


def test_run_time_estimate_and_the_one_line_warning():
    assert P.solved_dofs("coarse") == 1029
    assert P.forward_run_s("coarse") == pytest.approx(P.COARSE_RUN_S)
    # the documented growth: paper (9 450 dofs) ~ 8 s per run, fine ~ 40 s; the quarter costs more
    assert 5 < P.forward_run_s("paper") < 12 and 25 < P.forward_run_s("fine") < 60
    assert P.forward_run_s("coarse:quarter") > P.forward_run_s("coarse")
    quiet = io.StringIO()
    assert P.warn_if_long("identify", 300, "coarse", stream=quiet) < 3600 and quiet.getvalue() == ""
    loud = io.StringIO()
    est = P.warn_if_long("identify", 1000, "paper", workers=2, what="budget 1000", stream=loud)
    line = loud.getvalue()
    assert est > 3600 and line.count("\n") == 1
    assert line.startswith("femubench identify: warning: budget 1000")
    assert "h" in line and "paper" in line
    assert P.format_duration(30) == "30 s" and P.format_duration(3 * 3600) == "3.0 h"


def test_run_warns_per_mesh_with_that_mesh_s_own_run_count(tmp_path, capsys):
    """A suite with parts on two meshes: each warning counts the pending runs on its mesh."""
    from bench.cli import main

    suite = tmp_path / "two.toml"
    suite.write_text(
        '[suite]\nname = "two"\ncases = ["linear-compression", "linear-shear"]\nseeds = [0]\n'
        'mesh = "coarse"\n\n[[part]]\nmethods = ["lm"]\nbudgets = [20]\n\n'
        '[[part]]\nmethods = ["lm", "gauss-newton"]\nbudgets = [2000]\ntiers = ["model-error"]\n'
        'mesh = "9,9,18:g8:hex27"\n'
    )
    assert main(["run", str(suite), "--out", str(tmp_path / "o"), "--dry-run", "--quiet"]) == 0
    err = capsys.readouterr().err
    warned = [line for line in err.splitlines() if "warning:" in line]
    assert len(warned) == 1, err  # 40 coarse runs are short; 4 x 2000 hex27 runs are not
    assert "4 pending runs on 9,9,18:g8:hex27 (their whole budgets)" in warned[0]
    assert "up to 8000 forward run(s)" in warned[0]

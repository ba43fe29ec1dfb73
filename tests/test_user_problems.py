"""User problems: entry points in suites and the CLI, scalar objectives, success rules, and the
hashes of the shipped FE suites (unchanged by the new fields)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from bench.experiment import store
from bench.experiment.runner import run_suite
from bench.experiment.suite import load_suite, parse_suite
from problems.inverse.evaluator import Evaluator
from problems.user import ScalarProblem, UserProblem, correct_digits, least_squares, load_problem
from solvers import solve

ROOT = Path(__file__).resolve().parent.parent


# --- factories used by the tests (entry points "tests.test_user_problems:...") -------------------
def sphere(n: int = 3, shift: float = 0.5, infinite: bool = False):
    """f(x) = sum (x - shift)^2 + 1 over [-5, 5]^n (or R^n): f_min = 1 at x = shift."""
    lo, hi = (-np.inf, np.inf) if infinite else (-5.0, 5.0)
    return UserProblem(
        ScalarProblem(_Sphere(shift), np.full(n, lo), np.full(n, hi)),
        x0=np.full(n, 2.0),
        f_min=1.0,
        success={"kind": "f-target", "target": 1e-6},
    )


class _Sphere:
    def __init__(self, shift):
        self.shift = shift

    def __call__(self, x):
        return float(np.sum((np.asarray(x) - self.shift) ** 2) + 1.0)


def tagged(n: int = 3, shift: float = 0.5, tag: str = ""):
    """The sphere with a string argument (grid names)."""
    return sphere(n, shift)


def _exp_model(x):
    t = np.linspace(0.0, 4.0, 20)
    return x[0] * np.exp(-x[1] * t)


def exponential():
    """y = 2 exp(-0.7 t), noiseless: certified answer x = (2, 0.7)."""
    data = _exp_model(np.array([2.0, 0.7]))
    p = least_squares(_exp_model, data, [0.1, 0.01], [10.0, 5.0], sigma=0.01, names=["A", "k"])
    return UserProblem(p, x0=[1.0, 0.3], x_ref=[2.0, 0.7], success={"kind": "digits", "digits": 4})


# --- the shipped suites keep their hashes ---------------------------------------------------------
@pytest.mark.parametrize("name", ["default", "comparison"])
def test_shipped_suite_hashes_unchanged(name):
    """Every run of the shipped suite still has its record in results/<name>/runs (the new
    'problem' field stays out of the hash of FE runs)."""
    suite = load_suite(ROOT / "suites" / f"{name}.toml")
    have = {p.stem for p in store.runs_dir(ROOT / "results" / name).glob("*.json")}
    runs = suite.runs()
    missing = [r.label for r in runs if r.hash not in have]
    assert len(runs) == len(have) and not missing, missing[:5]


# --- entry points ---------------------------------------------------------------------------------
def test_entry_point_by_module_and_by_file(tmp_path):
    up = load_problem("tests.test_user_problems:sphere", {"n": 2})
    assert up.kind == "scalar" and up.problem.n_params == 2
    f = tmp_path / "myproblem.py"
    f.write_text(
        "import numpy as np\nfrom problems.user import ScalarProblem\n"
        "def make(scale=1.0):\n"
        "    return ScalarProblem(lambda x: scale * float(np.sum(x ** 2)), [-1, -1], [1, 1])\n"
    )
    up2 = load_problem(f"{f}:make", {"scale": 3.0})
    assert up2.success.kind == "solver" and np.allclose(up2.x0, 0.0)
    with pytest.raises(ValueError, match="has no function 'nope'"):
        load_problem(f"{f}:nope")
    with pytest.raises(ValueError, match="does not exist"):
        load_problem("missing/file.py:make")


def test_suite_validation_names_the_problem_table():
    raw = {
        "suite": {"methods": ["de"], "budgets": [10]},
        "problems": {"s": {"entry": "tests.test_user_problems:nothing", "argz": {}}},
    }
    with pytest.raises(ValueError) as exc:
        parse_suite(raw)
    text = str(exc.value)
    assert "[problems.s] unknown key 'argz'" in text and "has no function 'nothing'" in text


def test_grid_expands_and_hash_carries_the_problem():
    raw = {
        "suite": {"methods": ["de"], "budgets": [10]},
        "problems": {
            "sph": {
                "entry": "tests.test_user_problems:sphere",
                "args": {"n": 2},
                "grid": {"shift": [0.0, 1.0]},
            }
        },
    }
    suite = parse_suite(raw)
    runs = suite.runs()
    assert [r.case for r in runs] == ["sph-shift0.0", "sph-shift1.0"]
    assert runs[0].to_dict()["problem"] == {
        "entry": "tests.test_user_problems:sphere",
        "args": {"n": 2, "shift": 0.0},
    }
    assert runs[0].hash != runs[1].hash
    assert runs[0].label == "sph-shift0.0/de/s0/default0/b10"
    raw["problems"]["sph"]["grid"] = {"shift": [0.5], "tag": ["a"]}
    raw["problems"]["sph"]["entry"] = "tests.test_user_problems:tagged"
    assert [r.case for r in parse_suite(raw).runs()] == ["sph-shift0.5-a"]


# --- scalar objectives ----------------------------------------------------------------------------
def test_scalar_cost_is_f_and_counts_are_real():
    up = sphere(n=2)
    calls = []
    p = up.problem
    inner = p.model.fn
    p.model.fn = lambda x: calls.append(1) or inner(x)
    ev = Evaluator(p)
    res = solve(ev, "de", budget=300, seed=1, x0=up.x0)
    assert res.cost == pytest.approx(1.0, abs=1e-3)  # f itself, not a sum of squares
    assert res.n_evals == len(calls) <= 300


def test_least_squares_methods_refuse_a_scalar_problem():
    up = sphere(n=2)
    with pytest.raises(ValueError, match="needs a least-squares problem"):
        solve(Evaluator(up.problem), "lm", budget=20, x0=up.x0)


def test_infinite_bounds_scalar_with_a_local_method():
    up = sphere(n=3, infinite=True)
    res = solve(Evaluator(up.problem), "nlopt:SBPLX", budget=600, x0=up.x0)
    v = up.judge(np.asarray(res.x), res.cost, res.success)
    assert v["success"] and v["f_gap"] <= 1e-6


def test_sa_gradient_of_a_scalar_problem_is_df_dz():
    up = sphere(n=2, shift=0.0)
    ev = Evaluator(up.problem)
    f, g = ev.gradient(np.array([1.0, -2.0]))
    assert f == pytest.approx(6.0) and np.allclose(g, [2.0, -4.0], atol=1e-4)


def test_correct_digits():
    assert correct_digits([1.0001, 2.0], [1.0, 2.0]) == pytest.approx(4.0, abs=1e-6)
    assert correct_digits([np.nan, 2.0], [1.0, 2.0]) == 0.0


# --- a suite of user problems, run and judged ---
def test_suite_of_user_problems_runs_and_judges(tmp_path):
    raw = {
        "suite": {"name": "user", "methods": ["cma", "lm", "de"], "budgets": [400]},
        "problems": {
            "sphere": {"entry": "tests.test_user_problems:sphere", "args": {"n": 2}},
            "expo": {"entry": "tests.test_user_problems:exponential"},
        },
    }
    summary = run_suite(parse_suite(raw), tmp_path, workers=1, progress=False)
    recs = {(r["config"]["case"], r["config"]["method"]): r for r in store.load_records(tmp_path)}
    assert summary.total == 6 and summary.crashed == 1  # lm on the scalar sphere refuses
    # de ends at its budget (the solver's "success") short of both problems' own rules
    assert not recs[("sphere", "de")]["result"]["extra"]["problem"]["success"]
    assert recs[("sphere", "de")]["result"]["success"]
    assert summary.failed == 3  # the refused run and de on both: judged by the problems' rules
    assert "needs a least-squares problem" in recs[("sphere", "lm")]["result"]["message"]
    sph = recs[("sphere", "cma")]["result"]["extra"]["problem"]
    assert sph["success"] and sph["kind"] == "scalar" and sph["success_text"] == "f − f_min ≤ 1e-06"
    trace = recs[("sphere", "cma")]["result"]["trace"]
    assert trace[-1][1] == pytest.approx(recs[("sphere", "cma")]["result"]["cost"])
    assert all(a[0] < b[0] and a[1] > b[1] for a, b in zip(trace, trace[1:]))
    expo = recs[("expo", "lm")]["result"]["extra"]["problem"]
    assert expo["kind"] == "least-squares" and expo["digits"] >= 4 and expo["success"]
    json.dumps(sph)  # plain data
    assert math.isfinite(recs[("expo", "cma")]["result"]["cost"])


# --- the CLI ---
def test_cli_identify_and_run_a_user_problem(tmp_path, capsys):
    from bench.cli import main

    rc = main(
        [
            "identify",
            "--problem",
            "tests.test_user_problems:exponential",
            "--solver",
            "lm",
            "--budget",
            "60",
            "--quiet",
        ]
    )
    out = capsys.readouterr().out
    assert rc == 0 and "success (≥ 4 correct digits of every parameter): yes" in out
    assert (
        main(
            [
                "identify",
                "--problem",
                "tests.test_user_problems:sphere",
                "--solver",
                "lm",
                "--quiet",
            ]
        )
        == 2
    )
    assert "needs a least-squares problem" in capsys.readouterr().err
    assert (
        main(
            [
                "identify",
                "linear-shear",
                "--problem",
                "tests.test_user_problems:sphere",
                "--solver",
                "de",
            ]
        )
        == 2
    )
    rc = main(
        [
            "run",
            str(ROOT / "suites" / "smoke.toml"),
            "--problem",
            "tests.test_user_problems:exponential",
            "--out",
            str(tmp_path),
            "--workers",
            "1",
            "--quiet",
        ]
    )
    assert rc == 0
    recs = store.load_records(tmp_path)
    assert len(recs) == 6 and {r["config"]["case"] for r in recs} == {"exponential"}
    assert all(
        r["result"]["extra"]["problem"]["success"] for r in recs if r["config"]["method"] == "lm"
    )


# --- the documentation's example runs ---
def _blocks(text: str, lang: str) -> list[str]:
    import re

    return re.findall(rf"```{lang}\n(.*?)```", text, flags=re.S)


def test_docs_example_runs(tmp_path):
    """docs/user_problems.md: its Python block is the factory file, its TOML block the suite."""
    text = (ROOT / "docs" / "user_problems.md").read_text()
    code, suite = _blocks(text, "python")[0], _blocks(text, "toml")[0]
    assert len(code.strip().splitlines()) <= 25
    (tmp_path / "rosenbrock.py").write_text(code)
    suite = suite.replace("docs/examples/rosenbrock.py", str(tmp_path / "rosenbrock.py"))
    (tmp_path / "mine.toml").write_text(suite)
    summary = run_suite(
        load_suite(tmp_path / "mine.toml"), tmp_path / "out", workers=1, progress=False
    )
    recs = {
        (r["config"]["case"], r["config"]["method"]): r["result"]
        for r in store.load_records(tmp_path / "out")
    }
    assert summary.total == 9 and summary.crashed == 2  # lm refuses the two Rosenbrocks
    assert recs[("decay", "lm")]["extra"]["problem"]["success"]
    assert recs[("rosenbrock-n2", "cma")]["extra"]["problem"]["success"]
    assert recs[("rosenbrock-n4", "cma")]["extra"]["problem"]["f_gap"] <= 1e-6


def test_half_infinite_bounds_reject_points_below_the_finite_side():
    p = least_squares(lambda x: x, [1.0, 2.0], [0.0, 0.0], [np.inf, np.inf])
    (_, inside), (_, below) = p.classify(np.array([[5.0, 1e9], [-0.5, 1.0]]))
    assert inside is None and below.startswith("outside the bounds: x0 = -0.5")
    s = ScalarProblem(lambda x: float(x[0]), [0.0], [np.inf])
    assert s.classify(np.array([[-1.0]]))[0][1].startswith("outside the bounds")


def test_builtin_suites_parse():
    """suites/bbob.toml and suites/nist.toml: their problems load, their runs are as documented."""
    bbob = load_suite(ROOT / "suites" / "bbob.toml")
    assert len(bbob.runs()) == 18 * 10 and "bbob-function21-instance3" in bbob.problems
    nist = load_suite(ROOT / "suites" / "nist.toml")
    assert len(nist.problems) == 54 and len(nist.runs()) == 54 * 6
    up = load_problem(
        **{
            "entry": nist.problems["nist-MGH09-start1"]["entry"],
            "args": nist.problems["nist-MGH09-start1"]["args"],
        }
    )
    assert up.kind == "least-squares" and up.success.kind == "digits"

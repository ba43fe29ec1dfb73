"""Fuzz tests (seeded, reproducible): random inputs never raise; they are flagged or rejected in
one line.

* evaluators: >= 1000 random parameter vectors inside and outside the box (NaN, inf, huge,
  negative) through an FE objective on a tiny mesh and through every analytic objective: no
  exception, every failed or infeasible point a flagged result (ok/feasible False, FAILURE_COST);
* suite files: random and mutated TOML through :func:`bench.experiment.suite.load_suite`: a Suite
  or one ValueError/OSError, nothing else;
* data files: byte-garbled and structurally mutated (hash recomputed) data sets through
  :func:`problems.inverse.data.load`: a consistent Dataset or one ValueError/OSError;
* the command line: every option of every command with each value its type rejects (exit 2, one
  line naming the option), and random garbled argument vectors of every command, each anchored by
  an input that stops it before any computation (a bad case, a missing file): exit 2 with one line,
  never a traceback or an internal error.
"""

from __future__ import annotations

import io
import json
import math
import random
from contextlib import redirect_stderr, redirect_stdout

import numpy as np
import pytest

from bench.cli import build_parser, main
from problems.inverse.problem import FAILURE_COST

SEED = 20240611


# --------------------------------------------------------------------------- evaluators


def _random_vectors(
    rng: np.random.Generator, lower, upper, reference, n: int, pool=None
) -> list[np.ndarray]:
    """``n`` scaled points z = x / reference: special values, far outside, slightly outside and
    (from ``pool``, if given, so that the model runs only a few times) inside the box."""
    d = len(reference)
    zl, zu = lower / reference, upper / reference
    lz, uz = np.minimum(zl, zu), np.maximum(zl, zu)
    specials = [np.nan, np.inf, -np.inf, 0.0, -0.0, 1e308, -1e308, 1e-308, -1.0, 1e6, -1e6]
    out = []
    for k in range(n):
        kind = k % 6
        if kind == 0:  # special values sprinkled into a box point
            z = rng.uniform(lz, uz)
            idx = rng.choice(d, size=rng.integers(1, d + 1), replace=False)
            z[idx] = rng.choice(specials, size=len(idx))
        elif kind == 1:  # far outside: huge magnitudes of both signs
            z = rng.choice([-1, 1], size=d) * 10.0 ** rng.uniform(-3, 300, size=d)
        elif kind == 2:  # just outside one bound (beyond the clipping tolerance)
            z = rng.uniform(lz, uz)
            i = rng.integers(d)
            step = (uz[i] - lz[i]) * 10.0 ** rng.uniform(-6, 1)
            z[i] = uz[i] + step if rng.random() < 0.5 else lz[i] - step
        elif kind == 3:  # negative parameters
            z = -np.abs(rng.uniform(lz, uz))
        elif kind == 4 and pool is not None:  # a cached feasible point (or exactly on a bound)
            z = pool[rng.integers(len(pool))].copy()
        else:  # anywhere in the box (analytic models only: cheap)
            z = rng.uniform(lz, uz) if pool is None else pool[rng.integers(len(pool))].copy()
        if kind in (0, 3) and np.all(np.isfinite(z)) and np.all((lz <= z) & (z <= uz)):
            z[rng.integers(d)] = np.nan  # these kinds are meant to be infeasible
        out.append(z)
    return out


def _check_flagged(evaluations) -> None:
    for ev in evaluations:
        assert isinstance(ev.cost, float) and not math.isnan(ev.cost)
        if not (ev.ok and ev.feasible):
            assert ev.cost == FAILURE_COST and ev.message, ev
            assert not ev.usable
        else:
            assert 0.0 <= ev.cost < FAILURE_COST and np.all(np.isfinite(ev.residual))


@pytest.fixture(scope="module")
def fe_objective():
    from problems.inverse.build import build_objective
    from problems.inverse.cases import get_case
    from problems.inverse.data import make_data

    case = get_case("hyperbolic-tension")  # a box where some points are ill-posed materials (check)
    data = make_data(case, tier="consistent", mesh="2,2,4", snapshots=2)
    return build_objective(case, mesh="2,2,4", data=data)


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
def test_fe_evaluator_flags_every_bad_point(fe_objective):
    obj = fe_objective
    rng = np.random.default_rng(SEED)
    lz, uz = obj.lower_z, obj.upper_z
    pool = [np.ones(obj.n_params), lz.copy(), uz.copy()] + [rng.uniform(lz, uz) for _ in range(5)]
    points = _random_vectors(rng, obj.lower, obj.upper, obj.reference, 1200, pool=pool)
    evs = [obj.evaluate(z) for z in points[:600]]  # one at a time ...
    for k in range(600, 1200, 50):  # ... and in batches (one mapper call each)
        evs += obj.evaluate_many(np.array(points[k : k + 50]))
    assert len(evs) == 1200
    _check_flagged(evs)
    # every call is charged (repeats included); the model ran only at the pool points
    assert obj.n_evals == 1200
    assert obj.n_infeasible > 600 and obj.n_evals - obj.n_infeasible - obj.n_repeats <= len(pool)
    assert all(e.feasible for e in evs if e.cached) and obj.best is not None and obj.best.usable
    split = obj.cost_split(np.full(obj.n_params, np.nan))
    assert split["total"] == FAILURE_COST
    assert all(math.isnan(v) for k, v in split.items() if k != "total")


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
@pytest.mark.parametrize(
    "name",
    [
        "analytic-smooth",
        "analytic-multimodal",
        "analytic-rastrigin",
        "analytic-linear",
        "analytic-infeasible",
        "analytic-failing",
    ],
)
def test_analytic_evaluators_flag_every_bad_point(name):
    from problems.inverse.analytic import analytic_objective

    obj = analytic_objective(name)
    rng = np.random.default_rng(SEED)
    points = _random_vectors(rng, obj.lower, obj.upper, obj.reference, 1200)
    evs = obj.evaluate_many(np.array(points))
    _check_flagged(evs)
    costs = obj.costs(np.array(points[:200]))
    assert np.all(np.isfinite(costs)) and np.all(costs <= FAILURE_COST)
    inside = [
        z
        for z in points
        if np.all(np.isfinite(z)) and np.all((obj.lower_z <= z) & (z <= obj.upper_z))
    ]
    for z in inside[:5]:
        J = obj.jacobian(z)
        assert J.shape == (obj.n_residuals, obj.n_params) and np.all(np.isfinite(J))
    cost, grad = obj.gradient(np.full(obj.n_params, np.inf))
    assert cost == FAILURE_COST and np.all(grad == 0)


# --------------------------------------------------------------------------- suite files

VALID_SUITE = {
    "suite": {
        "name": "fz",
        "cases": ["analytic-linear"],
        "methods": ["lm"],
        "budgets": [10],
        "seeds": [0, 1],
        "starts": ["default", "random"],
        "random_starts": 2,
        "mesh": "coarse",
    },
    "data": {"noise_um": 0.5},
    "options": {"lm": {"xtol": 1e-8}},
}

JUNK = [
    0,
    -1,
    1,
    2**70,
    -(2**70),
    1.5,
    float("nan"),
    float("inf"),
    -float("inf"),
    "",
    "x",
    "all",
    "coarse",
    "0,0,0",
    True,
    False,
    [],
    [1, -1],
    ["lm", "lm"],
    ["analytic-linear", 3],
    [[1]],
    {},
    {"a": 1},
    [{"b": 2}],
    "lm",
    "nlopt:NOPE",
    "paper:eighth",
    "2,2,3:eighth",
    [0.5],
    ["random"],
]


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        return ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {_toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(v)


def _toml(doc: dict) -> str:
    lines = []
    for table, body in doc.items():
        if not isinstance(body, dict):
            lines.append(f"{json.dumps(table)} = {_toml_value(body)}")
            continue
        plain = {k: v for k, v in body.items() if not (isinstance(v, dict) and table == "options")}
        lines.append(f"[{json.dumps(table)}]")
        lines += [f"{json.dumps(k)} = {_toml_value(v)}" for k, v in plain.items()]
        for k, v in body.items():
            if isinstance(v, dict) and table == "options":
                lines.append(f"[options.{json.dumps(k)}]")
                lines += [f"{json.dumps(kk)} = {_toml_value(vv)}" for kk, vv in v.items()]
    return "\n".join(lines) + "\n"


def _mutate_suite(rng: random.Random) -> dict:
    doc = json.loads(json.dumps(VALID_SUITE))
    for _ in range(rng.randint(1, 3)):
        table = rng.choice(["suite", "suite", "suite", "data", "options", "extra"])
        if table == "extra":
            doc[rng.choice(["extra", "suite2", "Data"])] = {"k": rng.choice(JUNK)}
            continue
        body = doc.setdefault(table, {})
        if table == "options":
            body = body.setdefault(rng.choice(["lm", "de", "nope"]), {})
            keys = ["xtol", "ftol", "scheme", "max_nfev", "x_scale", "bogus"]
        elif table == "data":
            keys = [
                "noise_um",
                "resolution_um",
                "seed",
                "mesh",
                "tier",
                "snapshots",
                "displacement_mm",
                "route",
                "bogus",
            ]
        else:
            keys = list(VALID_SUITE["suite"]) + ["description", "bogus"]
        key = rng.choice(keys)
        if rng.random() < 0.15:
            body.pop(key, None)
        else:
            body[key] = rng.choice(JUNK)
    return doc


def test_random_suite_files_are_a_suite_or_one_clear_error(tmp_path):
    from bench.experiment.suite import Suite, load_suite

    rng = random.Random(SEED)
    base = _toml(VALID_SUITE)
    path = tmp_path / "s.toml"
    path.write_text(base)
    assert isinstance(load_suite(path), Suite)
    outcomes = {"ok": 0, "error": 0}
    for k in range(400):
        if k % 4 == 0:  # byte-level garbling of a valid file
            text = list(base)
            for _ in range(rng.randint(1, 6)):
                i = rng.randrange(len(text))
                text[i] = rng.choice(['"', "[", "]", "=", "\n", "\x00", "é", "#", ",", "{", "1"])
            text = "".join(text)
            if rng.random() < 0.3:
                text = text[: rng.randint(0, len(base))]
        else:
            text = _toml(_mutate_suite(rng))
        path.write_text(text, encoding="utf-8")
        try:
            suite = load_suite(path)
        except (ValueError, OSError) as exc:
            outcomes["error"] += 1
            assert str(exc).strip()
            continue
        outcomes["ok"] += 1
        assert all(b >= 1 for b in suite.budgets) and all(s >= 0 for s in suite.seeds)
        assert suite.random_starts >= 1
        assert len(suite.runs()) == len(suite) > 0
    assert outcomes["ok"] >= 5 and outcomes["error"] > 100
    (tmp_path / "dir.toml").mkdir()
    for bad in (tmp_path / "dir.toml", tmp_path / "missing.toml"):
        with pytest.raises((ValueError, OSError)):
            load_suite(bad)
    path.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(ValueError):
        load_suite(path)


# --------------------------------------------------------------------------- data files


@pytest.fixture(scope="module")
def data_text():
    from problems.inverse.data import default_path

    path = default_path("linear-compression")
    return path.read_text(encoding="utf-8")


def _rehash(doc: dict) -> dict:
    from problems.inverse.data import _digest

    doc["hash"] = _digest(doc)
    return doc


def test_garbled_and_mutated_data_files_are_loaded_or_rejected_in_one_line(tmp_path, data_text):
    from problems.inverse.data import Dataset, load

    rng = random.Random(SEED)
    good = json.loads(data_text)
    path = tmp_path / "d.json"
    fields = [
        "case",
        "settings",
        "parameters",
        "points",
        "snapshots_mm",
        "u_h",
        "u_v",
        "reaction_kN",
        "std_u_mm",
        "meta",
        "format",
    ]
    values = JUNK + [[[1.0, float("nan")]], [[float("inf")] * 2] * 3, "linear-shear", None]
    accepted = rejected = 0
    for k in range(300):
        if k % 3 == 0:  # byte garbling: truncation, flipped characters, not UTF-8
            raw = bytearray(data_text.encode())
            for _ in range(rng.randint(1, 4)):
                raw[rng.randrange(len(raw))] = rng.randrange(256)
            path.write_bytes(bytes(raw[: rng.randint(0, len(raw))] if rng.random() < 0.3 else raw))
        else:  # structure: wrong types, shapes, non-finite values, settings; hash recomputed
            doc = json.loads(data_text)
            name = rng.choice(fields)
            if name == "settings" and rng.random() < 0.7:
                doc["settings"][rng.choice(list(doc["settings"]) + ["bogus"])] = rng.choice(values)
            elif name in ("u_h", "u_v", "std_u_mm", "points") and rng.random() < 0.6:
                arr = np.array(doc[name], float)
                bad = rng.choice([float("nan"), float("inf"), -1.0, 0.0, 1e300])
                arr.flat[rng.randrange(arr.size)] = bad
                doc[name] = arr.tolist()
            elif rng.random() < 0.1:
                doc.pop(name, None)
            else:
                doc[name] = rng.choice(values)
            path.write_text(json.dumps(_rehash(doc) if rng.random() < 0.9 else doc, allow_nan=True))
        try:
            ds = load(path)
        except (ValueError, OSError) as exc:
            rejected += 1
            assert str(exc).startswith(f"data file {path}") and "\n" not in str(exc), exc
            continue
        accepted += 1
        assert isinstance(ds, Dataset) and np.all(np.isfinite(ds.values))
        assert np.all(ds.std_u_mm > 0) and np.all(np.isfinite(ds.points))
        assert ds.u_h.shape == ds.u_v.shape == (len(ds.snapshots_mm), len(ds.points))
    assert rejected > 150 and accepted >= 1
    path.write_text(json.dumps(_rehash(json.loads(json.dumps(good)))))
    assert load(path).hash == good["hash"]


# --------------------------------------------------------------------------- command line


def _run(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:  # --help / --version only
            code = exc.code
    return code, out.getvalue(), err.getvalue()


def _assert_one_line_error(argv, code, err, *, allow_ok: bool = False):
    assert "Traceback" not in err and "internal error" not in err, (argv, err)
    if allow_ok and code == 0:
        return
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2, (argv, code, err)
    assert len(lines) == 1 and "error:" in lines[0], (argv, err)


def _subparsers():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    return sub.choices


CANDIDATES = [
    "0",
    "-1",
    "-0",
    "1",
    "2",
    "3",
    "1.5",
    "0.5",
    "-0.5",
    "nan",
    "NaN",
    "inf",
    "-inf",
    "1e999",
    "1e-320",
    "abc",
    "",
    " ",
    "99999999999999999999",
    "0x10",
    "1,2",
    "1,,2",
    ",",
    "2,2,3:eighth",
    "bogus:quarter",
    "0,1,1",
    "coarse",
    "tcp://",
    "tcp://host:0",
    "host:99999",
    "/",
    "/nonexistent/file.json",
    "x.unknown",
    "out.png",
]


def test_every_typed_option_rejects_each_value_its_type_rejects(tmp_path):
    """Values are checked when parsed (no command runs): exit 2 and one line naming the option."""
    a_file = tmp_path / "file.txt"
    a_file.write_text("not a folder")
    candidates = CANDIDATES + [str(tmp_path), str(a_file), str(a_file / "below")]
    rng = random.Random(SEED)
    n_checked = 0
    for name, sub in _subparsers().items():
        for action in sub._actions:
            if (
                not action.option_strings
                or action.nargs == 0
                or action.type in (None, str)
                or action.choices
            ):
                continue
            flag = max(action.option_strings, key=len)
            rejected = []
            for value in candidates:
                try:
                    action.type(value)
                except Exception:  # noqa: BLE001 - the type rejects it: so must the command line
                    rejected.append(value)
            for value in rng.sample(rejected, min(len(rejected), 6)):
                argv = [name, f"{flag}={value}"]
                code, _, err = _run(argv)
                _assert_one_line_error(argv, code, err)
                assert f"argument {flag}" in err or f"{flag} " in err or flag in err, (argv, err)
                n_checked += 1
    assert n_checked > 300


#: per command: arguments that make it stop with exit 2 before any computation, whatever else is
#: given
#: (commands not listed whose first positional argument is a case get "no-such-case")
ANCHORS = {
    "cases": [],
    "solvers": [],
    "crosscheck": ["--render"],
    "data": ["no-such-case"],
    "dic": ["/nonexistent/ref.png"],
    "forward": ["no-such-case"],
    "gsa": ["no-such-case"],
    "identifiability": ["no-such-case"],
    "identify": ["no-such-case"],
    "material": ["no-such-case"],
    "model-error": ["no-such-case"],
    "objective": ["no-such-case"],
    "report": ["/nonexistent/results"],
    "run": ["/nonexistent/suite.toml"],
    "sensitivity": ["no-such-case"],
    "surrogate": ["no-such-case"],
    "uncertainty": ["no-such-case"],
}

GARBAGE = [
    "--",
    "-",
    "--x",
    "-x",
    "=",
    "==",
    "--=1",
    "E=",
    "=3",
    "E=nan",
    "p=inf",
    "NAME=VALUE",
    "--no-such-option",
    "\x00",
    "é",
    "' ; rm -rf",
    "{}",
    "[]",
    "all",
    "lm",
    "nlopt:",
    "nlopt:LN_NOPE",
    "coarse",
    "0",
    "-1",
    "nan",
]


def test_random_garbled_command_lines_are_one_line_errors(tmp_path):
    rng = random.Random(SEED)
    empty = tmp_path / "empty"
    empty.mkdir()
    commands = _subparsers()
    values = CANDIDATES + GARBAGE + [str(empty), str(tmp_path / "missing")]
    n = 0
    for name, sub in commands.items():
        positional = [a.dest for a in sub._actions if not a.option_strings]
        by_case = ["no-such-case"] if positional[:1] in (["case"], ["cases"]) else None
        anchor = ANCHORS.get(name, by_case)
        if anchor is None:
            continue  # no known cheap stop: only its typed options are fuzzed (test above)
        flags = [
            max(a.option_strings, key=len)
            for a in sub._actions
            if a.option_strings and not set(a.option_strings) & {"-h", "--help", "--version"}
        ]
        for _ in range(40):
            argv = [name, *anchor]
            for _ in range(rng.randint(0, 6)):
                r = rng.random()
                if r < 0.55 and flags:
                    argv.append(rng.choice(flags))
                    if rng.random() < 0.8:
                        argv.append(rng.choice(values))
                elif r < 0.75:
                    value = rng.choice(values)
                    argv.append(rng.choice(flags) + "=" + value if flags else value)
                else:
                    argv.append(rng.choice(values))
            if name == "crosscheck":
                argv += ["--out", str(empty)]  # last --out wins: an empty folder, nothing to render
            code, _, err = _run(argv)
            _assert_one_line_error(argv, code, err, allow_ok=name in ("cases", "solvers"))
            n += 1
    assert n >= 40 * len(ANCHORS)


def test_top_level_garbage_is_one_line():
    for argv in (
        ["no-such-command"],
        ["--no-such-option"],
        ["cases", "extra"],
        ["identify"],
        ["dic"],
        ["-"],
    ):
        code, _, err = _run(argv)
        _assert_one_line_error(argv, code, err)

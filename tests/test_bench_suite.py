"""Suites: strict validation (the promised errors), expansion and the config hash."""

from __future__ import annotations

import copy
import subprocess
import sys
from pathlib import Path

import pytest

from bench.experiment.spec import DataSpec, RunSpec, Treatment, config_hash
from bench.experiment.suite import load_suite, parse_suite

ROOT = Path(__file__).resolve().parent.parent

GOOD = {
    "suite": {
        "name": "t",
        "cases": ["analytic-smooth", "analytic-linear"],
        "methods": ["lm", "gauss-newton"],
        "seeds": [0, 1],
        "starts": ["default", "random"],
        "random_starts": 2,
        "budgets": [50, 100],
    },
}


def with_(path: str, value, base=GOOD):
    raw = copy.deepcopy(base)
    *head, last = path.split(".")
    d = raw
    for k in head:
        d = d.setdefault(k, {})
    if value is _DELETE:
        d.pop(last)
    else:
        d[last] = value
    return raw


_DELETE = object()


def test_expansion_counts_and_order():
    s = parse_suite(GOOD)
    runs = s.runs()
    # 2 cases x 2 methods x 2 budgets x (2 seeds x 2 random + 1 default: lm and Gauss-Newton are
    # deterministic, so the default start runs under the first seed only)
    assert len(runs) == len(s) == 2 * 2 * 2 * (2 * 2 + 1)
    assert len({config_hash(r) for r in runs}) == len(runs)
    assert runs[0] == RunSpec("analytic-smooth", "lm", 0, "default", 0, 50, "coarse")
    assert [(r.start, r.start_index) for r in runs[:3]] == [
        ("default", 0),
        ("random", 0),
        ("random", 1),
    ]
    assert s.total_budget == sum(r.budget for r in runs)
    stochastic = parse_suite(with_("suite.methods", ["ga"]))
    assert len(stochastic) == 2 * 2 * 2 * 3  # ga: every seed from the default start too


def test_all_cases_means_the_nine_fe_cases():
    from problems.inverse.cases import CASES

    s = parse_suite(with_("suite.cases", "all"))
    assert s.cases == tuple(CASES) and len(s.cases) == 9


def test_options_are_attached_to_their_method_only():
    from solvers import METHODS

    name, opt = next(iter(METHODS["lm"].options.items()))
    default = opt.default
    value = (
        default
        if not isinstance(default, (int, float)) or isinstance(default, bool)
        else default * 2
    )
    s = parse_suite(with_(f"options.lm.{name}", value))
    lm = [r for r in s.runs() if r.method == "lm"]
    gn = [r for r in s.runs() if r.method == "gauss-newton"]
    assert all(r.options == {name: value} for r in lm) and all(r.options == {} for r in gn)
    assert config_hash(lm[0]) != config_hash(parse_suite(GOOD).runs()[0])


def test_config_hash_is_canonical_and_stable():
    a = RunSpec(
        "analytic-smooth",
        "lm",
        0,
        "default",
        0,
        100,
        "coarse",
        {"y": 1, "x": "s"},
        DataSpec(settings={"b": 1, "a": 2.0}),
    )
    b = RunSpec(
        "analytic-smooth",
        "lm",
        0,
        "default",
        0,
        100,
        "coarse",
        {"x": "s", "y": 1},
        DataSpec(settings={"a": 2.0, "b": 1}),
    )
    assert config_hash(a) == config_hash(b)
    assert config_hash(a) != config_hash(RunSpec.from_dict({**a.to_dict(), "seed": 1}))
    assert RunSpec.from_dict(a.to_dict()) == a
    # changing this value orphans every stored record: bump CONFIG_SCHEMA deliberately if needed
    assert (
        config_hash(RunSpec("linear-compression", "lm", 0, "default", 0, 200, "coarse"))
        == "eed14cf8837e99bd0b695de64ff8df2cc2e0df32c4069d7586a377ab23af057b"
    )


@pytest.mark.parametrize(
    "raw, needles",
    [
        (
            with_("suite.seed", [0]),
            ["[suite] unknown key 'seed'", "did you mean 'seeds'", "allowed: name"],
        ),
        (
            with_("suite.cases", ["linear-compresion"]),
            ["case 'linear-compresion' is unknown", "linear-compression"],
        ),
        (with_("suite.cases", []), ["cases must be"]),
        (
            with_("suite.methods", ["lm", "levenberg"]),
            ["method 'levenberg' is unknown", "allowed:", "gauss-newton"],
        ),
        (with_("suite.methods", ["nlopt:NOSUCH"]), ["method 'nlopt:NOSUCH' is unknown"]),
        (with_("suite.budgets", [0]), ["budgets must be positive integers", "0"]),
        (with_("suite.budgets", [-5, 10]), ["budgets must be positive integers", "-5"]),
        (with_("suite.budgets", []), ["budgets must be a non-empty list"]),
        (with_("suite.budgets", _DELETE), ["missing key 'budgets'"]),
        (with_("suite.seeds", [0.5]), ["seeds must be integers >= 0", "0.5"]),
        (with_("suite.seeds", ["1"]), ["seeds must be integers >= 0"]),
        (with_("suite.seeds", [True]), ["seeds must be integers >= 0"]),
        (with_("suite.seeds", [1, 1]), ["seeds lists 1 more than once"]),
        (
            with_("suite.starts", ["default", "randon"]),
            ["'randon' is not a start kind", "default, random"],
        ),
        (with_("suite.random_starts", 0), ["random_starts must be an integer >= 1"]),
        (with_("suite.mesh", "huge"), ["mesh 'huge' is unknown", "coarse"]),
        (
            with_("results.x", 1),
            ["unknown top-level table [results]", "[suite], [[part]], [data], [options]"],
        ),
        (with_("data.noize_um", 1.0), ["[data] unknown key 'noize_um'", "allowed:"]),
        (with_("data.noise_um", -1.0), ["[data] noise_um = -1.0 is out of range"]),
        (with_("data.route", "laser"), ["[data] route = 'laser' is unknown", "fe, dic"]),
        (with_("data.seed", 1.5), ["[data] seed must be of type int"]),
        (
            with_("options.pso.w", 0.5),
            ["[options.pso] is for method 'pso', which the suite does not run"],
        ),
        (
            with_("options.lm.no_such_option", 1),
            ["[options.lm] unknown option 'no_such_option'", "allowed:"],
        ),
        ({"suite": {"cases": "all"}}, ["missing key 'methods'", "missing key 'budgets'"]),
    ],
)
def test_invalid_suites_are_rejected_with_the_key_and_what_is_allowed(raw, needles):
    with pytest.raises(ValueError) as info:
        parse_suite(raw)
    msg = str(info.value)
    for needle in needles:
        assert needle in msg, f"{needle!r} not in:\n{msg}"


def test_data_settings_are_attached_to_every_run():
    s = parse_suite(with_("data.noise_um", 2, with_("data.seed", 3)))
    assert all(r.data.settings == {"noise_um": 2.0, "seed": 3} for r in s.runs())
    # an int where a float is expected
    assert isinstance(s.runs()[0].data.settings["noise_um"], float)


def test_all_errors_are_reported_at_once():
    raw = with_("suite.budgets", [0], with_("suite.seeds", [-1], with_("suite.colour", "red")))
    msg = str(pytest.raises(ValueError, parse_suite, raw).value)
    assert "budgets" in msg and "seeds" in msg and "colour" in msg


def test_option_values_are_type_checked():
    from solvers import METHODS

    name = next(
        k
        for k, v in METHODS["lm"].options.items()
        if v.type in ("int", "float") and isinstance(v.default, (int, float))
    )
    with pytest.raises(ValueError, match=rf"\[options.lm\] {name} must be like its default"):
        parse_suite(with_(f"options.lm.{name}", "fast"))


def test_cli_rejects_an_invalid_suite_before_running_anything(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(
        '[suite]\ncases = ["analytic-smooth"]\nmethods = ["lm"]\nbudgets = [0]\nstart = '
        '["default"]\n'
    )
    out = tmp_path / "out"
    p = subprocess.run(
        [sys.executable, "-m", "bench", "run", str(bad), "--out", str(out), "--workers", "1"],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert p.returncode == 2
    assert "femubench run: error:" in p.stderr and "budgets must be positive integers" in p.stderr
    assert "unknown key 'start'" in p.stderr and "did you mean 'starts'" in p.stderr
    assert not out.exists()  # nothing ran, nothing written


def test_not_toml_and_missing_file(tmp_path):
    p = tmp_path / "x.toml"
    p.write_text("[suite\n")
    with pytest.raises(ValueError, match="not valid TOML"):
        load_suite(p)
    with pytest.raises(FileNotFoundError):
        load_suite(tmp_path / "missing.toml")


@pytest.mark.parametrize("name", ["default", "paper", "smoke"])
def test_shipped_suites_are_valid(name):
    s = load_suite(ROOT / "suites" / f"{name}.toml")
    assert s.name == name and len(s.runs()) == len(s) > 0


def test_the_table1_suite_runs_lm_on_the_model_error_default_with_three_treatments():
    from problems.inverse.build import hifi_mesh_for
    from problems.inverse.cases import CASES
    from problems.inverse.data import MODEL_ERROR_INVERSE_MESH

    runs = load_suite(ROOT / "suites" / "table1.toml").runs()
    assert len(runs) == 9 * 3 and {r.case for r in runs} == set(CASES)
    assert {(r.method, r.data.tier, r.mesh, r.start) for r in runs} == {
        ("lm", "model-error", MODEL_ERROR_INVERSE_MESH, "default")
    }
    assert {r.treatment.name for r in runs} == {"none", "one-point", "iterated"}
    assert hifi_mesh_for(MODEL_ERROR_INVERSE_MESH) == "9,9,18:g8:hex27"


def test_default_and_paper_suites_have_the_documented_shape():
    from problems.inverse.cases import CASES
    from problems.inverse.data import MODEL_ERROR_INVERSE_MESH

    d = load_suite(ROOT / "suites" / "default.toml")
    mission = {"lm", "gauss-newton", "ga", "pso", "sa", "mcmc", "cma"}
    assert set(d.cases) == set(CASES) and set(d.methods) == mission
    assert d.starts == ("default",) and d.mesh == "coarse"
    runs = d.runs()
    # the local methods on FE: consistent data on coarse (9 x 2); model-error data on the tier's
    # default inverse model, untreated (9 x 2) and LM with the one-point correction (9)
    local = [r for r in runs if r.method in ("lm", "gauss-newton")]
    assert len(local) == 45 and {
        (r.data.tier, r.treatment.name, r.track, r.mesh, r.method) for r in local
    } == {
        ("consistent", "none", "fe", "coarse", "lm"),
        ("consistent", "none", "fe", "coarse", "gauss-newton"),
        ("model-error", "none", "fe", MODEL_ERROR_INVERSE_MESH, "lm"),
        ("model-error", "none", "fe", MODEL_ERROR_INVERSE_MESH, "gauss-newton"),
        ("model-error", "one-point", "fe", MODEL_ERROR_INVERSE_MESH, "lm"),
    }
    # the global and sampling methods on the surrogate, consistent tier, with an FE polish: 9 x 5
    rest = [r for r in runs if r not in local]
    assert len(rest) == 45
    assert {(r.data.tier, r.track) for r in rest} == {("consistent", "surrogate")}
    assert all(r.polish_budget > 0 for r in rest)
    p = load_suite(ROOT / "suites" / "paper.toml")
    assert (
        set(p.cases) == set(CASES)
        and len(p.budgets) == 1
        and "random" in p.starts
        and len(p.seeds) > 1
    )
    for m in ("lm", "gauss-newton", "ga", "pso", "sa", "mcmc"):
        assert m in p.methods
    assert sum(m.startswith("nlopt:") for m in p.methods) >= 5


def test_tiers_and_treatments_span_the_suite_without_correcting_consistent_data():
    raw = {
        "suite": {
            "cases": ["linear-compression"],
            "methods": ["lm"],
            "budgets": [50],
            "tiers": ["consistent", "model-error"],
            "treatments": ["none", "iterated"],
            "plate_margin_mm": 15.0,
        }
    }
    s = parse_suite(raw)
    combos = sorted((r.data.tier, r.treatment.name) for r in s.runs())
    assert combos == [("consistent", "none"), ("model-error", "iterated"), ("model-error", "none")]
    assert all(r.treatment.plate_margin_mm == 15.0 for r in s.runs()) and len(s) == 3
    with pytest.raises(ValueError, match="treatments: 'twice' unknown"):
        parse_suite({"suite": {**raw["suite"], "treatments": ["twice"]}})
    with pytest.raises(ValueError, match="plate_margin_mm = 80"):
        parse_suite({"suite": {**raw["suite"], "plate_margin_mm": 80}})


def test_runs_of_different_tiers_never_share_a_data_set():
    from bench.experiment.runner import data_key, dataset_for

    s = parse_suite(
        {
            "suite": {
                "cases": ["linear-compression"],
                "methods": ["lm"],
                "budgets": [50],
                "tiers": ["consistent", "model-error"],
            }
        }
    )
    a, b = s.runs()
    assert data_key(a) != data_key(b)
    assert {dataset_for(r).settings.tier for r in (a, b)} == {"consistent", "model-error"}


# --- parts, tracks, Jacobians -------------------------------------------------------------


# an FE case: the surrogate track is for FE cases only (an analytic one is refused)
PARTS = {
    "suite": {"name": "p", "cases": ["linear-shear"], "budgets": [40], "seeds": [0]},
    "part": [
        {"methods": ["lm", "ga"], "jacobians": ["exact", "forward"]},
        {"methods": ["ga", "pso"], "tracks": ["surrogate"], "seeds": [0, 1], "polish_budget": 7},
    ],
}


def test_parts_are_a_union_of_products_over_the_shared_suite_table():
    s = parse_suite(PARTS)
    labels = sorted(r.label for r in s.runs())
    # part 1: lm x {exact, forward} + ga exact only (ga uses no Jacobian);
    # part 2: 2 methods x 2 seeds
    assert len(labels) == 3 + 4
    assert sum("/jac-forward" in lab for lab in labels) == 1
    assert sum(lab.endswith("/surrogate") for lab in labels) == 4
    assert s.methods == ("lm", "ga", "pso") and s.seeds == (0, 1)
    surrogate = [r for r in s.runs() if r.track == "surrogate"]
    assert {r.polish_budget for r in surrogate} == {7}
    assert {r.polish_budget for r in s.runs() if r.track == "fe"} == {0}
    assert s.total_budget == 7 * 40 + 4 * 7


def test_a_part_names_its_own_mesh_validated_like_the_suite_table():
    raw = copy.deepcopy(PARTS)
    raw["part"][0]["mesh"] = "6,6,12:g8:hex27"
    s = parse_suite(raw)
    assert {r.mesh for r in s.runs() if r.track == "fe"} == {"6,6,12:g8:hex27"}
    assert {r.mesh for r in s.runs() if r.track == "surrogate"} == {"coarse"}  # the suite's
    raw["part"][1]["mesh"] = "6,6,12:g0.5"
    with pytest.raises(ValueError) as info:
        parse_suite(raw)
    assert "[[part]] 2: mesh '6,6,12:g0.5': grading 'g0.5' is out of range" in str(info.value)


def test_a_bad_key_in_a_part_names_the_part():
    raw = copy.deepcopy(PARTS)
    raw["part"][1]["trakcs"] = ["fe"]
    raw["part"][0]["jacobians"] = ["exact", "complex-step"]
    with pytest.raises(ValueError) as info:
        parse_suite(raw)
    msg = str(info.value)
    assert "[[part]] 2: unknown key 'trakcs' (did you mean 'tracks'?)" in msg
    assert "[[part]] 1: jacobians: 'complex-step' unknown; allowed: exact, forward, central" in msg


def test_later_keys_keep_the_hash_of_earlier_records_when_default():
    fe = RunSpec("analytic-smooth", "lm", 0, "default", 0, 50, "coarse")
    assert "track" not in fe.to_dict() and "jacobian" not in fe.to_dict()
    sur = RunSpec("linear-shear", "cma", surrogate="default", polish_budget=9)
    assert sur.to_dict()["track"] == "surrogate" and "surrogate" not in sur.to_dict()
    assert sur.hash != RunSpec("linear-shear", "cma").hash
    assert RunSpec.from_dict(sur.to_dict()) == sur
    # the keys only ``identify`` sets: in the record (and the hash) only when not default
    named = RunSpec(
        "linear-shear",
        "lm",
        data=DataSpec(file="d.json"),
        treatment=Treatment("bae", 5.0, hifi_mesh="fine", bae_samples=8, bae_seed=1),
        surrogate="mine",
    )
    d = named.to_dict()
    assert (d["data_file"], d["hifi_mesh"], d["bae_samples"], d["bae_seed"]) == (
        "d.json",
        "fine",
        8,
        1,
    )
    assert d["surrogate"] == "mine" and RunSpec.from_dict(d) == named


def test_a_spec_refuses_what_cannot_run():
    with pytest.raises(ValueError, match="polish_budget > 0"):
        RunSpec("linear-shear", "lm", polish_budget=5)
    with pytest.raises(ValueError, match="start = 'middle' is unknown"):
        RunSpec("linear-shear", "lm", start="middle")
    with pytest.raises(ValueError, match="treatment = 'twice' is unknown"):
        Treatment("twice")

"""`femubench identify` shows the exponent cases' derived a with its error, as Table 1 does."""

import json

import pytest

from bench.cli import main
from problems.inverse.cases import CASES
from problems.materials.hardening import reference_test


def _a(case, x) -> float:
    """a = (pt0 + p_hat sigma0) / (q_hat sigma0)^b, written out independently of the case."""
    v = dict(zip(case.names, x))
    t = reference_test(case.hardening)
    return (v["pt0"] + t.p_hat * v["sigma0"]) / (t.q_hat * v["sigma0"]) ** v["b"]


def test_identify_prints_and_writes_the_derived_a_with_its_error(tmp_path, capsys):
    from problems.inverse.data import make_data, save

    case = CASES["exponent-compression"]
    data = save(make_data(case.name, mesh="2,2,4", snapshots=2), tmp_path / "me.json")
    out = tmp_path / "run.json"
    argv = ["identify", case.name, "--solver", "lm", "--mesh", "1,1,2", "--data", str(data),
            "--budget", "3", "--quiet", "--json", str(out)]  # fmt: skip
    assert main(argv) == 0
    doc = json.loads(out.read_text())
    a_ref, a_found = _a(case, doc["reference"]), _a(case, doc["x"])
    d = doc["derived"]["a"]
    assert d["reference"] == pytest.approx(a_ref, rel=1e-12)
    assert d["found"] == pytest.approx(a_found, rel=1e-12)
    assert d["start"] == pytest.approx(_a(case, doc["x0"]), rel=1e-12)
    assert d["error_percent"] == pytest.approx(100 * (a_found / a_ref - 1), rel=1e-9)
    assert abs(d["error_percent"]) > 0.1  # three evaluations from the start: not at the reference
    row = next(
        line.split()
        for line in capsys.readouterr().out.splitlines()
        if line.split()[:2] == ["a", "derived"]
    )
    assert float(row[-1]) == pytest.approx(d["error_percent"], abs=1e-3)
    assert float(row[2]) == pytest.approx(a_ref, rel=1e-5)
    assert "a" not in doc["errors_percent"]  # the identified parameters' errors stay apart


def test_a_case_without_a_derivation_has_none():
    from types import SimpleNamespace

    from bench.commands.identify import derived_errors

    case = CASES["linear-shear"]
    assert derived_errors(case, SimpleNamespace(reference=case.reference)) == {}
    exp = CASES["exponent-shear"]
    x = exp.reference * 1.1
    res = SimpleNamespace(reference=exp.reference, x0=exp.start, x=x)
    d = derived_errors(exp, res)["a"]
    assert d["error_percent"] == pytest.approx(100 * (_a(exp, x) / _a(exp, exp.reference) - 1))


def test_the_inverse_mesh_defaults_to_the_data_tier_s_model(tmp_path):
    from argparse import Namespace

    from bench.commands.identify import default_mesh
    from problems.inverse.data import MODEL_ERROR_INVERSE_MESH, make_data, save

    def args(**kw):
        base = dict(case="linear-shear", tier="model-error", data=None, surrogate=None)
        return Namespace(**(base | {"correction": "none"} | kw))

    assert default_mesh(args()) == MODEL_ERROR_INVERSE_MESH != "coarse"
    assert default_mesh(args(correction="iterated")) == MODEL_ERROR_INVERSE_MESH
    assert default_mesh(args(tier="consistent")) == "coarse"
    assert default_mesh(args(surrogate="default")) == "coarse"  # the surrogates' mesh
    assert default_mesh(args(correction="default")) == "coarse"  # the default BAE's mesh
    consistent = save(make_data("linear-shear", tier="consistent", mesh="1,1,2", snapshots=2),
                      tmp_path / "c.json")  # fmt: skip
    assert default_mesh(args(data=str(consistent))) == "coarse"  # the file's tier decides

"""A suite part's ``hifi_mesh``: the high-fidelity mesh of its correction treatments
(bench/experiment/suite.py), its refusals, its run identity and where it reaches."""

from __future__ import annotations

from pathlib import Path

import pytest

from bench.cli import main
from bench.experiment.spec import RunSpec
from bench.experiment.suite import load_suite, parse_suite

ROOT = Path(__file__).resolve().parents[1]
HIFI = "9,9,18:g16:gz8:hex27"
BASE = {
    "cases": ["exponent-shear"],
    "methods": ["lm"],
    "budgets": [200],
    "mesh": "6,6,12:g8:hex27",
    "treatments": ["none", "one-point", "iterated", "first-order", "bae"],
}


def _runs(**suite) -> dict[str, RunSpec]:
    """Treatment name -> the run of a suite of BASE with ``suite`` over it."""
    return {r.treatment.name: r for r in parse_suite({"suite": BASE | suite}).runs()}


def test_the_key_reaches_the_corrections_only_and_their_hash_only_when_given():
    plain, named = _runs(), _runs(hifi_mesh=HIFI)
    assert parse_suite({"suite": BASE | {"hifi_mesh": HIFI}}).parts[0].hifi_mesh == HIFI
    assert named["none"].treatment.hifi_mesh is None
    assert named["none"].hash == plain["none"].hash  # none runs unchanged
    for t in ("one-point", "iterated", "first-order", "bae"):
        assert named[t].treatment.hifi_mesh == HIFI and plain[t].treatment.hifi_mesh is None
        assert named[t].hash != plain[t].hash and named[t].to_dict()["hifi_mesh"] == HIFI
        # without the key: the run of before the key existed (no hifi_mesh in its record)
        assert "hifi_mesh" not in plain[t].to_dict()
    # a [[part]] may name it for itself; the [suite] value is its default
    suite = parse_suite(
        {"suite": BASE | {"treatments": ["iterated"]}, "part": [{}, {"hifi_mesh": HIFI}]}
    )
    assert [r.treatment.hifi_mesh for r in suite.runs()] == [None, HIFI]


def _refused(tmp_path, capsys, text: str) -> str:
    """``femubench run --dry-run`` of a suite of BASE plus ``text``: exit 2, nothing written,
    and the one error line of the suite; return it."""
    path = tmp_path / "s.toml"
    body = "\n".join(f"{k} = {v!r}".replace("'", '"') for k, v in BASE.items() if k != "treatments")
    path.write_text(f"[suite]\n{body}\n{text}\n")
    code = main(["run", str(path), "--out", str(tmp_path / "out"), "--dry-run"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2, err
    assert not (tmp_path / "out").exists()
    assert err[0].endswith("invalid suite:") and len(err) == 2, err  # the suite's error style
    return err[1].strip()


@pytest.mark.parametrize(
    "value, needles",
    [
        ("9,9,x", ["[suite] hifi_mesh: mesh '9,9,x' is unknown; allowed: coarse"]),
        # the model-error data's discretisation in any spelling: the honesty rule's one check
        ("converged:quarter", ["hifi_mesh = 'converged:quarter'", "15,15,30:g16:hex27",
                               "made the model-error data"]),
        ("6,6,12:g8:hex27", ["hifi_mesh = '6,6,12:g8:hex27' (6,6,12 elements) is not finer "
                             "than the inverse mesh '6,6,12:g8:hex27'", "allowed: a mesh"]),
    ],
)  # fmt: skip
def test_a_bad_hifi_mesh_is_one_line_and_exit_2(tmp_path, capsys, value, needles):
    line = _refused(tmp_path, capsys, f'treatments = ["iterated"]\nhifi_mesh = "{value}"')
    for needle in needles:
        assert needle in line, line


def test_the_data_mesh_of_the_data_table_is_refused_too(tmp_path, capsys):
    line = _refused(
        tmp_path,
        capsys,
        'treatments = ["one-point"]\nhifi_mesh = "8,8,16:g8:hex27"\n'
        '[data]\nmesh = "8,8,16:g8:hex27:quarter"',
    )
    assert "hifi_mesh = '8,8,16:g8:hex27': the hifi model uses discretisation 8,8,16" in line


@pytest.mark.parametrize(
    "treatments, needle",
    [
        ('["iterated", "default"]', 'treatments lists "default", which sets its own'),
        ('["none"]', "applies to no run"),
    ],
)
def test_hifi_mesh_with_default_or_without_a_correction_is_refused(
    tmp_path, capsys, treatments, needle
):
    line = _refused(tmp_path, capsys, f'treatments = {treatments}\nhifi_mesh = "{HIFI}"')
    assert line.startswith(f"- [suite] hifi_mesh = '{HIFI}'") and needle in line, line


def test_the_shipped_suite_runs_the_first_order_correction_on_the_named_mesh():
    """suites/table1-first-order.toml: two runs whose assembled objective's correction models
    are the named high-fidelity mesh and the inverse mesh (no FE run)."""
    from bench.experiment.objective import prepare
    from bench.experiment.store import method_label

    named = "11,11,22:g8:hex27"
    runs = load_suite(ROOT / "suites" / "table1-first-order.toml").runs()
    assert [(r.case, r.method, r.budget, r.start, r.mesh, r.data.tier) for r in runs] == [
        (c, "lm", 200, "default", "6,6,12:g8:hex27", "model-error")
        for c in ("exponent-shear", "exponent-tension")
    ]
    assert {(r.treatment.name, r.treatment.hifi_mesh) for r in runs} == {("first-order", named)}
    asm = prepare(runs[0])
    hifi, inverse = asm.models()
    assert (asm.hifi_mesh, hifi.mesh, inverse.mesh) == (named, named, "6,6,12:g8:hex27")
    assert method_label(runs[0].to_dict()) == f"lm (model-error, first-order on {named})"
    assert method_label(_runs()["iterated"].to_dict()) == "lm (model-error, iterated)"


def test_the_note_quotes_no_study_rows_of_another_high_fidelity_mesh(tmp_path):
    """The model-error study's rows made with the default high-fidelity mesh are not this
    correction's: the case is left to the convergence study."""
    import json

    from bench.report import model_error_note as N

    d = tmp_path / "model_error" / "exponent-shear"
    d.mkdir(parents=True)
    prov = {"hifi_mesh": "9,9,18:g8:hex27", "inverse_mesh": "6,6,12:g8:hex27"}
    row = {"linearised_bias_percent": {"pt0": 0.59}, "provenance": prov}
    (d / "6,6,12:g8:hex27__hifi-at-reference__margin0__fe__bias.json").write_text(json.dumps(row))
    s = N.Setting("iterated", "iterated", "6,6,12:g8:hex27", 0.0, HIFI)
    assert N.load_study([tmp_path / "model_error"], {"exponent-shear": s}) == {}
    default = s._replace(hifi_mesh="9,9,18:g8:hex27")
    got = N.load_study([tmp_path / "model_error"], {"exponent-shear": default})
    assert got["exponent-shear"]["floor"] == ("pt0", 0.59)


@pytest.mark.parametrize(
    "value",
    [
        "converged",
        "converged:eighth",
        "15,15,30:g16:hex27:eighth",
        "15,15,30:g16:gz16:hex27",  # gz equal to g: the same mesh
        " 15, 15,30:gz16.0:g16:hex27:quarter ",
    ],
)
def test_no_spelling_of_the_data_mesh_passes_as_hifi_mesh(value):
    """The honesty rule compares discretisations, not strings: every spelling of the model-error
    data mesh 15,15,30:g16:hex27 is refused (a [[part]] too), and a grading that differs is not."""
    with pytest.raises(ValueError, match="which made the model-error data") as info:
        parse_suite({"suite": BASE | {"treatments": ["iterated"], "hifi_mesh": value}})
    assert "hifi model uses discretisation 15,15,30:g16:hex27," in str(info.value)
    with pytest.raises(ValueError, match=r"\[\[part\]\] 2: hifi_mesh = .*made the model-error"):
        parse_suite(
            {"suite": BASE | {"treatments": ["iterated"]}, "part": [{}, {"hifi_mesh": value}]}
        )
    other = "15,15,30:g16:gz8:hex27"
    suite = parse_suite({"suite": BASE | {"treatments": ["iterated"], "hifi_mesh": other}})
    assert [r.treatment.hifi_mesh for r in suite.runs()] == [other]

"""The note under a model-error Table 1: cases within the tolerance, the worst parameter of each
miss, and the model-error study's bias and floor when the study is found (its absence said)."""

from __future__ import annotations

import json

from bench.experiment import store
from bench.experiment.runner import make_record
from bench.experiment.spec import RunSpec, Treatment
from bench.report import metrics as M
from bench.report import model_error_note as N
from bench.report import tables as T
from bench.report import write_report
from problems.inverse.cases import get_case
from tests.test_report_metrics import frame, run_row

LIN = "linear-compression"
OK = "linear-shear"
LABEL = "lm (model-error, default bae 30 mm)"
FLOOR_FILE = "coarse__hifi-at-reference__margin30__fe__bias.json"
OWN_FILE = "coarse__bae__margin30__fe.json"


def _table():
    """LIN misses (beta 3.1 %, H 1.5 %), OK is within 2 % on every parameter."""
    rows = [
        run_row(c, e, method=LABEL, tier="model-error", treatment="default", budget=200)
        for c, e in ((LIN, {"beta": 3.1, "H": 1.5}), (OK, {"E": 0.5, "sigma0": -1.9}))
    ]
    runs, _ = M.prepare(frame(rows))
    return runs, T.table1(runs, LABEL)


def _study_row(case, treatment, biases, data_hash="d" * 64):
    return {
        "case": case,
        "treatment": treatment,
        "linearised_bias_percent": biases,
        "max_abs_error_percent": "nan",
        "provenance": {"data_hash": data_hash, "hifi_mesh": "paper", "inverse_mesh": "coarse"},
    }


def _write_study(root, case=LIN, data_hash="d" * 64):
    d = root / case
    d.mkdir(parents=True)
    floor = _study_row(case, "hifi-at-reference", {"H": -4.18, "beta": -3.87}, data_hash)
    own = _study_row(case, "bae", {"H": -0.71, "beta": 3.07}, data_hash)
    (d / FLOOR_FILE).write_text(json.dumps(floor))
    (d / OWN_FILE).write_text(json.dumps(own))
    return root


def test_note_counts_cases_names_the_miss_and_quotes_the_study_floor(tmp_path):
    runs, t = _table()
    settings = N.run_settings(runs)
    assert settings[LIN] == N.Setting("default", "bae", "coarse", 30.0, "paper", None)
    study = N.load_study([_write_study(tmp_path / "model_error")], settings)
    assert study[LIN]["floor"] == ("H", 4.18) and OK not in study
    note = N.model_error_note(t, settings, study, tol=2.0, doc="../docs/objective.md")
    assert "treatment `default bae 30 mm`" in note
    assert "**1 of 2 cases**" in note
    assert f"- {LIN}: beta 3.1 % (bias 3.07 %; floor 4.18 % on H)" in note
    assert f"- {OK}" not in note
    assert "within 0.03 points" in note and "biases of the objective" in note
    assert "The floor is above 2 % on 1 of these 1 case" in note
    assert "BAE" in note and "ends below the floor on 1 of them" in note
    assert "(../docs/objective.md#where-the-2--target-is-not-reached" in note
    # the report's own tolerance: at 4 % both cases meet it and there is nothing to explain
    loose = N.model_error_note(t, settings, study, tol=4.0)
    assert "**2 of 2 cases**" in loose and "floor" not in loose


def test_note_without_the_study_still_names_the_miss(tmp_path):
    runs, t = _table()
    settings = N.run_settings(runs)
    assert N.load_study([tmp_path / "absent"], settings) is None
    note = N.model_error_note(t, settings, None)
    assert "**1 of 2 cases**" in note and f"- {LIN}: beta 3.1 %" in note
    assert "was not found" in note and "floor 4.18" not in note


def test_study_made_with_other_data_is_not_quoted(tmp_path):
    runs, t = _table()
    runs["data_hash"] = "e" * 64
    settings = N.run_settings(runs)
    study = N.load_study([_write_study(tmp_path / "model_error")], settings)
    assert study[LIN]["stale"] and study[LIN]["floor"] is None
    note = N.model_error_note(t, settings, study)
    assert "made with other data" in note and "4.18" not in note


def _record(case, errors):
    from solvers.result import RunResult

    c = get_case(case)
    ref = list(map(float, c.reference))
    xn = [1.0 + errors.get(n, 0.0) / 100.0 for n in c.names]
    res = RunResult(
        method="lm",
        options={},
        seed=0,
        budget=200,
        parameter_names=list(c.names),
        reference=ref,
        x0=ref,
        x=[r * v for r, v in zip(ref, xn)],
        x_normalised=xn,
        cost=1.0,
        status="converged",
        success=True,
        message="",
        n_evals=10,
        n_iterations=5,
        wall_s=0.1,
        forward_equivalents=12.0,
        history=[],
        provenance={"treatment": "bae", "region_plate_margin_mm": 30.0, "hifi_mesh": "paper"},
    )
    conf = RunSpec(case, "lm", 0, "default", 0, 200, "coarse", treatment=Treatment("default"))
    return make_record(conf, res, suite="me", data_hash="d" * 64, started="t0", finished="t1")


def test_report_puts_the_note_under_the_model_error_table1(tmp_path):
    suite = tmp_path / "results" / "me"
    for case, e in ((LIN, {"beta": 3.1}), (OK, {"E": 0.5})):
        store.write_record(suite, _record(case, e))
    text = write_report(suite, ["md"], figures=False, posterior_dirs=[]).read_text()
    assert "study (`results/studies/model_error`) was not found" in text
    # the results root's study, found like the posterior study's (DIR/../studies/...)
    _write_study(tmp_path / "results" / "studies" / "model_error")
    text = write_report(suite, ["md"], figures=False, posterior_dirs=[]).read_text()
    table = text.split(f"### {LABEL}\n", 1)[1]
    note = table.split("\n**Model-error tier", 1)[1].split("Files:", 1)[0]
    assert "**1 of 2 cases**" in note
    assert f"- {LIN}: beta 3.1 % (bias 3.07 %; floor 4.18 % on H)" in note


def _write_convergence(root, case=LIN):
    """A fake ``<case>/convergence.json`` of the hex27 convergence study: the inverse mesh
    ``6,6,12:g8:hex27`` and the high-fidelity mesh ``9,9,18:g8:hex27``."""
    d = root / case
    d.mkdir(parents=True)
    meshes = [
        {"mesh": "6,6,12:g8:hex27", "data_bias_pct": {"H": 1.2, "beta": 3.04}},
        {"mesh": "9,9,18:g8:hex27", "data_bias_pct": {"H": -0.61, "beta": 0.25}},
        {"mesh": "12,12,24:g8:hex27"},  # the data mesh: no bias
    ]
    conv = {"case": case, "data_mesh": "12,12,24:g8:hex27", "meshes": meshes}
    (d / "convergence.json").write_text(json.dumps(conv))
    return root


def test_note_takes_bias_and_floor_from_the_convergence_study_for_other_meshes(tmp_path):
    runs, t = _table()
    studies = tmp_path / "studies"
    _write_study(studies / "model_error")  # rows for `coarse` only
    written = _write_convergence(studies / "convergence" / "hex27-g8")
    # a study's own report (studies/<study>) finds its sibling studies/model_error
    assert N.default_model_error_dirs(studies / "table1") == [studies / "model_error"]
    conv = N.convergence_dirs([studies / "model_error"])
    assert conv == [written]
    hex27 = {"mesh": "6,6,12:g8:hex27", "hifi_mesh": "9,9,18:g8:hex27"}
    for treatment, floor in (("one-point", ("H", 0.61)), ("none", None)):
        s = N.run_settings(runs)[LIN]._replace(treatment=treatment, margin=0.0, **hex27)
        if treatment == "none":
            s = s._replace(hifi_mesh="")
        settings = {LIN: s}
        assert N.load_study([studies / "model_error"], settings) == {}
        study = N.load_convergence(conv, settings)
        assert study[LIN]["bias"] == ({"H": 1.2, "beta": 3.04} if floor is None else {})
        assert study[LIN]["floor"] == floor
        note = N.model_error_note(t, settings, study, tol=2.0, convergence_name="CONV")
        assert "from the hex27 convergence study (CONV;" in note
        assert "mesh `12,12,24:g8:hex27`" in note and "not in the study" not in note
        if treatment == "none":
            assert f"- {LIN}: beta 3.1 % (bias 3.04 %)" in note
            assert "within 0.06 points" in note
            assert "floor" not in note and "high-fidelity" not in note
        else:  # a correction: the floor only (the study has no bias of the treated objective)
            assert f"- {LIN}: beta 3.1 % (floor 0.61 % on H)" in note and "bias 3" not in note
            assert "high-fidelity model `9,9,18:g8:hex27`" in note
            assert "The floor is within 2 % on all 1 case (0.61–0.61 %)" in note

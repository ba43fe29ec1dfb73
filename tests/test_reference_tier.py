"""The model-error tier's converged reference: the ``converged`` preset, the honesty rule for every
spelling of it, and the one reference solve shared by the data generator and the convergence
study (problems/inverse/response_cache.py)."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import pytest

import problems.inverse.data as data
from bench.studies.convergence import render_overview, run_convergence
from problems.fe.mesh import discretisation_key, parse_mesh_spec
from problems.inverse import response_cache
from problems.inverse.build import check_discretisations
from problems.inverse.cases import get_case
from problems.inverse.forward import FEForwardModel
from problems.inverse.model_error import HonestyError

CASE = "linear-compression"


def test_converged_is_the_model_error_mesh_and_a_preset_with_tokens():
    assert data.MODEL_ERROR_MESH == data.tier_settings("model-error").mesh == "15,15,30:g16:hex27"
    spec = parse_mesh_spec("converged")
    assert (spec.shape, spec.grading, spec.element, spec.symmetry) == (
        (15, 15, 30),
        16.0,
        "hex27",
        "eighth",
    )
    assert discretisation_key("converged:quarter") == "15,15,30:g16:hex27"
    with pytest.raises(ValueError, match="element given twice"):
        parse_mesh_spec("converged:hex8")


@pytest.mark.parametrize(
    "role, kwargs",
    [
        ("forward", {"mesh": "15,15,30:hex27:g16:quarter"}),
        ("hifi", {"mesh": "coarse", "hifi_mesh": "converged:eighth"}),  # corrections and BAE
        ("hifi", {"mesh": "coarse", "hifi_mesh": "15,15,30:g16.0:hex27"}),
    ],
)
def test_the_honesty_rule_refuses_every_spelling_of_the_converged_reference(role, kwargs):
    ds = SimpleNamespace(case=CASE, settings=data.tier_settings("model-error"))
    with pytest.raises(HonestyError, match=f"the {role} model uses discretisation 15,15,30:g16"):
        check_discretisations(get_case(CASE), ds, **kwargs)
    # the previous reference and another grading of today's are other discretisations
    check_discretisations(get_case(CASE), ds, mesh="15,15,30:g8:hex27", hifi_mesh="paper")
    check_discretisations(get_case(CASE), ds, mesh="coarse", hifi_mesh="12,12,24:g8:hex27")


def test_the_honesty_rule_refuses_a_surrogate_trained_on_the_converged_reference(monkeypatch):
    import problems.surrogate.model as surrogate_model

    monkeypatch.setattr(surrogate_model, "discretisation_of", lambda fwd: fwd.trained_on)
    ds = SimpleNamespace(case=CASE, settings=data.tier_settings("model-error"))
    trained = SimpleNamespace(trained_on=discretisation_key("converged:quarter"))
    with pytest.raises(HonestyError, match="the surrogate model uses"):
        check_discretisations(get_case(CASE), ds, mesh="coarse", forward=trained)


@pytest.fixture
def counted_runs(monkeypatch, tmp_path):
    """The data mesh made tiny (3,3,6:g4), the cache in ``tmp_path``; counts the FE runs."""
    monkeypatch.setenv(data.CACHE_DIR_ENV, str(tmp_path / "cache"))
    monkeypatch.setattr(data, "MODEL_ERROR_MESH", "3,3,6:g4")
    runs = []
    original = FEForwardModel.run_with_response

    def counting(self, x, jacobian=False):
        runs.append(self.mesh)
        return original(self, x, jacobian)

    monkeypatch.setattr(FEForwardModel, "run_with_response", counting)
    return runs


def test_data_and_study_share_the_one_reference_solve(counted_runs, tmp_path, monkeypatch):
    shared = data.make_data(CASE, mesh="3,3,6:g4:quarter")
    assert counted_runs == ["3,3,6:g4:quarter"]
    entries = list(response_cache.folder().iterdir())
    assert len(entries) == 1
    # any spelling of the mesh takes the same entry; the bytes are those of a plain run
    again = data.make_data(CASE, mesh="3,3,6:g4:quarter")
    assert again.to_json() == shared.to_json() and len(counted_runs) == 1
    with monkeypatch.context() as m:
        m.setattr(data, "shares_reference_solve", lambda mesh: False)
        assert data.make_data(CASE, mesh="3,3,6:g4:quarter").to_json() == shared.to_json()
    counted_runs.clear()
    folder = run_convergence(
        CASE,
        {"hex8 g4": ["2,2,4:g4", "3,3,6:g4", "4,4,8:g4"]},
        ["3,3,6"],
        tmp_path / "r" / "s" / CASE,
    )
    assert counted_runs == ["2,2,4:g4", "4,4,8:g4", "3,3,6"]  # 3,3,6:g4 from the cache
    entry = json.loads(entries[0].read_text())
    summary = json.loads((folder / "convergence.json").read_text())
    rows = {r["mesh"]: r for r in summary["meshes"]}
    assert summary["data_mesh"] == "3,3,6:g4"
    assert rows["3,3,6:g4"]["cpu_s"] == entry["cpu_s"] and entry["jacobian"] is None
    # the data run has no Jacobian: its errors are measured, its own bias is not
    assert rows["3,3,6:g4"]["ok"] and "rms_sigma" in rows["3,3,6:g4"]
    assert "worst_bias" not in rows["3,3,6:g4"]
    assert abs(rows["3,3,6"]["worst_data_bias"]["pct"]) > 1.0  # uniform 3,3,6: biased
    text = render_overview(tmp_path / "r").read_text()
    assert "## The model-error tier's data mesh" in text
    assert f"| {CASE} | s | 3,3,6:g4 |" in text
    assert "## Candidate inverse models" in text and "| 2,2,4:g4 |" in text


def test_a_torn_cache_entry_is_solved_again_and_a_jacobian_is_added_on_demand(counted_runs):
    model, x = FEForwardModel(get_case(CASE), mesh="2,2,4"), get_case(CASE).reference
    first = response_cache.solve(model, x)
    assert not first["reused"] and first["jacobian"] is None
    assert response_cache.solve(model, x)["reused"]
    full = response_cache.solve(model, x, jacobian=True)  # the entry had none: solved again
    assert not full["reused"] and full["jacobian"].shape == (len(first["values"]), 6)
    assert (full["values"] == first["values"]).all()
    assert response_cache.solve(model, x)["jacobian"] is not None  # now kept
    path = next(response_cache.folder().iterdir())
    path.write_text(path.read_text()[:-100])
    assert response_cache.lookup(model, x) is None
    assert not response_cache.solve(model, x)["reused"]
    assert not response_cache.solve(model, x, reuse=False)["reused"]  # data --check: afresh
    assert counted_runs == ["2,2,4"] * 4


def test_an_entry_of_other_code_is_not_served(counted_runs, monkeypatch):
    """The key holds the hash of the FE, material and forward-model sources: an entry written
    under another code hash is solved again, one of the same code hash is served."""
    model, x = FEForwardModel(get_case(CASE), mesh="2,2,4"), get_case(CASE).reference
    monkeypatch.setattr(response_cache, "code_hash", lambda: "old-code")
    assert not response_cache.solve(model, x)["reused"]
    assert response_cache.solve(model, x)["reused"]
    monkeypatch.setattr(response_cache, "code_hash", lambda: "new-code")
    assert response_cache.lookup(model, x) is None
    assert not response_cache.solve(model, x)["reused"]
    monkeypatch.setattr(response_cache, "code_hash", lambda: "old-code")
    assert response_cache.solve(model, x)["reused"]
    assert counted_runs == ["2,2,4"] * 2


def test_the_code_hash_follows_the_response_sources_only(tmp_path):
    for rel in (
        "fe/newton.py",
        "fe/sub/kernel.py",
        "materials/dp.py",
        "inverse/forward.py",
        "inverse/data.py",
        "analysis/gsa.py",
        "fe/presets.py",
    ):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(f"# {rel}\n")
    before = response_cache.sources_hash(tmp_path)
    (tmp_path / "inverse/data.py").write_text("changed\n")  # not a response source
    (tmp_path / "analysis/gsa.py").write_text("changed\n")
    (tmp_path / "fe/presets.py").write_text("changed\n")  # names only: requests spell them out
    assert response_cache.sources_hash(tmp_path) == before
    for rel in ("fe/sub/kernel.py", "materials/dp.py", "inverse/forward.py"):
        (tmp_path / rel).write_text("changed\n")
        assert response_cache.sources_hash(tmp_path) != before
        before = response_cache.sources_hash(tmp_path)
    # docstrings, comments and layout compute nothing: editing them keeps the hash
    code = "def f(x):\n    return 2 * x\n"
    (tmp_path / "fe/newton.py").write_text(code)
    before = response_cache.sources_hash(tmp_path)
    (tmp_path / "fe/newton.py").write_text(
        '"""Newton."""\n\n\ndef f(x):  # doubles\n    """Twice x, mm."""\n    return 2*x\n'
    )
    assert response_cache.sources_hash(tmp_path) == before
    (tmp_path / "fe/newton.py").write_text("def f(x):\n    return 3 * x\n")
    assert response_cache.sources_hash(tmp_path) != before
    (tmp_path / "fe/newton.py").write_text('def f(x):\n    x = "2"\n    return 2 * x\n')
    assert response_cache.sources_hash(tmp_path) != before  # a string that is not a docstring
    assert response_cache.code_hash() == response_cache.sources_hash(
        Path(response_cache.__file__).resolve().parents[1]
    )


def test_a_shipped_set_made_with_other_settings_is_served_with_a_warning(monkeypatch):
    """A shipped model-error set made on another mesh than the tier's (e.g. one not yet remade)
    is not silently taken for the tier's: the warning names the file, both meshes and the fix."""
    monkeypatch.setattr(data, "MODEL_ERROR_MESH", "6,6,12:g4")
    made = r"mesh '15,15,30:g16:hex27' \(asked '6,6,12:g4'\).*--force"
    with pytest.warns(UserWarning, match=made):
        ds = data.get_data(CASE, data.tier_settings("model-error"))
    assert ds.settings.mesh == "15,15,30:g16:hex27"


def test_a_plain_mesh_is_solved_once_without_jacobian_and_again_when_asked_with_one(
    counted_runs, tmp_path
):
    """``plain`` meshes (the finest of a study) go through the response cache without the
    Jacobian: they extend the extrapolation, their errors are measured, their bias is not; a
    later study that wants the mesh's Jacobian solves it again."""
    family = {"hex8 g4": ["2,2,4:g4", "3,3,6:g4", "4,4,8:g4"]}
    folder = run_convergence(CASE, family, [], tmp_path / "s", plain=["4,4,8:g4:quarter"])
    assert counted_runs == ["2,2,4:g4", "3,3,6:g4", "4,4,8:g4"]
    entries = {p.name.split("__")[1] for p in response_cache.folder().iterdir()}
    assert entries == {"3x3x6_g4", "4x4x8_g4"}  # the data mesh and the plain one
    rows = {r["mesh"]: r for r in json.loads((folder / "convergence.json").read_text())["meshes"]}
    assert rows["4,4,8:g4"]["ok"] and rows["4,4,8:g4"]["message"] == "no Jacobian (a plain run)"
    assert "worst_bias" not in rows["4,4,8:g4"] and "worst_bias" in rows["2,2,4:g4"]
    assert 0 < rows["4,4,8:g4"]["rms_sigma"] < rows["2,2,4:g4"]["rms_sigma"]  # in the family
    # meshes without a Jacobian get their own bias estimated through 2,2,4:g4's: its bias
    # against the extrapolation minus its bias against their response
    assert rows["4,4,8:g4"]["bias_est_via"] == rows["3,3,6:g4"]["bias_est_via"] == "2,2,4:g4"
    coarse = rows["2,2,4:g4"]
    for name, est in rows["3,3,6:g4"]["bias_est_pct"].items():
        assert est == pytest.approx(
            coarse["bias_pct"][name] - coarse["data_bias_pct"][name], abs=1e-9
        )
    assert "bias_est_pct" not in coarse
    first = rows["2,2,4:g4"]["rms_sigma"]
    text = render_overview(tmp_path).read_text()  # the plain mesh is no inverse-model candidate
    candidates = text.split("## Candidate inverse models")[1].split("##")[0]
    assert "| 2,2,4:g4 |" in candidates and "4,4,8:g4" not in candidates
    counted_runs.clear()
    folder = run_convergence(CASE, family, [], tmp_path / "s")  # now with its Jacobian
    assert counted_runs == ["4,4,8:g4"]  # the data mesh's plain record is kept
    rows = {r["mesh"]: r for r in json.loads((folder / "convergence.json").read_text())["meshes"]}
    assert "worst_bias" in rows["4,4,8:g4"] and rows["2,2,4:g4"]["rms_sigma"] == first

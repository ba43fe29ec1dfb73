"""The case's default model-error treatment (``--correction default``) and the studies' data
tier and treatment (``--tier``, ``--correction``)."""

import json
from dataclasses import replace
from pathlib import Path

import pytest

from bench.experiment.objective import assemble, bae_path
from bench.experiment.spec import RunSpec, Treatment
from problems.inverse.cases import CASES, default_treatment

ROOT = Path(__file__).resolve().parents[1]


def test_default_treatment_is_bae_with_a_plate_margin_on_every_case():
    for name in CASES:
        d = default_treatment(name)
        assert (d.treatment, d.plate_margin_mm, d.hifi_mesh, d.bae_samples, d.inverse_mesh) == (
            "bae",
            30.0,
            "paper",
            32,
            "coarse",
        )
    assert default_treatment("analytic-smooth").treatment == "none"


def test_default_resolves_to_the_case_settings_and_explicit_treatments_stay():
    default = Treatment("default", 5.0)
    got = default.resolved("linear-shear", "coarse", "model-error")
    assert (got.name, got.plate_margin_mm, got.hifi_mesh, got.bae_samples) == (
        "bae",
        30.0,
        "paper",
        32,
    )
    # another inverse mesh takes its own next finer preset (never the coarse default's paper)
    assert default.resolved("linear-shear", "paper", "model-error").hifi_mesh is None
    # consistent data have no model error: nothing to treat
    assert default.resolved("linear-shear", "coarse", "consistent").name == "none"
    explicit = Treatment("one-point", 5.0)
    assert explicit.resolved("linear-shear", "coarse", "model-error") is explicit


def test_cases_lists_the_default_treatment(capsys):
    from bench.cli import main

    assert main(["cases"]) == 0
    out = capsys.readouterr().out
    assert (
        out.count("--correction default): bae (32 samples on paper for coarse), plate margin 30 mm")
        == 9
    )


def test_identify_refuses_a_margin_with_the_default(capsys):
    from bench.cli import main

    code = main(
        [
            "identify",
            "linear-compression",
            "--solver",
            "lm",
            "--correction",
            "default",
            "--plate-margin-mm",
            "10",
            "--quiet",
        ]
    )
    assert code == 2 and "sets the plate margin" in capsys.readouterr().err


@pytest.mark.parametrize("name", list(CASES))
def test_the_default_bae_statistics_are_release_artefacts(name):
    """`make run` uses the default treatment: its statistics (32 paper runs per case) are listed
    in the release manifest with the command that rebuilds exactly them, and when present (in the
    tree or the artefact directory) they are the listed bytes and the documented statistics."""
    from bench import artefacts
    from problems.inverse.build import resolve_data
    from problems.inverse.cases import get_case
    from problems.inverse.model_error import Correction

    spec = RunSpec(name, "lm")
    spec = replace(spec, treatment=Treatment("default").resolved(name, spec.mesh, "model-error"))
    data = resolve_data(get_case(name), spec.mesh, spec.data.tier, None)
    path = bae_path(spec, spec.treatment.hifi_mesh, data)
    rel = f"model_error/{path.name}"
    entry = artefacts.read_manifest(ROOT / "results").get(rel)
    assert entry is not None, f"{rel} is not in results/{artefacts.MANIFEST}"
    assert entry["rebuild"].startswith(f"femubench identify {name} --solver lm --mesh coarse")
    assert "--correction bae --hifi-mesh paper --plate-margin-mm 30 " in entry["rebuild"]
    roots = (ROOT / "results", artefacts.search_roots()[1])
    found = next((r / rel for r in roots if (r / rel).exists()), None)
    if found is None:
        return
    assert artefacts.mismatches(found, entry) == []
    corr = Correction.load(found)  # hash-checked
    assert corr.treatment == "bae" and corr.provenance["samples"] == 32 and corr.n_hifi >= 28
    assert corr.provenance["hifi_mesh"] == "paper" and corr.provenance["inverse_mesh"] == "coarse"


@pytest.fixture
def stored_statistics(tmp_path, monkeypatch):
    """Small BAE statistics of linear-compression's default treatment stored where the default
    objective looks for them, in a fresh results root (the shipped ones may be absent: they are
    release artefacts). Returns the Correction."""
    import numpy as np

    from bench.experiment.objective import prepare
    from problems.inverse.model_error import Correction

    monkeypatch.setenv("FEMUBENCH_RESULTS_DIR", str(tmp_path / "results"))
    monkeypatch.setenv("FEMUBENCH_ARTEFACT_DIR", str(tmp_path / "artefacts"))
    asm = prepare(RunSpec("linear-compression", "lm", treatment=Treatment("default")))
    m = asm.objective().problem.data.size
    corr = Correction(
        "bae",
        np.zeros(m),
        np.full((m, 2), 1e-6),
        n_hifi=32,
        hifi_wall_s=3.0,
        n_inverse=32,
        inverse_wall_s=1.0,
        points=np.ones((32, 6)),
        provenance={"case": "linear-compression", "hifi_mesh": "paper", "samples": 32},
    )
    corr.save(bae_path(asm.spec, asm.hifi_mesh, asm.data))
    return corr


def test_default_objective_uses_the_stored_statistics_without_a_run(stored_statistics):
    obj = assemble(RunSpec("linear-compression", "lm", treatment=Treatment("default")))
    prov = obj.provenance
    assert (prov["treatment"], prov["hifi_mesh"], prov["region_plate_margin_mm"]) == (
        "bae",
        "paper",
        30.0,
    )
    hifi = obj.charges["hifi"]  # the stored statistics' runs, charged; none made now
    assert obj.n_evals == 0 and (hifi["n"], hifi["wall_s"]) == (32, 3.0)


@pytest.mark.parametrize(
    "tier, mesh", [("consistent", "coarse"), ("model-error", "15,15,30:g16:hex27")]
)
def test_study_objective_takes_the_tier_data(tier, mesh):
    from bench.studies import study_objective

    obj, text = study_objective("linear-compression", tier=tier)
    assert obj.provenance["data_tier"] == tier and obj.provenance["data_mesh"] == mesh
    assert f"{tier} tier" in text and "treatment none" in text


def test_study_objective_refuses_tier_with_data_and_iterated():
    from bench.studies import study_objective

    with pytest.raises(ValueError, match="give one of them"):
        study_objective("linear-compression", tier="consistent", data="shipped")
    with pytest.raises(ValueError, match="identifications only"):
        study_objective("linear-compression", tier="model-error", correction="iterated")
    with pytest.raises(ValueError, match="sets the plate margin"):
        study_objective("linear-compression", correction="default", plate_margin_mm=10.0)
    obj, text = study_objective("linear-compression", tier="consistent", correction="default")
    assert obj.provenance["treatment"] == "none"  # consistent data: nothing to correct


def test_study_objective_default_treatment_on_model_error_data(stored_statistics):
    from bench.studies import study_objective

    obj, text = study_objective("linear-compression", tier="model-error", correction="default")
    assert obj.provenance["treatment"] == "bae" and "= the case's default" in text
    assert "30 mm of the plates left out" in text


@pytest.mark.parametrize("command", ["identifiability", "gsa", "uncertainty"])
def test_study_commands_pass_the_tier_and_correction_on(command, monkeypatch):
    """The options reach the study's run function (which hands them to study_objective)."""
    import bench.studies.global_sensitivity as gsa
    import bench.studies.identifiability as ident
    import bench.studies.uncertainty as unc
    from bench.cli import main

    seen = {}

    class Stop(Exception):
        pass

    def fake(*args, **kwargs):
        seen.update(kwargs)
        raise Stop

    module, fn = {
        "identifiability": (ident, "run_identifiability"),
        "gsa": (gsa, "run_gsa"),
        "uncertainty": (unc, "run_uncertainty"),
    }[command]
    monkeypatch.setattr(module, fn, fake)
    argv = [
        command,
        "linear-compression",
        "--tier",
        "consistent",
        "--correction",
        "one-point",
        "--plate-margin-mm",
        "20",
        "--quiet",
        "--workers",
        "1",
    ]
    if command == "identifiability":
        argv.remove("--quiet")
    assert main(argv) == 1  # the fake's exception: an internal error, after the call
    assert (seen["tier"], seen["correction"], seen["plate_margin_mm"]) == (
        "consistent",
        "one-point",
        20.0,
    )


def test_identifiability_study_records_the_tier(tmp_path):
    """End to end on coarse (7 FE runs): the consistent tier's data reach the study's files."""
    from bench.studies.identifiability import run_identifiability

    run_identifiability(["linear-compression"], tier="consistent", out=tmp_path, progress=False)
    doc = json.loads((tmp_path / "identifiability.json").read_text())
    assert "consistent tier, data mesh coarse" in doc["data"]


def test_identify_json_says_where_it_stands(tmp_path):
    """Issue item 8: the JSON of `femubench identify` has the provenance block and iterations."""
    from bench.cli import main
    from problems.inverse.data import make_data, save

    data = save(make_data("linear-compression", mesh="2,2,4", snapshots=2), tmp_path / "me.json")
    out = tmp_path / "run.json"
    argv = ["identify", "linear-compression", "--solver", "lm", "--mesh", "1,1,2", "--data",
            str(data), "--correction", "one-point", "--hifi-mesh", "1,1,4", "--budget", "8",
            "--quiet", "--json", str(out)]  # fmt: skip
    assert main(argv) == 0
    doc = json.loads(out.read_text())
    prov = doc["provenance"]
    assert prov["case"] == "linear-compression" and prov["data_tier"] == "model-error"
    assert prov["data_mesh"] == "2,2,4" and prov["inverse_mesh"] == "1,1,2"
    assert prov["treatment"] == "one-point" and prov["hifi_mesh"] == "1,1,4"
    assert len(prov["data_hash"]) >= 12 and prov["data_file"] == str(data)
    assert doc["iterations"] == doc["n_iterations"] >= 1
    assert doc["charges"]["hifi"]["n"] == 1

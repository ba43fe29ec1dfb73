"""``femubench model-error --plan FILE``: the phases of a study plan (suites/studies/), each
checked as a command line, run one after another with the command line's shared options."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest

import bench.studies.model_error as study
from bench.cli import main

PLAN = Path(__file__).resolve().parents[1] / "suites" / "studies" / "model_error.toml"


def test_the_shipped_plan_prints_its_phases(capsys):
    assert main(["model-error", "--plan", str(PLAN), "--dry-run"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 7 and lines[0].startswith("=== phase 1/7: the default")
    assert lines[3].endswith(
        "femubench model-error all --meshes paper --treatments none,one-point --margins 0,30 "
        "--bias-only --no-figures"
    )
    assert lines[-1].endswith("femubench model-error all")


def test_phases_run_in_order_with_the_shared_options(tmp_path, monkeypatch):
    plan = tmp_path / "plan.toml"
    plan.write_text(
        '[[phase]]\ncases = ["linear-shear", "linear-compression"]\ntreatments = ["bae"]\n'
        "margins = [30]\nbias-only = true\nno-figures = true\n"
        '[[phase]]\ncases = ["linear-tension"]\nmeshes = ["paper"]\nbudget = 7\n'
    )
    calls, drawn = [], []

    def run_model_error(name, **kw):
        calls.append((name, kw))
        return SimpleNamespace(rows=[], dir=tmp_path / name)

    monkeypatch.setattr(study, "run_model_error", run_model_error)
    monkeypatch.setattr(study, "render_model_error", lambda d: drawn.append(d.name) or d)
    monkeypatch.setattr(study, "render_overview", lambda root: drawn.append(root.name) or [])
    argv = ["model-error", "--plan", str(plan), "--workers", "1", "--out", str(tmp_path / "o")]
    assert main(argv) == 0
    assert [name for name, _ in calls] == ["linear-shear", "linear-compression", "linear-tension"]
    first, last = calls[0][1], calls[-1][1]
    assert first["out"] == tmp_path / "o" / "linear-shear"
    assert (tuple(first["treatments"]), tuple(first["margins"]), first["bias_only"]) == (
        ("bae",),
        (30.0,),
        True,
    )
    assert first["budget"] == 200 and tuple(first["meshes"]) == ("coarse",)  # the defaults
    assert last["out"] == tmp_path / "o" / "linear-tension"  # --out: a folder per case
    assert tuple(last["meshes"]) == ("paper",)
    assert last["budget"] == 7 and tuple(last["margins"]) == (0.0, 30.0)
    assert drawn == ["linear-tension", "o"]  # figures of the second phase only, and the overview


@pytest.mark.parametrize(
    "text, message",
    [
        ('[[phase]]\ncases = ["all"]\nworkers = 2\n', "phase 1: unknown key 'workers'"),
        ('[[phase]]\ncases = ["all"]\ntreatments = ["bogus"]\n', "phase 1: argument --treatments"),
        ('[[phase]]\ntreatments = ["bae"]\n', "phase 1: cases must be a list"),
        ("[plan]\n", "needs [[phase]] tables"),
    ],
)
def test_a_bad_plan_is_one_line_naming_the_phase(tmp_path, capsys, text, message):
    plan = tmp_path / "plan.toml"
    plan.write_text(text)
    assert main(["model-error", "--plan", str(plan), "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


def test_plan_and_cases_exclude_each_other(capsys):
    assert main(["model-error", "linear-shear", "--plan", str(PLAN)]) == 2
    assert main(["model-error"]) == 2
    assert "give the cases" in capsys.readouterr().err

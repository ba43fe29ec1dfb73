"""Careless inputs refused up front (issue 28, second round): one line naming the option, the
value and what is allowed, exit code 2, before any work; plausibility warnings with the numbers."""

from __future__ import annotations

from pathlib import Path

import pytest

from bench.cli import main

ROOT = Path(__file__).resolve().parent.parent


def one_line_error(capsys, argv, *needles) -> str:
    """Run ``argv``; assert exit 2 and a one-line error holding every needle; return it."""
    code = main(argv)
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert len(err.splitlines()) == 1, err
    for needle in needles:
        assert needle in err, err
    return err


# --- meshes ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("mesh", ["1,1,1", "2,2,1:quarter", "4,4,1"])
def test_a_mesh_without_free_dofs_is_refused(capsys, mesh):
    """NZ = 1 puts every node on a plate (was: "cannot reshape array of size 0")."""
    one_line_error(capsys, ["forward", "--mesh", mesh], "--mesh", "NZ = 1", "NZ >= 2")


def test_a_mesh_whose_operators_exceed_half_the_memory_is_refused(capsys, monkeypatch):
    from bench.resources import mesh_operator_bytes

    monkeypatch.setenv("FEMUBENCH_MEMORY_BYTES", str(16e9))
    # 200 x 200 x 400 solved as the eighth: 24.4 M dofs, ~71 GB of operators
    assert mesh_operator_bytes("200,200,400") > 70e9
    assert mesh_operator_bytes("fine") < 1e8
    err = one_line_error(capsys, ["forward", "--mesh", "200,200,400"], "--mesh", "200,200,400")
    assert "71 GB" in err and "8 GB" in err


# --- option values ----------------------------------------------------------------------------


@pytest.mark.parametrize("delta", ["1e-300", "-0.01", "0", "0.9"])
def test_sensitivity_delta_outside_a_sane_relative_range_is_refused(capsys, delta, tmp_path):
    one_line_error(
        capsys,
        ["sensitivity", "linear-compression", "--delta", delta, "--out", str(tmp_path)],
        "--delta",
        "[1e-06, 0.5]",
    )


@pytest.mark.parametrize("hifi", ["1,1,2", "coarse", "6,6,10"])
def test_a_hifi_mesh_not_finer_than_the_inverse_mesh_is_refused(capsys, hifi, tmp_path):
    one_line_error(
        capsys,
        ["identify", "linear-compression", "--solver", "lm", "--correction", "one-point",
         "--hifi-mesh", hifi, "--json", str(tmp_path / "r.json")],  # fmt: skip
        "--hifi-mesh",
        "not finer",
    )
    assert not (tmp_path / "r.json").exists()


@pytest.mark.parametrize("command", [["identify", "analytic-linear", "--solver", "lm"],
                                     ["forward", "--mesh", "2,2,2"]])  # fmt: skip
def test_json_paths_are_checked_before_the_computation(capsys, tmp_path, command):
    err = one_line_error(
        capsys, [*command, "--json", str(tmp_path / "missing" / "r.json")], "--json", "missing"
    )
    assert "does not exist" in err
    one_line_error(capsys, [*command, "--json", str(tmp_path)], "--json", "is a directory")


def test_the_smoke_suite_has_the_number_of_runs_the_readme_says(capsys, tmp_path):
    assert main(["run", str(ROOT / "suites/smoke.toml"), "--dry-run", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "12 runs," in out
    readme = (ROOT / "README.md").read_text()
    assert "# 12 runs on analytic problems" in readme and "16 runs" not in readme

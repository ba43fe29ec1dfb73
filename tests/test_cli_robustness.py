"""The command line itself: --version, and a closed output pipe ends it quietly."""

from __future__ import annotations

import os
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import pytest

from bench.cli import main

ROOT = Path(__file__).resolve().parent.parent


def test_version_prints_the_package_version(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"femubench {metadata.version('femubench')}"


@pytest.mark.parametrize("argv", [["solvers"], ["--help"], ["solvers", "--json"]])
def test_a_closed_output_pipe_gives_no_traceback(argv):
    """As ``femubench solvers | head -0``: the reader is gone before anything is written."""
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.Popen(
        [sys.executable, "-m", "bench", *argv],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) in (0, 141), err  # argparse itself ignores a failed --help write
    assert err == ""


def test_an_output_path_that_is_a_directory_is_a_one_line_error(tmp_path, capsys):
    suite = tmp_path / "s.toml"
    suite.write_text('[suite]\ncases = ["analytic-linear"]\nmethods = ["lm"]\nbudgets = [10]\n')
    blocker = tmp_path / "out"
    blocker.write_text("a file where a folder should be")
    code = main(["run", str(suite), "--out", str(blocker), "--workers", "1"])
    err = capsys.readouterr().err
    assert (
        code == 2 and err.startswith("femubench run: error:") and len(err.strip().splitlines()) == 1
    )

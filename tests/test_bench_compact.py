"""Compact run records: JSON + ``<hash>.history.npz`` companion, read back bit for bit."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from bench import store
from bench.cli import main as cli
from bench.runner import run_suite
from bench.suite import parse_suite

SHIPPED = Path(__file__).resolve().parents[1] / "results" / "default" / "runs"
SUITE = {
    "suite": {
        "name": "tiny",
        "cases": ["analytic-smooth", "analytic-linear"],
        "methods": ["lm", "de"],
        "seeds": [0],
        "starts": ["default"],
        "budgets": [400],
    }
}


def _largest_shipped(k=1):
    return sorted(SHIPPED.glob("*.json"), key=lambda p: -p.stat().st_size)[:k]


def test_a_shipped_record_round_trips_compact_bit_for_bit(tmp_path):
    src = _largest_shipped()[0]
    original = store.load_record(src)
    dest = tmp_path / src.name
    assert store.write_encoded(dest, json.loads(src.read_text())) is True
    assert "history" not in json.loads(dest.read_text())["result"]
    back = store.load_record(dest)
    assert back == original  # arrays included: every float compares equal ...
    h0, h1 = original["result"]["history"], back["result"]["history"]
    assert len(h1) == len(h0) > 1000
    # ... and bit for bit (same canonical JSON, so the same repr of every float)
    assert json.dumps(back, sort_keys=True) == json.dumps(original, sort_keys=True)
    assert dest.stat().st_size + store.companion_path(dest).stat().st_size < src.stat().st_size / 3


@pytest.mark.parametrize("damage", ["torn", "edited", "missing"])
def test_a_damaged_companion_makes_the_record_unreadable(tmp_path, damage):
    src = _largest_shipped()[0]
    runs = tmp_path / "runs"
    dest = runs / src.name
    store.write_encoded(dest, json.loads(src.read_text()))
    comp = store.companion_path(dest)
    data = comp.read_bytes()
    if damage == "torn":
        comp.write_bytes(data[: len(data) // 2])
    elif damage == "edited":
        comp.write_bytes(data[:-1] + bytes([data[-1] ^ 1]))
    else:
        comp.unlink()
    with pytest.raises(ValueError, match="history companion"):
        store.load_record(dest)
    assert store.done_hashes(tmp_path) == set()
    moved = store.set_aside_unreadable(tmp_path)
    assert len(moved) == 1 and not dest.exists() and not comp.exists()
    assert len(store.set_aside_files(tmp_path)) == 1


def test_runs_are_written_compact_resume_finds_them_done_and_report_renders(tmp_path):
    from bench.report import write_report

    suite = parse_suite(SUITE)
    first = run_suite(suite, tmp_path, workers=1, progress=False)
    assert first.ran == 4
    comps = sorted(store.runs_dir(tmp_path).glob(f"*{store.HISTORY_SUFFIX}"))
    assert len(comps) >= 1
    for c in comps:
        rec = json.loads(c.with_name(c.name.replace(store.HISTORY_SUFFIX, ".json")).read_text())
        assert store.HISTORY_FILE in rec and "history" not in rec["result"]
    assert all(r["result"]["history"] for r in store.load_records(tmp_path))
    again = run_suite(suite, tmp_path, workers=1, progress=False)
    assert (again.skipped, again.ran) == (4, 0)
    write_report(tmp_path, ["md"], figures=False)
    md = (tmp_path / "report" / "report.md").read_text()
    assert "**4 runs**" in md and "Unreadable" not in md


def test_records_compact_cli_converts_verifies_and_reports_sizes(tmp_path, capsys):
    runs = tmp_path / "runs"
    runs.mkdir()
    srcs = _largest_shipped(3)
    for p in srcs:
        shutil.copy(p, runs / p.name)
    before = {r["config_hash"]: r for r in store.load_records(tmp_path)}
    assert cli(["records", "compact", str(tmp_path), "--dry-run"]) == 0
    assert "would convert 3 record(s)" in capsys.readouterr().out
    assert sorted(q.name for q in runs.iterdir()) == sorted(p.name for p in srcs)
    assert cli(["records", "compact", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "converted 3 record(s)" in out
    assert len(list(runs.glob(f"*{store.HISTORY_SUFFIX}"))) == 3
    assert {r["config_hash"]: r for r in store.load_records(tmp_path)} == before
    assert not [q for q in runs.iterdir() if q.name.startswith(".")]
    assert cli(["records", "compact", str(tmp_path)]) == 0  # idempotent
    assert "converted 0 record(s)" in capsys.readouterr().out
    assert cli(["records", "compact", str(tmp_path / "nope")]) == 2

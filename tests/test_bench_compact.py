"""Compact run records: JSON + ``<hash>.history.xz`` companion, read back bit for bit."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from bench.cli import main as cli
from bench.experiment import store
from bench.experiment.runner import run_suite
from bench.experiment.suite import parse_suite

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


def _largest_shipped(where: Path, k: int = 1):
    """The ``k`` shipped records with the longest histories, rewritten in the one-file form
    (history inline, as every record was before format 2) under ``where``: the shipped folders
    are compact, the conversion is what these tests exercise."""
    where.mkdir(parents=True, exist_ok=True)
    comps = sorted(SHIPPED.glob(f"*{store.HISTORY_SUFFIX}"), key=lambda p: -p.stat().st_size)
    out = []
    for comp in comps[:k]:
        src = comp.with_name(comp.name.replace(store.HISTORY_SUFFIX, ".json"))
        rec = store.read_record(src)  # the stored JSON, its history put back
        rec.pop(store.HISTORY_FILE, None)
        dest = where / src.name
        dest.write_text(json.dumps(rec, sort_keys=True, separators=(",", ":")) + "\n")
        out.append(dest)
    return out


def test_a_shipped_record_round_trips_compact_bit_for_bit(tmp_path):
    src = _largest_shipped(tmp_path / "one-file")[0]
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
    src = _largest_shipped(tmp_path / "one-file")[0]
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
    srcs = _largest_shipped(tmp_path / "one-file", 3)
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


COMPARISON = SHIPPED.parents[1] / "comparison" / "runs"
#: One shipped record of each kind: FE track of the comparison (CMA-ES: keys only some evaluations
#: carry; PSO+LM: phases), surrogate track (CMA-ES) and MCMC on the surrogate of results/default
#: (the comparison's surrogate-track companions are release artefacts, maybe absent).
KINDS = {
    "fe-cma": "db540e42605dedfc14c3b5dbbdb7fda88137308db704743c4ee4b3f44f0879a0",
    "fe-pso+lm": "be67dfcfa698a7357c9580f0435b26a9fee5f0e89b9dc27f83dbac4fffa52c6b",
    "surrogate-cma": "d8a4033dd5aeeb69df2393fd20319280c3046dcb7ba0af4890563b4c7fe17096",
    "mcmc": "763609cbbf5f36318e0d4c88e8e70f4abdcba154091a14cfa3afc297707834b9",
}


def _shipped(h: str) -> Path:
    """The shipped record file of hash ``h`` (comparison or default)."""
    return next(p for d in (COMPARISON, SHIPPED) if (p := d / f"{h}.json").is_file())


def _copy_one_file(h: str, runs: Path) -> None:
    """The shipped record ``h`` into ``runs`` in the one-file form it was written in (some are
    shipped compact)."""
    (runs / f"{h}.json").write_text(store._record_text(store.load_record(_shipped(h))))


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_shipped_records_of_each_kind_round_trip_format_2(tmp_path, kind):
    src = _shipped(KINDS[kind])
    original = store.load_record(src)
    history = original["result"]["history"]
    dest = tmp_path / src.name
    assert store.write_encoded(dest, original) is True
    comp = store.companion_path(dest)
    assert comp.name.endswith(".history.xz")
    back = store.load_record(dest)
    assert json.dumps(back, sort_keys=True) == json.dumps(original, sort_keys=True)
    # the format-1 companion of the same history (np.savez_compressed) is larger
    from io import BytesIO

    import numpy as np

    buf = BytesIO()
    np.savez_compressed(buf, **store._history_columns(history))
    assert comp.stat().st_size < 0.8 * len(buf.getvalue())


def test_derivable_columns_are_stored_as_their_rule():
    h = [
        {"cost": c, "best_cost": b, "n_evals": 30 * (i + 1), "phase": p, "x": [float(i), 2.0]}
        for i, (c, b, p) in enumerate(
            [(5.0, 5.0, "surrogate"), (7.0, 5.0, "surrogate"), (1.0, 1.0, "fe"), (3.0, 1.0, "fe")]
        )
    ]
    entries = store._history_entries(h)
    assert "best_cost@runmin" in entries and str(entries["best_cost@runmin"]) == "cost"
    assert sorted(k for k in entries if k.startswith("phase@")) == ["phase@raw", "phase@vocab"]
    assert entries["phase@raw"].dtype == np.uint8
    assert store._history_rows(entries) == h
    h[1]["best_cost"] = 7.0  # no longer a running minimum: kept as values
    assert "best_cost@runmin" not in store._history_entries(h)
    assert store._history_rows(store._history_entries(h)) == h


def test_a_format_1_companion_is_read_and_converted(tmp_path, capsys):
    from io import BytesIO

    src = COMPARISON / f"{KINDS['fe-cma']}.json"
    original = store.load_record(src)
    buf = BytesIO()
    np.savez_compressed(buf, **store._history_columns(original["result"]["history"]))
    runs = tmp_path / "runs"
    runs.mkdir()
    old = runs / f"{src.stem}.history.npz"
    old.write_bytes(buf.getvalue())
    import hashlib

    body = {**original, "result": {k: v for k, v in original["result"].items() if k != "history"}}
    body["history_file"] = {
        "name": old.name,
        "sha256": hashlib.sha256(buf.getvalue()).hexdigest(),
        "n": len(original["result"]["history"]),
    }
    (runs / src.name).write_text(json.dumps(body, sort_keys=True))
    assert store.load_record(runs / src.name) == original
    assert cli(["records", "compact", str(tmp_path)]) == 0
    assert "converted 1 record(s)" in capsys.readouterr().out
    assert not old.exists() and store.companion_path(runs / src.name).is_file()
    assert store.load_record(runs / src.name) == original


def test_records_compact_selects_by_track_record_and_limit(tmp_path, capsys):
    runs = tmp_path / "runs"
    runs.mkdir()
    for h in KINDS.values():
        _copy_one_file(h, runs)
    assert cli(["records", "compact", str(tmp_path), "--track", "fe", "--dry-run"]) == 0
    out = capsys.readouterr().out
    fe = sum((runs / f"{KINDS[k]}.json").stat().st_size for k in ("fe-cma", "fe-pso+lm"))
    assert "would convert 2 record(s)" in out and f"deleted {fe} bytes" in out
    assert not list(runs.glob("*.xz"))
    assert cli(["records", "compact", str(tmp_path), "--track", "surrogate", "--limit", "1"]) == 0
    assert "converted 1 record(s)" in capsys.readouterr().out
    assert [p.stem.split(".")[0] for p in runs.glob("*.xz")] == [KINDS["mcmc"]]
    assert cli(["records", "compact", str(tmp_path), "--record", KINDS["fe-cma"]]) == 0
    assert len(list(runs.glob("*.xz"))) == 2
    assert cli(["records", "compact", str(tmp_path), "--limit", "0"]) == 2
    assert "--limit 0 must be >= 1" in capsys.readouterr().err


def test_records_compact_selects_by_tier(tmp_path, capsys):
    runs = tmp_path / "runs"
    runs.mkdir()
    model_error = "1c79f646a17686b843bb0630d731e042eb86ed66092e2a2e420244836f90cae2"
    for h in (*KINDS.values(), model_error):
        _copy_one_file(h, runs)
    assert cli(["records", "compact", str(tmp_path), "--tier", "no-such-tier"]) == 0
    assert "converted 0 record(s)" in capsys.readouterr().out
    assert cli(["records", "compact", str(tmp_path), "--track", "fe", "--tier", "consistent"]) == 0
    assert "converted 2 record(s)" in capsys.readouterr().out
    assert {p.name.split(".")[0] for p in runs.glob("*.xz")} == {
        KINDS["fe-cma"],
        KINDS["fe-pso+lm"],
    }
    assert cli(["records", "compact", str(tmp_path), "--tier", "model-error"]) == 0
    assert "converted 1 record(s)" in capsys.readouterr().out
    assert store.companion_path(runs / f"{model_error}.json").is_file()
    assert cli(["records", "compact", str(tmp_path), "--method", "mcmc", "--dry-run"]) == 0
    assert "would convert 1 record(s)" in capsys.readouterr().out
    assert cli(["records", "compact", str(tmp_path), "--method", "mcmc"]) == 0
    assert store.companion_path(runs / f"{KINDS['mcmc']}.json").is_file()
    assert not store.companion_path(runs / f"{KINDS['surrogate-cma']}.json").exists()


def test_the_report_of_a_folder_is_byte_identical_after_compaction(tmp_path):
    from bench.report import write_report

    runs = tmp_path / "runs"
    runs.mkdir()
    for h in KINDS.values():
        _copy_one_file(h, runs)

    def report(dest):
        write_report(tmp_path, ["md", "csv", "tex"], figures=False, dest=dest)
        return {p.relative_to(dest): p.read_bytes() for p in sorted(dest.rglob("*")) if p.is_file()}

    before = report(tmp_path / "before")
    assert len(store.compact_records(tmp_path)) == len(KINDS)
    assert len(list(runs.glob("*.xz"))) == len(KINDS)
    after = report(tmp_path / "after")
    assert len(before) > 3 and after == before


def test_records_compact_dry_run_predicts_the_diff_text_of_its_commit(tmp_path, capsys):
    import re
    import subprocess

    out_dir = tmp_path / "results" / "comparison"  # the shipped paths: same header lengths
    runs = out_dir / "runs"
    runs.mkdir(parents=True)
    for h in KINDS.values():
        _copy_one_file(h, runs)

    def git(*a):
        cmd = ["git", "-c", "user.name=t", "-c", "user.email=t@t", "-C", str(tmp_path), *a]
        return subprocess.run(cmd, check=True, capture_output=True).stdout

    git("init", "-q")
    git("add", "-A")
    git("commit", "-qm", "one-file")
    assert cli(["records", "compact", str(out_dir), "--dry-run"]) == 0
    predicted = int(re.search(r"diff text ~([0-9]+) bytes", capsys.readouterr().out).group(1))
    assert cli(["records", "compact", str(out_dir)]) == 0
    git("add", "-A")
    git("commit", "-qm", "compact")
    actual = len(git("show", "--binary", "HEAD"))
    assert predicted == pytest.approx(actual, rel=0.05), (predicted, actual)

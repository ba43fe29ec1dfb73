"""Fault injection on `femubench run` and its records (issue 28): content-hashed records, records
made on other data, planned vs present runs, crash records, worker caps, Ctrl-C."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bench.cli import main as cli
from bench.experiment import store
from bench.experiment.runner import (
    current_data_hash,
    default_workers,
    failed_result,
    make_record,
    pending_runs,
    worker_count,
)
from bench.experiment.spec import DataSpec, RunSpec, config_hash
from bench.experiment.suite import load_suite

ROOT = Path(__file__).resolve().parent.parent

SUITE = """
[suite]
name = "tiny"
cases = ["analytic-linear"]
methods = ["lm"]
seeds = [0, 1, 2]
starts = ["random"]
budgets = [40]
"""


def _suite(tmp_path, text=SUITE):
    path = tmp_path / "tiny.toml"
    path.write_text(text)
    return path


def _edit(path, change):
    rec = json.loads(path.read_text())
    change(rec)
    path.write_text(json.dumps(rec, sort_keys=True, separators=(",", ":")))


# --- content hash and config of a record ---------------------------------------------------


def test_an_edited_record_is_torn_set_aside_rerun_and_reported(tmp_path, capsys):
    suite = _suite(tmp_path)
    out = tmp_path / "res"
    assert cli(["run", str(suite), "--out", str(out), "--quiet", "--workers", "1"]) == 0
    recs = {r["config_hash"]: r for r in store.load_records(out)}
    assert len(recs) == 3 and all(r["digest"] == store.record_digest(r) for r in recs.values())
    h_x, h_budget, h_legacy = sorted(recs)
    x_true = recs[h_x]["result"]["x"]

    def wrong_x(rec):  # a plausible wrong answer
        rec["result"]["x"] = [1.01 * v for v in rec["result"]["x"]]

    def wrong_budget(rec):  # a plausible wrong budget, digest recomputed by the editor
        rec["config"]["budget"] = 400
        rec["digest"] = store.record_digest(rec)

    _edit(store.record_path(out, h_x), wrong_x)
    _edit(store.record_path(out, h_budget), wrong_budget)
    _edit(store.record_path(out, h_legacy), lambda rec: rec.pop("digest"))  # before digests
    records, unreadable = store.scan_records(out)
    assert [r["config_hash"] for r in records] == [h_legacy]  # legacy: still readable
    why = {p.stem: w for p, w in unreadable}
    assert "content hash mismatch" in why[h_x]
    assert "config does not match the file name" in why[h_budget]

    assert cli(["report", str(out), "--no-figures", "--quiet", "--format", "md"]) == 0
    err = capsys.readouterr().err
    assert f"{h_x}.json" in err and f"{h_budget}.json" in err  # named by the report
    assert cli(["run", str(suite), "--out", str(out), "--quiet", "--workers", "1"]) == 0
    assert "2 unreadable record(s) moved" in capsys.readouterr().out
    again = {r["config_hash"]: r for r in store.load_records(out)}
    assert sorted(again) == sorted(recs) and again[h_x]["result"]["x"] == x_true
    assert len(store.set_aside_files(out)) == 2
    md = (out / "report").exists() and cli(["report", str(out), "--no-figures", "--quiet"])
    assert md == 0
    text = (out / "report" / "report.md").read_text()
    assert text.count("kept aside by 'femubench run'") == 2


# --- records made on other data ---------------------------------------------------------------


def _fe_record(data_hash):
    cfg = RunSpec("linear-shear", "lm", 0, "default", 0, 10, "coarse", data=DataSpec("consistent"))
    rec = make_record(cfg, failed_result(cfg, "fake"), suite="fe", data_hash=data_hash)
    rec["error"] = None
    return cfg, rec


FE_SUITE = """
[suite]
name = "fe"
cases = ["linear-shear"]
methods = ["lm"]
budgets = [10]
tiers = ["consistent"]
"""


def test_records_made_on_other_data_are_set_aside_and_rerun(tmp_path, monkeypatch):
    from problems.inverse import data as D

    suite = load_suite(_suite(tmp_path, FE_SUITE))
    cfg, _ = _fe_record(None)
    assert [config_hash(r) for r in suite.runs()] == [config_hash(cfg)]
    shipped = current_data_hash(cfg)
    assert shipped == D.get_data("linear-shear", D.tier_settings("consistent")).hash
    out = tmp_path / "res"
    for stored, pending in ((shipped, 0), (None, 0), ("0" * 64, 1)):  # None: a legacy record
        store.write_record(out, _fe_record(stored)[1])
        assert len(pending_runs(suite, out)[1]) == pending

    # the same data set changed in another FEMUBENCH_DATA_DIR: the shipped-data record is stale
    store.write_record(out, _fe_record(shipped)[1])
    ds = D.get_data("linear-shear", D.tier_settings("consistent"))
    other = dataclasses.replace(ds, u_h=ds.u_h * 1.001)
    D.save(other, tmp_path / "data" / "consistent" / "linear-shear.json")
    monkeypatch.setenv(D.DATA_DIR_ENV, str(tmp_path / "data"))
    assert current_data_hash(cfg) == other.hash != shipped
    assert len(pending_runs(suite, out)[1]) == 1
    from bench.experiment.runner import set_aside_stale

    moved = set_aside_stale(suite.runs(), out, store.scan_records(out)[0])
    assert [p.parent.name for p in moved] == ["stale"] and not store.has_record(out, cfg.hash)
    monkeypatch.setenv(D.DATA_DIR_ENV, str(tmp_path / "empty"))  # no file: accepted as made
    assert current_data_hash(cfg) is None


def test_a_record_of_a_re_pointed_tier_is_stale_before_its_data_set_exists(tmp_path, monkeypatch):
    """A non-default data set is made when its first run runs, so its hash is unknown before:
    the data mesh in the record's provenance decides (a tier re-pointed to another mesh, any
    spelling of the same mesh passing)."""
    from bench.experiment.runner import current_data_mesh, stale_records
    from problems.inverse import data as D

    monkeypatch.setenv(D.DATA_DIR_ENV, str(tmp_path / "empty"))
    cfg, _ = _fe_record(None)
    assert current_data_hash(cfg) is None and current_data_mesh(cfg) == "6,6,12"

    def record(data_mesh):
        rec = _fe_record("f" * 64)[1]
        rec["result"]["provenance"]["data_mesh"] = data_mesh
        return {config_hash(cfg): rec}

    assert stale_records([cfg], record("coarse:eighth")) == []  # the same mesh spelt otherwise
    ((_, why),) = stale_records([cfg], record("12,12,24:g8:hex27"))
    assert why == "made on data of mesh 12,12,24:g8:hex27, today's data mesh is 6,6,12"
    legacy = record("12,12,24:g8:hex27")
    del legacy[config_hash(cfg)]["result"]["provenance"]["data_mesh"]
    assert stale_records([cfg], legacy) == []  # nothing to compare: accepted


def test_the_report_says_whether_the_runs_of_set_aside_records_were_made_again(tmp_path):
    """A record set aside as made on other data is either rerun or missing: the completeness
    note counts which (it used to say "run again" whatever happened)."""
    from types import SimpleNamespace

    from bench.report.completeness import section_completeness

    suite = _suite(tmp_path)
    out = tmp_path / "res"
    assert cli(["run", str(suite), "--out", str(out), "--quiet", "--workers", "1"]) == 0
    first = sorted(store.scan_records(out)[0], key=lambda r: r["config_hash"])[0]
    store.set_aside(store.record_path(out, first["config_hash"]), store.STALE)
    note = "".join(section_completeness(SimpleNamespace(source=out)))
    assert "| tiny | 3 | 2 | 0 | 1 |" in note
    assert "1 record(s) made on other data than today's were set aside in `runs/stale/`; " in note
    assert "0 of their runs have a record made again" in note
    assert cli(["run", str(suite), "--out", str(out), "--quiet", "--workers", "1"]) == 0
    note = "".join(section_completeness(SimpleNamespace(source=out)))
    assert "| tiny | 3 | 3 | 0 | 0 |" in note and "1 of their runs have a record made again" in note


# --- planned vs present, crashes --------------------------------------------------------------


def test_report_names_missing_and_crashed_runs_and_run_exits_1_on_crashes(tmp_path, capsys):
    suite = _suite(tmp_path)
    out = tmp_path / "res"
    assert cli(["run", str(suite), "--out", str(out), "--quiet", "--workers", "1"]) == 0
    plan = json.loads((out / "tiny.plan.json").read_text())
    labels = [r.label for r in load_suite(suite).runs()]
    assert [p["label"] for p in plan["runs"]] == labels
    first, second, _ = sorted(plan["runs"], key=lambda p: p["label"])
    store.record_path(out, first["hash"]).unlink()  # lost (a kill before it was written)
    cfg = RunSpec.from_dict(
        json.loads(store.record_path(out, second["hash"]).read_text())["config"]
    )
    crash = make_record(cfg, failed_result(cfg, "KilledWorker"), suite="tiny", error="KilledWorker")
    store.write_record(out, crash)  # a worker killed under it

    assert cli(["report", str(out), "--no-figures", "--quiet", "--format", "md"]) == 0
    md = (out / "report" / "report.md").read_text()
    section = md.split("## Completeness")[1].split("\n## ")[0]
    assert "| tiny | 3 | 2 | 1 | 1 |" in section
    assert f"missing `{first['label']}`" in section and f"crashed `{second['label']}`" in section
    capsys.readouterr()

    assert cli(["run", str(suite), "--out", str(out), "--quiet", "--workers", "1"]) == 1
    err = capsys.readouterr().err
    assert second["label"] in err and "--retry-failed" in err
    assert store.has_record(out, first["hash"])  # the lost run ran
    args = ["run", str(suite), "--out", str(out), "--quiet", "--workers", "1", "--retry-failed"]
    assert cli(args) == 0
    assert not any(r.get("error") for r in store.load_records(out))
    assert cli(["report", str(out), "--no-figures", "--quiet", "--format", "md"]) == 0
    assert "Every planned run has a record." in (out / "report" / "report.md").read_text()


# --- workers, results root ---------------------------------------------------------------------


def test_workers_are_capped_at_cores_and_pending_runs(tmp_path, capsys, monkeypatch):
    assert worker_count(10000, 12) == min(default_workers(), 12)
    assert worker_count(20, 1) == 1 and worker_count(None, 0) == 1
    monkeypatch.setenv("FEMUBENCH_RESULTS_DIR", str(tmp_path / "root"))
    suite = _suite(tmp_path)
    assert cli(["run", str(suite), "--workers", "10000", "--quiet"]) == 0  # in-process: no hang
    err = capsys.readouterr().err
    assert f"--workers 10000: capped at {min(default_workers(), 3)}" in err
    assert len(store.load_records(tmp_path / "root" / "tiny")) == 3  # FEMUBENCH_RESULTS_DIR
    assert not (Path.cwd() / "results" / "tiny").exists()


# --- Ctrl-C on a local cluster -----------------------------------------------------------------


SLOW = """
[suite]
name = "slow"
cases = ["analytic-smooth"]
methods = ["lm", "gauss-newton"]
seeds = [0, 1, 2, 3]
starts = ["random"]
budgets = [80]
"""
SLOW_CLI = (
    "import sys, time, problems.inverse.analytic as a\n"
    "cls = a.StressStrainModel\n"
    "def slow(self, x, _f=cls.__call__):\n"
    "    time.sleep(0.05)\n"
    "    return _f(self, x)\n"
    "cls.__call__ = slow\n"
    "from bench.cli import main\n"
    "raise SystemExit(main(sys.argv[1:]))\n"
)


@pytest.mark.slow
def test_ctrl_c_on_a_local_cluster_is_one_clean_line_and_exit_130(tmp_path):
    suite = _suite(tmp_path, SLOW)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-c", SLOW_CLI, "run", str(suite), "--out", str(tmp_path / "r")]
    proc = subprocess.Popen(
        cmd + ["--workers", "2", "--quiet"],
        cwd=tmp_path,
        env=env,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    deadline = time.time() + 120
    while time.time() < deadline and not list((tmp_path / "r" / "runs").glob("*.json")):
        time.sleep(0.2)  # the cluster is up and the first run has finished
    os.killpg(proc.pid, signal.SIGINT)  # what a terminal's Ctrl-C does: the whole group
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert "interrupted" in err


# --- disk full while a record is written; a torn data cache -------------------------------


def test_disk_full_during_a_run_names_the_record_path_and_leaves_nothing_torn(
    tmp_path, capsys, monkeypatch
):
    import errno

    from problems.io import atomic

    def full(fh):
        fh.write("{half a record")
        raise OSError(errno.ENOSPC, "No space left on device")

    def record_writer(path, text):  # the disk fills up when the first record is written
        if path.parent.name == "runs":
            return atomic.atomic_write(path, full, binary=False)
        return atomic.atomic_write_text(path, text)

    out = tmp_path / "res"
    monkeypatch.setattr(store, "atomic_write_text", record_writer)
    assert cli(["run", str(_suite(tmp_path)), "--out", str(out), "--quiet", "--workers", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "[Errno 28] No space left on device" in err
    assert f"{out / 'runs'}/" in err and ".json'" in err  # the record that could not be written
    monkeypatch.undo()
    assert store.scan_records(out) == ([], []) and store.stray_tmp(out) == []
    assert cli(["run", str(_suite(tmp_path)), "--out", str(out), "--quiet", "--workers", "1"]) == 0
    assert len(store.load_records(out)) == 3


def test_a_torn_data_cache_is_set_aside_and_made_again(tmp_path, monkeypatch):
    from problems.inverse import data as D

    monkeypatch.setenv("FEMUBENCH_CACHE_DIR", str(tmp_path))
    settings = D.tier_settings("consistent", seed=7)  # not the shipped settings: a cache
    path = D.cached_path("linear-shear", settings)
    made = D.get_data("linear-shear", D.tier_settings("consistent"))
    path.write_text(made.to_json()[:500])  # killed while writing (before the atomic writer)
    monkeypatch.setattr(D, "make_data", lambda *a, **k: made)
    with pytest.warns(UserWarning, match=f"data file {path}.*moved to {path}.torn"):
        assert D.get_data("linear-shear", settings).hash == made.hash
    assert D.load(path).hash == made.hash and (tmp_path / f"{path.name}.torn").is_file()

"""Results store and runner: atomic records, resume, --force, crashes as records, tidy frames."""

from __future__ import annotations

import json
import os

import pytest

from bench.experiment import store
from bench.experiment.runner import run_one, run_suite
from bench.experiment.spec import RunSpec, config_hash
from bench.experiment.suite import parse_suite

SUITE = {
    "suite": {
        "name": "tiny",
        "cases": ["analytic-smooth", "analytic-linear"],
        "methods": ["lm"],
        "seeds": [0],
        "starts": ["default", "random"],
        "budgets": [60],
    }
}


def test_atomic_write_leaves_no_partial_file_when_the_writer_dies(tmp_path, monkeypatch):
    path = tmp_path / "runs" / "abc.json"
    store.atomic_write_text(path, "first\n")

    def boom(fd):  # the writer dies between writing and renaming
        raise OSError("disk on fire")

    monkeypatch.setattr(os, "fsync", boom)
    with pytest.raises(OSError):
        store.atomic_write_text(path, "second, longer content\n")
    assert path.read_text() == "first\n"  # the old content, whole
    assert list(path.parent.glob("*.tmp")) == []


def test_loaders_ignore_stray_tmp_files_and_report_them(tmp_path, caplog):
    cfg = RunSpec("analytic-linear", "lm", 0, "default", 0, 50, "coarse")
    store.write_record(tmp_path, run_one(cfg, suite="t"))
    (tmp_path / "runs" / ".deadbeef.x1.tmp").write_text('{"config_hash": "deadb')  # a killed writer
    with caplog.at_level("WARNING", logger="femubench.store"):
        recs = store.load_records(tmp_path)
    assert [r["config_hash"] for r in recs] == [config_hash(cfg)]
    assert "1 stray temporary file" in caplog.text
    assert store.clean_tmp(tmp_path) == 1 and store.stray_tmp(tmp_path) == []


def test_record_content(tmp_path):
    cfg = RunSpec("analytic-smooth", "lm", 0, "random", 1, 60, "coarse")
    rec = run_one(cfg, suite="t")
    assert rec["config_hash"] == config_hash(cfg) and rec["config"] == cfg.to_dict()
    assert rec["error"] is None and rec["suite"] == "t"
    res = rec["result"]
    assert res["method"] == "lm" and res["budget"] == 60 and 0 < res["n_evals"] <= 60
    assert res["parameter_names"] == ["E", "sigma0", "H", "psi"]
    assert {"numpy", "scipy", "python"} <= set(rec["versions"])
    assert {"hostname", "platform", "cpu_count"} <= set(rec["machine"])
    assert rec["started"] <= rec["finished"]
    assert "data_hash" in rec
    # random start 1 of seed 0 differs from the default start and from random start 0
    x0_r1 = res["x0"]
    x0_r0 = run_one(RunSpec("analytic-smooth", "lm", 0, "random", 0, 5, "coarse"))["result"]["x0"]
    x0_d = run_one(RunSpec("analytic-smooth", "lm", 0, "default", 0, 5, "coarse"))["result"]["x0"]
    assert x0_r1 != x0_r0 and x0_r1 != x0_d
    path = store.write_record(tmp_path, rec)
    assert path.name == f"{rec['config_hash']}.json"
    back = store.read_record(path)
    assert back.pop("digest") == store.record_digest(rec)  # the content hash, added on write
    assert back == json.loads(json.dumps(rec))


def test_a_crash_becomes_a_failed_record_and_never_stops_the_suite(tmp_path, monkeypatch):
    import solvers

    real = solvers.solve

    def flaky(objective, method, **kw):
        if objective.n_params == 3:  # analytic-linear
            raise RuntimeError("solver exploded")
        return real(objective, method, **kw)

    monkeypatch.setattr(solvers, "solve", flaky)
    suite = parse_suite(SUITE)
    summary = run_suite(suite, tmp_path, workers=1, progress=False)
    assert summary.ran == 4 and summary.crashed == 2
    runs, _ = store.to_frames(tmp_path)
    crashed = runs[runs["crashed"]]
    assert set(crashed["case"]) == {"analytic-linear"} and (crashed["status"] == "failed").all()
    assert all(
        "RuntimeError: solver exploded" in m and "Traceback" in m for m in crashed["message"]
    )
    assert (runs.loc[~runs["crashed"], "status"] != "failed").all()
    assert "solver exploded" in (tmp_path / "tiny.log").read_text()

    # resume: nothing to do; --retry-failed reruns only the crashed ones (now they work)
    monkeypatch.setattr(solvers, "solve", real)
    assert run_suite(suite, tmp_path, workers=1, progress=False).ran == 0
    again = run_suite(suite, tmp_path, workers=1, progress=False, retry_failed=True)
    assert again.ran == 2 and again.crashed == 0
    assert not store.to_frames(tmp_path)[0]["crashed"].any()


def test_unknown_case_at_run_time_is_a_failed_record_not_an_exception():
    rec = run_one(RunSpec("no-such-case", "lm", 0, "default", 0, 10, "coarse"))
    assert rec["result"]["status"] == "failed" and "no-such-case" in rec["result"]["message"]
    assert rec["error"]


def test_a_crashed_run_records_the_start_it_was_given():
    from problems.inverse.cases import get_case
    from problems.inverse.starts import start_point

    rec = run_one(RunSpec("analytic-smooth", "no-such-method", 2, "random", 1, 10))
    res = rec["result"]
    assert res["status"] == "failed" and "no-such-method" in res["message"]
    x0 = start_point(get_case("analytic-smooth"), kind="random", seed=2, index=1)
    assert res["x0"] == res["x"] == [float(v) for v in x0]


def test_resume_and_force(tmp_path):
    suite = parse_suite(SUITE)
    first = run_suite(suite, tmp_path, workers=1, progress=False)
    assert (first.total, first.skipped, first.ran) == (4, 0, 4)
    stamps = {r["config_hash"]: r["finished"] for r in store.load_records(tmp_path)}
    # a bigger suite sharing the directory runs only the new runs (lm is deterministic: the
    # second seed adds only its random starts)
    bigger = parse_suite({"suite": {**SUITE["suite"], "seeds": [0, 1]}})
    second = run_suite(bigger, tmp_path, workers=1, progress=False)
    assert (second.total, second.skipped, second.ran) == (6, 4, 2)
    assert {
        h: f
        for h, f in ((r["config_hash"], r["finished"]) for r in store.load_records(tmp_path))
        if h in stamps
    } == stamps  # finished runs untouched
    forced = run_suite(suite, tmp_path, workers=1, progress=False, force=True)
    assert forced.ran == 4 and len(store.load_records(tmp_path)) == 6
    assert sorted(store.done_hashes(tmp_path)) == sorted(config_hash(r) for r in bigger.runs())


def test_frames_are_tidy(tmp_path):
    suite = parse_suite(SUITE)
    run_suite(suite, tmp_path, workers=1, progress=False)
    runs, hist = store.to_frames(tmp_path)
    assert len(runs) == 4 and runs["config_hash"].is_unique
    assert {
        "case",
        "method",
        "seed",
        "start",
        "start_index",
        "budget",
        "cost",
        "n_evals",
        "wall_s",
        "err.E",
        "err.p",
        "xn.psi",
        "x0.H",
        "data_hash",
    } <= set(runs.columns)
    smooth = runs[runs["case"] == "analytic-smooth"]
    assert smooth["err.p"].isna().all() and smooth["err.E"].notna().all()  # inactive -> NaN
    assert (
        len(hist)
        == sum(len(r["result"]["history"]) for r in store.load_records(tmp_path))
        > len(runs)
    )
    assert set(hist["config_hash"]) == set(runs["config_hash"])
    assert (hist.groupby("config_hash")["n_evals"].apply(lambda s: s.is_monotonic_increasing)).all()
    paths = store.write_parquet(tmp_path)
    import pandas as pd

    back = pd.read_parquet(paths[0])
    assert len(back) == 4 and list(back.columns) == list(runs.columns)


def test_two_runners_cannot_share_a_directory(tmp_path):
    from bench.experiment.runner import _dir_lock

    with _dir_lock(tmp_path):
        with pytest.raises(ValueError, match="another 'femubench run' is writing"):
            run_suite(parse_suite(SUITE), tmp_path, workers=1, progress=False)


def test_a_data_set_that_cannot_be_made_fails_its_runs_only(tmp_path, monkeypatch):
    import bench.experiment.runner as runner

    def broken(cfg, **kw):
        raise RuntimeError(f"data model of {cfg.case} did not converge")

    monkeypatch.setattr(runner, "dataset_for", broken)
    suite = parse_suite(
        {
            "suite": {
                "name": "d",
                "cases": ["linear-compression", "analytic-linear"],
                "methods": ["lm"],
                "budgets": [20],
            },
            "data": {"noise_um": 1.0},
        }
    )
    summary = run_suite(suite, tmp_path, workers=1, progress=False)
    assert summary.ran == 2 and summary.crashed == 1
    runs, _ = store.to_frames(tmp_path)
    fe = runs[runs["case"] == "linear-compression"].iloc[0]
    assert fe["crashed"] and fe["status"] == "failed" and "did not converge" in fe["message"]
    assert fe["data.noise_um"] == 1.0 and fe["n_evals"] == 0
    # analytic runs need no data set
    assert not runs[runs["case"] == "analytic-linear"]["crashed"].any()


def test_dry_run_counts_and_runs_nothing(tmp_path, capsys):
    from bench.cli import main

    suite = tmp_path / "s.toml"
    suite.write_text(
        '[suite]\ncases = ["analytic-smooth"]\nmethods = ["lm", "gauss-newton"]\n'
        'seeds = [0, 1]\nstarts = ["default", "random"]\nrandom_starts = 3\nbudgets = [50]\n'
    )
    assert main(["run", str(suite), "--out", str(tmp_path / "o"), "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert (
        "14 runs, 0 with a record" in out  # deterministic: one default start for both seeds
        and "14 to run" in out
        and "at most 700 evaluations (0 of an FE model)" in out
    )
    assert not (tmp_path / "o" / "runs").exists()


CORRUPTIONS = {
    "truncated": lambda text: text[: len(text) // 2],
    "empty": lambda text: "",
    "garbage": lambda text: "\x00\x17 not json at all {{{",
    "wrong shape": lambda text: json.dumps([{"config_hash": "x"}]),
    "other hash": lambda text: text.replace('"config_hash":"', '"config_hash":"0', 1),
}


@pytest.mark.parametrize("kind", sorted(CORRUPTIONS))
def test_an_unreadable_record_is_moved_aside_rerun_and_reported(tmp_path, kind, capsys):
    from bench.report import write_report

    suite = parse_suite(SUITE)
    run_suite(suite, tmp_path, workers=1, progress=False)
    victim = store.record_path(tmp_path, config_hash(suite.runs()[0]))
    bad = CORRUPTIONS[kind](victim.read_text())
    victim.write_text(bad)
    assert victim.stem not in store.done_hashes(tmp_path)
    assert len(store.scan_records(tmp_path)[1]) == 1

    # before the rerun: the record is left out, and named
    write_report(tmp_path, ["md"], figures=False)
    err = capsys.readouterr().err
    assert f"unreadable record {victim} left out" in err
    md = (tmp_path / "report" / "report.md").read_text()
    assert "## Unreadable records" in md and f"runs/{victim.name} left out" in md
    assert "**3 runs**" in md

    summary = run_suite(suite, tmp_path, workers=1, progress=False)
    assert summary.skipped == 3 and summary.ran == 1  # the torn run is run again, the others not
    (aside,) = store.set_aside_files(tmp_path)
    assert aside.parent == store.corrupt_dir(tmp_path) and aside.name.startswith(
        f"{victim.name}.corrupt-"
    )
    assert aside.read_text() == bad  # kept as found, for inspection
    assert summary.set_aside == [aside] and "1 unreadable record(s) moved to" in str(summary)
    log = (tmp_path / "tiny.log").read_text()
    assert f"unreadable record {victim.name}" in log and str(aside) in log
    assert len(store.load_records(tmp_path)) == 4 and store.scan_records(tmp_path)[1] == []

    # after the rerun: complete, the file kept aside is named
    write_report(tmp_path, ["md"], figures=False)
    assert (
        f"kept aside by 'femubench run' (its run was run again): {aside}" in capsys.readouterr().err
    )
    md = (tmp_path / "report" / "report.md").read_text()
    assert "**4 runs**" in md and f"runs/corrupt/{aside.name}" in md

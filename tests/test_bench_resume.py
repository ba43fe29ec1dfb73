"""Interrupting a suite with SIGKILL, resuming it, and Dask vs in-process runs."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from bench.experiment import store
from bench.experiment.runner import run_suite
from bench.experiment.spec import config_hash
from bench.experiment.suite import load_suite
from bench.report import write_report

ROOT = Path(__file__).resolve().parent.parent

SUITE = """
[suite]
name = "killme"
cases = ["analytic-smooth", "analytic-linear"]
methods = ["lm", "gauss-newton"]
seeds = [0, 1, 2]
starts = ["random"]
random_starts = 3
budgets = [80]
"""
# `python -m bench` with every analytic forward evaluation slowed down by 3 ms, so that the
# suite takes a few seconds and the kill lands part-way (the results are unchanged).
SLOW_CLI = (
    "import sys, time, problems.inverse.analytic as a\n"
    "for cls in (a.StressStrainModel, a.LinearModel):\n"
    "    def slow(self, x, _f=cls.__call__):\n"
    "        time.sleep(0.003)\n"
    "        return _f(self, x)\n"
    "    cls.__call__ = slow\n"
    "from bench.cli import main\n"
    "raise SystemExit(main(sys.argv[1:]))\n"
)


def _comparable_records(out_dir):
    """Records without times, machine and versions (the shared checkout's HEAD may move while a
    test runs), keyed by config hash."""
    out = {}
    for rec in store.load_records(out_dir):
        rec = json.loads(json.dumps(rec))
        for key in ("started", "finished", "machine", "versions", "digest"):  # digest: of all
            rec.pop(key)
        rec["result"].pop("wall_s")
        for row in rec["result"].get("history", []):
            row.pop("wall_s", None)
        rec["result"].get("extra", {}).pop("wall_s", None)
        out[rec["config_hash"]] = rec
    return out


def _tables(out_dir):
    """Report tables that do not depend on timing: Table 1 per method, success matrix and the
    comparison table without its wall-time column."""
    rep = Path(out_dir) / "report" / "tables"
    out = {p.name: p.read_text() for p in sorted(rep.glob("table1__*.csv")) + [rep / "success.csv"]}
    import pandas as pd

    out["comparison"] = pd.read_csv(rep / "comparison.csv").drop(columns=["wall_median_s"]).to_csv()
    return out


def test_sigkill_part_way_then_resume_gives_the_uninterrupted_result(tmp_path):
    suite_file = tmp_path / "killme.toml"
    suite_file.write_text(SUITE)
    suite = load_suite(suite_file)
    expected = {config_hash(r) for r in suite.runs()}
    assert len(expected) == 36

    out = tmp_path / "interrupted"
    cmd = [
        sys.executable,
        "-c",
        SLOW_CLI,
        "run",
        str(suite_file),
        "--out",
        str(out),
        "--workers",
        "1",
        "--quiet",
    ]
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.Popen(
        cmd,
        cwd=ROOT,
        env=env,
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    deadline = time.monotonic() + 60
    try:
        while len(store.done_hashes(out)) < 5:
            assert proc.poll() is None, (
                f"suite ended before the kill: {proc.stderr.read().decode()}"
            )
            assert time.monotonic() < deadline, "no record appeared in 60 s"
            time.sleep(0.005)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the whole process tree, at an arbitrary moment
        proc.wait()
    assert proc.returncode == -signal.SIGKILL
    # all parse: no partial record
    before = {r["config_hash"]: r["finished"] for r in store.load_records(out)}
    assert 5 <= len(before) < len(expected), "the kill did not land part-way"
    assert set(before) <= expected

    p = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert f"{len(before)} already done, {len(expected) - len(before)} run now" in p.stdout
    records = store.load_records(out)
    hashes = [r["config_hash"] for r in records]
    # each run exactly once
    assert len(hashes) == len(set(hashes)) == len(expected) and set(hashes) == expected
    assert all(store.record_path(out, r["config_hash"]).stem == config_hash_of(r) for r in records)
    assert store.stray_tmp(out) == []
    assert {
        h: f for h, f in ((r["config_hash"], r["finished"]) for r in records) if h in before
    } == before
    log = (out / "killme.log").read_text()
    assert f"{len(before)} with a record, {len(expected) - len(before)} to run" in log

    # the report equals that of an uninterrupted run (in-process, no slow-down)
    ref = tmp_path / "uninterrupted"
    run_suite(suite, ref, workers=1, progress=False)
    assert _comparable_records(ref) == _comparable_records(out)
    write_report(out, ["csv"], figures=False)
    write_report(ref, ["csv"], figures=False)
    assert _tables(out) == _tables(ref)


def test_torn_records_are_rerun_kept_aside_and_reported_by_the_cli(tmp_path, capsys):
    from bench.cli import main

    suite_file = tmp_path / "torn.toml"
    suite_file.write_text(
        '[suite]\nname = "torn"\ncases = ["analytic-linear"]\nmethods = ["lm"]\n'
        'seeds = [0, 1, 2]\nstarts = ["random"]\nbudgets = [40]\n'
    )
    out = tmp_path / "out"
    assert main(["run", str(suite_file), "--out", str(out), "--workers", "1", "--quiet"]) == 0
    paths = sorted(store.runs_dir(out).glob("*.json"))
    assert len(paths) == 3
    paths[0].write_text(paths[0].read_text()[:100])  # truncated, as by a full disk
    paths[1].write_text("")  # empty
    paths[2].write_bytes(b"\xff\xfe garbage")  # not even text
    capsys.readouterr()

    # nothing readable: an error ...
    assert main(["report", str(out), "--format", "md", "--no-figures"]) == 2
    err = capsys.readouterr().err
    # ... naming every bad file
    assert all(f"unreadable record {p} left out" in err for p in paths)
    assert "(3 unreadable)" in err

    assert main(["run", str(suite_file), "--out", str(out), "--workers", "1", "--quiet"]) == 0
    stdout = capsys.readouterr().out
    assert "0 already done, 3 run now" in stdout and "3 unreadable record(s) moved to" in stdout
    aside = store.set_aside_files(out)
    assert sorted(p.name.split(".corrupt-")[0] for p in aside) == [p.name for p in paths]
    assert len(store.load_records(out)) == 3
    log = (out / "torn.log").read_text()
    assert all(f"moved to {a}" in log for a in aside)

    assert main(["report", str(out), "--format", "md", "--no-figures"]) == 0
    err = capsys.readouterr().err
    md = (out / "report" / "report.md").read_text()
    for a in aside:
        assert str(a) in err and f"runs/corrupt/{a.name}" in md


def config_hash_of(record) -> str:
    from bench.experiment.spec import RunSpec

    return config_hash(RunSpec.from_dict(record["config"]))


def test_dask_local_cluster_gives_the_same_records_as_in_process(tmp_path):
    suite = load_suite_text(
        tmp_path,
        """
[suite]
name = "dask"
cases = ["analytic-smooth", "analytic-multimodal"]
methods = ["lm", "gauss-newton"]
seeds = [0, 1]
starts = ["default", "random"]
budgets = [60]
""",
    )
    one = run_suite(suite, tmp_path / "one", workers=1, progress=False)
    two = run_suite(suite, tmp_path / "two", workers=2, progress=False)
    assert one.ran == two.ran == len(suite) == 12  # 2 x 2 x (1 default + 2 seeds x 1 random)
    a, b = _comparable_records(tmp_path / "one"), _comparable_records(tmp_path / "two")
    assert a.keys() == b.keys() and a == b
    machines = {r["machine"]["omp_num_threads"] for r in store.load_records(tmp_path / "two")}
    assert machines == {"1"}  # BLAS/OpenMP pinned to one thread in the workers


def test_existing_scheduler_with_fan_out_gives_the_same_records(tmp_path):
    from distributed import LocalCluster

    suite = load_suite_text(
        tmp_path,
        """
[suite]
name = "sched"
cases = ["analytic-smooth"]
methods = ["lm", "ga"]
seeds = [3]
budgets = [60]
""",
    )
    run_suite(suite, tmp_path / "one", workers=1, progress=False)
    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
    ) as cluster:
        s = run_suite(
            suite,
            tmp_path / "sched",
            scheduler=cluster.scheduler_address,
            fan_out=True,
            progress=False,
        )
    assert s.ran == 2 and s.crashed == 0
    assert _comparable_records(tmp_path / "one") == _comparable_records(tmp_path / "sched")


def load_suite_text(tmp_path, text):
    p = tmp_path / "suite.toml"
    p.write_text(text)
    return load_suite(p)

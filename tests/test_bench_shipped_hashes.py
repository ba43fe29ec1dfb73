"""The run hashes of the shipped suites are the names of their shipped records: the run spec
(bench.experiment.spec.RunSpec) and its hash must not drift, or every shipped record is
orphaned."""

from __future__ import annotations

from pathlib import Path

import pytest

from bench.experiment.suite import load_suite

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("name", ["default", "comparison"])
def test_hashes_of_the_shipped_suites_are_the_shipped_record_names(name):
    suite = load_suite(ROOT / "suites" / f"{name}.toml")
    hashes = {run.hash for run in suite.runs()}
    records = {p.stem for p in (ROOT / "results" / name / "runs").glob("*.json")}
    assert len(records) > 50  # 81 default, 1359 comparison records shipped
    assert hashes == records


@pytest.mark.parametrize("name", ["table1", "table1-margin"])
def test_every_run_of_a_shipped_study_suite_has_its_shipped_record(name):
    """Keys added to the run spec later (e.g. a suite's hifi_mesh) leave these runs' hashes as
    they were: each is the name of a record of results/studies/<name> (the folder may also hold
    records of other suites run into it, e.g. table1-first-order)."""
    hashes = {run.hash for run in load_suite(ROOT / "suites" / f"{name}.toml").runs()}
    records = {p.stem for p in (ROOT / "results" / "studies" / name / "runs").glob("*.json")}
    assert len(hashes) >= 18 and hashes <= records

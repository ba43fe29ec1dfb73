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

"""The shipped results are reproducible: a record of the shipped default suite (and of the shipped
comparison) is rerun from its stored configuration. On a machine whose arithmetic takes the same
code paths as the one that made the record (``machine.arch``: the CPU numba compiles for and the
BLAS kernels) it must give the same numbers bit for bit (parameters, cost, evaluations,
iterations); elsewhere floating-point results differ in the last digits, and the run must reach
the same answer: the same status and every parameter within 1e-6 (relative) of the record. A
change of the code that changes the answers fails here until the shipped results are regenerated
(``make run``)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from bench.experiment.spec import RunSpec

ROOT = Path(__file__).resolve().parent.parent

#: (results folder, the configuration to pick): cheap runs, one per kind of shipped run
PICKS = [
    ("results/default", {"case": "linear-compression", "method": "lm", "tier": "consistent"}),
    # needs the shipped surrogate (a release artefact, maybe absent: skipped; docs/artefacts.md)
    pytest.param(
        "results/default",
        {"case": "linear-shear", "method": "cma", "track": "surrogate"},
        marks=pytest.mark.slow,
    ),
    (
        "results/default",
        {"case": "exponent-tension", "method": "lm", "tier": "model-error", "treatment": "none"},
    ),
    # the shipped comparison (suites/comparison.toml): an FE-track run from a seeded random start
    (
        "results/comparison",
        {
            "case": "linear-compression",
            "method": "lm",
            "start": "random",
            "seed": 2,
            "jacobian": None,
        },
    ),
]


def _record(folder: str, want: dict) -> dict:
    for path in sorted((ROOT / folder / "runs").glob("*.json")):
        rec = json.loads(path.read_text())
        if all(rec["config"].get(k) == v for k, v in want.items()):
            return rec
    raise AssertionError(f"no record of {want} in {folder}/runs")


def _label(pick) -> str:
    folder, want = pick.values if hasattr(pick, "values") else pick
    return f"{folder}:{want['method']}"


@pytest.mark.parametrize("folder, want", PICKS, ids=[_label(p) for p in PICKS])
def test_a_shipped_record_is_reproduced_bit_for_bit(folder, want, tmp_path):
    from bench.experiment import store
    from bench.experiment.runner import run_one
    from bench.experiment.suite import missing_surrogates

    shipped = _record(folder, want)
    if want.get("track") == "surrogate":
        missing = missing_surrogates([RunSpec.from_dict(shipped["config"])])
        if missing:
            pytest.skip(missing[0])
    again = run_one(shipped["config"], suite=shipped.get("suite"))
    store.write_record(tmp_path, again)
    again = store.load_record(store.record_path(tmp_path, again["config_hash"]))
    assert again["config_hash"] == shipped["config_hash"]
    old, new = shipped["result"], again["result"]
    assert new["status"] == old["status"]
    if shipped["machine"].get("arch") == again["machine"]["arch"]:
        assert new["x"] == old["x"]  # bit for bit: the JSON floats are exact
        assert new["cost"] == old["cost"]
        assert (new["n_evals"], new.get("n_iterations")) == (
            old["n_evals"],
            old.get("n_iterations"),
        )
    else:
        np.testing.assert_allclose(new["x"], old["x"], rtol=1e-6, atol=0)

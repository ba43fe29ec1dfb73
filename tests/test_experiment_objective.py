"""The one assembly of a run's objective (bench/experiment/objective.py)."""

from __future__ import annotations

import pytest

from bench.experiment.identify import identify
from bench.experiment.objective import Assembly, assemble, prepare
from bench.experiment.spec import RunSpec, Treatment
from problems.inverse.model_error import HonestyError


def test_a_dishonest_high_fidelity_mesh_is_refused_before_any_high_fidelity_run(monkeypatch):
    # linear-compression's model-error data were made on converged = 15,15,30:g16:hex27: a
    # correction on it (any spelling) is refused by the one check up front (before: only after
    # the correction's runs had been made)
    def no_runs(self):
        raise AssertionError("a high-fidelity model was made before the honesty check")

    monkeypatch.setattr(Assembly, "models", no_runs)
    spec = RunSpec(
        "linear-compression",
        "lm",
        treatment=Treatment("one-point", hifi_mesh="15,15,30:hex27:g16:quarter"),
    )
    with pytest.raises(HonestyError, match="hifi model uses discretisation"):
        prepare(spec)
    with pytest.raises(HonestyError, match="hifi model uses discretisation"):
        identify(spec)


def test_the_assembly_resolves_the_default_treatment_once_and_carries_the_run_flags():
    spec = RunSpec(
        "linear-shear", "lm", treatment=Treatment("default"), jacobian="central", free_repeats=True
    )
    asm = prepare(spec)
    assert asm.spec.treatment.name == "bae" and asm.spec.treatment.plate_margin_mm == 30.0
    assert asm.hifi_mesh == "paper" and asm.region.plate_margin_mm == 30.0
    obj = asm.objective()  # uncorrected, on the FE model: no high-fidelity run
    assert obj.provenance["treatment"] == "none" and obj.provenance["region_plate_margin_mm"] == 30
    assert obj.exact_jacobian is False and obj.free_repeats is True and obj.n_evals == 0


def test_iterated_has_no_fixed_correction():
    with pytest.raises(ValueError, match="identifications only"):
        assemble(RunSpec("linear-shear", "lm", treatment=Treatment("iterated")))

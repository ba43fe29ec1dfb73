"""The report's frozen table of cases and methods (bench/report/catalogue.py) agrees with the code
it was frozen from. When this fails a case or a method changed: decide whether the reports of old
results should follow (then update the table) or not (then the change needs a new case name)."""

from __future__ import annotations

import numpy as np
import pytest

from bench.experiment import store
from bench.report import catalogue as C
from problems.inverse import cases
from solvers import METHODS


def test_cases_and_their_boxes_are_those_of_the_code():
    assert C.CASE_ORDER == tuple(cases.CASES)
    assert set(C.CASES) == set(cases.all_cases())
    for name, case in cases.all_cases().items():
        info = C.CASES[name]
        box = tuple((p.name, p.lower, p.upper, p.reference) for p in case.parameters)
        assert info.parameters == box, name
        assert info.analytic == case.is_analytic, name
        d = cases.default_treatment(name)
        assert info.default_treatment == (d.treatment, d.plate_margin_mm, d.hifi_mesh), name
        assert C.case_facts(name) == store.case_facts(name), name


@pytest.mark.parametrize("name", [n for n, c in cases.all_cases().items() if c.derive is not None])
def test_derived_a_is_the_cases_own_to_the_bit(name):
    case, info = cases.all_cases()[name], C.CASES[name]
    rng = np.random.default_rng(3)
    lo, hi = (
        np.array([p.lower for p in case.parameters]),
        np.array([p.upper for p in case.parameters]),
    )
    for x in [np.array(case.reference)] + list(lo + rng.random((50, len(lo))) * (hi - lo)):
        assert info.derived(x) == {"a": case.material_parameters(x)["a"]}
    x = np.array(case.reference)
    x[case.names.index("sigma0")] *= -1
    with pytest.raises(ValueError):
        case.material_parameters(x)
    with pytest.raises(ValueError):
        info.derived(x)


def test_methods_labels_and_the_paper_range_are_those_of_the_code():
    assert C.METHOD_FAMILIES == {name: m.family for name, m in METHODS.items()}
    assert C.family("lm") == "local" and C.family("no-such-solver") == "other"
    assert C.PAPER_A_ERROR == cases.PAPER_A_ERROR

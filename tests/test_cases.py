"""The nine cases: names, parameters, reference values, bounds, starts."""

import json
import math

import numpy as np
import pytest

from problems.inverse.cases import A_REF, CASES, get_case
from problems.materials.drucker_prager import hyperbolic_l0


def test_nine_cases_with_the_paper_active_parameters():
    assert sorted(CASES) == sorted(
        f"{f}-{h}"
        for f in ("linear", "hyperbolic", "exponent")
        for h in ("compression", "shear", "tension")
    )
    assert CASES["linear-shear"].names == ("E", "beta", "K", "psi", "sigma0", "H")
    assert CASES["hyperbolic-tension"].names == ("E", "beta", "psi", "sigma0", "H", "pt0")
    # the exponent form identifies its hydrostatic tension strength pt0 in place of a
    assert CASES["exponent-compression"].names == ("E", "psi", "sigma0", "H", "pt0", "b")


@pytest.mark.parametrize("hardening", ["compression", "shear", "tension"])
def test_exponent_cases_derive_the_papers_a_exactly(hardening):
    case = CASES[f"exponent-{hardening}"]
    mat = case.material_parameters(case.reference)
    assert "pt0" not in mat and math.isclose(mat["a"], A_REF, rel_tol=1e-12)  # the same concrete
    x = case.reference * np.array([1.1, 0.9, 1.2, 0.8, 0.85, 1.15])
    names = ("E", "psi", "sigma0", "H", "a", "b", "nu")
    J = case.material_jacobian(x, names)
    for j in range(6):
        h = 1e-6 * x[j]
        up, dn = x.copy(), x.copy()
        up[j] += h
        dn[j] -= h
        fd = [
            (case.material_parameters(up)[n] - case.material_parameters(dn)[n]) / (2 * h)
            for n in names
        ]
        np.testing.assert_allclose(J[:, j], fd, rtol=1e-7, atol=1e-12)


@pytest.mark.parametrize("name", list(CASES))
def test_at_least_95_percent_of_every_box_is_a_well_posed_material(name):
    from problems.materials.drucker_prager import validate_parameters

    case = CASES[name]
    ok = 0
    X = case.random_starts(1000, seed=7)
    for x in X:
        try:
            validate_parameters(case.form, case.hardening, case.material_parameters(x))
            ok += 1
        except ValueError:
            pass
    assert ok / len(X) >= 0.95


def test_exponent_a_gives_2_5_MPa_hydrostatic_tension():
    assert abs(A_REF - 0.1025) < 5e-5
    assert math.isclose(A_REF * 20.0**1.5 - 20.0 / 3.0, 2.5, rel_tol=1e-12)


def test_shear_and_tension_variants_describe_the_same_initial_surface():
    tb = math.tan(math.radians(35.0))
    K = 0.85
    d = (1 - tb / 3) * 20.0
    st = CASES["linear-tension"].reference[4]
    tau = CASES["linear-shear"].reference[4]
    assert math.isclose((1 / K + tb / 3) * st, d, rel_tol=1e-12)
    assert math.isclose(math.sqrt(3) / 2 * (1 + 1 / K) * tau, d, rel_tol=1e-12)
    l0 = hyperbolic_l0("compression", 20.0, 2.5, 35.0)
    d0 = l0 + 2.5 * tb
    assert math.isclose(math.sqrt(l0**2 + 20.0**2) - 20.0 * tb / 3, d0, rel_tol=1e-12)
    st = CASES["hyperbolic-tension"].reference[3]
    assert math.isclose(math.sqrt(l0**2 + st**2) + st * tb / 3, d0, rel_tol=1e-10)
    tau = CASES["exponent-shear"].reference[2]
    assert math.isclose(A_REF * (math.sqrt(3) * tau) ** 1.5, 2.5, rel_tol=1e-12)
    for case in CASES.values():  # H / sigma0 = 75 throughout
        ref = dict(zip(case.names, case.reference))
        assert math.isclose(ref["H"] / ref["sigma0"], 75.0, rel_tol=1e-12)


def test_bounds_and_default_start_follow_the_rules():
    c = CASES["linear-compression"]
    assert np.allclose(c.lower, [15_000, 20, 0.778, 5, 14, 750])
    assert np.allclose(c.upper, [45_000, 50, 1.0, 30, 26, 2250])
    # reference x (1 + 0.25 s), s = +1, -1, ...; K = 1.0625 is clipped to its bound 1.0
    assert np.allclose(c.start, [37_500, 26.25, 1.0, 11.25, 25.0, 1125.0])
    e = CASES["exponent-compression"]
    assert np.allclose(e.start / e.reference, [1.25, 0.75, 1.25, 0.75, 1.25, 0.75])


def test_random_starts_are_seeded_latin_hypercube_in_bounds():
    c = CASES["hyperbolic-shear"]
    a, b = c.random_starts(8, seed=3), c.random_starts(8, seed=3)
    assert np.array_equal(a, b) and not np.array_equal(a, c.random_starts(8, seed=4))
    assert np.all((a >= c.lower) & (a <= c.upper))
    # Latin hypercube: one point in each of the 8 strata of every parameter
    strata = np.floor((a - c.lower) / (c.upper - c.lower) * 8).astype(int)
    assert all(sorted(col) == list(range(8)) for col in strata.T)


def test_unknown_case_lists_the_allowed_names():
    with pytest.raises(ValueError, match="linear-compression"):
        get_case("linear-compresion")


def test_cases_cli_json(capsys):
    from bench.cli import main

    assert main(["cases", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert len(doc) == 9
    first = doc[0]
    assert set(first) == {"name", "form", "hardening", "parameters", "fixed", "default_treatment"}
    assert first["default_treatment"]["treatment"] == "bae"
    assert set(first["parameters"][0]) == {"name", "unit", "reference", "lower", "upper", "start"}
    assert first["fixed"]["nu"] == 0.2

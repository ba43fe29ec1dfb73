"""Extended Drucker-Prager: public API, parameter validation, surface constants."""

import math
import pickle

import numpy as np
import pytest

from problems.materials import drucker_prager as dp
from problems.materials.base import Material
from problems.materials.hardening import HARDENINGS, REFERENCE_TESTS
from problems.materials.invariants import (
    HESS_J2,
    deviator,
    grad_j2,
    grad_j3,
    hess_j3,
    j2,
    j3,
    mises,
    third_invariant_r,
)
from problems.materials.verification import rotation_matrix, typical_parameters, voigt_rotations
from tests.support import VARIANTS


def test_form_parameters_are_the_published_contract():
    assert dp.FORM_PARAMETERS == {
        "linear": ("E", "beta", "K", "psi", "sigma0", "H"),
        "hyperbolic": ("E", "beta", "psi", "sigma0", "H", "pt0"),
        "exponent": ("E", "psi", "sigma0", "H", "a", "b"),
    }


@pytest.mark.parametrize("form,hardening", VARIANTS)
def test_typical_parameters_build_a_picklable_material(form, hardening):
    params = typical_parameters(form, hardening)
    dp.validate_parameters(form, hardening, params)
    mat = dp.make_material(form, hardening, params)
    assert isinstance(mat, Material)
    assert mat.state_names[0] == "eqps" and len(mat.state_names) == 7
    assert mat.params["nu"] == 0.2
    clone = pickle.loads(pickle.dumps(mat))
    de = np.array([[-2e-3, 5e-4, 4e-4, 1e-4, -2e-4, 3e-4]])
    a = mat.update(de, np.zeros((1, 6)), mat.initial_state(1))
    b = clone.update(de, np.zeros((1, 6)), clone.initial_state(1))
    assert a.state[0, 0] > 0.0  # the check went plastic
    np.testing.assert_array_equal(a.stress, b.stress)
    np.testing.assert_array_equal(a.tangent, b.tangent)


@pytest.mark.parametrize(
    "name,value",
    [
        ("E", 0.0),
        ("E", -1.0),
        ("E", math.inf),
        ("nu", 0.5),
        ("nu", -1.0),
        ("beta", 0.0),
        ("beta", 90.0),
        ("psi", -0.1),
        ("psi", 90.0),
        ("K", 0.777),
        ("K", 1.0001),
        ("sigma0", 0.0),
        ("H", -1.0),
        ("pt0", 0.0),
        ("a", 0.0),
        ("b", 0.0),
        ("eccentricity", 0.0),
        ("E", math.nan),
    ],
)
def test_out_of_range_values_name_the_parameter_and_range(name, value):
    form = {
        "K": "linear",
        "beta": "linear",
        "pt0": "hyperbolic",
        "a": "exponent",
        "b": "exponent",
    }.get(name, "hyperbolic")
    params = {**typical_parameters(form, "compression"), name: value}
    with pytest.raises(ValueError, match=rf"{name} = .*allowed .*{name}"):
        dp.validate_parameters(form, "compression", params)
    with pytest.raises(ValueError, match=name):
        dp.make_material(form, "compression", params)


def test_missing_unknown_and_non_numeric_parameters():
    params = typical_parameters("linear", "compression")
    with pytest.raises(ValueError, match="missing parameter.*'K'"):
        dp.validate_parameters(
            "linear", "compression", {k: v for k, v in params.items() if k != "K"}
        )
    with pytest.raises(ValueError, match="unknown parameter.*'pt0'"):
        dp.validate_parameters("linear", "compression", {**params, "pt0": 2.5})
    with pytest.raises(ValueError, match="beta = 'steep' is not a number"):
        dp.validate_parameters("linear", "compression", {**params, "beta": "steep"})
    with pytest.raises(ValueError, match="form 'cap'"):
        dp.validate_parameters("cap", "compression", params)
    with pytest.raises(ValueError, match="hardening 'biaxial'"):
        dp.validate_parameters("linear", "biaxial", params)
    # the fixed constants are accepted by every form
    dp.validate_parameters("linear", "compression", {**params, "nu": 0.25, "eccentricity": 0.2})


def test_form_specific_well_posedness():
    # linear, compression hardening: d = (1 - tan(beta)/3) sigma_c > 0 needs beta < atan 3
    lin = typical_parameters("linear", "compression")
    with pytest.raises(ValueError, match=r"beta = 72 deg .* atan\(3\) = 71.5651"):
        dp.validate_parameters("linear", "compression", {**lin, "beta": 72.0})
    with pytest.raises(ValueError, match=r"psi = 75 deg"):
        dp.validate_parameters("linear", "compression", {**lin, "psi": 75.0})
    dp.validate_parameters(
        "linear", "tension", {**typical_parameters("linear", "tension"), "beta": 80.0}
    )
    # hyperbolic: l0 = (S^2 - A^2) / 2A > 0; compression upper bound sigma0/tan(beta) - sigma0/3
    hyp = typical_parameters("hyperbolic", "compression")
    hi = 20.0 / math.tan(math.radians(35.0)) - 20.0 / 3.0
    dp.validate_parameters("hyperbolic", "compression", {**hyp, "pt0": 0.999 * hi})
    with pytest.raises(ValueError, match=rf"pt0 = .* allowed 0 < pt0 < {hi:.6g} MPa.*l0 > 0"):
        dp.validate_parameters("hyperbolic", "compression", {**hyp, "pt0": 1.001 * hi})
    # tension: the hydrostatic strength must exceed sigma_t / 3
    hyt = typical_parameters("hyperbolic", "tension")
    with pytest.raises(ValueError, match=r"allowed 0.833333 < pt0"):
        dp.validate_parameters("hyperbolic", "tension", {**hyt, "pt0": 0.8})
    # exponent, compression: a sigma0^b <= sigma0/3 leaves no tensile strength
    exp_ = typical_parameters("exponent", "compression")
    a_min = 20.0 ** (1.0 - 1.5) / 3.0
    with pytest.raises(ValueError, match=rf"a = .* allowed a > {a_min:.6g}"):
        dp.validate_parameters("exponent", "compression", {**exp_, "a": 0.999 * a_min})
    dp.validate_parameters("exponent", "compression", {**exp_, "a": 1.001 * a_min})


@pytest.mark.parametrize("hardening", HARDENINGS)
def test_yield_constants_match_the_definitions(hardening):
    K, tb, tp = 0.85, math.tan(math.radians(35.0)), math.tan(math.radians(15.0))
    mat = dp.make_material("linear", hardening, typical_parameters("linear", hardening))
    d_hat = {
        "compression": 1 - tb / 3,
        "tension": 1 / K + tb / 3,
        "shear": math.sqrt(3) / 2 * (1 + 1 / K),
    }[hardening]
    c = {"compression": 1 - tp / 3, "tension": 1 / K + tp / 3, "shear": 0.5 * (1 + 1 / K)}[
        hardening
    ]
    assert mat.yield_function.d_hat == pytest.approx(d_hat, rel=1e-14)
    assert mat.eqps_rule.c == pytest.approx(c, rel=1e-14)


@pytest.mark.parametrize("form,hardening", VARIANTS)
def test_surfaces_pass_through_the_reference_state(form, hardening):
    """F = 0 at the hardening test's stress with sigma_bar = sigma0 (and 1.7 sigma0 after
    hardening), and for hyperbolic/exponent at p = -pt0, q = 0 initially."""
    params = typical_parameters(form, hardening)
    mat = dp.make_material(form, hardening, params)
    s0, H = params["sigma0"], params["H"]
    for eqps in (0.0, 0.7 * s0 / H):
        sbar = s0 + H * eqps
        stress = {
            "compression": [-sbar, 0, 0, 0, 0, 0],
            "tension": [sbar, 0, 0, 0, 0, 0],
            "shear": [0, 0, 0, 0, 0, sbar],
        }[hardening]
        assert mat.yield_value(np.array([stress]), eqps)[0] == pytest.approx(0.0, abs=1e-12 * sbar)
    if form == "hyperbolic":
        pt0 = params["pt0"]
    elif form == "exponent":
        t = REFERENCE_TESTS[hardening]
        pt0 = params["a"] * (t.q_hat * s0) ** params["b"] - t.p_hat * s0
    else:
        return
    assert mat.yield_value(np.array([[pt0, pt0, pt0, 0, 0, 0]]), 0.0)[0] == pytest.approx(
        0.0, abs=1e-12 * s0
    )


def test_invariants_and_their_derivatives():
    rng = np.random.default_rng(0)
    sig = rng.normal(size=(5, 6)) * 10.0
    s = deviator(sig)
    h = 1e-5
    for f, grad in (
        (lambda x: j2(deviator(x)), grad_j2(s)),
        (lambda x: j3(deviator(x)), grad_j3(s)),
    ):
        fd = np.stack([(f(sig + h * e) - f(sig - h * e)) / (2 * h) for e in np.eye(6)], axis=1)
        np.testing.assert_allclose(fd, grad, rtol=0, atol=1e-8 * np.abs(grad).max())
    for g, hess in ((grad_j2, np.broadcast_to(HESS_J2, (5, 6, 6))), (grad_j3, hess_j3(s))):
        fd = np.stack(
            [(g(deviator(sig + h * e)) - g(deviator(sig - h * e))) / (2 * h) for e in np.eye(6)],
            axis=2,
        )
        np.testing.assert_allclose(fd, hess, rtol=0, atol=1e-8 * np.abs(hess).max())
    # r keeps its sign: -sigma_c in uniaxial compression, +sigma_t in tension, 0 in pure shear
    probe = np.array([[-20.0, 0, 0, 0, 0, 0], [3.0, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, 7.0]])
    np.testing.assert_allclose(third_invariant_r(probe), [-20.0, 3.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(mises(probe), [20.0, 3.0, 7.0 * math.sqrt(3.0)], rtol=1e-14)


def test_voigt_rotations_are_consistent():
    R = rotation_matrix([1.0, 2.0, -0.5], 0.7)
    Ts, Te = voigt_rotations(R)
    # work is invariant: T_e = T_s^-T
    np.testing.assert_allclose(Te, np.linalg.inv(Ts).T, atol=1e-14)


def test_apex_polar_factor_is_the_gauge_of_the_flow_cone():
    """sup over deviators s of y:s / t(s) equals 2/3 q_y m(xi_y): brute force over deviators
    coaxial with y (where the sup is attained) and random ones (which must not exceed it)."""
    from problems.materials.drucker_prager import _polar_factor
    from problems.materials.yield_surfaces import LodeMeasure, lode_xi

    rng = np.random.default_rng(9)
    for K in (0.778, 0.9):
        lode = LodeMeasure(K)
        y = deviator(rng.normal(size=(4, 6)))
        R = rotation_matrix(rng.normal(size=3), 0.8)
        Ts, _ = voigt_rotations(R)
        y = y @ Ts.T  # not in principal axes
        expected = 2.0 / 3.0 * mises(y) * _polar_factor(lode_xi(y), K)
        for i in range(4):
            Y = np.array(
                [
                    [y[i, 0], y[i, 5], y[i, 4]],
                    [y[i, 5], y[i, 1], y[i, 3]],
                    [y[i, 4], y[i, 3], y[i, 2]],
                ]
            )
            w, V = np.linalg.eigh(Y)
            phi = np.linspace(0.0, 2.0 * np.pi, 200_001)
            princ = (2.0 / 3.0) * np.cos(phi[:, None] - 2.0 * np.pi / 3.0 * np.arange(3)[None, :])
            S = np.einsum("ij,nj,kj->nik", V, princ, V)  # coaxial deviators with q = 1
            s_v = np.stack(
                [S[:, 0, 0], S[:, 1, 1], S[:, 2, 2], S[:, 1, 2], S[:, 0, 2], S[:, 0, 1]], axis=1
            )
            ratio = (s_v[:, :3] @ y[i, :3] + 2.0 * s_v[:, 3:] @ y[i, 3:]) / lode.value(s_v)
            # brute-force grid error ~1e-9
            assert ratio.max() == pytest.approx(expected[i], rel=1e-8)
            rand = deviator(rng.normal(size=(20_000, 6)))
            r_ratio = (rand[:, :3] @ y[i, :3] + 2.0 * rand[:, 3:] @ y[i, 3:]) / lode.value(rand)
            assert r_ratio.max() <= expected[i] * (1 + 1e-12)

"""Parameter sensitivities of the material update (direct differentiation, DDM).

The DDM derivatives of whole multi-step strain paths (elastic loading, plastic loading,
unloading into the elastic range, reloading; and hydrostatic tension to the linear cone's apex
or the hyperbolic/exponent tip) are compared with central differences of the same paths with
respect to each physical parameter.

Error measure, per point and parameter p: the largest deviation over the path's increments and
components divided by the largest finite-difference derivative of that column, floored at
1e-3 max|response| / |p| (max over the point's path; stress and state separately): a parameter
that moves the response by less than 0.1 % of its magnitude over a 100 % change counts as
insensitive, and its error is measured against that floor.

Reference: fourth-order central differences (stencil +-h, +-2h) with h = 5e-4 |p|. Plain
central differences are not clean enough at any single step: near the hyperbolic/exponent tip
the response to some parameters is weak, so round-off weighs more (up to 1e-6 with h = 1e-5 |p|,
1e-5 with h = 1e-6 |p|, scaling as 1/h), while the exponent b, which enters as q^b, shows the
h^2 truncation at 7e-7 with h = 1e-4 |p|. The test checks that the step is in the clean range:
the references with h and h/2 agree with each other to the tolerance as well as with the DDM.
"""

import re

import numpy as np
import pytest

from problems.inverse.cases import CASES
from problems.materials import _kernels as K
from problems.materials import drucker_prager as dp
from problems.materials.base import (
    DifferentiableMaterial,
    isotropic_stiffness,
    isotropic_stiffness_derivatives,
)
from problems.materials.ddm import affine_sensitivity, run_path_sensitivity
from problems.materials.elastic import LinearElastic
from problems.materials.kernel_jacobian import kernel_parameter_jacobian

TOL = 1e-6
REL_STEP = 5e-4
VARIANTS = list(CASES)


def _reference(name):
    case = CASES[name]
    params = case.material_parameters(case.reference)
    return case, params, dp.make_material(case.form, case.hardening, params)


def general_paths(rng, n=6):
    """Eight increments (steps, n, 6) of n random compression-dominated directions: loading
    (elastic, then plastic), unloading into the elastic range, reloading to plastic flow."""
    dirs = rng.normal(size=(n, 6)) * 0.4
    dirs[:, 0] -= 1.0
    dirs[:, 1:3] += 0.3
    dirs /= np.abs(dirs).max(axis=1, keepdims=True)
    profile = np.array([0.3, 0.5, 0.5, 0.5, -0.4, 0.3, 0.5, 0.5])
    return profile[:, None, None] * dirs[None] * 1e-3


def tension_paths():
    """Six increments of hydrostatic tension, with small deviatoric parts: the linear cone's
    apex (and near-apex smooth returns), the hyperbolic/exponent tip; unloading and reloading."""
    dirs = np.array(
        [[1, 1, 1, 0, 0, 0], [1, 1, 1, 0.1, 0, 0], [1, 0.9, 1.1, 0, 0.05, 0], [1, 1, 1, 0, 0, 0.3]]
    )
    profile = np.array([0.5, 0.5, 0.5, -0.8, 0.6, 0.5])
    return profile[:, None, None] * dirs[None] * 4e-4


def _stress_path(mat, increments):
    """Stress and state histories (steps, n, 6|7) of the path, update only."""
    stress, state = np.zeros(increments.shape[1:]), mat.initial_state(increments.shape[1])
    out = []
    for de in increments:
        up = mat.update(de, stress, state)
        assert up.ok.all()
        stress, state = up.stress, up.state
        out.append(np.concatenate([stress, state], axis=1))
    return np.stack(out)


def _fd(case, params, name, rel, increments):
    """Fourth-order central differences (stress, state) of the whole path with respect to one
    parameter: (8 (f(h) - f(-h)) - (f(2h) - f(-2h))) / (12 h), h = rel |p|."""
    h = rel * abs(params[name])
    f = {
        j: _stress_path(
            dp.make_material(case.form, case.hardening, {**params, name: params[name] + j * h}),
            increments,
        )
        for j in (-2, -1, 1, 2)
    }
    d = (8.0 * (f[1] - f[-1]) - (f[2] - f[-2])) / (12.0 * h)
    return d[..., :6], d[..., 6:]


def _column_error(ddm, fd, floor):
    """Per point: max |ddm - fd| over increments and components / max(max |fd|, floor)."""
    return np.abs(ddm - fd).max(axis=(0, 2)) / np.maximum(np.abs(fd).max(axis=(0, 2)), floor)


def path_errors(name, increments):
    """{parameter: (stress error, state error, clean-range check)} of the DDM along the path."""
    case, params, mat = _reference(name)
    res = run_path_sensitivity(mat, increments)
    assert res.ok.all()
    out = {}
    for k, pname in enumerate(mat.parameter_names):
        # insensitive: a 100 % change moves the response by less than 0.1 % of its magnitude
        floor_s, floor_q = (
            1e-3 * np.abs(a).max(axis=(0, 2)) / abs(params[pname]) for a in (res.stress, res.state)
        )
        fd_s, fd_q = _fd(case, params, pname, REL_STEP, increments)
        fd2_s, fd2_q = _fd(case, params, pname, 0.5 * REL_STEP, increments)
        out[pname] = (
            _column_error(res.dstress[:, :, k], fd_s, floor_s).max(),
            _column_error(res.dstate[:, :, k], fd_q, floor_q).max(),
            max(
                _column_error(fd2_s, fd_s, floor_s).max(), _column_error(fd2_q, fd_q, floor_q).max()
            ),
        )
    return res, out


def _kinds(res):
    """Per increment and point: 'e' elastic, 'P' plastic (smooth), 'A' exactly hydrostatic
    plastic."""
    plastic = np.diff(res.state[:, :, 0], axis=0, prepend=0.0) > 0.0
    hydro = np.all(res.stress[..., 3:] == 0.0, axis=-1) & np.all(
        res.stress[..., :3] == res.stress[..., :1], axis=-1
    )
    return np.where(plastic & hydro, "A", np.where(plastic, "P", "e"))


@pytest.mark.parametrize("name", VARIANTS)
def test_ddm_matches_finite_differences_on_general_paths(name):
    res, errors = path_errors(name, general_paths(np.random.default_rng(0)))
    kinds = _kinds(res)
    # every point flows, unloads into the elastic range and flows again on reloading
    assert all(re.search("P.*e.*P", "".join(kinds[:, j])) for j in range(kinds.shape[1]))
    assert (kinds == "P").sum() >= 29 and (kinds[0] == "e").sum() >= 2
    for pname, (e_stress, e_state, clean) in errors.items():
        assert e_stress < TOL and e_state < TOL and clean < TOL, (pname, e_stress, e_state, clean)


@pytest.mark.parametrize("name", VARIANTS)
def test_ddm_matches_finite_differences_in_hydrostatic_tension(name):
    res, errors = path_errors(name, tension_paths())
    kinds = _kinds(res)
    if CASES[name].form == "linear":
        assert (kinds == "A").sum() >= 8 and (kinds == "P").sum() >= 2
    else:  # the tip: exactly hydrostatic for the purely hydrostatic path, near it otherwise
        assert (kinds[:, 0] == "A").sum() >= 3 and (kinds == "P").sum() >= 9
    for pname, (e_stress, e_state, clean) in errors.items():
        assert e_stress < TOL and e_state < TOL and clean < TOL, (pname, e_stress, e_state, clean)


def _random_history(rng, n, n_p):
    return (
        rng.normal(size=(n, n_p, 6)),
        rng.normal(size=(n, n_p, 7)) * 1e-4,
        rng.normal(size=(n, n_p, 6)) * 1e-5,
    )


@pytest.mark.parametrize("name", ["linear-compression", "hyperbolic-tension", "exponent-shear"])
def test_elastic_points(name):
    """Elastic points: dstress = dstress_old + D ddeps + dD/dp deps exactly, state derivatives
    carried unchanged, and exactly zero derivatives for the plastic parameters without history."""
    _, params, mat = _reference(name)
    rng = np.random.default_rng(1)
    n, names = 50, mat.parameter_names
    de = rng.normal(size=(n, 6)) * 1e-5
    sig_n, st_n = np.zeros((n, 6)), mat.initial_state(n)
    up = mat.update(de, sig_n, st_n)
    assert (up.state == st_n).all()
    dsig_old, dst_old, dde = _random_history(rng, n, len(names))
    dsig, dst = mat.sensitivity(de, sig_n, st_n, up, dsig_old, dst_old, dde)
    D = isotropic_stiffness(mat.E, mat.nu)
    expected = dsig_old + dde @ D.T
    for name_p, dD in zip(("E", "nu"), isotropic_stiffness_derivatives(mat.E, mat.nu)):
        expected[:, names.index(name_p)] += de @ dD.T
    np.testing.assert_allclose(dsig, expected, rtol=1e-14, atol=1e-14 * np.abs(expected).max())
    np.testing.assert_array_equal(dst, dst_old)
    dsig, dst = mat.sensitivity(
        de, sig_n, st_n, up, np.zeros_like(dsig_old), np.zeros_like(dst_old), np.zeros_like(dde)
    )
    plastic_params = [k for k, p in enumerate(names) if p not in ("E", "nu")]
    assert (dsig[:, plastic_params] == 0.0).all() and (dst == 0.0).all()
    assert (np.abs(dsig[:, [names.index("E"), names.index("nu")]]).max(axis=(1, 2)) > 0).all()


def test_apex_does_not_depend_on_K_under_compression_hardening():
    """With compression hardening the apex pressure -d/tan(beta), d = (1 - tan(beta)/3) sigma_bar,
    and c = 1 - tan(psi)/3 do not involve K: its derivative at apex points is exactly zero."""
    _, _, mat = _reference("linear-compression")
    n = 4
    de = np.tile([[1.5e-3, 1.5e-3, 1.5e-3, 0.0, 0.0, 0.0]], (n, 1))
    up = mat.update(de, np.zeros((n, 6)), mat.initial_state(n))
    assert up.ok.all() and (up.state[:, 0] > 0).all() and (up.stress[:, 3:] == 0).all()
    P = len(mat.parameter_names)
    dsig, dst = mat.sensitivity(
        de,
        np.zeros((n, 6)),
        mat.initial_state(n),
        up,
        np.zeros((n, P, 6)),
        np.zeros((n, P, 7)),
        np.zeros((n, P, 6)),
    )
    k = mat.parameter_names.index("K")
    assert (dsig[:, k] == 0.0).all() and (dst[:, k] == 0.0).all()
    assert np.abs(dsig[:, mat.parameter_names.index("beta"), :3]).min() > 0.0


@pytest.mark.parametrize(
    "name", ["linear-tension", "hyperbolic-compression", "exponent-compression"]
)
def test_strain_increment_derivative_goes_through_the_consistent_tangent(name):
    """dstress = T ddeps + (the rest): the ddeps part of the sensitivity is the update's tangent."""
    _, _, mat = _reference(name)
    rng = np.random.default_rng(2)
    n, P = 40, len(mat.parameter_names)
    res = run_path_sensitivity(mat, general_paths(rng, n)[:3])
    sig_n, st_n = res.stress[-1], res.state[-1]
    de = general_paths(np.random.default_rng(2), n)[3]
    up = mat.update(de, sig_n, st_n)
    plastic = up.state[:, 0] > st_n[:, 0]
    assert plastic.sum() >= 10
    dde = rng.normal(size=(n, P, 6)) * 1e-4
    zero_s, zero_q = np.zeros((n, P, 6)), np.zeros((n, P, 7))
    with_dde = mat.sensitivity(de, sig_n, st_n, up, zero_s, zero_q, dde)[0]
    without = mat.sensitivity(de, sig_n, st_n, up, zero_s, zero_q, np.zeros_like(dde))[0]
    through_T = np.einsum("nij,npj->npi", up.tangent, dde)
    scale = np.abs(through_T).max(axis=(1, 2))
    assert (np.abs(with_dde - without - through_T).max(axis=(1, 2)) <= 1e-8 * scale).all()


def test_failed_points_get_nan():
    """psi = 0, H = 0: a trial beyond the apex cannot be returned (ok False): NaN derivatives."""
    mat = dp.make_material(
        "linear",
        "compression",
        {
            **CASES["linear-compression"].material_parameters(
                CASES["linear-compression"].reference
            ),
            "psi": 0.0,
            "H": 0.0,
        },
    )
    de = np.array(
        [[2e-3, 2e-3, 2e-3, 0, 0, 0], [-1e-3, 2e-4, 2e-4, 0, 0, 0], [1e-5, 0, 0, 0, 0, 0]]
    )
    up = mat.update(de, np.zeros((3, 6)), mat.initial_state(3))
    assert up.ok.tolist() == [False, True, True]
    P = len(mat.parameter_names)
    dsig, dst = mat.sensitivity(
        de,
        np.zeros((3, 6)),
        mat.initial_state(3),
        up,
        np.zeros((3, P, 6)),
        np.zeros((3, P, 7)),
        np.zeros((3, P, 6)),
    )
    assert np.isnan(dsig[0]).all() and np.isnan(dst[0]).all()
    assert np.isfinite(dsig[1:]).all() and np.isfinite(dst[1:]).all()


@pytest.mark.parametrize("name", VARIANTS)
def test_kernel_parameter_jacobian_matches_the_mapping(name):
    """The chain rule from the physical parameters to the kernel vectors against central
    differences of make_material's mapping (which is smooth: differences are clean to 1e-8)."""
    case, params, mat = _reference(name)

    def theta(m):
        mp, yp, gp = m._kernel_params, m.yield_function.kernel_params, m.potential.kernel_params
        return np.concatenate([mp[[K.M_E, K.M_NU, K.M_S0, K.M_H, K.M_RULE_C]], yp[1:6], gp[1:4]])

    jac = kernel_parameter_jacobian(mat)
    assert jac.shape == (K.TH_SIZE, len(mat.parameter_names))
    for k, pname in enumerate(mat.parameter_names):
        h = 1e-6 * abs(params[pname])
        plus = dp.make_material(case.form, case.hardening, {**params, pname: params[pname] + h})
        minus = dp.make_material(case.form, case.hardening, {**params, pname: params[pname] - h})
        fd = (theta(plus) - theta(minus)) / (2 * h)
        np.testing.assert_allclose(
            jac[:, k], fd, rtol=1e-7, atol=1e-9 * np.abs(fd).max(), err_msg=pname
        )


def test_parameter_names_and_protocol():
    for name in VARIANTS:
        _, _, mat = _reference(name)
        assert mat.parameter_names == dp.FORM_PARAMETERS[mat.form] + ("nu",)
        assert isinstance(mat, DifferentiableMaterial)
    assert LinearElastic().parameter_names == ("E", "nu")
    assert isinstance(LinearElastic(), DifferentiableMaterial)


def test_linear_elastic_sensitivity():
    """LinearElastic: dstress = dstress_old + D ddeps + dD/dp deps, against central differences."""
    mat = LinearElastic(30_000.0, 0.2)
    rng = np.random.default_rng(3)
    n = 10
    de, sig_n = rng.normal(size=(n, 6)) * 1e-4, rng.normal(size=(n, 6))
    up = mat.update(de, sig_n, mat.initial_state(n))
    zero = np.zeros((n, 2, 6))
    dsig, dst = mat.sensitivity(
        de, sig_n, mat.initial_state(n), up, zero, np.zeros((n, 2, 0)), zero
    )
    assert dst.shape == (n, 2, 0)
    for k, (E, nu) in enumerate(((1.0, 0.0), (0.0, 1.0))):
        h = 1e-6 * (mat.E if E else mat.nu)
        plus = (
            LinearElastic(mat.E + h * E, mat.nu + h * nu)
            .update(de, sig_n, mat.initial_state(n))
            .stress
        )
        minus = (
            LinearElastic(mat.E - h * E, mat.nu - h * nu)
            .update(de, sig_n, mat.initial_state(n))
            .stress
        )
        np.testing.assert_allclose(
            dsig[:, k], (plus - minus) / (2 * h), rtol=1e-7, atol=1e-9 * np.abs(dsig[:, k]).max()
        )


@pytest.mark.parametrize("name", VARIANTS)
def test_one_pass_affine_split_equals_the_sensitivity(name):
    """affine_sensitivity: c + T_s e and h + T_q e equal ``sensitivity`` with the strain-increment
    derivative dde_known + e, for a subset of the parameter columns, at elastic, plastic and
    (linear form, hydrostatic tension) apex points; T_s is the consistent tangent."""
    _, _, mat = _reference(name)
    rng = np.random.default_rng(5)
    incs = np.concatenate([general_paths(rng, 8)[2:], tension_paths()], axis=1)  # (6, 12, 6)
    res = run_path_sensitivity(mat, incs[:5])
    sig_n, st_n = res.stress[-1], res.state[-1]
    ds_n, dq_n = res.dstress[-1], res.dstate[-1]
    de = incs[5]
    up = mat.update(de, sig_n, st_n)
    assert up.ok.all()
    kinds = _kinds(run_path_sensitivity(mat, incs))[-1]
    assert "P" in kinds and ("A" in kinds or mat.form != "linear")
    n, P = de.shape[0], len(mat.parameter_names)
    known = rng.normal(size=(n, P, 6)) * 1e-4
    e = rng.normal(size=(n, P, 6)) * 1e-4
    full_s, full_q = mat.sensitivity(de, sig_n, st_n, up, ds_n, dq_n, known + e)
    cols = [j for j in range(P) if j % 2 == 0]  # a subset, as the FE model asks
    c, h, T = affine_sensitivity(
        mat, de, sig_n, st_n, up, ds_n[:, cols], dq_n[:, cols], known[:, cols], cols
    )
    assert c.shape == (n, len(cols), 6) and h.shape == (n, len(cols), 7) and T.shape == (n, 13, 6)
    np.testing.assert_allclose(T[:, :6], up.tangent, rtol=0, atol=1e-9 * np.abs(up.tangent).max())
    lin = np.einsum("nrj,nkj->nkr", T, e[:, cols])
    for got, want in ((c + lin[..., :6], full_s[:, cols]), (h + lin[..., 6:], full_q[:, cols])):
        scale = np.maximum(np.abs(want).max(axis=(1, 2), keepdims=True), 1e-300)
        assert (np.abs(got - want) / scale).max() < 1e-12
    assert (
        affine_sensitivity(LinearElastic(30_000.0, 0.2), de, sig_n, st_n, up, None, None, None, [0])
        is None
    )

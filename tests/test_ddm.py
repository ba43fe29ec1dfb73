"""Exact Jacobians of the FE model by direct differentiation (problems/fe/ddm.py).

Every column is checked against central differences of plain runs with a step in their clean
range (the columns of two steps a decade apart agree, so neither truncation nor the noise of the
Newton tolerance shows); small meshes keep the file well under a minute.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

import problems.fe.ddm as ddm
from problems.fe.ddm import SensitivitySettings
from problems.fe.linear_solver import superlu_factor
from problems.fe.mesh import parse_mesh_spec
from problems.fe.newton import Loading, NewtonSettings, discretise, run
from problems.inverse import layout
from problems.inverse.cases import get_case
from problems.inverse.forward import FORWARD_SETTINGS, FEForwardModel, case_material
from problems.inverse.protocol import RunModel, provides_jacobian
from problems.materials import LinearElastic

#: one case per yield surface; the exponent case identifies pt0 in place of a (chain rule)
CASES = ("linear-compression", "hyperbolic-shear", "exponent-tension")
STEP, STEP_SMALL = 1e-4, 1e-5  # relative central-difference steps, both in the clean range


def with_sensitivity(**kw) -> NewtonSettings:
    """FORWARD_SETTINGS with these :class:`SensitivitySettings` fields."""
    return replace(FORWARD_SETTINGS, sensitivity=SensitivitySettings(**kw))


def central(model, x, j, step):
    """Central-difference column j of the measurement vector (physical units)."""
    h = step * abs(x[j])
    xp, xm = x.copy(), x.copy()
    xp[j] += h
    xm[j] -= h
    rp, rm = model(xp), model(xm)
    assert rp.ok and rm.ok
    return (rp.values - rm.values) / (2.0 * h)


def rel(a, b) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def check_columns(model, x, J, tol=1e-5, steps=(STEP,)):
    for j in range(len(x)):
        cols = [central(model, x, j, s) for s in steps]
        for g in cols:
            assert rel(J[:, j], g) < tol, (model.names[j], rel(J[:, j], g))
        if len(cols) == 2:  # the step is in the clean range: a decade smaller changes nothing
            assert rel(cols[0], cols[1]) < 1e-6, model.names[j]


@pytest.mark.parametrize("name", CASES)
def test_jacobian_matches_central_differences(name):
    case = get_case(name)
    model = FEForwardModel(case, "2,2,4")
    x = case.reference
    res = model(x, jacobian=True)
    assert res.ok and res.jacobian.shape == (layout.size(10, len(model.points)), len(x))
    np.testing.assert_array_equal(res.values, model(x).values)
    check_columns(model, x, res.jacobian, steps=(STEP, STEP_SMALL))


@pytest.mark.parametrize("name", ("linear-compression", "exponent-tension"))
def test_jacobian_on_a_graded_27_node_mesh_matches_central_differences(name):
    """The inverse loop's element and grading (Q2-P1 hexahedra graded 8:1, as the default inverse
    model on model-error data): the measured columns (front-face points through the biquadratic
    face operator, the force, the exponent case's pt0 through the chain rule) agree with central
    differences of plain runs."""
    case = get_case(name)
    model = FEForwardModel(case, "2,2,4:g8:hex27")
    x = case.reference
    res = model(x, jacobian=True)
    assert res.ok
    np.testing.assert_array_equal(res.values, model(x).values)
    check_columns(model, x, res.jacobian, steps=(STEP, STEP_SMALL))


def test_jacobian_away_from_the_reference_on_a_finer_mesh():
    """At the default start the response has a kink within 1e-4 sigma0 (a Gauss point that starts
    to yield one snapshot earlier or later): the clean range of the steps begins lower there."""
    case = get_case("exponent-tension")
    model = FEForwardModel(case, "3,3,6")
    x = case.start
    check_columns(model, x, model(x, jacobian=True).jacobian, steps=(1e-6, 1e-7))


@pytest.mark.parametrize("name", ["linear-tension", "hyperbolic-shear", "exponent-compression"])
def test_one_material_pass_gives_the_jacobian_of_two_calls(name):
    """The one-pass affine split (problems.materials.ddm.affine_sensitivity, the default) and the
    two ``sensitivity`` calls per increment of the material interface give the same Jacobian,
    and the run itself is the plain run bit for bit."""
    case = get_case(name)
    model = FEForwardModel(case, "2,2,4")
    x = case.start
    out = {}
    for affine in (True, False):
        two = FEForwardModel(case, "2,2,4", settings=with_sensitivity(affine=affine))
        out[affine] = two(x, jacobian=True)
        assert out[affine].ok
    np.testing.assert_array_equal(out[True].values, model(x).values)
    for j in range(len(x)):
        assert rel(out[True].jacobian[:, j], out[False].jacobian[:, j]) < 1e-10, case.names[j]


def test_krylov_and_direct_sensitivity_solves_agree():
    case = get_case("hyperbolic-shear")
    disc = discretise(parse_mesh_spec("3,3,6").mesh, symmetry="eighth")
    mat = case_material(case, case.reference)
    out = {}
    for mode in ("direct", "krylov"):
        r = run(disc, mat, Loading(), with_sensitivity(mode=mode), sensitivities=True)
        assert r.sensitivities.timing["mode"] == mode and r.sensitivities.ok
        out[mode] = r.sensitivities
    assert out["krylov"].timing["krylov_iterations"] > 0
    for j in range(len(mat.parameter_names)):
        assert rel(out["krylov"].displacements[..., j], out["direct"].displacements[..., j]) < 1e-7
        assert rel(out["krylov"].reaction_kN[:, j], out["direct"].reaction_kN[:, j]) < 1e-7
    assert out["direct"].residual < 1e-9 and out["krylov"].residual < 1e-6


def test_mixed_precision_direct_solves_give_the_double_lu_jacobian():
    """Above mixed_min_dofs (forced here on a small mesh) the direct solves factorise in single
    precision and refine: the Jacobian is the double LU's (without handing the LU to the Newton
    predictor, which keeps the response bit for bit; the hand-over is tested below)."""
    case = get_case("hyperbolic-shear")
    x = case.reference
    out, timing = {}, {}
    for name, threshold in (("double", 10**9), ("mixed", 0)):
        settings = with_sensitivity(mode="direct", hand_over=False, mixed_min_dofs=threshold)
        model = FEForwardModel(case, "3,3,6", settings=settings)
        out[name] = model(x, jacobian=True)
        sens = model.response(x, sensitivities=model.material_chain(x)[0]).sensitivities
        assert out[name].ok and sens.ok and sens.residual < 1e-9
        timing[name] = sens.timing
    np.testing.assert_array_equal(out["mixed"].values, out["double"].values)
    t = timing["mixed"]
    assert t["factorisations"] == t["mixed_factorisations"] > 0 and t["fallbacks"] == 0
    assert t["refinements"] >= t["mixed_factorisations"]
    assert timing["double"]["mixed_factorisations"] == timing["double"]["refinements"] == 0
    for j in range(len(x)):
        assert rel(out["mixed"].jacobian[:, j], out["double"].jacobian[:, j]) < 1e-8, j


def test_coarse_keeps_the_double_lu(monkeypatch):
    """coarse (749 free dofs) is below mixed_min_dofs: its direct solves are the double SuperLU
    ones of before (its shipped records are reproduced bit for bit)."""
    case = get_case("linear-compression")
    model = FEForwardModel(case, "coarse")
    x = case.reference

    def refuse(A):
        raise AssertionError(f"mixed-precision factor asked for {A.shape[0]} dofs")

    calls = []

    def double(A):
        calls.append(A.shape[0])
        return superlu_factor(A)

    monkeypatch.setattr(ddm, "mixed_superlu_factor", refuse)
    monkeypatch.setattr(ddm, "superlu_factor", double)
    resp = model.response(x, sensitivities=model.material_chain(x)[0])
    s = resp.sensitivities
    assert s.ok and s.timing["mode"] == "direct"
    assert resp.timing["handed_predictors"] == 0  # the Newton solves are the plain run's
    assert calls and set(calls) == {749} and 749 <= SensitivitySettings().mixed_min_dofs
    assert len(calls) == s.timing["factorisations"] and s.timing["mixed_factorisations"] == 0


def test_factor_handed_to_the_newton_predictor_keeps_the_response_and_the_jacobian():
    """Above mixed_min_dofs (forced here on a small mesh) the direct solves hand their LU of the
    converged tangent to the next increment's Newton predictor: the response is the plain run's
    to the Newton tolerance and the Jacobian the one without the hand-over to 1e-8."""
    case = get_case("hyperbolic-shear")
    x = case.reference
    plain = FEForwardModel(case, "3,3,6").response(x)
    resp, out = {}, {}
    for hand in (False, True):
        settings = with_sensitivity(mode="direct", mixed_min_dofs=0, hand_over=hand)
        model = FEForwardModel(case, "3,3,6", settings=settings)
        resp[hand] = model.response(x, sensitivities=model.material_chain(x)[0])
        out[hand] = model(x, jacobian=True)
        assert resp[hand].converged and resp[hand].sensitivities.ok and out[hand].ok
    assert plain.timing["handed_predictors"] == resp[False].timing["handed_predictors"] == 0
    for f in ("reaction_kN", "displacements", "stress", "state"):  # no hand-over: bit for bit
        np.testing.assert_array_equal(getattr(resp[False], f), getattr(plain, f))
    r = resp[True]
    # every increment but the first (elastic: symmetric tangent, no LU) gets the LU ...
    assert r.timing["handed_predictors"] == r.increments - 1 > 0
    # ... whose predictor solve is exact: fewer Krylov iterations than the plain run
    assert r.timing["krylov_iterations"] < plain.timing["krylov_iterations"]
    assert r.increments == plain.increments and r.cuts == plain.cuts == 0
    assert rel(r.reaction_kN, plain.reaction_kN) < 1e-8
    assert rel(r.displacements, plain.displacements) < 1e-8
    assert rel(out[True].values, model(x).values) < 1e-8
    for j in range(len(x)):
        assert rel(out[True].jacobian[:, j], out[False].jacobian[:, j]) < 1e-8, j


def test_superlu_newton_runs_give_the_same_sensitivities():
    case = get_case("linear-compression")
    disc = discretise(parse_mesh_spec("2,2,4").mesh, symmetry="eighth")
    mat = case_material(case, case.reference)
    a = run(disc, mat, Loading(), FORWARD_SETTINGS, sensitivities=True).sensitivities
    settings = NewtonSettings(rtol_force=1e-10, rtol_displacement=1e-10, linear_solver="superlu")
    b = run(disc, mat, Loading(), settings, sensitivities=True).sensitivities
    assert b.timing["mode"] == "direct"
    for j in range(len(mat.parameter_names)):
        assert rel(b.displacements[..., j], a.displacements[..., j]) < 1e-7


def test_eighth_and_quarter_models_give_the_same_jacobian():
    case = get_case("exponent-tension")
    x = case.reference
    J8 = FEForwardModel(case, "2,2,4:eighth")(x, jacobian=True).jacobian
    J4 = FEForwardModel(case, "2,2,4:quarter")(x, jacobian=True).jacobian
    for j in range(len(x)):
        assert rel(J8[:, j], J4[:, j]) < 1e-8


def test_increments_that_were_cut_carry_the_sensitivities():
    """Two snapshots with at most 4 Newton iterations: the increments are bisected many times;
    the perturbed runs are cut the same way, so central differences see the same discrete path."""
    case = get_case("hyperbolic-shear")
    settings = NewtonSettings(
        rtol_force=1e-10, rtol_displacement=1e-10, max_iterations=4, max_cuts=20
    )
    model = FEForwardModel(case, "2,2,4", Loading(snapshots=2), settings=settings)
    x = case.reference
    resp = model.response(x)
    assert resp.converged and resp.cuts >= 5
    for j in range(len(x)):
        xp = x.copy()
        xp[j] *= 1.0 + STEP
        perturbed = model.response(xp)
        assert (perturbed.increments, perturbed.cuts) == (resp.increments, resp.cuts)
    check_columns(model, x, model(x, jacobian=True).jacobian)


def test_the_run_is_unchanged_when_sensitivities_are_asked():
    case = get_case("hyperbolic-shear")
    disc = discretise(parse_mesh_spec("3,3,6").mesh, symmetry="eighth")
    mat = case_material(case, case.reference)
    a = run(disc, mat, Loading(), FORWARD_SETTINGS)
    b = run(disc, mat, Loading(), FORWARD_SETTINGS, sensitivities=["E", "psi"])
    assert a.sensitivities is None
    for f in ("snapshots_mm", "reaction_kN", "displacements", "stress", "state"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
    assert (a.increments, a.iterations, a.cuts) == (b.increments, b.iterations, b.cuts)
    assert a.timing["krylov_iterations"] == b.timing["krylov_iterations"]
    s = b.sensitivities
    assert s.parameter_names == ("E", "psi")
    assert s.displacements.shape == a.displacements.shape + (2,) and s.reaction_kN.shape == (10, 2)
    with pytest.raises(ValueError, match="distinct names"):
        run(disc, mat, Loading(snapshots=1), FORWARD_SETTINGS, sensitivities=["E", "a"])


def test_elastic_plate_force_is_proportional_to_E():
    """Prescribed displacements: u does not depend on E and F = E f(nu), so dF/dE = F/E."""
    disc = discretise(parse_mesh_spec("2,2,4").mesh, symmetry="eighth")
    r = run(
        disc,
        LinearElastic(30_000.0, 0.2),
        Loading(snapshots=3),
        FORWARD_SETTINGS,
        sensitivities=True,
    )
    s = r.sensitivities
    np.testing.assert_allclose(s.reaction_kN[:, 0], r.reaction_kN / 30_000.0, rtol=1e-10)
    scale = np.max(np.abs(r.displacements)) / 30_000.0
    assert np.max(np.abs(s.displacements[..., 0])) < 1e-12 * scale
    assert np.max(np.abs(s.displacements[..., 1])) > 0.0  # nu moves the free faces


def test_forward_model_declares_exact_jacobians_and_fails_like_a_plain_run():
    case = get_case("linear-compression")
    model = FEForwardModel(case, "2,2,4")
    assert provides_jacobian(model)
    res = RunModel(model, with_jacobian=True)(case.reference)
    assert res.ok and res.jacobian is not None
    hopeless = FEForwardModel(case, "2,2,4", settings=NewtonSettings(max_iterations=1, max_cuts=0))
    res = hopeless(case.reference, jacobian=True)
    assert not res.ok and res.values is None and res.jacobian is None and "failed" in res.message


def test_cli_jacobian_writes_the_documented_json(tmp_path, capsys):
    from bench.cli import main

    out = tmp_path / "j.json"
    argv = ["jacobian", "exponent-shear", "--mesh", "1,1,2", "--param", "pt0=2.7"]
    assert main([*argv, "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    case = get_case("exponent-shear")
    m = len(FEForwardModel(case).points)
    assert doc["names"] == list(case.names)
    assert doc["x"][case.names.index("pt0")] == 2.7
    J = np.array(doc["jacobian"])
    assert J.shape == (layout.size(10, m), len(case.names))
    assert doc["wall_s"] > 0 and doc["forward_wall_s"] > 0
    assert "x one forward run" in capsys.readouterr().out
    central = tmp_path / "c.json"
    assert main([*argv, "--method", "central", "--json", str(central)]) == 0
    Jc = np.array(json.loads(central.read_text())["jacobian"])
    for j in range(J.shape[1]):
        assert rel(J[:, j], Jc[:, j]) < 1e-5
    assert main(["jacobian", "exponent-shear", "--mesh", "1,1,2", "--param", "nu=0.3"]) == 2

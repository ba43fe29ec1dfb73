"""Material-point driver and the ``femubench material`` command."""

import argparse
import csv
import math

import numpy as np
import pytest

from bench.commands import material as cmd
from problems.materials.drucker_prager import make_material
from problems.materials.elastic import LinearElastic
from problems.materials.point_driver import COLUMNS, PATHS, run_material_point
from tests.support import material


def _dp(form="linear", hardening="compression", **over):
    return material(form, hardening, **over)


@pytest.mark.parametrize("path", PATHS)
def test_elastic_paths_follow_hooke(path):
    """Linear elasticity: E on the uniaxial paths (lateral strain -nu eps), G on shear,
    3K on the hydrostatic path; the stress-free components stay zero."""
    E, nu = 30_000.0, 0.2
    res = run_material_point(LinearElastic(E, nu), path, 1e-3, 4)
    assert res.columns == COLUMNS and res.table.shape == (4, 6)
    np.testing.assert_array_equal(res.column("step"), [1, 2, 3, 4])
    eps, sig = res.column("eps_axial"), res.column("sig_axial")
    sign = -1.0 if path == "uniaxial-compression" else 1.0
    np.testing.assert_allclose(eps, sign * 1e-3 * np.arange(1, 5) / 4, rtol=1e-14)
    modulus = {"shear": E / (2 * (1 + nu)), "hydrostatic": E / (1 - 2 * nu)}.get(path, E)
    np.testing.assert_allclose(sig, modulus * eps, rtol=1e-10)
    np.testing.assert_array_equal(res.column("eqps"), 0.0)
    if path.startswith("uniaxial"):
        np.testing.assert_allclose(
            res.strain[:, 1:3], -nu * eps[:, None] * np.ones((1, 2)), rtol=1e-10
        )
        assert np.abs(res.stress[:, 1:]).max() < 1e-10 * np.abs(sig).max()
        np.testing.assert_allclose(res.column("q"), np.abs(sig), rtol=1e-12)
        np.testing.assert_allclose(res.column("p"), -sig / 3, rtol=1e-12)
    if path == "shear":
        np.testing.assert_allclose(res.column("q"), math.sqrt(3) * sig, rtol=1e-12)
        assert np.abs(res.stress[:, :5]).max() < 1e-10 * sig.max()


def test_dilatant_shear_frees_the_normal_strains():
    """Pure shear stress on a dilatant material: plastic volume increase shows as normal strains,
    the normal stresses stay zero and eqps = gamma_pl / sqrt(3)."""
    mat = _dp("linear", "shear", psi=20.0)
    res = run_material_point(mat, "shear", 4e-3, 20)
    plastic = res.column("eqps") > 0
    assert plastic.sum() > 10
    vol = res.strain[:, :3].sum(axis=1)
    assert (vol[plastic] > 0).all()
    assert np.abs(res.stress[:, :5]).max() < 1e-9
    gamma_pl = res.column("eps_axial") - res.column("sig_axial") / mat.shear_modulus
    np.testing.assert_allclose(
        res.column("eqps")[plastic], gamma_pl[plastic] / math.sqrt(3), rtol=1e-8
    )


@pytest.mark.parametrize("form", ["linear", "hyperbolic", "exponent"])
def test_hydrostatic_tension_caps_at_the_tensile_strength(form):
    """Hydrostatic extension yields at p = -pt0 (hyperbolic, exponent) or at the cone's apex
    p = -d/tan(beta) (linear) and then follows the hardening of that point."""
    mat = _dp(form, "compression")
    p0 = {
        "linear": mat.yield_function.d_hat * mat.law.sigma0 / mat.yield_function.tan_beta
        if form == "linear"
        else None,
        "hyperbolic": mat.params.get("pt0"),
        "exponent": mat.yield_function.tension_strength(mat.law.sigma0)[0]
        if form == "exponent"
        else None,
    }[form]
    res = run_material_point(mat, "hydrostatic", 20 * p0 / mat.E, 40)
    p, eqps = res.column("p"), res.column("eqps")
    plastic = eqps > 0
    assert 10 < plastic.sum() < 40
    assert -p[~plastic].min() < p0 < -p[plastic].min()
    assert np.abs(res.column("q")).max() < 1e-9
    # the plastic branch stays on the (hardening) surface's tip
    F = mat.yield_value(res.stress[plastic], eqps[plastic])
    assert np.abs(F).max() < 1e-9 * mat.law.sigma0
    assert np.all(np.diff(-p[plastic]) > 0)  # hardening raises the tensile strength
    if form == "linear":  # -p = d_hat (sigma0 + H eqps) / tan(beta): intercept p0
        slope, intercept = np.polyfit(eqps[plastic], -p[plastic], 1)
        assert intercept == pytest.approx(p0, rel=1e-9)
        assert slope == pytest.approx(
            mat.yield_function.d_hat * mat.law.H / mat.yield_function.tan_beta, rel=1e-9
        )


class _Fussy:
    """Wraps a material; its local return 'fails' (ok False) for increments above a size."""

    def __init__(self, inner, limit):
        self.inner, self.limit, self.calls = inner, limit, 0
        self.state_names = inner.state_names

    def initial_state(self, n):
        return self.inner.initial_state(n)

    def update(self, de, sig, st):
        self.calls += 1
        up = self.inner.update(de, sig, st)
        return type(up)(
            up.stress, up.tangent, up.state, up.ok & (np.abs(de).max(axis=1) <= self.limit)
        )


def test_failed_steps_are_bisected():
    """A step whose local return fails is halved until it passes; on the uniaxial hardening
    path the end point is path independent, sigma = (sigma0 + H |eps|) / (1 + H/E)."""
    mat = _dp("exponent", "compression")
    fussy = _Fussy(mat, 1.1e-3)
    res = run_material_point(fussy, "uniaxial-compression", 0.01, 2)  # 5e-3 steps: 8 sub-steps each
    s0, H, E = mat.law.sigma0, mat.law.H, mat.E
    assert -res.column("sig_axial")[-1] == pytest.approx((s0 + H * 0.01) / (1 + H / E), rel=1e-9)
    assert fussy.calls > 16
    with pytest.raises(RuntimeError, match="bisection"):
        run_material_point(_Fussy(mat, 0.0), "uniaxial-compression", 0.01, 2)


def test_bad_input_is_a_value_error():
    mat = _dp()
    with pytest.raises(ValueError, match="path 'biaxial' is unknown"):
        run_material_point(mat, "biaxial", 1e-3, 3)
    with pytest.raises(ValueError, match="strain = -0.001 must be a positive magnitude"):
        run_material_point(mat, "shear", -1e-3, 3)
    with pytest.raises(ValueError, match="steps = 0 must be a positive integer"):
        run_material_point(mat, "shear", 1e-3, 0)


def _cli(argv):
    parser = argparse.ArgumentParser()
    cmd.add_arguments(parser)
    return cmd.main(parser.parse_args(argv))


def test_cli_prints_the_table_and_writes_csv(tmp_path, capsys):
    out = tmp_path / "mp.csv"
    assert (
        _cli(
            [
                "linear",
                "--hardening",
                "tension",
                "--path",
                "uniaxial-tension",
                "--strain",
                "0.002",
                "--steps",
                "6",
                "--param",
                "E=25000",
                "--param",
                "psi=10",
                "--csv",
                str(out),
            ]
        )
        == 0
    )
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0].startswith("# linear-tension along uniaxial-tension") and "E=25000" in lines[0]
    assert lines[1].split() == list(COLUMNS) and len(lines) == 8
    with open(out) as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == list(COLUMNS) and len(rows) == 7
    assert float(rows[-1][1]) == pytest.approx(0.002, rel=1e-14)
    # the command runs the same driver as the library
    mat = make_material(
        "linear",
        "tension",
        {**cmd.reference_parameters("linear", "tension"), "E": 25000.0, "psi": 10.0},
    )
    ref = run_material_point(mat, "uniaxial-tension", 0.002, 6)
    np.testing.assert_allclose([float(r[2]) for r in rows[1:]], ref.column("sig_axial"), rtol=1e-15)


def test_cli_case_names_and_errors(capsys):
    assert _cli(["hyperbolic-shear", "--steps", "3"]) == 0
    assert "hyperbolic-shear along shear" in capsys.readouterr().out
    with pytest.raises(ValueError, match="case 'cap' is unknown"):
        _cli(["cap"])
    with pytest.raises(ValueError, match="contradicts"):
        _cli(["linear-shear", "--hardening", "tension"])
    with pytest.raises(ValueError, match=r"K = 0.5 is out of range: allowed 0.778 <= K <= 1"):
        _cli(["linear", "--param", "K=0.5"])
    with pytest.raises(ValueError, match="unknown parameter.*'pt0'"):
        _cli(["linear", "--param", "pt0=2"])
    with pytest.raises(ValueError, match="NAME=VALUE"):
        _cli(["linear", "--param", "K"])
    assert cmd.NAME == "material" and cmd.HELP

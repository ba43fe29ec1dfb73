"""The femubench -> OpenSees DruckerPrager parameter mapping of bench/crosscheck/mapping.py, and
the `femubench crosscheck` command without openseespy.

Pure checks: nothing here needs openseespy (the cross-check run itself does).
"""

import math
import subprocess
import sys

import numpy as np
import pytest

from bench.crosscheck.mapping import (
    REFERENCE,
    dp_return,
    eqps_from_alpha,
    opensees_flow_direction,
    opensees_parameters,
    opensees_yield_value,
    tension_cutoff_I1,
)
from bench.crosscheck.reference import material_point_uniaxial, uniaxial_closed_form
from problems.materials.drucker_prager import make_material

P = {k: REFERENCE[k] for k in ("E", "nu", "beta", "psi", "sigma0", "H")}


def _ours(p):
    return make_material(
        "linear",
        "compression",
        {**{k: p[k] for k in ("E", "nu", "beta", "psi", "sigma0", "H")}, "K": 1.0},
    )


def test_mapping_values_at_the_reference():
    osp = opensees_parameters(**P)
    tb = math.tan(math.radians(35.0))
    assert osp["K"] == pytest.approx(30_000 / 1.8)
    assert osp["G"] == pytest.approx(12_500.0)
    assert osp["rho"] == pytest.approx(math.sqrt(2 / 3) * tb / 3) and osp["rho"] == pytest.approx(
        0.190572, abs=1e-6
    )
    assert osp["rhoBar"] == osp["rho"]  # psi = beta: associated
    assert osp["sigmaY"] == pytest.approx(15.3319, abs=1e-4)
    assert osp["H"] == pytest.approx((1 - tb / 3) ** 2 * 1500.0)
    assert (osp["theta"], osp["Kinf"], osp["Ko"], osp["delta1"], osp["delta2"]) == (
        1.0,
        0.0,
        0.0,
        0.0,
        0.0,
    )
    non = opensees_parameters(**{**P, "psi": 15.0})
    assert non["rhoBar"] == pytest.approx(math.sqrt(2 / 3) * math.tan(math.radians(15.0)) / 3)
    assert non["H"] == pytest.approx((1 - tb / 3) * (1 - math.tan(math.radians(15.0)) / 3) * 1500.0)
    # the cutoff plane sits at the apex of the initial cone
    assert tension_cutoff_I1(osp) == pytest.approx(3 * 20.0 * (1 - tb / 3) / tb)


@pytest.mark.parametrize(
    "bad", [{"psi": 40.0}, {"beta": 75.0}, {"psi": -1.0}, {"nu": 0.5}, {"sigma0": 0.0}]
)
def test_mapping_rejects_what_opensees_cannot_represent(bad):
    with pytest.raises(ValueError):
        opensees_parameters(**{**P, **bad})


@pytest.mark.parametrize("psi", [35.0, 15.0, 0.0])
def test_yield_surface_and_hardening_coincide(psi):
    """F_femubench = sqrt(3/2) f1_OpenSees with alpha1 = eqps / (1 - tan(psi)/3), anywhere in stress
    space."""
    p = {**P, "psi": psi}
    mat, osp = _ours(p), opensees_parameters(**p)
    rng = np.random.default_rng(1)
    stress = rng.normal(0.0, 30.0, (200, 6))
    eqps = rng.uniform(0.0, 0.02, 200)
    alpha = eqps / (1.0 - math.tan(math.radians(psi)) / 3.0)
    assert np.allclose(eqps_from_alpha(alpha, psi), eqps)
    F = mat.yield_value(stress, eqps)
    f = opensees_yield_value(stress, alpha, osp)
    assert np.allclose(F, math.sqrt(1.5) * f, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("psi", [35.0, 15.0])
def test_flow_directions_coincide(psi):
    """dG/dsigma = sqrt(3/2) (n + rhoBar 1): gamma = sqrt(3/2) dlambda and d alpha1 = dlambda."""
    p = {**P, "psi": psi}
    mat, osp = _ours(p), opensees_parameters(**p)
    stress = np.random.default_rng(2).normal(0.0, 30.0, (100, 6))
    assert np.allclose(
        mat.flow_direction(stress),
        math.sqrt(1.5) * opensees_flow_direction(stress, osp),
        rtol=1e-12,
        atol=1e-12,
    )


@pytest.mark.parametrize("psi", [35.0, 15.0])
def test_closed_form_uniaxial_matches_the_material(psi):
    p = {**P, "psi": psi}
    strain = np.linspace(0.0, 0.01, 21)[1:]
    s, lat, eqps = material_point_uniaxial(_ours(p), strain)
    cs, clat = uniaxial_closed_form(strain, **p)
    assert np.allclose(s, cs, rtol=1e-10)
    assert np.allclose(lat, clat, rtol=1e-10)
    # eqps = |eps_pl_11| in uniaxial compression
    assert np.allclose(eqps, strain - s / p["E"], rtol=1e-10, atol=1e-14)


def test_rederived_opensees_return_and_its_two_tangents():
    """The trial-norm tangent of the radial return is its exact derivative; the returned-norm
    variant (what OpenSees uses) is not, except for the rank-one part."""
    osp = opensees_parameters(**{**P, "psi": 15.0})
    eps = np.array([5e-4, 2e-4, -2e-3, 4e-4, -3e-4, 2e-4])
    h = 1e-9
    fd = np.column_stack(
        [
            (dp_return(eps + h * e, osp)[0] - dp_return(eps - h * e, osp)[0]) / (2 * h)
            for e in np.eye(6)
        ]
    )
    _, C = dp_return(eps, osp, "trial")
    _, C_ret = dp_return(eps, osp, "returned")
    assert np.abs(C - fd).max() < 1e-6 * np.abs(fd).max()
    assert np.abs(C_ret - fd).max() > 0.05 * np.abs(fd).max()
    # the re-derived return lands on femubench's cone (same material, one step from zero)
    mat = _ours({**P, "psi": 15.0})
    upd = mat.update(eps[None], np.zeros((1, 6)), mat.initial_state(1))
    assert np.allclose(dp_return(eps, osp)[0], upd.stress[0], rtol=1e-9, atol=1e-9)


def test_importing_the_crosscheck_does_not_import_openseespy():
    modules = (
        "mapping",
        "reference",
        "loader",
        "opensees_box",
        "single_element",
        "cube",
        "tangent",
        "report",
        "study",
        "figures",
    )
    code = (
        "import sys, bench.commands.crosscheck; "
        + "; ".join(f"import bench.crosscheck.{m}" for m in modules)
        + "; assert 'openseespy' not in sys.modules"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_command_without_openseespy_exits_2_with_the_install_hint(monkeypatch, capsys, tmp_path):
    from bench.cli import main
    from bench.crosscheck import loader

    monkeypatch.setattr(loader, "installed", lambda: False)
    monkeypatch.setattr(loader, "_OPS", None)
    assert main(["crosscheck", "--skip-cube", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "femubench[crosscheck]" in err and "pip install" in err
    assert not (tmp_path / "opensees_dp.json").exists()


def test_render_redraws_the_figures_from_the_report(tmp_path, capsys):
    """--render needs only opensees_dp.json (no openseespy): a report with one single-element run
    and
    one cube whose first OpenSees attempt converged."""
    from bench.cli import main

    strain = np.linspace(0.0, 0.01, 7)[1:]
    s, lat = uniaxial_closed_form(strain, **P)
    curve = {"stress": s.tolist(), "lateral": lat.tolist()}
    attempt = {
        "strategy": "Newton",
        "converged": True,
        "snapshots_mm": [0.75, 1.5],
        "reaction_kN": [500.0, 700.0],
    }
    report = {
        "single_element": [
            {
                "psi": 35.0,
                "strain": strain.tolist(),
                "closed_form": curve,
                "femubench": curve,
                "material_point": curve,
                "opensees": {"bbarBrick": curve, "stdBrick": curve},
            }
        ],
        "cube": [
            {
                "psi": 35.0,
                "femubench": {"snapshots_mm": [0.75, 1.5], "reaction_kN": [510.0, 705.0]},
                "opensees": [attempt],
                "plot": {
                    "strategy": "Newton",
                    "at_mm": 1.5,
                    "step": 2,
                    "z_mm": [5.0, 75.0, 145.0],
                    "u_h_femubench": [0.01, 0.03, 0.01],
                    "u_h_opensees": [0.01, 0.03, 0.01],
                    "residuals_opensees": [1.0, 1e-2, 1e-5, 1e-9],
                    "residuals_femubench": [1.0, 1e-4, 1e-10],
                },
            }
        ],
    }
    import json

    (tmp_path / "opensees_dp.json").write_text(json.dumps(report))
    assert main(["crosscheck", "--render", "--out", str(tmp_path)]) == 0
    for name in ("single_element.png", "cube.png"):
        assert (tmp_path / name).stat().st_size > 0
    assert main(["crosscheck", "--render", "--out", str(tmp_path / "missing")]) == 2

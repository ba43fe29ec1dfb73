"""Local sensitivities (eqs. 16-18) against closed forms on an analytic [u_h, u_v, r] model."""

import numpy as np
import pytest

from problems.analysis.local_sensitivity import (
    ModelFields,
    local_sensitivities,
    snapshot_sensitivities,
)
from problems.inverse import layout
from problems.inverse.protocol import ForwardResult

N, M = 6, 5
T = np.linspace(0.2, 1.2, N)  # "load" of each snapshot
G = np.linspace(1.0, 2.0, M)  # spatial shape of u_h
H = np.cos(np.linspace(0.0, 1.0, M))  # spatial shape of u_v
X_REF = np.array([2.0, 0.7, 5.0])


def fields(x):
    """u_h = x1 exp(x2 t) g, u_v = x1^2 t h, r = x3 t / (1 + x2 t): known sensitivities."""
    x1, x2, x3 = x
    u_h = x1 * np.exp(x2 * T)[:, None] * G[None, :]
    u_v = x1**2 * T[:, None] * H[None, :]
    r = x3 * T / (1.0 + x2 * T)
    return u_h, u_v, r


def closed_form(delta):
    """Exact finite-difference values of eqs. 16-18 for ``fields`` (per snapshot),
    [param][measure]."""
    x1, x2, x3 = X_REF
    d = delta
    return {
        0: {"ux": np.full(N, -1.0), "uy": np.full(N, -(2.0 + d)), "r": np.zeros(N)},
        1: {
            "ux": (1.0 - np.exp(x2 * d * T)) / d,
            "uy": np.zeros(N),
            "r": x2 * T / (1.0 + x2 * (1.0 + d) * T),
        },
        2: {"ux": np.zeros(N), "uy": np.zeros(N), "r": np.full(N, -1.0)},
    }


@pytest.mark.parametrize("delta", [0.01, 0.1, -0.05])
def test_eqs_16_18_match_the_exact_finite_difference_formulas(delta):
    s = local_sensitivities(fields, X_REF, delta=delta, names=("x1", "x2", "x3"))
    exact = closed_form(delta)
    for i in range(3):
        for m in ("ux", "uy", "r"):
            assert np.allclose(s.per_snapshot[m][i], exact[i][m], rtol=1e-10, atol=1e-12), (i, m)
            assert s.summed[m][i] == pytest.approx(exact[i][m].sum(), rel=1e-10, abs=1e-12)
    # linear dependence: 1 - ||u(x(1+d))|| / ||u(x)|| = -d exactly, so s = -N
    assert s.summed["ux"][0] == pytest.approx(-N)
    assert s.summed["r"][2] == pytest.approx(-N)
    assert s.n_evals == 4
    assert list(s.deltas) == [delta] * 3


def test_small_delta_tends_to_minus_the_log_derivative():
    s = local_sensitivities(fields, X_REF, delta=1e-6)
    x2 = X_REF[1]
    # d ln||u_h,n|| / d ln x2 = x2 t_n ; d ln r_n / d ln x2 = -x2 t_n / (1 + x2 t_n)
    assert np.allclose(s.per_snapshot["ux"][1], -x2 * T, rtol=1e-5)
    assert np.allclose(s.per_snapshot["r"][1], x2 * T / (1 + x2 * T), rtol=1e-5)
    # |s|: x1 -> N + 2 N, x3 -> N, x2 -> sum x2 t + sum x2 t / (1 + x2 t) = 2.94 + 1.87
    assert s.ranking() == ["x2", "x3", "x1"] and s.smallest() == "x2"


def test_failed_forward_step_falls_back_to_the_other_side():
    def fragile(x):
        if x[1] > X_REF[1]:  # x2 (1 + delta) fails
            return None
        return fields(x)

    with pytest.warns(RuntimeWarning, match="used x"):
        s = local_sensitivities(fragile, X_REF, delta=0.02)
    assert s.deltas[1] == -0.02 and s.deltas[0] == 0.02
    assert np.allclose(s.per_snapshot["ux"][1], closed_form(-0.02)[1]["ux"], rtol=1e-10)
    assert s.n_evals == 5 and len(s.messages) == 1


def test_both_sides_failing_gives_nan_and_reference_failure_raises():
    def no_x3(x):
        if x[2] != X_REF[2]:
            raise RuntimeError("diverged")
        return fields(x)

    with pytest.warns(RuntimeWarning, match="both"):
        s = local_sensitivities(no_x3, X_REF)
    assert np.all(np.isnan(s.per_snapshot["r"][2])) and np.isfinite(s.total_abs[:2]).all()
    assert s.ranking()[-1] == "x3"
    with pytest.raises(RuntimeError, match="reference"):
        local_sensitivities(lambda x: None, X_REF)
    with pytest.raises(ValueError, match="delta"):
        local_sensitivities(fields, X_REF, delta=0.0)


class LayoutModel:
    """A ForwardModel whose measurement vector is [u_h, u_v, r] (snapshot-major), as the FE one."""

    names = ("x1", "x2", "x3")

    def check(self, x):
        return None if x[0] > 0 else "x1 must be positive"

    def __call__(self, x):
        u_h, u_v, r = fields(x)
        return ForwardResult(True, np.concatenate([u_h.ravel(), u_v.ravel(), r]))


def test_model_fields_adapter_layout_and_mapper():
    values = LayoutModel()(X_REF).values
    for a, e in zip(layout.unstack(values, N, M), fields(X_REF)):
        assert np.array_equal(a, e)
    assert np.array_equal(layout.stack(*fields(X_REF)), values)
    with pytest.raises(ValueError, match="2 N m"):
        layout.unstack(values[:-1], N, M)
    calls = []

    def mapper(fn, items):
        calls.append(len(items))
        return [fn(x) for x in items]

    s = local_sensitivities(ModelFields(LayoutModel(), N, M), X_REF, delta=0.01, mapper=mapper)
    assert calls == [4]  # the reference and the three perturbations in one batch
    assert np.allclose(s.summed["uy"], [closed_form(0.01)[0]["uy"].sum(), 0, 0])
    assert ModelFields(LayoutModel(), N, M)(np.array([-1.0, 0.7, 5.0])) is None  # check() rejects


def test_snapshot_sensitivities_rejects_mismatched_shapes_and_zero_reference():
    ref = fields(X_REF)
    with pytest.raises(ValueError, match="shapes"):
        snapshot_sensitivities(ref, (ref[0][:2], ref[1], ref[2]), 0.01)
    zero = (np.zeros_like(ref[0]), ref[1], ref[2])
    out = snapshot_sensitivities(zero, ref, 0.01)
    assert np.all(np.isnan(out["ux"])) and np.all(np.isfinite(out["uy"]))


def test_rows_and_snapshot_rows():
    s = local_sensitivities(fields, X_REF, names=("a", "b", "c"))
    rows = s.rows()
    assert [r["parameter"] for r in rows] == ["a", "b", "c"]
    assert rows[0]["sum_abs"] == pytest.approx(
        abs(rows[0]["s_ux"]) + abs(rows[0]["s_uy"]) + abs(rows[0]["s_r"])
    )
    assert len(s.snapshot_rows()) == 3 * N
    assert s.smallest("r") in ("a", "b")  # s_r(a) = 0


def test_sensitivity_cli_on_a_tiny_fe_mesh(tmp_path, capsys):
    """Smoke test of `femubench sensitivity` (2 x 2 x 4 elements: 7 runs of ~0.5 s)."""
    import csv

    from bench.cli import main

    out = tmp_path / "sens"
    assert main(["sensitivity", "exponent-compression", "--mesh", "2,2,4", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "least to most sensitive" in text and "7 FE evaluations" in text
    rows = list(csv.DictReader((out / "sensitivity.csv").open()))
    assert [r["parameter"] for r in rows] == ["E", "psi", "sigma0", "H", "pt0", "b"]
    assert all(np.isfinite(float(r[k])) for r in rows for k in ("s_ux", "s_uy", "s_r"))
    assert len(list(csv.DictReader((out / "sensitivity_snapshots.csv").open()))) == 6 * 10
    for name in (
        "sensitivity.png",
        "sensitivity_snapshots.png",
        "sensitivity.md",
        "sensitivity.json",
    ):
        assert (out / name).stat().st_size > 0
    (out / "sensitivity.png").unlink()
    assert main(["sensitivity", "exponent-compression", "--render", "--out", str(out)]) == 0
    assert (out / "sensitivity.png").stat().st_size > 0
    assert main(["sensitivity", "exponent-compression", "--delta", "0", "--out", str(out)]) == 2
    assert main(["sensitivity", "analytic-smooth", "--out", str(out)]) == 2
    assert main(["sensitivity", "no-such-case", "--out", str(out)]) == 2

"""A point's DIC errors correlated between snapshots (the images route's shared reference image):
the equicorrelated-group whitening of LeastSquaresProblem, the Dataset's snapshot_rho, the
experiment file's snapshot_correlation (docs/calibrating.md, "DIC error correlation")."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from problems.inverse import layout
from problems.inverse.data import default_path, load
from problems.inverse.experiment import ExperimentFileError, import_experiment, load_experiment
from problems.inverse.problem import LeastSquaresProblem

ROOT = Path(__file__).resolve().parents[1]
CUBE100 = ROOT / "suites" / "experiments" / "cube100" / "experiment.toml"


def problem(m, **noise):
    one = np.ones(2)
    return LeastSquaresProblem(None, np.zeros(m), 0.5 * one, 2 * one, one, **noise)


def dense(sigma, groups, rho):
    """The full covariance: diag(sigma^2), each group's block D [(1 - rho) I + rho 1 1^T] D."""
    C = np.diag(sigma**2)
    n = groups.shape[1]
    R = (1 - rho) * np.eye(n) + rho * np.ones((n, n))
    for g in groups:
        C[np.ix_(g, g)] = np.outer(sigma[g], sigma[g]) * R
    return C


@pytest.mark.parametrize("rho", [0.5, 0.9, -0.3])
def test_group_whitening_equals_the_dense_cholesky(rho):
    N, m_pts = 4, 3
    m = layout.size(N, m_pts)
    rng = np.random.default_rng(1)
    sigma = rng.uniform(0.5, 2.0, m)
    G = layout.point_groups(N, m_pts)
    assert G.shape == (2 * m_pts, N) and len(np.unique(G)) == G.size
    assert G.max() < 2 * N * m_pts  # the force is in no group
    C = dense(sigma, G, rho)
    grouped = problem(m, sigma=sigma, groups=G, group_rho=rho)
    full = problem(m, covariance=C)
    d = rng.standard_normal(m)
    J = rng.standard_normal((m, 3))
    r1, r2 = grouped.whiten(d), full.whiten(d)
    assert np.isclose(r1 @ r1, d @ np.linalg.solve(C, d), rtol=1e-12)
    assert np.isclose(r1 @ r1, r2 @ r2, rtol=1e-12)
    W1, W2 = grouped.whiten(J), full.whiten(J)
    assert np.allclose(W1.T @ W1, J.T @ np.linalg.solve(C, J), rtol=1e-11)
    assert np.allclose(W1.T @ W1, W2.T @ W2, rtol=1e-11)
    assert np.allclose(W1.T @ r1, J.T @ np.linalg.solve(C, d), rtol=1e-11)
    # the values outside the groups (the force) are whitened by their sigma alone
    f = layout.blocks(N, m_pts)["force"]
    assert np.array_equal(r1[f], d[f] / sigma[f])


def test_rho_zero_is_the_diagonal_bit_for_bit_on_shipped_data():
    ds = load(default_path("linear-compression", "consistent"))
    assert ds.snapshot_rho == 0.0 and set(ds.noise()) == {"sigma"}
    N, m_pts = len(ds.snapshots_mm), len(ds.points)
    m = layout.size(N, m_pts)
    d = np.random.default_rng(2).standard_normal((m, 2))
    diag = problem(m, sigma=ds.sigma())
    zero = problem(m, sigma=ds.sigma(), groups=layout.point_groups(N, m_pts), group_rho=0.0)
    noise = problem(m, **ds.noise())
    for p in (zero, noise):
        assert np.array_equal(p.whiten(d), diag.whiten(d))
        assert np.array_equal(p.whiten(d[:, 0]), diag.whiten(d[:, 0]))
    # an experiment's export (the shipped example): no correlation, the same bytes and hash
    ex = import_experiment(load_experiment(CUBE100))
    assert ex.snapshot_rho == 0.0 and "snapshot_rho" not in ex.to_json()
    assert set(ex.noise()) == {"sigma"}


@pytest.mark.parametrize("rho", [1.0, 1.5, -1 / 3, -0.5, float("nan")])
def test_bad_rho_is_a_one_line_error_naming_the_value(rho):
    N, m_pts = 4, 3
    m = layout.size(N, m_pts)
    with pytest.raises(ValueError) as exc:
        problem(m, sigma=np.ones(m), groups=layout.point_groups(N, m_pts), group_rho=rho)
    msg = str(exc.value)
    assert f"rho = {rho!r} is out of range" in msg and "\n" not in msg
    assert "-0.333333 < rho < 1" in msg


def test_dataset_carries_rho_through_its_file_and_hash(tmp_path):
    ds = import_experiment(load_experiment(CUBE100))
    corr = dataclasses.replace(ds, snapshot_rho=0.5)
    assert corr.hash != ds.hash
    f = tmp_path / "d.json"
    f.write_text(corr.to_json())
    back = load(f)
    assert back.snapshot_rho == 0.5 and back.hash == corr.hash
    noise = back.noise()
    assert noise["group_rho"] == 0.5
    assert noise["groups"].shape == (2 * len(ds.points), len(ds.snapshots_mm))
    bad = tmp_path / "bad.json"
    bad.write_text(dataclasses.replace(ds, snapshot_rho=1.5).to_json())
    with pytest.raises(ValueError, match=r"field snapshot_rho = 1.5 is out of range"):
        load(bad)


def test_calibration_objective_whitens_with_the_data_correlation():
    from bench.calibration import objective_for
    from problems.inverse.lab import lab_case

    ds = dataclasses.replace(import_experiment(load_experiment(CUBE100)), snapshot_rho=0.5)
    case = lab_case("linear-compression", ds)
    p = objective_for(ds, case, "2,2,4").problem
    d = np.random.default_rng(3).standard_normal(len(ds.values))
    noise = ds.noise()
    C = dense(noise["sigma"], noise["groups"], 0.5)
    r = p.whiten(d)
    assert np.isclose(r @ r, d @ np.linalg.solve(C, d), rtol=1e-10)


def test_experiment_file_snapshot_correlation(tmp_path):
    text = CUBE100.read_text()
    assert load_experiment(CUBE100).snapshot_rho == 0.0  # an export: independent by default
    f = tmp_path / "rho.toml"
    base = text.replace('log = "machine_log.csv"', f'log = "{CUBE100.parent / "machine_log.csv"}"')
    base = base.replace('files = "dic/image_*.csv"', f'files = "{CUBE100.parent}/dic/image_*.csv"')
    f.write_text(base.replace("[dic]\n", "[dic]\nsnapshot_correlation = 0.25\n"))
    assert load_experiment(f).snapshot_rho == 0.25
    assert import_experiment(load_experiment(f)).snapshot_rho == 0.25
    f.write_text(base.replace("[dic]\n", "[dic]\nsnapshot_correlation = 1\n"))
    with pytest.raises(ExperimentFileError) as exc:
        load_experiment(f)
    assert exc.value.errors == ["[dic] snapshot_correlation = 1: must be in [0, 1)"]


def test_the_benchmark_objective_refuses_a_correlation_it_would_drop():
    """build_objective whitens by sigma alone: a data set with snapshot_rho is refused in one line
    rather than fitted as if its snapshots were independent."""
    from problems.inverse.build import build_objective

    ds = load(default_path("linear-compression", "consistent"))
    with pytest.raises(ValueError) as exc:
        build_objective(
            "linear-compression", mesh="coarse", data=dataclasses.replace(ds, snapshot_rho=0.3)
        )
    assert "snapshot_rho = 0.3" in str(exc.value) and "\n" not in str(exc.value)

"""Fisher information and Laplace covariance against closed forms on linear models."""

import numpy as np
import pytest

from problems.analysis.identifiability import (
    analyse_jacobian,
    correlation_matrix,
    fisher_information,
    identifiability,
    laplace_covariance,
    refine_mode,
)
from problems.inverse.protocol import ForwardResult
from tests.support import evaluator

REF = np.array([2.0, 50.0, 0.3])
SIGMA = np.array([0.1] * 8 + [0.5] * 4)


def design(m=12, seed=1):
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, m)
    return np.column_stack([1 + t, t**2, np.sin(3 * t)]) + 0.2 * rng.standard_normal((m, 3))


class Linear:
    names = ("a", "b", "c")

    def __init__(self, A):
        self.A = A

    def check(self, x):
        return None

    def __call__(self, x):
        return ForwardResult(True, self.A @ np.asarray(x))


def objective(A, data=None):
    model = Linear(A)
    data = model(REF).values if data is None else data
    return evaluator(model, data, lower=REF * 0.5, upper=REF * 1.5, reference=REF, sigma=SIGMA)


def closed_form(A):
    """Physical Fisher A^T W A (W = diag 1/sigma^2), z-Fisher S F S, covariance (A^T W A)^-1."""
    W = np.diag(1 / SIGMA**2)
    Fx = A.T @ W @ A
    S = np.diag(REF)
    return Fx, S @ Fx @ S, np.linalg.inv(Fx)


def test_fisher_and_laplace_match_closed_forms_from_the_exact_jacobian():
    A = design()
    Fx, Fz, Cx = closed_form(A)
    Jz = -(A * REF) / SIGMA[:, None]  # dR/dz = -C^-1/2 A S
    ident = analyse_jacobian(Jz, REF, names=("a", "b", "c"))
    assert np.allclose(fisher_information(Jz), Fz, rtol=1e-12)
    assert np.allclose(ident.fisher_x, Fx, rtol=1e-12)
    assert np.allclose(ident.cov_x, Cx, rtol=1e-10)
    assert np.allclose(ident.cov_z, np.linalg.inv(Fz), rtol=1e-10)
    sd = np.sqrt(np.diag(Cx))
    assert np.allclose(ident.std_x, sd, rtol=1e-10)
    assert np.allclose(ident.std_percent, 100 * sd / REF, rtol=1e-10)
    assert np.allclose(ident.correlation, Cx / np.outer(sd, sd), atol=1e-12)
    lam = np.linalg.eigvalsh(Fz)
    assert np.allclose(ident.eigenvalues, lam[::-1], rtol=1e-10)
    assert ident.condition == pytest.approx(lam[-1] / lam[0], rel=1e-8)
    assert ident.condition == pytest.approx(np.linalg.cond(Fz), rel=1e-6)
    assert ident.rank == 3 and not ident.pinv and not ident.warnings
    # the weakest direction is the eigenvector of the smallest eigenvalue
    v = np.array(list(ident.weakest.values()))
    assert np.allclose(Fz @ v, lam[0] * v, rtol=1e-8, atol=1e-8 * lam[-1])


def test_objective_jacobian_route_matches_the_closed_form():
    A = design()
    obj = objective(A)
    _, Fz, Cx = closed_form(A)
    for scheme in ("forward", "central"):
        obj.reset()
        ident = identifiability(obj, scheme=scheme)
        assert np.allclose(ident.fisher_z, Fz, rtol=1e-5)
        assert np.allclose(ident.cov_x, Cx, rtol=1e-4)
        assert ident.n_evals == (4 if scheme == "forward" else 7)
    assert np.array_equal(ident.x, REF)


def test_singular_fisher_uses_the_pseudo_inverse_and_says_so():
    A = design()
    A[:, 2] = 2.0 * A[:, 0] * REF[0] / REF[2]  # c moves the data exactly like a: z-columns parallel
    Jz = -(A * REF) / SIGMA[:, None]
    ident = analyse_jacobian(Jz, REF, names=("a", "b", "c"))
    assert ident.pinv and ident.rank == 2
    assert ident.condition > 1e12 or ident.condition == np.inf
    assert any("pseudo-inverse" in w and "not identifiable" in w for w in ident.warnings)
    assert np.allclose(
        ident.cov_z,
        np.linalg.pinv(ident.fisher_z, rcond=1e-12, hermitian=True),
        rtol=1e-6,
        atol=1e-12 * np.abs(ident.cov_z).max(),
    )
    w = ident.weakest  # null direction: a and c with opposite signs, b absent
    assert abs(w["b"]) < 1e-6 and w["a"] * w["c"] < 0


def test_zero_jacobian_column_is_reported():
    Jz = -(design() * REF) / SIGMA[:, None]
    Jz[:, 1] = 0.0
    ident = analyse_jacobian(Jz, REF, names=("a", "b", "c"))
    assert ident.rank == 2 and ident.condition == np.inf
    assert any("do not depend on b" in w for w in ident.warnings)
    # pinv: no variance in the unidentifiable direction, flagged
    assert ident.std_percent[1] < 1e-9 * ident.std_percent.max()


def test_helpers_and_input_checks():
    cov, rank, used = laplace_covariance(np.diag([4.0, 1.0]))
    assert np.allclose(cov, np.diag([0.25, 1.0])) and rank == 2 and not used
    rho = correlation_matrix(np.array([[4.0, 1.0], [1.0, 1.0]]))
    assert rho[0, 1] == pytest.approx(0.5) and rho[0, 0] == 1.0
    with pytest.raises(ValueError, match="shape"):
        analyse_jacobian(np.ones((5, 2)), REF)
    with pytest.raises(ValueError, match="non-finite"):
        analyse_jacobian(np.full((5, 3), np.nan), REF)


def test_refine_mode_reaches_the_least_squares_solution_in_one_step():
    A = design()
    rng = np.random.default_rng(3)
    clean = A @ REF
    data = clean + 0.1 * SIGMA * rng.standard_normal(clean.size)  # keeps the LS point in the box
    obj = objective(A, data)
    W = A / SIGMA[:, None]
    x_ls = np.linalg.solve(W.T @ W, W.T @ (data / SIGMA))
    out = refine_mode(obj, np.full(3, 1.1), max_steps=4)
    assert out.converged
    assert np.allclose(obj.to_physical(out.z), x_ls, rtol=1e-6)
    assert out.cost == pytest.approx(float(np.sum(((data - A @ x_ls) / SIGMA) ** 2)), rel=1e-8)
    assert out.steps <= 2 and out.n_evals == obj.n_evals
    ident = analyse_jacobian(out.jacobian, REF, x=obj.to_physical(out.z))
    assert np.allclose(ident.cov_x, closed_form(A)[2], rtol=1e-4)


def test_identifiability_cli_on_analytic_cases(tmp_path, capsys):
    import csv
    import json

    from bench.cli import main

    out = tmp_path / "ident"
    assert (
        main(
            [
                "identifiability",
                "analytic-smooth",
                "analytic-linear",
                "--scheme",
                "central",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "analytic-smooth: cond(J^T J) =" in text and "analytic-linear" in text
    doc = json.loads((out / "analytic-linear" / "identifiability.json").read_text())
    # analytic-linear: closed-form posterior covariance of the LinearModel
    from problems.inverse.analytic import analytic_model

    model = analytic_model("analytic-linear")
    _, cov = model.posterior(model.values(model.reference))
    assert np.allclose(doc["cov_x"], cov, rtol=1e-5)
    rows = list(csv.DictReader((out / "analytic-smooth" / "identifiability.csv").open()))
    assert [r["parameter"] for r in rows] == ["E", "sigma0", "H", "psi"]
    for name in ("correlation.png", "correlation.csv", "fisher_eigen.csv", "identifiability.md"):
        assert (out / "analytic-smooth" / name).stat().st_size > 0
    assert (out / "summary.md").exists() and (out / "std_percent.png").exists()
    for png in (out / "std_percent.png", out / "analytic-smooth" / "correlation.png"):
        png.unlink()
    assert (
        main(
            ["identifiability", "analytic-smooth", "analytic-linear", "--render", "--out", str(out)]
        )
        == 0
    )
    assert (out / "std_percent.png").exists() and (
        out / "analytic-smooth" / "correlation.png"
    ).exists()
    assert main(["identifiability", "analytic-smooth", "--x", "E=1e9", "--out", str(out)]) == 2
    assert main(["identifiability", "analytic-smooth", "analytic-linear", "--x", "E=3e4"]) == 2


def test_default_output_goes_under_the_results_root_not_the_current_directory(
    tmp_path, monkeypatch
):
    from bench.cli import main

    root, cwd = tmp_path / "root", tmp_path / "cwd"
    cwd.mkdir()
    monkeypatch.chdir(cwd)
    monkeypatch.setenv("FEMUBENCH_RESULTS_DIR", str(root))
    assert main(["identifiability", "analytic-linear", "--no-figures"]) == 0
    assert (
        root / "studies" / "identifiability" / "analytic-linear" / "identifiability.json"
    ).exists()
    assert not any(cwd.iterdir())
    assert main(["identifiability", "analytic-linear", "--render"]) == 0
    assert (root / "studies" / "identifiability" / "analytic-linear" / "correlation.png").exists()

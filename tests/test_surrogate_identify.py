"""Identification on a stored surrogate: forward-model swap in build_objective, the honesty rule,
the measurement region, the vectorised mapper, the accounting of the combined run, the separate
force block of the POD, the enrichment search and the packed GP prediction."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from bench.experiment.identify import identify
from bench.experiment.spec import DataSpec, RunSpec
from problems.fe.mesh import discretisation_key
from problems.inverse.build import Region, build_objective
from problems.inverse.cases import get_case
from problems.inverse.data import get_data, tier_settings
from problems.inverse.forward import FEForwardModel
from problems.inverse.model_error import HonestyError
from problems.surrogate import SurrogateSettings, fit_surrogate, save
from problems.surrogate.build import surrogate_optimum
from problems.surrogate.model import VectorisedMapper, restricted
from problems.surrogate.pod import fit_pod
from problems.surrogate.regression import fit_gp
from problems.surrogate.training import Runs

CASE = "linear-compression"


def fake_surrogate(
    mesh: str = "coarse", discretisation: str | None = None, n: int = 40, case: str = CASE
):
    """A surrogate of the case's FE layout fitted to a cheap smooth map of x (no FE run): the
    consistent data's values plus a smooth function of the scaled parameters (of ``case``)."""
    name, case = case, get_case(case)
    data = get_data(name, tier_settings("consistent"))
    rng = np.random.default_rng(0)
    X = case.lower + rng.random((n, len(case.names))) * (case.upper - case.lower)
    Z = (X - case.lower) / (case.upper - case.lower)
    base = data.values
    m = base.size
    pattern = np.sin(np.arange(m)[None, :] * 0.01 + np.arange(6)[:, None]) * 1e-4
    Y = base + (Z - 0.5) @ pattern + 0.5 * np.sin(3 * Z[:, :1]) * 1e-4
    Y[:, -10:] = base[-10:] + 40.0 * (Z[:, :1] - 0.5) + 10 * Z[:, 1:2] ** 2
    checker = FEForwardModel(case, mesh, data.settings.loading, data.points)
    s = SurrogateSettings(regression="gp", gp_restarts=0, gp_individual=2)
    from problems.inverse import layout

    blocks = {k: v for k, v in layout.blocks(10, len(data.points)).items() if k != "displacement"}
    sur = fit_surrogate(
        Runs(X, Y, np.full(n, 0.3)),
        case.lower,
        case.upper,
        data.sigma(),
        names=case.names,
        settings=s,
        blocks=blocks,
        checker=checker,
    )
    info = dict(
        sur.info,
        description={
            "case": name,
            "mesh": mesh,
            "discretisation": discretisation or discretisation_key(mesh),
            "n_snapshots": 10,
            "n_points": len(data.points),
        },
        cost={"training": {"n_runs": n, "fe_wall_s": 0.3 * n, "median_run_s": 0.3}},
        validation={"fe_eval_s": 0.3, "blocks": {"force": {"rms_sigma": 0.5}}},
    )
    return dataclasses.replace(sur, info=info, hold_out_variance=np.full(m, 1e-14))


@pytest.fixture(scope="module")
def stored(tmp_path_factory):
    folder = tmp_path_factory.mktemp("sur") / "lc"
    save(fake_surrogate(), folder)
    return folder


def test_force_values_kept_out_of_the_pod_are_exact_identity_columns():
    rng = np.random.default_rng(1)
    Y = rng.standard_normal((30, 4)) @ rng.standard_normal((4, 50))
    blocks = {"u": slice(0, 45), "force": slice(45, 50)}
    pod = fit_pod(Y, 1.0, tol_sigma=1e-6, blocks=blocks, separate=("force",))
    np.testing.assert_allclose(pod.modes.T @ pod.modes, np.eye(pod.n_modes), atol=1e-12)
    np.testing.assert_allclose(pod.modes[45:, -5:], np.eye(5))
    assert np.all(pod.modes[45:, :-5] == 0) and np.all(pod.modes[:45, -5:] == 0)
    np.testing.assert_allclose(pod.reconstruct(pod.coefficients(Y)), Y, atol=1e-8)
    assert pod.projection_rms["force"] == 0.0


def test_packed_gp_prediction_and_gradient_match_the_components():
    rng = np.random.default_rng(2)
    Z = rng.random((40, 3))
    A = np.column_stack([np.sin(3 * Z[:, 0]), Z[:, 1] ** 2, Z[:, 2], np.cos(Z[:, 0] * Z[:, 1])])
    g = fit_gp(Z, A, n_individual=1, restarts=0, individual=(3,))
    assert len(g.components) == 3
    Zq = rng.random((7, 3))
    slow = np.empty((7, 4))
    for c in g.components:
        slow[:, c.outputs] = c.predict(Zq)
    # same sums in another order: round-off times the (large) GP weights alpha
    np.testing.assert_allclose(g.predict(Zq), slow, rtol=0, atol=1e-5)
    np.testing.assert_allclose(g.predict(Zq[:1]), slow[:1], rtol=0, atol=1e-5)
    gs = np.vstack([c.gradient(Zq[0]) for c in g.components])
    order = np.concatenate([c.outputs for c in g.components])
    np.testing.assert_allclose(g.gradient(Zq[0])[order], gs, rtol=1e-5, atol=1e-4)


def test_batch_evaluation_equals_single_calls_and_mapper_uses_it(stored):
    from problems.inverse.protocol import RunModel
    from problems.surrogate import load

    sur = load(stored)
    rng = np.random.default_rng(3)
    X = sur.lower + rng.random((5, 6)) * (sur.upper - sur.lower)
    X[2, 0] = sur.upper[0] * 2  # outside the box: refused like the single call
    batch = sur.evaluate_batch(X)
    for x, b in zip(X, batch):
        one = sur(x)
        assert one.ok == b.ok
        if one.ok:
            # same sums in another order: round-off times the GP weights, far below the noise
            assert np.max(np.abs(b.values - one.values) / sur.pod.scale) < 1e-3
    out = VectorisedMapper()(RunModel(sur, True), list(X[:2]))
    np.testing.assert_allclose(out[1].jacobian, sur(X[1], jacobian=True).jacobian, rtol=1e-12)


def test_surrogate_replaces_the_fe_model_and_honours_the_region(stored):
    from problems.surrogate import load

    sur = load(stored)
    obj = build_objective(CASE, tier="consistent", forward=sur, region=Region(30.0))
    assert obj.provenance["forward"] == "surrogate"
    assert obj.provenance["surrogate_hash"] == sur.hash
    x = 0.5 * (sur.lower + sur.upper)
    full = sur(x).values
    part = obj.model(x).values
    assert part.size == obj.n_residuals < full.size
    data = get_data(CASE, tier_settings("consistent"))
    keep = Region(30.0).mask(data.points)
    N, m = 10, len(data.points)
    np.testing.assert_allclose(part[: N * keep.sum()], full[: N * m].reshape(N, m)[:, keep].ravel())
    np.testing.assert_allclose(part[-N:], full[-N:])


def test_honesty_rule_refuses_a_surrogate_of_the_data_discretisation():
    reference = fake_surrogate(discretisation=discretisation_key("converged"))
    with pytest.raises(HonestyError, match="surrogate"):
        build_objective(CASE, tier="model-error", forward=reference)
    paper = fake_surrogate(mesh="paper")
    with pytest.raises(ValueError, match="inverse mesh"):
        build_objective(CASE, tier="model-error", forward=paper)
    other = fake_surrogate()
    with pytest.raises(ValueError, match="parameters|case"):
        restricted(other, get_case("linear-shear"), other.checker.points, other.checker.loading)


def test_identify_on_surrogate_counts_and_charges_honestly(stored):
    spec = RunSpec(
        CASE,
        "cma",
        budget=120,
        options={"sigma0": 0.2},
        data=DataSpec("consistent"),
        surrogate=str(stored),
    )
    res = identify(spec)
    assert res.n_evals == 120 or res.n_evals < 120
    train = res.charges["surrogate-training"]
    assert train["n"] == 40 and train["forward_equivalents"] == 40.0
    # each surrogate evaluation costs far less than one FE run (its measured wall time / 0.3 s)
    assert 0 < res.forward_equivalents < 0.2 * res.n_evals
    assert res.provenance["forward"] == "surrogate" and res.provenance["polish"] is False
    assert res.provenance["surrogate_hash"] == res.extra["surrogate"]["hash"]
    assert res.extra["surrogate"]["amortised_forward_equivalents"] == pytest.approx(
        res.forward_equivalents
    )


def test_identify_with_fe_polish_counts_the_fe_runs(stored):
    spec = RunSpec(
        CASE, "cma", budget=60, data=DataSpec("consistent"), surrogate=str(stored), polish_budget=2
    )
    res = identify(spec)
    pol = res.extra["polish"]
    assert pol["method"] == "lm" and 1 <= pol["n_evals"] <= 2
    assert res.n_evals == res.extra["surrogate"]["n_evals"] + pol["n_evals"]
    assert res.forward_equivalents == pytest.approx(
        res.extra["surrogate"]["forward_equivalents"] + pol["forward_equivalents"]
    )
    assert pol["forward_equivalents"] >= 1.0  # FE runs: the first one is a plain FE run
    assert res.provenance["forward"] == "surrogate+fe-polish" and res.provenance["polish"] is True
    assert res.x == pol["x"] and res.cost == pol["cost"]


def test_polish_without_surrogate_is_refused():
    with pytest.raises(ValueError, match="surrogate"):
        RunSpec(CASE, "lm", polish_budget=60)


def test_enrichment_search_finds_the_surrogate_optimum_of_the_data():
    sur = fake_surrogate()
    x_true = sur.lower + np.array([0.3, 0.6, 0.4, 0.5, 0.7, 0.2]) * (sur.upper - sur.lower)
    target = sur.predict(x_true)[0]
    x, cost = surrogate_optimum(sur, target, sur.pod.scale)
    assert cost < 1e-6 * np.sum(((sur.predict(sur.lower)[0] - target) / sur.pod.scale) ** 2)
    np.testing.assert_allclose(sur.predict(x)[0], target, rtol=0, atol=1e-3 * sur.pod.scale.max())

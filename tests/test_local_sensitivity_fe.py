"""Fig. 5 on the FE model: local sensitivities of exponent-compression (coarse mesh). Slow: 22 FE
runs.

The paper reports that the exponent form's ``a`` barely moves the measurements. On this
implementation it does not come out smallest (measured, coarse mesh, delta = 0.01, sum of
|s_ux| + |s_uy| + |s_r|): H 2.56 < psi 2.66 < E 5.20 < a 6.02 < sigma0 6.41 < b 36.1.
Why (docs/sensitivity.md): the hardening is measured in uniaxial compression, so the yield
surface F = a q^b - p - pt(sigma_bar) is pinned at the current compression state
(pt = a sigma_bar^b - sigma_bar / 3); ``a`` only tilts the meridian there, through the slope
dF/dq = a b q^(b-1), which ``b`` changes (1 + b ln sigma_bar) ~ 6 times more strongly per
relative step. Hence ``a`` and ``b`` have the same sensitivity *pattern*, with ``s(b) ~ 6 s(a)``
in every measure, and ``a`` lies mid-table rather than last. But the two patterns are collinear, so
the Fisher information makes ``a`` the least identifiable parameter (corr(a, b) = -0.999): the
paper's conclusion holds for identifiability, not for the size of s. These assertions pin those
facts.
"""

import numpy as np
import pytest

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def both_sides():
    from bench.studies.local_sensitivity import fe_sensitivities

    plus, _ = fe_sensitivities("exponent-compression", mesh="coarse", delta=0.01)
    minus, _ = fe_sensitivities("exponent-compression", mesh="coarse", delta=-0.01)
    for s in (plus, minus):
        print(
            f"delta {s.delta:+g}: "
            + ", ".join(
                f"{r['parameter']} (s_ux {r['s_ux']:.3g}, s_uy {r['s_uy']:.3g}, s_r "
                f"{r['s_r']:.3g}, sum {r['sum_abs']:.3g})"
                for r in s.rows()
            )
        )
    return plus, minus


def test_all_six_sensitivities_are_finite_and_one_sided_steps_agree(both_sides):
    plus, minus = both_sides
    assert plus.names == ("E", "psi", "sigma0", "H", "a", "b")
    assert np.all(np.isfinite(plus.total_abs)) and not plus.messages
    # +-1 % steps give the same sums to within 5 % (measured <= 3 %): the step is in the linear
    # range, far above FE noise. Except b (measured 36.1 vs 41.3): a 1 % step in b is a ~6 % step in
    # the meridian slope, so the curvature of the response shows.
    assert np.allclose(plus.total_abs[:5], minus.total_abs[:5], rtol=0.05)
    assert plus.total_abs[5] == pytest.approx(minus.total_abs[5], rel=0.2)


def test_vertical_field_is_nearly_insensitive(both_sides):
    """u_v is prescribed by the plate: |s_uy| is an order below the larger of |s_ux|, |s_r|."""
    s = both_sides[0].summed
    assert np.all(np.abs(s["uy"]) < 0.4 * np.maximum(np.abs(s["ux"]), np.abs(s["r"])))


def test_a_versus_the_paper_fig5(both_sides):
    s = both_sides[0]
    t = dict(zip(s.names, s.total_abs))
    # b is by far the most sensitive, and a acts like b scaled down by ~ 1 + b ln(sigma_bar) ~ 6
    assert s.ranking()[-1] == "b"
    for m in ("ux", "uy", "r"):
        ratio = s.summed[m][5] / s.summed[m][4]
        assert 4.0 < ratio < 8.0, (m, ratio)
    # not the paper's finding: a is mid-table; the least sensitive are H and psi
    assert set(s.ranking()[:2]) == {"H", "psi"}
    assert t["a"] > 1.5 * min(t.values())


def test_a_and_b_move_the_measurements_the_same_way(both_sides):
    """Per-snapshot sensitivity patterns (s_ux, s_uy, s_r over the 10 snapshots) of a and b are
    collinear (cosine 0.999 measured): what a does, b can undo. This, not a small |s|, is why a is
    hard to identify -- see the Fisher test below."""
    s = both_sides[0]
    V = np.hstack([s.per_snapshot[m] for m in ("ux", "uy", "r")])
    a, b = V[4], V[5]
    assert a @ b / (np.linalg.norm(a) * np.linalg.norm(b)) > 0.99


def test_fisher_information_makes_a_the_least_identifiable():
    """Laplace covariance on synthetic coarse data: a has the largest predicted sd (% of reference),
    the weakest Fisher direction is mostly a, and corr(a, b) is close to -1 (measured -0.999)."""
    from bench.studies.identifiability import case_identifiability

    ident, _, _ = case_identifiability("exponent-compression", mesh="coarse", data="synthetic")
    sd = dict(zip(ident.names, ident.std_percent))
    print(
        "Laplace sd %:", {k: round(v, 4) for k, v in sd.items()}, "cond", f"{ident.condition:.3g}"
    )
    assert max(sd, key=sd.get) == "a"
    assert abs(ident.weakest["a"]) > 0.9
    rho = ident.correlation
    assert rho[4, 5] < -0.99

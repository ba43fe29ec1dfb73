"""Fig. 5 on the FE model: local sensitivities of exponent-compression (coarse mesh). Slow: 14 FE
runs for the sensitivities, 1 (with the exact Jacobian) for the Fisher information; 6 s.

The exponent cases identify (E, psi, sigma0, H, pt0, b); ``a = (pt0 + sigma0/3) / sigma0^b`` is
derived (problems/inverse/cases.py, since 1e7ca83). The paper reports that the exponent form's
``a`` barely moves the measurements. Measured today (coarse mesh, delta = 0.01, sum of
|s_ux| + |s_uy| + |s_r|): pt0 1.66 < H 2.56 < psi 2.66 < E 5.20 < b 10.80 < sigma0 10.91, so in
this parametrisation the strength parameter ``pt0`` is the least sensitive *and* (Fisher
information) the least identifiable one: the paper's finding holds for pt0.

How ``a`` compares (docs/sensitivity.md): at fixed sigma0 and b, ``a`` is affine in pt0 with
d ln a / d ln pt0 = pt0 / (pt0 + sigma0/3) = 0.273, so a 1 % step in ``a`` is a 3.67 % step in
pt0 and s(a) = 3.67 s(pt0) = 6.09 to first order -- the 6.02 measured when ``a`` was identified
(mid-table then, as now). The parametrisation does not change what the data determine: the
Laplace sd of the derived ``a`` is 0.68 % and corr(a, b) = -0.999, as when ``a`` was identified.
These assertions pin those facts.
"""

import numpy as np
import pytest

pytestmark = pytest.mark.slow

NAMES = ("E", "psi", "sigma0", "H", "pt0", "b")


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
    assert plus.names == NAMES
    assert np.all(np.isfinite(plus.total_abs)) and not plus.messages
    # +-1 % steps give the same sums to within 3 % (measured <= 1.5 %, E 5.20 vs 5.28): the step is
    # in the linear range, far above FE noise. b is more curved (measured 10.80 vs 11.36, 5 %).
    assert np.allclose(plus.total_abs[:5], minus.total_abs[:5], rtol=0.03)
    assert plus.total_abs[5] == pytest.approx(minus.total_abs[5], rel=0.1)


def test_vertical_field_is_nearly_insensitive(both_sides):
    """u_v is prescribed by the plate: |s_uy| is an order below the larger of |s_ux|, |s_r|
    (measured: largest |s_uy| 0.27, for b, against s_r(b) 7.9)."""
    s = both_sides[0].summed
    assert np.all(np.abs(s["uy"]) < 0.4 * np.maximum(np.abs(s["ux"]), np.abs(s["r"])))


def test_pt0_is_the_least_sensitive_as_a_in_the_paper_fig5(both_sides):
    s = both_sides[0]
    t = dict(zip(s.names, s.total_abs))
    # measured: pt0 1.66 < H 2.56 < psi 2.66 < E 5.20 < b 10.80 < sigma0 10.91
    assert s.ranking()[0] == "pt0"
    assert t["pt0"] < 0.75 * min(v for k, v in t.items() if k != "pt0")  # measured 0.65
    # sigma0 and b (both also move a) lead, about twice E (their order flips with the sign of delta)
    assert set(s.ranking()[-2:]) == {"sigma0", "b"}
    assert min(t["sigma0"], t["b"]) > 1.8 * t["E"]  # measured 2.08


def test_a_sensitivity_follows_from_pt0(both_sides):
    """At fixed sigma0, b the derived a is affine in pt0: s(a) = s(pt0) (pt0 + sigma0/3) / pt0.
    That reproduces the s(a) measured when a was identified (s_ux -1.611, s_uy 0.154, s_r 4.26,
    sum 6.02; now 3.67 x pt0's: -1.63, 0.154, 4.31, sum 6.09)."""
    s = both_sides[0]
    x = dict(zip(s.names, s.x_ref))
    factor = (x["pt0"] + x["sigma0"] / 3.0) / x["pt0"]
    i = s.names.index("pt0")
    for m, old in (("ux", -1.611), ("uy", 0.154), ("r", 4.26)):
        assert factor * s.summed[m][i] == pytest.approx(old, rel=0.03), m
    assert factor * s.total_abs[i] == pytest.approx(6.02, rel=0.03)


def test_pt0_b_and_sigma0_move_the_measurements_the_same_way(both_sides):
    """Per-snapshot sensitivity patterns (s_ux, s_uy, s_r over the 10 snapshots): pt0 and b are
    collinear (cosine 0.987 measured), pt0 and sigma0 anti-collinear (-0.972). What pt0 does, b
    or sigma0 can undo: this, together with its small |s|, is why pt0 is hard to identify."""
    s = both_sides[0]
    V = np.hstack([s.per_snapshot[m] for m in ("ux", "uy", "r")])
    V = V / np.linalg.norm(V, axis=1)[:, None]
    i, j, k = (s.names.index(n) for n in ("pt0", "b", "sigma0"))
    assert V[i] @ V[j] > 0.98
    assert V[i] @ V[k] < -0.96


def test_fisher_information_makes_pt0_the_least_identifiable():
    """Laplace covariance on synthetic coarse data (measured sd %: E 0.056, psi 0.043, sigma0 0.046,
    H 0.069, pt0 0.73, b 0.11; cond 1.46e4 against 9.8e4 when a was identified): pt0 has the
    largest sd, the weakest Fisher direction is mostly pt0 (0.988), corr(pt0, b) = -0.987. The
    derived a (delta method) keeps the a-parametrisation's numbers: sd 0.68 %,
    corr(a, b) = -0.9994."""
    from bench.studies.identifiability import case_identifiability
    from problems.inverse.cases import get_case

    ident, _, _ = case_identifiability("exponent-compression", mesh="coarse", data="synthetic")
    sd = dict(zip(ident.names, ident.std_percent))
    print(
        "Laplace sd %:", {k: round(v, 4) for k, v in sd.items()}, "cond", f"{ident.condition:.3g}"
    )
    assert ident.names == NAMES
    assert max(sd, key=sd.get) == "pt0"
    assert sd["pt0"] > 5 * max(v for k, v in sd.items() if k != "pt0")  # measured 6.7
    assert ident.weakest["pt0"] > 0.95
    assert 1e4 < ident.condition < 2e4
    rho = ident.correlation
    assert rho[4, 5] < -0.98

    case = get_case("exponent-compression")
    a = case.material_parameters(ident.x)["a"]
    g = case.material_jacobian(ident.x, ["a"])[0]  # d a / d (E, psi, sigma0, H, pt0, b)
    var_a = g @ ident.cov_x @ g
    assert 100 * np.sqrt(var_a) / a == pytest.approx(0.69, abs=0.03)  # measured 0.685
    corr_ab = (ident.cov_x @ g)[5] / np.sqrt(var_a * ident.cov_x[5, 5])
    assert corr_ab < -0.998  # measured -0.9994

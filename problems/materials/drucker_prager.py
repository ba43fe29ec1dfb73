"""Extended Drucker-Prager plasticity (linear, hyperbolic and exponent yield surfaces, each with
its hardening measured in uniaxial compression, pure shear or uniaxial tension): parameter
validation, construction, and the vectorised return mapping with its consistent tangent.

Conventions are those of :mod:`problems.materials.base` (Voigt ``[xx, yy, zz, yz, xz, xy]``,
MPa, tension-positive stress, engineering shear strains); the yield functions use the
compression-positive pressure ``p = -tr(sigma)/3``. Angles are given in degrees. The equations
and their derivation are in ``docs/drucker_prager.md``.

Return mapping (backward Euler, closest-point projection), unknowns per plastic point
``x = [sigma (6), E dlambda, E eqps]`` (all in MPa so that the local Jacobian is well scaled)::

    R1 = sigma - sigma_trial + dlambda D dG/dsigma(sigma)               = 0   (6)
    R2 = F(sigma, sigma_bar(eqps))                                      = 0
    R3 = E (eqps - eqps_n - c dlambda)                       (linear)     = 0
    R3 = (q_hat sigma_bar (eqps - eqps_n) - dlambda sigma:dG/dsigma) E/sigma0  (work) = 0

solved by Newton with a backtracking line search on ||R||, iterating only the unconverged
subset. The consistent tangent follows from the converged Jacobian J: since dR/d(strain
increment) = [-D; 0; 0], ``d sigma / d eps = (J^-1)[:6, :6] D`` (non-symmetric unless psi = beta
for the linear form). The linear form's cone apex is handled by a closed-form return to the
apex, chosen when the trial deviator lies inside the apex's cone of admissible flow directions.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from problems.materials.base import MaterialUpdate, isotropic_stiffness
from problems.materials.hardening import (
    HARDENINGS, LinearHardening, ProportionalEqps, WorkEqps, linear_eqps_constant, reference_test,
)
from problems.materials.invariants import M_VEC, deviator, j2, pressure
from problems.materials.meridional_return import meridional_return
from problems.materials.yield_surfaces import (
    ExponentYield, HyperbolicPotential, HyperbolicYield, LinearPotential, LinearYield, LodeMeasure,
    lode_xi, tan_deg,
)

FORMS = ("linear", "hyperbolic", "exponent")
FORM_PARAMETERS = {
    "linear": ("E", "beta", "K", "psi", "sigma0", "H"),
    "hyperbolic": ("E", "beta", "psi", "sigma0", "H", "pt0"),
    "exponent": ("E", "psi", "sigma0", "H", "a", "b"),
}
#: Fixed constants accepted by every form, with their defaults (eccentricity is unused by linear).
OPTIONAL_PARAMETERS = {"nu": 0.2, "eccentricity": 0.1}
STATE_NAMES = ("eqps", "ep_xx", "ep_yy", "ep_zz", "ep_yz", "ep_xz", "ep_xy")

_INF = math.inf
# name: (lower, upper, lower included, upper included, unit)
PARAMETER_RANGES = {
    "E": (0.0, _INF, False, False, "MPa"),
    "nu": (-1.0, 0.5, False, False, "-"),
    "beta": (0.0, 90.0, False, False, "deg"),
    "psi": (0.0, 90.0, True, False, "deg"),
    "K": (0.778, 1.0, True, True, "-"),
    "sigma0": (0.0, _INF, False, False, "MPa"),
    "H": (0.0, _INF, True, False, "MPa"),
    "pt0": (0.0, _INF, False, False, "MPa"),
    "a": (0.0, _INF, False, False, "MPa^(1-b)"),
    "b": (0.0, _INF, False, False, "-"),
    "eccentricity": (0.0, _INF, False, False, "-"),
}
# The angle whose tangent is 3: beyond it the compression-hardened linear cone no longer contains
# the unstressed state (d <= 0) and c = 1 - tan(psi)/3 <= 0 would make eqps decrease.
_ATAN3_DEG = math.degrees(math.atan(3.0))


def _range_text(name: str) -> str:
    lo, hi, lo_in, hi_in, unit = PARAMETER_RANGES[name]
    left = f"{lo:g} {'<=' if lo_in else '<'} {name}"
    right = "" if hi == _INF else f" {'<=' if hi_in else '<'} {hi:g}"
    return f"{left}{right}" + ("" if unit == "-" else f" ({unit})")


def _check_form(form: str, hardening: str) -> None:
    if form not in FORMS:
        raise ValueError(f"form {form!r} is unknown; allowed: {', '.join(FORMS)}")
    if hardening not in HARDENINGS:
        raise ValueError(f"hardening {hardening!r} is unknown; allowed: {', '.join(HARDENINGS)}")


def _complete(form: str, hardening: str, params: Mapping[str, float]) -> dict[str, float]:
    """Checked, complete parameter dict (defaults filled in); raises ValueError on any problem."""
    _check_form(form, hardening)
    required = FORM_PARAMETERS[form]
    allowed = set(required) | set(OPTIONAL_PARAMETERS)
    unknown = sorted(set(params) - allowed)
    if unknown:
        raise ValueError(f"unknown parameter(s) {', '.join(map(repr, unknown))} for the {form} form; "
                         f"expected {', '.join(required)} and optionally {', '.join(OPTIONAL_PARAMETERS)}")
    missing = [n for n in required if n not in params]
    if missing:
        raise ValueError(f"missing parameter(s) {', '.join(map(repr, missing))} for the {form} form "
                         f"(required: {', '.join(required)})")
    values = {**OPTIONAL_PARAMETERS}
    for name, raw in params.items():
        try:
            v = float(raw)
        except (TypeError, ValueError):
            raise ValueError(f"{name} = {raw!r} is not a number; allowed range {_range_text(name)}") from None
        lo, hi, lo_in, hi_in, _ = PARAMETER_RANGES[name]
        inside = np.isfinite(v) and (v >= lo if lo_in else v > lo) and (v <= hi if hi_in else v < hi)
        if not inside:
            raise ValueError(f"{name} = {raw!r} is out of range: allowed {_range_text(name)}")
        values[name] = v
    _check_well_posed(form, hardening, values)
    return values


def _check_well_posed(form: str, hardening: str, v: dict[str, float]) -> None:
    """Form-specific conditions for a surface that contains the unstressed state and hardens."""
    test = reference_test(hardening)
    s0 = v["sigma0"]
    if form == "linear" and hardening == "compression":
        # d = (1 - tan(beta)/3) sigma_c > 0 and c = 1 - tan(psi)/3 > 0
        for name in ("beta", "psi"):
            if v[name] >= _ATAN3_DEG:
                raise ValueError(
                    f"{name} = {v[name]:g} deg is out of range for the linear form with compression "
                    f"hardening: allowed {'0 <' if name == 'beta' else '0 <='} {name} < atan(3) = "
                    f"{_ATAN3_DEG:.4f} deg (tan({name})/3 must stay below 1)")
    elif form == "hyperbolic":
        # The hyperbola through p = -pt0, q = 0 and the reference state has
        # l0 = (S^2 - A^2)/(2A), S = q_hat sigma0, A = tan(beta)(pt0 + p_hat sigma0): l0 > 0
        # (non-degenerate) iff 0 < A < S.
        lo = max(0.0, -test.p_hat * s0)
        hi = test.q_hat * s0 / tan_deg(v["beta"]) - test.p_hat * s0
        l0 = hyperbolic_l0(hardening, s0, v["pt0"], v["beta"])
        if not (l0 > 0.0 and np.isfinite(l0)):
            raise ValueError(
                f"pt0 = {v['pt0']:g} MPa is out of range for the hyperbolic form with {hardening} "
                f"hardening (sigma0 = {s0:g} MPa, beta = {v['beta']:g} deg): allowed {lo:g} < pt0 < "
                f"{hi:g} MPa, so that l0 > 0 (a non-degenerate hyperbola)")
    elif form == "exponent":
        pt0 = v["a"] * (test.q_hat * s0) ** v["b"] - test.p_hat * s0
        if not pt0 > 0.0:
            a_min = test.p_hat * s0 / (test.q_hat * s0) ** v["b"]
            raise ValueError(
                f"a = {v['a']:g} MPa^(1-b) is out of range for the exponent form with {hardening} "
                f"hardening (sigma0 = {s0:g} MPa, b = {v['b']:g}): allowed a > {a_min:.6g} so that the "
                f"hydrostatic tension strength pt0 = a sigma0^b - sigma0/3 is positive")


def hyperbolic_l0(hardening: str, sigma0: float, pt0: float, beta_deg: float) -> float:
    """l0 (MPa) of the hyperbolic surface through (p, q) = (-pt0, 0) and the reference state.

    From d'0 = l0 + pt0 tan(beta) and d'0 = sqrt(l0^2 + S^2) - p_hat sigma0 tan(beta):
    ``(l0 + A)^2 = l0^2 + S^2`` with S = q_hat sigma0, A = tan(beta)(pt0 + p_hat sigma0), so
    ``l0 = (S^2 - A^2)/(2A)`` (meaningful for 0 < A < S; returns -inf when A <= 0).
    """
    test = reference_test(hardening)
    S = test.q_hat * sigma0
    A = tan_deg(beta_deg) * (pt0 + test.p_hat * sigma0)
    return (S * S - A * A) / (2.0 * A) if A > 0.0 else -_INF


def validate_parameters(form: str, hardening: str, params: Mapping[str, float]) -> None:
    """Raise ValueError (naming the parameter and its allowed range) unless ``params`` define a
    well-posed material of this form and hardening; runs no FE and builds nothing heavy."""
    _complete(form, hardening, params)


def make_material(form: str, hardening: str, params: Mapping[str, float]) -> "DruckerPrager":
    """The extended Drucker-Prager material ``form`` (linear | hyperbolic | exponent) with
    hardening measured in ``hardening`` (compression | shear | tension).

    ``params``: the names of ``FORM_PARAMETERS[form]`` plus optionally ``nu`` (default 0.2) and
    ``eccentricity`` (default 0.1); E, sigma0, H, pt0 in MPa, beta and psi in degrees, a in
    MPa^(1-b). Raises ValueError for missing, unknown or out-of-range parameters.
    """
    v = _complete(form, hardening, params)
    test = reference_test(hardening)
    law = LinearHardening(v["sigma0"], v["H"])
    tan_psi = tan_deg(v["psi"])
    if form == "linear":
        lode = LodeMeasure(v["K"])
        yf = LinearYield(tan_deg(v["beta"]), lode, test)
        potential = LinearPotential(tan_psi, lode)
        rule = ProportionalEqps(linear_eqps_constant(test, v["K"], tan_psi))
    else:
        # Eccentricity scale: the initial yield stress sigma0 in the hardening test's own measure.
        # At psi = 0 the hyperbola degenerates to the cone G = q; a tiny e keeps G smooth at q = 0.
        e = max(v["eccentricity"] * v["sigma0"] * tan_psi, 1e-6 * v["sigma0"])
        potential = HyperbolicPotential(tan_psi, e)
        rule = WorkEqps(test.q_hat)
        if form == "hyperbolic":
            yf = HyperbolicYield(tan_deg(v["beta"]), hyperbolic_l0(hardening, v["sigma0"], v["pt0"], v["beta"]), test)
        else:
            yf = ExponentYield(v["a"], v["b"], test)
    used = FORM_PARAMETERS[form] + (("nu",) if form == "linear" else ("nu", "eccentricity"))
    return DruckerPrager(form, hardening, v["E"], v["nu"], yf, potential, law, rule,
                         tuple((n, v[n]) for n in used))


# --------------------------------------------------------------------------------------------
# The material
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class _Return:
    """Result of the plastic correction at m points."""

    stress: np.ndarray    # (m, 6)
    eqps: np.ndarray      # (m,)
    tangent: np.ndarray   # (m, 6, 6)
    ok: np.ndarray        # (m,)
    apex: np.ndarray      # (m,) bool, returned to the cone apex (linear form)


@dataclass(frozen=True)
class DruckerPrager:
    """Extended Drucker-Prager material (see module docstring); build it with :func:`make_material`.

    state columns: ``eqps`` (equivalent plastic strain, -) and the plastic strain
    ``ep_xx .. ep_xy`` (engineering shear components).
    """

    form: str
    hardening: str
    E: float
    nu: float
    yield_function: LinearYield | HyperbolicYield | ExponentYield
    potential: LinearPotential | HyperbolicPotential
    law: LinearHardening
    eqps_rule: ProportionalEqps | WorkEqps
    parameters: tuple[tuple[str, float], ...]
    tol: float = 1e-10          # local Newton: max |residual| / max(sigma0, |sigma_trial|), then one more step
    yield_tol: float = 1e-10    # trial F above this (relative) is plastic
    max_iter: int = 50
    state_names: tuple[str, ...] = field(default=STATE_NAMES, init=False)

    # ---- elasticity -------------------------------------------------------------------------
    @property
    def stiffness(self) -> np.ndarray:
        """Elastic stiffness (6, 6), MPa."""
        return isotropic_stiffness(self.E, self.nu)

    @property
    def bulk_modulus(self) -> float:
        return self.E / (3.0 * (1.0 - 2.0 * self.nu))

    @property
    def shear_modulus(self) -> float:
        return self.E / (2.0 * (1.0 + self.nu))

    def _apply_D(self, x: np.ndarray) -> np.ndarray:
        """D @ x for engineering-strain-like x of shape (m, 6) or (m, 6, k), without a matmul."""
        lam = self.E * self.nu / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu))
        mu = self.shear_modulus
        out = np.empty_like(x)
        tr = x[:, 0] + x[:, 1] + x[:, 2]
        out[:, :3] = 2.0 * mu * x[:, :3] + lam * tr[:, None]
        out[:, 3:] = mu * x[:, 3:]
        return out

    # ---- convenience for drivers and tests ---------------------------------------------------
    @property
    def params(self) -> dict[str, float]:
        """The complete (checked, defaults filled) parameter dict."""
        return dict(self.parameters)

    def yield_stress(self, eqps) -> np.ndarray:
        """sigma_bar(eqps) in the hardening test's measure, MPa."""
        return self.law.yield_stress(np.asarray(eqps, float))

    def yield_value(self, stress, eqps) -> np.ndarray:
        """F(sigma, sigma_bar(eqps)) in MPa; <= 0 is admissible."""
        stress = np.atleast_2d(np.asarray(stress, float))
        return self.yield_function.value(stress, self.yield_stress(np.broadcast_to(eqps, stress.shape[:1])))

    def flow_direction(self, stress) -> np.ndarray:
        """dG/dsigma (n, 6), engineering components (undefined at the linear cone's apex)."""
        return self.potential.gradient(np.atleast_2d(np.asarray(stress, float)))

    def initial_state(self, n: int) -> np.ndarray:
        return np.zeros((n, len(STATE_NAMES)))

    # ---- the update --------------------------------------------------------------------------
    def update(self, strain_increment, stress_old, state_old) -> MaterialUpdate:
        """Integrate one strain increment (n, 6) from the converged (stress_old, state_old).

        Elastic points (trial F <= 0) cost one yield-function evaluation. Points whose local
        return does not converge get ``ok = False`` and keep the trial stress, elastic tangent
        and old state (the FE solver cuts the increment).
        """
        de = np.asarray(strain_increment, float)
        sig_n = np.asarray(stress_old, float)
        st_n = np.asarray(state_old, float)
        n = de.shape[0]
        D = self.stiffness
        sig_tr = sig_n + self._apply_D(de)
        eqps_n = st_n[:, 0]
        scale = np.maximum(self.law.sigma0, np.abs(sig_tr).max(axis=1)) if n else np.zeros(0)
        F_tr = self.yield_function.value(sig_tr, self.law.yield_stress(eqps_n))
        plastic = F_tr > self.yield_tol * scale

        stress = sig_tr.copy()
        tangent = np.empty((n, 6, 6))
        tangent[:] = D
        state = st_n.copy()
        ok = np.ones(n, bool)
        if plastic.any():
            idx = np.flatnonzero(plastic)
            # extreme trial states may overflow on the way; they end up flagged through ok
            with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
                res = self._plastic_return(sig_tr[idx], eqps_n[idx], scale[idx])
            good = idx[res.ok]
            stress[good] = res.stress[res.ok]
            tangent[good] = res.tangent[res.ok]
            state[good, 0] = res.eqps[res.ok]
            # plastic strain = total increment minus its elastic part C (sigma - sigma_n)
            dsig = stress[good] - sig_n[good]
            state[good, 1:] = st_n[good, 1:] + de[good] - dsig @ self._scaled_compliance / self.E
            ok[idx[~res.ok]] = False
        return MaterialUpdate(stress, tangent, state, ok)

    # ---- plastic correction -------------------------------------------------------------------
    def _plastic_return(self, sig_tr, eqps_n, scale) -> _Return:
        m = sig_tr.shape[0]
        stress = np.empty((m, 6))
        eqps = np.empty(m)
        tangent = np.empty((m, 6, 6))
        ok = np.zeros(m, bool)
        apex = np.zeros(m, bool)
        smooth = np.ones(m, bool)
        if self.form == "linear":
            apex, a_sig, a_eqps, a_tan = self._apex_return(sig_tr, eqps_n)
            stress[apex], eqps[apex], tangent[apex], ok[apex] = a_sig, a_eqps, a_tan, True
            smooth = ~apex
        if smooth.any():
            idx = np.flatnonzero(smooth)
            x0 = self._start(sig_tr[idx], eqps_n[idx], scale[idx])
            s_sig, s_eqps, s_dlam, s_tan, s_ok = self._newton_return(
                sig_tr[idx], eqps_n[idx], scale[idx], x0)
            # a valid smooth return has a non-negative multiplier; on the cone it must also keep
            # the deviator on the trial's side of the apex (else the apex branch applies)
            s_ok &= s_dlam >= -self.tol * 1e-3
            if self.form == "linear":
                s_dev, t_dev = deviator(s_sig), deviator(sig_tr[idx])
                s_ok &= np.einsum("ni,ni->n", s_dev[:, :3], t_dev[:, :3]) + 2.0 * np.einsum(
                    "ni,ni->n", s_dev[:, 3:], t_dev[:, 3:]) > 0.0
            stress[idx], eqps[idx], tangent[idx], ok[idx] = s_sig, s_eqps, s_tan, s_ok
        return _Return(stress, eqps, tangent, ok, apex)

    def _apex_return(self, sig_tr, eqps_n):
        """Closed-form return of the linear cone to its apex where that is the solution.

        At the apex sigma = -p I, s = 0, so the whole trial deviator becomes plastic:
        d e_pl = s_trial / (2 G) must lie in dlambda * (subdifferential of t at 0), and the
        volumetric part is dlambda tan(psi). The pressure and the hardening then give
        ``p = p_trial + K_b tan(psi) dlambda`` and
        ``-p tan(beta) - d_hat sigma_bar(eqps_n + c dlambda) = 0`` (linear in dlambda).
        The apex applies iff dlambda > 0 and the gauge of s_trial/(2 G dlambda) with respect to
        the subdifferential, ``q_trial * m(xi_trial) / (3 G dlambda)``, is <= 1 (see
        :func:`_polar_factor`); else the smooth return is the solution.
        """
        yf, pot, law = self.yield_function, self.potential, self.law
        Kb, G = self.bulk_modulus, self.shear_modulus
        tb, tp, dh, c = yf.tan_beta, pot.tan_psi, yf.d_hat, self.eqps_rule.c
        p_tr = pressure(sig_tr)
        q_tr = np.sqrt(3.0 * j2(deviator(sig_tr)))
        den = Kb * tp * tb + dh * c * law.H
        num = -p_tr * tb - dh * law.yield_stress(eqps_n)
        m = sig_tr.shape[0]
        empty = (np.zeros(m, bool), np.zeros((0, 6)), np.zeros(0), np.zeros((0, 6, 6)))
        if den <= 0.0:  # psi = 0 and H = 0: the apex cannot be reached by any flow
            return empty
        dlam = num / den
        # K <= m(xi) <= 1 (t/q lies in [1, 1/K]): only the undecided band needs m itself
        apex = (dlam > 0.0) & (q_tr * yf.lode.K <= 3.0 * G * dlam)
        band = apex & (q_tr > 3.0 * G * dlam)
        if band.any():
            factor = _polar_factor(lode_xi(sig_tr[band]), yf.lode.K)
            apex[band] = q_tr[band] * factor <= 3.0 * G * dlam[band]
        if not apex.any():
            return empty
        p = p_tr[apex] + Kb * tp * dlam[apex]
        stress = -p[:, None] * M_VEC
        eqps = eqps_n[apex] + c * dlam[apex]
        # dp/dp_trial = d_hat c H / den and dp_trial/d eps = -K_b m  =>  D_apex = K_b (dhcH/den) m m
        k_alg = Kb * dh * c * law.H / den
        tangent = np.broadcast_to(k_alg * np.outer(M_VEC, M_VEC), (int(apex.sum()), 6, 6)).copy()
        return apex, stress, eqps, tangent

    def _start(self, sig_tr, eqps_n, scale):
        """Newton's starting point x0 (m, 8). Linear form: the closed-form cone return with
        t/q frozen at the trial Lode angle. Von Mises-section forms: the exact meridional-plane
        return (see :mod:`meridional_return`), or the trial state where that failed."""
        E = self.E
        x = np.zeros((sig_tr.shape[0], 8))
        x[:, :6] = sig_tr
        x[:, 7] = E * eqps_n
        s_tr = deviator(sig_tr)
        q_tr = np.sqrt(3.0 * j2(s_tr))
        inv_q_tr = np.where(q_tr > 0.0, 1.0 / np.where(q_tr > 0.0, q_tr, 1.0), 0.0)  # radial scaling of s_tr
        if self.form == "linear":
            # The return with t/q frozen at the trial Lode angle is a Drucker-Prager cone return
            # in closed form; the Lode angle moves little, so it is close to the solution.
            yf, law = self.yield_function, self.law
            h = yf.lode.per_unit_q(lode_xi(sig_tr))
            p_tr = pressure(sig_tr)
            f_tr = h * q_tr - p_tr * yf.tan_beta - yf.d_hat * law.yield_stress(eqps_n)
            den = (3.0 * self.shear_modulus * h * h + self.bulk_modulus * self.potential.tan_psi * yf.tan_beta
                   + yf.d_hat * self.eqps_rule.c * law.H)
            dl = np.maximum(f_tr, 0.0) / den
            # stay off the apex, where the cone's flow direction is undefined
            q = np.maximum(q_tr - 3.0 * self.shear_modulus * h * dl, 0.05 * q_tr)
            p = p_tr + self.bulk_modulus * self.potential.tan_psi * dl
            x[:, :6] = s_tr * (q * inv_q_tr)[:, None] - p[:, None] * M_VEC
            x[:, 6] = E * dl
            x[:, 7] = E * (eqps_n + self.eqps_rule.c * dl)
            return x
        pot = self.potential
        p, q, eqps, dl, ok = meridional_return(
            pressure(sig_tr), q_tr, eqps_n, bulk=self.bulk_modulus, shear=self.shear_modulus,
            tan_psi=pot.tan_psi, e=pot.e, q_hat=self.eqps_rule.q_hat, law=self.law,
            yield_pq=self.yield_function.value_pq, f_tol=1e-3 * self.tol * scale)
        x[ok, :6] = s_tr[ok] * (q * inv_q_tr)[ok, None] - p[ok, None] * M_VEC
        x[ok, 6] = E * dl[ok]
        x[ok, 7] = E * eqps[ok]
        return x

    def _newton_return(self, sig_tr, eqps_n, scale, x0):
        """Closest-point projection by Newton with line search from x0; returns stress, eqps,
        dlambda, consistent tangent and convergence flags for the m given trial states."""
        m = sig_tr.shape[0]
        E = self.E
        x = x0.copy()
        tangent = np.zeros((m, 6, 6))
        conv = np.zeros(m, bool)
        act = np.arange(m)
        # consistent tangent: dR/d eps = [-E C D; 0; 0] = [-E I; 0; 0], so
        # d sigma / d eps = (J^-1 [E I; 0; 0])[:6], solved together with the last Newton step
        rhs_tangent = np.zeros((8, 6))
        rhs_tangent[:6] = E * np.eye(6)
        for it in range(self.max_iter + 1):
            R, J = self._residual(x[act], sig_tr[act], eqps_n[act], jacobian=True)
            err = np.abs(R).max(axis=1) / scale[act]
            done = err <= self.tol
            if done.any():
                # One last full Newton step: quadratic convergence takes the solution from the
                # tolerance to round-off, so that finite differences of the map are clean. The
                # tangent uses the same Jacobian (it differs from the final one by ~tol).
                n_done = int(done.sum())
                rhs = np.concatenate([-R[done][:, :, None], np.broadcast_to(rhs_tangent, (n_done, 8, 6))], axis=2)
                sol, solved = _solve(J[done], rhs)
                idx = act[done]
                x[idx] += np.where(solved[:, None], sol[:, :, 0], 0.0)
                tangent[idx] = sol[:, :6, 1:]
                conv[idx] = solved
            keep = ~done & np.isfinite(err)
            act, R, J = act[keep], R[keep], J[keep]
            if act.size == 0 or it == self.max_iter:
                break
            step, solved = _solve(J, -R)
            act, R, step = act[solved], R[solved], step[solved]
            x[act] = self._line_search(x[act], step, R, sig_tr[act], eqps_n[act], scale[act])
        return x[:, :6].copy(), x[:, 7] / E, x[:, 6] / E, tangent, conv

    def _residual(self, x, sig_tr, eqps_n, jacobian=False):
        """Residuals (m, 8) in MPa and, if asked, their Jacobian (m, 8, 8) w.r.t. x.

        The stress residual is written in strain space and scaled by E,
        ``R1 = E C (sigma - sigma_trial) + (E dlambda) dG/dsigma``, so that its Jacobian
        ``E C + (E dlambda) d2G/dsigma2`` is symmetric and needs no product with D.
        """
        E, law, rule = self.E, self.law, self.eqps_rule
        sig, lam, kap = x[:, :6], x[:, 6], x[:, 7]
        dkap = kap - E * eqps_n
        sbar = law.yield_stress(kap / E)
        EC = self._scaled_compliance
        R = np.empty((x.shape[0], 8))
        if jacobian:
            g, lam_Hg = self.potential.hessian(sig, lam)
            F, dF, dF_dsbar = self.yield_function.gradient(sig, sbar)
        else:
            g = self.potential.gradient(sig)
            F = self.yield_function.value(sig, sbar)
        R[:, :6] = (sig - sig_tr) @ EC + lam[:, None] * g
        R[:, 6] = F
        if isinstance(rule, ProportionalEqps):
            R[:, 7] = dkap - rule.c * lam
        else:
            w, dw = self.potential.work(sig)  # plastic work per unit multiplier, sigma : dG/dsigma
            s0 = law.sigma0
            R[:, 7] = (rule.q_hat * sbar * dkap - lam * w) / s0
        if not jacobian:
            return R
        J = np.zeros((x.shape[0], 8, 8))
        J[:, :6, :6] = lam_Hg
        J[:, :6, :6] += EC
        J[:, :6, 6] = g
        J[:, 6, :6] = dF
        J[:, 6, 7] = dF_dsbar * law.H / E
        if isinstance(rule, ProportionalEqps):
            J[:, 7, 6] = -rule.c
            J[:, 7, 7] = 1.0
        else:
            J[:, 7, :6] = -(lam / s0)[:, None] * dw
            J[:, 7, 6] = -w / s0
            J[:, 7, 7] = rule.q_hat * (sbar + law.H * dkap / E) / s0
        return R, J

    @property
    def _scaled_compliance(self) -> np.ndarray:
        """E C (6, 6), dimensionless (C = D^-1, engineering shear); symmetric."""
        EC = np.zeros((6, 6))
        EC[:3, :3] = -self.nu
        EC[np.arange(3), np.arange(3)] = 1.0
        EC[np.arange(3, 6), np.arange(3, 6)] = 2.0 * (1.0 + self.nu)
        return EC

    def _line_search(self, x, step, R0, sig_tr, eqps_n, scale):
        """Backtracking (Armijo on ||R/scale||^2) from x along the Newton step, per point.

        On the linear cone a step may also not shrink q by more than 20x nor flip the deviator:
        the cone's flow direction is discontinuous at its apex, where Newton must not land.
        """
        phi0 = np.einsum("ni,ni->n", R0, R0) / scale**2
        alpha = np.ones(x.shape[0])
        x_new = x + step
        todo = np.arange(x.shape[0])
        for _ in range(12):
            R = self._residual(x_new[todo], sig_tr[todo], eqps_n[todo])
            phi = np.einsum("ni,ni->n", R, R) / scale[todo] ** 2
            good = np.isfinite(phi) & (phi <= (1.0 - 1e-4 * alpha[todo]) * phi0[todo])
            if self.form == "linear":
                s_old, s_new = deviator(x[todo, :6]), deviator(x_new[todo, :6])
                q_old, q_new = np.sqrt(3.0 * j2(s_old)), np.sqrt(3.0 * j2(s_new))
                same_side = np.einsum("ni,ni->n", s_old[:, :3], s_new[:, :3]) + 2.0 * np.einsum(
                    "ni,ni->n", s_old[:, 3:], s_new[:, 3:]) > 0.0
                good &= same_side & (q_new >= 0.05 * q_old)
            todo = todo[~good]
            if todo.size == 0:
                break
            alpha[todo] *= 0.5
            x_new[todo] = x[todo] + alpha[todo, None] * step[todo]
        return x_new


def _solve(A: np.ndarray, b: np.ndarray):
    """Batched solve A x = b (b (m, k) or (m, k, r)); returns x and a flag of solvable systems.

    A singular system in the batch must not sink the others, so on failure retry one by one.
    """
    vec = b.ndim == 2
    bb = b[..., None] if vec else b
    try:
        x = np.linalg.solve(A, bb)
        solved = np.isfinite(x).all(axis=(1, 2))
    except np.linalg.LinAlgError:
        x = np.zeros_like(bb)
        solved = np.zeros(A.shape[0], bool)
        for i in range(A.shape[0]):
            try:
                x[i] = np.linalg.solve(A[i], bb[i])
                solved[i] = np.isfinite(x[i]).all()
            except np.linalg.LinAlgError:
                pass
    return (x[..., 0] if vec else x), solved


def _polar_factor(xi: np.ndarray, K: float) -> np.ndarray:
    """m(xi) = max over Lode angles phi of cos(phi - phi_y) / h(phi), with cos 3 phi_y = xi the
    Lode measure (r/q)^3 of a deviator y and h(phi) = t/q at Lode angle phi.

    The gauge of y with respect to the subdifferential of t at s = 0 (the deviatoric flow
    directions the apex admits) is ``sup_s (y:s)/t(s) = 2/3 q_y m(xi)``; for K = 1 that set is a
    ball and m = 1, in general K <= m <= 1. The maximiser is bracketed on a grid around phi_y
    and polished by Newton steps on f'(phi) = 0 with analytic derivatives of f = cos(u)/h,
    u = phi - phi_y, h' = 3/2 (1 - 1/K) sin 3 phi, h'' = 9/2 (1 - 1/K) cos 3 phi.
    """
    if K == 1.0 or xi.size == 0:
        return np.ones_like(xi)
    k1 = 1.0 - 1.0 / K
    phi_y = np.arccos(np.clip(xi, -1.0, 1.0)) / 3.0
    offsets = np.linspace(-0.5 * np.pi, 0.5 * np.pi, 361)
    h_grid = 0.5 * ((1.0 + 1.0 / K) - k1 * np.cos(3.0 * (phi_y[:, None] + offsets[None, :])))
    u = offsets[(np.cos(offsets)[None, :] / h_grid).argmax(axis=1)]
    for _ in range(4):
        phi = phi_y + u
        c, s = np.cos(u), np.sin(u)
        h = 0.5 * ((1.0 + 1.0 / K) - k1 * np.cos(3.0 * phi))
        h1 = 1.5 * k1 * np.sin(3.0 * phi)
        h2 = 4.5 * k1 * np.cos(3.0 * phi)
        f1 = (-s * h - c * h1) / h**2
        f2 = ((-c * h - c * h2) * h + 2.0 * h1 * (s * h + c * h1)) / h**3
        u = u - np.where(f2 < 0.0, f1 / f2, 0.0)  # only where f is locally concave (a maximum)
    h = 0.5 * ((1.0 + 1.0 / K) - k1 * np.cos(3.0 * (phi_y + u)))
    return np.cos(u) / h

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

solved per point by Newton with a backtracking line search on ||R||. The consistent tangent
follows from the converged Jacobian J: since dR/d(strain increment) = [-D; 0; 0],
``d sigma / d eps = (J^-1)[:6, :6] D`` (non-symmetric unless psi = beta for the linear form).
The linear form's cone apex is handled by a closed-form return to the apex, chosen when the
trial deviator lies inside the apex's cone of admissible flow directions.

The elastic trial, the elastic/plastic split and the bookkeeping are vectorised numpy here; the
plastic points go to the compiled per-point kernel :func:`_kernels.plastic_return` (numba).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from problems.materials import _kernels as _K
from problems.materials.base import MaterialUpdate, isotropic_stiffness
from problems.materials.hardening import (
    HARDENINGS,
    LinearHardening,
    ProportionalEqps,
    WorkEqps,
    linear_eqps_constant,
    reference_test,
)
from problems.materials.kernel_jacobian import kernel_parameter_jacobian
from problems.materials.yield_surfaces import (
    ExponentYield,
    HyperbolicPotential,
    HyperbolicYield,
    LinearPotential,
    LinearYield,
    LodeMeasure,
    tan_deg,
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
        raise ValueError(
            f"unknown parameter(s) {', '.join(map(repr, unknown))} for the {form} form; "
            f"expected {', '.join(required)} and optionally {', '.join(OPTIONAL_PARAMETERS)}"
        )
    missing = [n for n in required if n not in params]
    if missing:
        raise ValueError(
            f"missing parameter(s) {', '.join(map(repr, missing))} for the {form} form "
            f"(required: {', '.join(required)})"
        )
    values = {**OPTIONAL_PARAMETERS}
    for name, raw in params.items():
        try:
            v = float(raw)
        except (TypeError, ValueError):
            raise ValueError(
                f"{name} = {raw!r} is not a number; allowed range {_range_text(name)}"
            ) from None
        lo, hi, lo_in, hi_in, _ = PARAMETER_RANGES[name]
        inside = (
            np.isfinite(v) and (v >= lo if lo_in else v > lo) and (v <= hi if hi_in else v < hi)
        )
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
                    f"{name} = {v[name]:g} deg is out of range for the linear form with "
                    f"compression hardening: allowed {'0 <' if name == 'beta' else '0 <='} {name} "
                    f"< atan(3) = {_ATAN3_DEG:.4f} deg (tan({name})/3 must stay below 1)"
                )
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
                f"hardening (sigma0 = {s0:g} MPa, beta = {v['beta']:g} deg): allowed {lo:g} < pt0 "
                f"< {hi:g} MPa, so that l0 > 0 (a non-degenerate hyperbola)"
            )
    elif form == "exponent":
        pt0 = v["a"] * (test.q_hat * s0) ** v["b"] - test.p_hat * s0
        if not pt0 > 0.0:
            a_min = test.p_hat * s0 / (test.q_hat * s0) ** v["b"]
            raise ValueError(
                f"a = {v['a']:g} MPa^(1-b) is out of range for the exponent form with {hardening} "
                f"hardening (sigma0 = {s0:g} MPa, b = {v['b']:g}): allowed a > {a_min:.6g} so that "
                "the hydrostatic tension strength pt0 = a sigma0^b - sigma0/3 is positive"
            )


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
            yf = HyperbolicYield(
                tan_deg(v["beta"]), hyperbolic_l0(hardening, v["sigma0"], v["pt0"], v["beta"]), test
            )
        else:
            yf = ExponentYield(v["a"], v["b"], test)
    used = FORM_PARAMETERS[form] + (("nu",) if form == "linear" else ("nu", "eccentricity"))
    return DruckerPrager(
        form, hardening, v["E"], v["nu"], yf, potential, law, rule, tuple((n, v[n]) for n in used)
    )


# --------------------------------------------------------------------------------------------
# The material
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Return:
    """Result of the plastic correction at m points."""

    stress: np.ndarray  # (m, 6)
    eqps: np.ndarray  # (m,)
    tangent: np.ndarray  # (m, 6, 6)
    ok: np.ndarray  # (m,)
    apex: np.ndarray  # (m,) bool, returned to the cone apex (linear form)


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
    # local Newton: max |residual| / max(sigma0, |sigma_trial|), then one more step
    tol: float = 1e-10
    yield_tol: float = 1e-10  # trial F above this (relative) is plastic
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
        return self.yield_function.value(
            stress, self.yield_stress(np.broadcast_to(eqps, stress.shape[:1]))
        )

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
        de = np.ascontiguousarray(strain_increment, dtype=float)
        sig_n = np.ascontiguousarray(stress_old, dtype=float)
        st_n = np.ascontiguousarray(state_old, dtype=float)
        eqps_n = np.ascontiguousarray(st_n[:, 0])
        sig_tr, scale, plastic = self._elastic_trial(de, sig_n, eqps_n)
        idx = np.flatnonzero(plastic)
        if idx.size:
            res = self._plastic_return(sig_tr[idx], eqps_n[idx], scale[idx])
            r_stress, r_eqps, r_tangent, r_ok = res.stress, res.eqps, res.tangent, res.ok
        else:
            r_stress, r_eqps, r_tangent, r_ok = (
                np.zeros((0, 6)),
                np.zeros(0),
                np.zeros((0, 6, 6)),
                np.zeros(0, bool),
            )
        n = de.shape[0]
        out = MaterialUpdate(
            np.empty((n, 6)), np.empty((n, 6, 6)), np.empty_like(st_n), np.empty(n, bool)
        )
        # returned points: plastic strain = total increment minus its elastic part
        # C (sigma - sigma_n)
        _K.merge_update(
            self.stiffness,
            self.E,
            self.nu,
            de,
            sig_n,
            st_n,
            sig_tr,
            idx,
            r_stress,
            r_eqps,
            r_tangent,
            r_ok,
            out.stress,
            out.tangent,
            out.state,
            out.ok,
        )
        return out

    def failure_reason(self, strain_increment, stress_old, state_old, ok) -> str:
        """Why the returns flagged ``ok`` False by :meth:`update` of these inputs failed, where
        that is known ("" otherwise); called by the FE solver for its message, only on failure.

        Known: the strength is exhausted (hyperbolic and exponent forms, see
        :func:`_kernels.work_exhaustion`): negative plastic work has lowered sigma_bar, and the
        backward-Euler return, which can take at most half of sigma_bar_n in one increment, has
        no solution; cutting the increment only approaches sigma_bar = 0, past which the hardening
        law sigma0 + H eqps is not defined. ``docs/drucker_prager.md`` section 5.
        """
        bad = np.flatnonzero(~np.asarray(ok, bool))
        if bad.size == 0:
            return ""
        de = np.ascontiguousarray(np.asarray(strain_increment, float)[bad])
        sig_n = np.ascontiguousarray(np.asarray(stress_old, float)[bad])
        eqps_n = np.ascontiguousarray(np.asarray(state_old, float)[bad, 0])
        sig_tr, _, _ = self._elastic_trial(de, sig_n, eqps_n)
        exhausted = _K.work_exhaustion(
            self._kernel_params,
            self.yield_function.kernel_params,
            self.potential.kernel_params,
            sig_tr,
            eqps_n,
        )[0]
        n = int(np.count_nonzero(exhausted))
        if n == 0:
            return ""
        sbar = float(np.min(self.yield_stress(eqps_n[exhausted])))
        return (
            f"strength exhausted at {n} of them: negative plastic work under confinement has "
            f"lowered sigma_bar to {sbar:.3g} MPa (sigma0 {self.law.sigma0:.3g} MPa) and no "
            "return exists; the model has no solution once sigma_bar reaches 0"
        )

    # ---- parameter sensitivities (direct differentiation) -------------------------------------
    @property
    def parameter_names(self) -> tuple[str, ...]:
        """The differentiable parameters in the column order of :meth:`sensitivity`:
        ``FORM_PARAMETERS[form] + ("nu",)`` (the eccentricity is a fixed constant)."""
        return FORM_PARAMETERS[self.form] + ("nu",)

    def sensitivity(
        self,
        strain_increment,
        stress_old,
        state_old,
        update: MaterialUpdate,
        dstress_old,
        dstate_old,
        dstrain_increment,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Exact derivatives of one converged update with respect to the parameters.

        ``update`` is what :meth:`update` returned for this (strain_increment (n, 6),
        stress_old (n, 6), state_old (n, 7)); dstress_old (n, P, 6), dstate_old (n, P, 7) and
        dstrain_increment (n, P, 6) are the total derivatives of the inputs with respect to the
        P = len(parameter_names) parameters, per parameter unit (MPa, deg or -): stress
        derivatives in MPa, state and strain derivatives in 1 per unit. Returns
        (dstress (n, P, 6), dstate (n, P, 7)) of the update's stress and state:

        * elastic points: the trial stress, ``dstress_old + D ddeps + dD/dp deps``, old state;
        * plastic points: the implicit function theorem on the converged local residual (its
          Jacobian J and the residual's partial derivatives with respect to the trial stress,
          eqps_n and the parameters), or the closed-form apex return of the linear form; the
          plastic strain as formed by the update, ``eps_pl_n + deps - C (sigma - sigma_n)``;
        * points with ``update.ok`` False: NaN (the update kept a trial state that is no
          solution; the FE solver cuts such increments).

        In terms of the consistent tangent T of the update this is
        ``dstress = T ddeps + dsigma/dsigma_n dstress_old + dsigma/dstate_n dstate_old
        + dsigma/dp``.
        """
        de, sig_n, st_n, dsig_n, dst_n, dde = (
            np.ascontiguousarray(a, dtype=float)
            for a in (
                strain_increment,
                stress_old,
                state_old,
                dstress_old,
                dstate_old,
                dstrain_increment,
            )
        )
        sig_tr, _, plastic = self._elastic_trial(de, sig_n, np.ascontiguousarray(st_n[:, 0]))
        return _K.update_sensitivities(
            self._kernel_params,
            self.yield_function.kernel_params,
            self.potential.kernel_params,
            kernel_parameter_jacobian(self),
            de,
            sig_n,
            st_n,
            sig_tr,
            plastic,
            np.ascontiguousarray(update.stress),
            np.ascontiguousarray(update.state),
            np.ascontiguousarray(update.ok),
            dsig_n,
            dst_n,
            dde,
        )

    def _elastic_trial(self, de, sig_n, eqps_n):
        """Elastic predictor (:func:`_kernels.elastic_trial`) of C-contiguous float arrays de,
        sig_n (n, 6) and eqps_n (n,): trial stress (n, 6) MPa, residual scale (n,) MPa and the
        plastic flags (n,)."""
        lam = self.E * self.nu / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu))
        return _K.elastic_trial(
            lam,
            self.shear_modulus,
            self.law.sigma0,
            self.law.H,
            self.yield_tol,
            self.yield_function.kernel_params,
            de,
            sig_n,
            eqps_n,
        )

    # ---- plastic correction -------------------------------------------------------------------
    @property
    def _kernel_params(self) -> np.ndarray:
        """The material vector of :mod:`_kernels` (elasticity, hardening, eqps rule, Newton
        controls)."""
        mp = np.empty(_K.M_SIZE)
        mp[_K.M_E], mp[_K.M_NU] = self.E, self.nu
        mp[_K.M_S0], mp[_K.M_H] = self.law.sigma0, self.law.H
        if isinstance(self.eqps_rule, ProportionalEqps):
            mp[_K.M_RULE], mp[_K.M_RULE_C] = _K.PROPORTIONAL, self.eqps_rule.c
        else:
            mp[_K.M_RULE], mp[_K.M_RULE_C] = _K.WORK, self.eqps_rule.q_hat
        mp[_K.M_TOL], mp[_K.M_MAXIT] = self.tol, self.max_iter
        return mp

    def _plastic_return(self, sig_tr, eqps_n, scale) -> _Return:
        """Return of m plastic trial states (see :func:`_kernels.plastic_return`)."""
        stress, eqps, _, tangent, ok, apex, _ = _K.plastic_return(
            self._kernel_params,
            self.yield_function.kernel_params,
            self.potential.kernel_params,
            np.ascontiguousarray(sig_tr, dtype=float),
            np.ascontiguousarray(eqps_n, dtype=float),
            np.ascontiguousarray(scale, dtype=float),
        )
        return _Return(stress, eqps, tangent, ok, apex)


def _polar_factor(xi: np.ndarray, K: float) -> np.ndarray:
    """m(xi) = max over Lode angles phi of cos(phi - phi_y) / h(phi), with cos 3 phi_y = xi and
    h(phi) = t/q at Lode angle phi: the apex test's gauge factor (see
    :func:`_kernels._polar_factor`)."""
    return _K.polar_factors(np.ascontiguousarray(xi, dtype=float), float(K))

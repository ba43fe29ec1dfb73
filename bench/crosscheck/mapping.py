r"""The femubench -> OpenSees ``nDMaterial DruckerPrager`` parameter mapping, and OpenSees's
model re-derived in numpy (yield function, flow direction, one return-mapping step with its two
tangents). Pure: no openseespy. Angles in degrees, stresses and moduli in MPa, Voigt order
``[xx, yy, zz, yz, xz, xy]`` with engineering shear strains.

Parameter mapping (derivation)
------------------------------
femubench, linear form with K = 1 and compression hardening (p = -I1/3 compression positive,
q = sqrt(3 J2) = sqrt(3/2) ||s||, angles in degrees)::

    F = q - p tan(beta) - d,   d = (1 - tan(beta)/3) sigma_c,   sigma_c = sigma0 + H eqps
    G = q - p tan(psi),        d eps_pl = d lambda dG/dsigma,  d eqps = (1 - tan(psi)/3) d lambda

(the last from plastic-work equivalence, :func:`problems.materials.hardening.linear_eqps_constant`;
in uniaxial compression it makes ``eqps = |eps_pl_11|``).

OpenSees
``nDMaterial DruckerPrager tag K G sigmaY rho rhoBar Kinf Ko delta1 delta2 H theta density``
(``SRC/material/nD/DruckerPrager.cpp``, I1 = tr(sigma) tension positive, ||.|| the Frobenius norm
of the *tensor*)::

    f1 = ||s - beta_kin|| + rho I1 - sqrt(2/3) Kiso(alpha1),
    Kiso(a) = sigmaY + theta H a + (Kinf - Ko)(1 - exp(-delta1 a)),
        kinematic modulus (1 - theta) H
    f2 = I1 - T(alpha2),  T = To exp(-delta2 alpha2),  To = sqrt(2/3) sigmaY / rho  (tension cutoff)
    d eps_pl = gamma (n + rhoBar 1),  n = s/||s||,
        d alpha1 = sqrt(2/3) gamma,  d alpha2 = rhoBar gamma

1. Yield surface. With I1 = -3p and q = sqrt(3/2) ||s||, ``F / sqrt(3/2) = ||s|| + sqrt(2/3)
   tan(beta)/3 I1 - sqrt(2/3) d``: the same cone as f1 (beta_kin = 0) iff

       rho = sqrt(2/3) tan(beta)/3,     Kiso(alpha1) = d = (1 - tan(beta)/3)(sigma0 + H eqps).

2. Flow. ``dG/dsigma = sqrt(3/2) n + tan(psi)/3 1 = sqrt(3/2) (n + rhoBar 1)`` with
   ``rhoBar = sqrt(2/3) tan(psi)/3``, so gamma = sqrt(3/2) d lambda. OpenSees documents
   0 <= rhoBar <= rho, i.e. psi <= beta (associated: psi = beta, rhoBar = rho).

3. Hardening variable. ``d alpha1 = sqrt(2/3) gamma = d lambda``: OpenSees's alpha1 is *our
   plastic multiplier* on any stress path (not only in uniaxial compression), and
   ``eqps = (1 - tan(psi)/3) alpha1``. In uniaxial compression alpha1 = sqrt(2/3) ||dev eps_pl||
   = |dev eps_pl_11| = |eps_pl_11| + eps_pl_vol/3 = eqps / (1 - tan(psi)/3). Hence, purely
   isotropic (theta = 1) and linear (Kinf = Ko = delta1 = 0)::

       sigmaY = (1 - tan(beta)/3) sigma0,      H_os = (1 - tan(beta)/3)(1 - tan(psi)/3) H.

4. Elasticity: K = E / (3 (1 - 2 nu)), G = E / (2 (1 + nu)); density 0 (static); atmPressure
   irrelevant (the pressure-dependent moduli are only switched on by ``updateMaterialStage 1``).

5. Tension cutoff: f2 cannot be removed and ``To`` is not an input: OpenSees sets it to the apex
   of the *initial* cone, I1 = sqrt(2/3) sigmaY / rho = 3 sigma0 (1 - tan(beta)/3) / tan(beta)
   (65.7 MPa, a hydrostatic tension of 21.9 MPa for the reference values). With delta2 = 0 it
   stays there; it is then active only where the mean stress exceeds that tension, which
   compression of the cube never reaches, whereas femubench returns such states to the
   (hardened) cone apex. The two models are identical for I1 < To.

Reference values: E = 30 000 MPa, nu = 0.2, beta = 35 deg, psi = 35 deg (associated) and
15 deg (non-associated), sigma0 = 20 MPa, H = 1 500 MPa (:data:`REFERENCE`).
"""

from __future__ import annotations

import math

import numpy as np

#: the cross-check's material: MPa and degrees
REFERENCE = {"E": 30_000.0, "nu": 0.2, "beta": 35.0, "psi": 35.0, "sigma0": 20.0, "H": 1_500.0}
#: femubench parameters the mapping takes, in :func:`opensees_parameters` order
MAPPED = ("E", "nu", "beta", "psi", "sigma0", "H")
#: OpenSees ``nDMaterial DruckerPrager`` arguments after the tag, in command order
OPENSEES_ARGS = (
    "K",
    "G",
    "sigmaY",
    "rho",
    "rhoBar",
    "Kinf",
    "Ko",
    "delta1",
    "delta2",
    "H",
    "theta",
    "density",
)
_SQ23 = math.sqrt(2.0 / 3.0)


def _tan(deg: float) -> float:
    return math.tan(math.radians(deg))


def opensees_parameters(
    E: float, nu: float, beta: float, psi: float, sigma0: float, H: float
) -> dict:
    """OpenSees ``nDMaterial DruckerPrager`` arguments equivalent to femubench's linear form with
    K = 1 and compression hardening (see the module docstring). Angles in degrees, MPa.

    Returns the arguments by their OpenSees names, in command order after the tag:
    ``K G sigmaY rho rhoBar Kinf Ko delta1 delta2 H theta density``.
    """
    if not (E > 0 and -1.0 < nu < 0.5):
        raise ValueError(f"E = {E!r}, nu = {nu!r}: need E > 0 and -1 < nu < 0.5")
    if not (0.0 < beta < math.degrees(math.atan(3.0))):
        raise ValueError(f"beta = {beta!r} deg: need 0 < beta < atan(3) = 71.57 deg")
    if not (0.0 <= psi <= beta):
        raise ValueError(
            f"psi = {psi!r} deg: OpenSees's DruckerPrager needs 0 <= rhoBar <= rho, i.e. "
            f"0 <= psi <= beta = {beta!r} deg"
        )
    if not (sigma0 > 0 and H >= 0):
        raise ValueError(f"sigma0 = {sigma0!r}, H = {H!r}: need sigma0 > 0 and H >= 0 MPa")
    tb, tp = _tan(beta), _tan(psi)
    return {
        "K": E / (3.0 * (1.0 - 2.0 * nu)),
        "G": E / (2.0 * (1.0 + nu)),
        "sigmaY": (1.0 - tb / 3.0) * sigma0,
        "rho": _SQ23 * tb / 3.0,
        "rhoBar": _SQ23 * tp / 3.0,
        "Kinf": 0.0,
        "Ko": 0.0,
        "delta1": 0.0,
        "delta2": 0.0,
        "H": (1.0 - tb / 3.0) * (1.0 - tp / 3.0) * H,
        "theta": 1.0,
        "density": 0.0,
    }


def eqps_from_alpha(alpha, psi: float):
    """femubench's eqps from OpenSees's alpha1 (= our plastic multiplier): (1 - tan(psi)/3)
    alpha1."""
    return (1.0 - _tan(psi) / 3.0) * np.asarray(alpha, float)


def tension_cutoff_I1(osp: dict) -> float:
    """I1 (MPa, tension positive) of OpenSees's fixed tension cutoff plane, sqrt(2/3)
    sigmaY / rho."""
    return _SQ23 * osp["sigmaY"] / osp["rho"] if osp["rho"] > 0 else 1e10


def opensees_yield_value(stress, alpha, osp: dict) -> np.ndarray:
    """OpenSees's f1 = ||s|| + rho I1 - sqrt(2/3) Kiso(alpha1) (MPa; theta = 1, no kinematic part)
    for stresses (n, 6) in femubench's Voigt order ``[xx, yy, zz, yz, xz, xy]``."""
    s = np.atleast_2d(np.asarray(stress, float))
    I1 = s[:, :3].sum(axis=1)
    dev = s[:, :3] - I1[:, None] / 3.0
    norm = np.sqrt((dev**2).sum(axis=1) + 2.0 * (s[:, 3:] ** 2).sum(axis=1))
    a = np.asarray(alpha, float)
    kiso = (
        osp["sigmaY"]
        + osp["theta"] * osp["H"] * a
        + (osp["Kinf"] - osp["Ko"]) * (1.0 - np.exp(-osp["delta1"] * a))
    )
    return norm + osp["rho"] * I1 - _SQ23 * kiso


def opensees_flow_direction(stress, osp: dict) -> np.ndarray:
    """OpenSees's plastic strain rate per unit gamma, n + rhoBar 1, in femubench's engineering
    Voigt components (shear entries 2 n_ij), shape (n, 6)."""
    s = np.atleast_2d(np.asarray(stress, float))
    I1 = s[:, :3].sum(axis=1)
    dev = s.copy()
    dev[:, :3] -= I1[:, None] / 3.0
    norm = np.sqrt((dev[:, :3] ** 2).sum(axis=1) + 2.0 * (dev[:, 3:] ** 2).sum(axis=1))
    n = dev / norm[:, None]
    out = n.copy()
    out[:, :3] += osp["rhoBar"]
    out[:, 3:] *= 2.0
    return out


def dp_return(eps, osp: dict, tangent_norm: str = "trial"):
    """One backward-Euler step of OpenSees's cone (single surface, theta = 1, linear hardening)
    from the virgin state to the total strain ``eps`` (engineering, femubench Voigt order),
    re-derived here: radial return ``s = s_tr - 2 G gamma n``, ``I1 = I1_tr - 9 K rhoBar gamma``,
    ``gamma = f_tr / (2 G + 2/3 H + 9 K rho rhoBar)``, and the algorithmic tangent

        C = Ce - (2G n + 3K rhoBar 1)(2G n + 3K rho 1)/den - 4 G^2 gamma / ||eta|| (IIdev - n n).

    ``tangent_norm = "trial"`` uses ||eta|| = ||s_tr|| (the consistent tangent);
    ``"returned"`` uses ||s_n+1|| = ||s_tr|| - 2 G gamma, as OpenSees does
    (docs/crosscheck_opensees.md).
    Returns (stress, tangent) in femubench's Voigt order."""
    K, G, rho, rb = osp["K"], osp["G"], osp["rho"], osp["rhoBar"]
    one = np.array([1.0, 1, 1, 0, 0, 0])
    IIdev = np.zeros((6, 6))
    IIdev[:3, :3] = np.eye(3) - 1.0 / 3.0
    IIdev[3:, 3:] = 0.5 * np.eye(3)
    Ce = K * np.outer(one, one) + 2.0 * G * IIdev
    sig = Ce @ np.asarray(eps, float)
    I1 = sig[:3].sum()
    s = sig - I1 / 3.0 * one
    norm = math.sqrt((s[:3] ** 2).sum() + 2.0 * (s[3:] ** 2).sum())
    f = norm + rho * I1 - _SQ23 * osp["sigmaY"]
    if f <= 0.0:
        return sig, Ce
    n = s / norm
    den = 2.0 * G + 2.0 / 3.0 * osp["H"] * osp["theta"] + 9.0 * K * rho * rb
    gamma = f / den
    sig = sig - 3.0 * K * rb * gamma * one - 2.0 * G * gamma * n
    eta = norm if tangent_norm == "trial" else norm - 2.0 * G * gamma
    C = (
        Ce
        - np.outer(2.0 * G * n + 3.0 * K * rb * one, 2.0 * G * n + 3.0 * K * rho * one) / den
        - 4.0 * G * G * gamma / eta * (IIdev - np.outer(n, n))
    )
    return sig, C

"""Tools to verify a material: finite-difference tangents, Voigt rotations and typical
Drucker-Prager parameter sets. Used by the tests, the perf script and the material-point CLI.
"""

from __future__ import annotations

import math

import numpy as np

from problems.materials.base import Material
from problems.materials.drucker_prager import FORM_PARAMETERS
from problems.materials.invariants import M_VEC

# Typical concrete, compression variants (MPa, degrees); a such that the exponent surface
# passes through p = -pt0, q = 0: a = (pt0 + sigma_c/3) / sigma_c^b.
_TYPICAL = {
    "E": 30_000.0,
    "beta": 35.0,
    "K": 0.85,
    "psi": 15.0,
    "pt0": 2.5,
    "b": 1.5,
    "a": (2.5 + 20.0 / 3.0) / 20.0**1.5,
}
_TYPICAL_SIGMA0 = {"compression": 20.0, "shear": 10.0, "tension": 2.5}


def typical_parameters(form: str, hardening: str) -> dict[str, float]:
    """A well-posed parameter set of typical concrete for this form and hardening.

    sigma0 = 20 MPa (compression), 10 MPa (shear), 2.5 MPa (tension); H = 75 sigma0.
    """
    if form not in FORM_PARAMETERS:
        raise ValueError(f"form {form!r} is unknown; allowed: {', '.join(FORM_PARAMETERS)}")
    if hardening not in _TYPICAL_SIGMA0:
        raise ValueError(
            f"hardening {hardening!r} is unknown; allowed: {', '.join(_TYPICAL_SIGMA0)}"
        )
    s0 = _TYPICAL_SIGMA0[hardening]
    values = {**_TYPICAL, "sigma0": s0, "H": 75.0 * s0}
    return {name: values[name] for name in FORM_PARAMETERS[form]}


def fd_tangent(
    material: Material, strain_increment, stress_old, state_old, rel_step: float = 1e-7
) -> np.ndarray:
    """Central-difference tangent d stress / d strain_increment (n, 6, 6) of ``material.update``.

    The step of each point is ``rel_step * max|strain_increment|`` (absolute 1e-12 if zero);
    all points are perturbed at once, one strain component at a time (12 updates in all).
    """
    de = np.asarray(strain_increment, float)
    h = rel_step * np.maximum(np.abs(de).max(axis=1), 1e-5)
    out = np.empty((de.shape[0], 6, 6))
    for k in range(6):
        e = np.zeros(6)
        e[k] = 1.0
        plus = material.update(de + h[:, None] * e, stress_old, state_old).stress
        minus = material.update(de - h[:, None] * e, stress_old, state_old).stress
        out[:, :, k] = (plus - minus) / (2.0 * h[:, None])
    return out


def relative_difference(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per-point ``||a - b||_F / ||b||_F`` for stacks of matrices (n, 6, 6)."""
    return np.linalg.norm(a - b, axis=(1, 2)) / np.linalg.norm(b, axis=(1, 2))


def rotation_matrix(axis, angle: float) -> np.ndarray:
    """Proper rotation (3, 3) by ``angle`` (rad) about ``axis`` (Rodrigues)."""
    k = np.asarray(axis, float)
    k = k / np.linalg.norm(k)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * K @ K


_PAIRS = ((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))


def voigt_rotations(R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T_stress, T_strain) (6, 6): Voigt images of ``sigma -> R sigma R^T`` for stress (tensor
    shear components) and for strain (engineering shear components)."""
    T_s = np.zeros((6, 6))
    T_e = np.zeros((6, 6))
    for b, (k, m) in enumerate(_PAIRS):
        # unit tensor of Voigt component b (symmetric pair for shear), rotated
        E = np.zeros((3, 3))
        E[k, m] = E[m, k] = 1.0
        Er = R @ E @ R.T
        for a, (i, j) in enumerate(_PAIRS):
            T_s[a, b] = Er[i, j]
            # engineering strain: component b carries gamma = 2 eps for shear
            T_e[a, b] = Er[i, j] * (2.0 if i != j else 1.0) * (0.5 if k != m else 1.0)
    return T_s, T_e


def hydrostatic(p: np.ndarray) -> np.ndarray:
    """Stress (n, 6) of the compression-positive pressure p (MPa): sigma = -p I."""
    return -np.asarray(p, float)[:, None] * M_VEC

"""The material protocol: what the FE solver asks of a constitutive model.

Conventions (shared by every material and the FE code)
------------------------------------------------------
* Voigt order ``[xx, yy, zz, yz, xz, xy]``.
* Stress in MPa, tension positive. Strain is small strain with *engineering* shear
  components (``gamma_yz = 2 eps_yz``), so that ``stress @ strain`` is the work density.
* Tangent ``D[i, j] = d stress_i / d strain_j`` in the same convention, shape ``(n, 6, 6)``;
  it may be non-symmetric (non-associated flow).
* Everything is vectorised over ``n`` material points: no Python loop over points.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np


@dataclass(frozen=True)
class MaterialUpdate:
    """Result of a constitutive update at ``n`` points.

    stress  : (n, 6) MPa, at the end of the increment
    tangent : (n, 6, 6) MPa, consistent (algorithmic) tangent d stress / d strain
    state   : (n, n_state) history variables at the end of the increment
    ok      : (n,) bool, False where the local return mapping failed to converge
    """

    stress: np.ndarray
    tangent: np.ndarray
    state: np.ndarray
    ok: np.ndarray


@runtime_checkable
class Material(Protocol):
    """A constitutive model, vectorised over material points.

    ``state_names`` names the history columns (for output, e.g. ``"eqps"`` for the equivalent
    plastic strain); ``n_state = len(state_names)`` may be zero.
    """

    state_names: tuple[str, ...]

    def initial_state(self, n: int) -> np.ndarray:
        """History variables of ``n`` virgin points, shape (n, n_state)."""
        ...

    def update(
        self, strain_increment: np.ndarray, stress_old: np.ndarray, state_old: np.ndarray
    ) -> MaterialUpdate:
        """Integrate one strain increment (n, 6) from the converged (stress_old, state_old)."""
        ...


@runtime_checkable
class DifferentiableMaterial(Material, Protocol):
    """A material whose update can be differentiated with respect to its parameters (direct
    differentiation, for sensitivities of a global FE solution).

    ``parameter_names`` fixes the P parameter columns. ``sensitivity(strain_increment,
    stress_old, state_old, update, dstress_old, dstate_old, dstrain_increment)`` takes the
    increment and the :class:`MaterialUpdate` that ``update`` returned for it, with the total
    parameter derivatives of the old stress (n, P, 6), old state (n, P, n_state) and strain
    increment (n, P, 6), and returns those of the new stress and state,
    ``(dstress (n, P, 6), dstate (n, P, n_state))``, per parameter unit.
    """

    parameter_names: tuple[str, ...]

    def sensitivity(
        self,
        strain_increment: np.ndarray,
        stress_old: np.ndarray,
        state_old: np.ndarray,
        update: MaterialUpdate,
        dstress_old: np.ndarray,
        dstate_old: np.ndarray,
        dstrain_increment: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Derivatives of one converged update with respect to the parameters."""
        ...


def isotropic_stiffness(E: float, nu: float) -> np.ndarray:
    """Isotropic elastic stiffness (6, 6) in MPa for Young's modulus E (MPa) and Poisson's ratio
    nu."""
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    mu = E / (2.0 * (1.0 + nu))
    D = np.zeros((6, 6))
    D[:3, :3] = lam
    D[np.arange(3), np.arange(3)] += 2.0 * mu
    D[np.arange(3, 6), np.arange(3, 6)] = mu
    return D


def isotropic_stiffness_derivatives(E: float, nu: float) -> tuple[np.ndarray, np.ndarray]:
    """dD/dE (-) and dD/dnu (MPa) of :func:`isotropic_stiffness`, (6, 6) each."""
    dlam_dnu = E * (1.0 + 2.0 * nu * nu) / ((1.0 + nu) * (1.0 - 2.0 * nu)) ** 2
    dmu_dnu = -E / (2.0 * (1.0 + nu) ** 2)
    dD_dnu = np.zeros((6, 6))
    dD_dnu[:3, :3] = dlam_dnu
    dD_dnu[np.arange(3), np.arange(3)] += 2.0 * dmu_dnu
    dD_dnu[np.arange(3, 6), np.arange(3, 6)] = dmu_dnu
    return isotropic_stiffness(E, nu) / E, dD_dnu


def trial_stress_sensitivity(
    E: float, nu: float, i_E: int, i_nu: int, strain_increment, dstress_old, dstrain_increment
) -> np.ndarray:
    """Parameter derivatives (n, P, 6) in MPa per parameter unit of the elastic trial stress
    ``sigma_old + D(E, nu) deps``: ``dsigma_old + D ddeps + dD/dp deps``, where only the
    parameters in columns i_E (E) and i_nu (nu) enter D."""
    de = np.asarray(strain_increment, float)
    D = isotropic_stiffness(E, nu)
    dD_dE, dD_dnu = isotropic_stiffness_derivatives(E, nu)
    out = np.asarray(dstress_old, float) + np.asarray(dstrain_increment, float) @ D.T
    out[:, i_E] += de @ dD_dE.T
    out[:, i_nu] += de @ dD_dnu.T
    return out

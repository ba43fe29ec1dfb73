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

    def update(self, strain_increment: np.ndarray, stress_old: np.ndarray, state_old: np.ndarray) -> MaterialUpdate:
        """Integrate one strain increment (n, 6) from the converged (stress_old, state_old)."""
        ...


def isotropic_stiffness(E: float, nu: float) -> np.ndarray:
    """Isotropic elastic stiffness (6, 6) in MPa for Young's modulus E (MPa) and Poisson's ratio nu."""
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    mu = E / (2.0 * (1.0 + nu))
    D = np.zeros((6, 6))
    D[:3, :3] = lam
    D[np.arange(3), np.arange(3)] += 2.0 * mu
    D[np.arange(3, 6), np.arange(3, 6)] = mu
    return D

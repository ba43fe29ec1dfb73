"""Isotropic linear elasticity."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from problems.materials.base import MaterialUpdate, isotropic_stiffness, trial_stress_sensitivity


@dataclass(frozen=True)
class LinearElastic:
    """Isotropic linear elastic material.

    E  : Young's modulus, MPa (> 0)
    nu : Poisson's ratio (-1 < nu < 0.5)
    """

    E: float = 30_000.0
    nu: float = 0.2
    state_names: tuple[str, ...] = field(default=(), init=False)

    def __post_init__(self):
        if not np.isfinite(self.E) or self.E <= 0:
            raise ValueError(f"E = {self.E!r} MPa is out of range: E must be > 0")
        if not (-1.0 < self.nu < 0.5):
            raise ValueError(f"nu = {self.nu!r} is out of range: -1 < nu < 0.5")

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """The differentiable parameters, in the column order of :meth:`sensitivity`."""
        return ("E", "nu")

    @property
    def stiffness(self) -> np.ndarray:
        """Elastic stiffness (6, 6), MPa."""
        return isotropic_stiffness(self.E, self.nu)

    def initial_state(self, n: int) -> np.ndarray:
        return np.zeros((n, 0))

    def update(self, strain_increment, stress_old, state_old) -> MaterialUpdate:
        D = self.stiffness
        stress = stress_old + strain_increment @ D.T
        n = strain_increment.shape[0]
        return MaterialUpdate(stress, np.broadcast_to(D, (n, 6, 6)), state_old, np.ones(n, bool))

    def sensitivity(
        self,
        strain_increment,
        stress_old,
        state_old,
        update,
        dstress_old,
        dstate_old,
        dstrain_increment,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Derivatives with respect to (E, nu) of one update (see ``DruckerPrager.sensitivity``):
        ``dstress = dstress_old + D ddeps + dD/dp deps`` (n, 2, 6) in MPa per MPa and per unit
        of nu, and the (empty) state's (n, 2, 0)."""
        dstress = trial_stress_sensitivity(
            self.E, self.nu, 0, 1, strain_increment, dstress_old, dstrain_increment
        )
        return dstress, np.array(dstate_old, dtype=float)

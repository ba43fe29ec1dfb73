"""What an identification case is: active parameters with reference, bounds and default start.

A :class:`Case` is a plain description of an identification problem; it knows nothing of FE or
solvers. ``kind`` says which forward model family it belongs to (``"fe"``: the cube test of a
Drucker-Prager variant; ``"analytic"``: a cheap test problem of :mod:`problems.inverse.analytic`).

Units: MPa for E, sigma0, H, pt0; degrees for beta and psi; ``a`` in MPa^(1-b); K, b, nu -.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.stats import qmc

KINDS = ("fe", "analytic")


@dataclass(frozen=True)
class Parameter:
    """One identified parameter: reference value and box bounds in physical units."""

    name: str
    unit: str
    reference: float
    lower: float
    upper: float

    def __post_init__(self):
        if not (self.lower <= self.reference <= self.upper):
            raise ValueError(f"{self.name}: reference {self.reference} outside [{self.lower}, {self.upper}]")


@dataclass(frozen=True)
class Case:
    """An identification problem: active parameters, bounds, default start and fixed constants."""

    name: str
    form: str
    hardening: str
    parameters: tuple[Parameter, ...]
    fixed: dict = field(default_factory=dict)
    kind: str = "fe"

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"case kind {self.kind!r} is unknown; allowed: {', '.join(KINDS)}")

    @property
    def is_analytic(self) -> bool:
        return self.kind == "analytic"

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    @property
    def reference(self) -> np.ndarray:
        return np.array([p.reference for p in self.parameters])

    @property
    def lower(self) -> np.ndarray:
        return np.array([p.lower for p in self.parameters])

    @property
    def upper(self) -> np.ndarray:
        return np.array([p.upper for p in self.parameters])

    @property
    def start(self) -> np.ndarray:
        """Default start: reference x (1 + 0.25 s), s = +1, -1, +1, ... in listed order, clipped."""
        s = np.where(np.arange(len(self.parameters)) % 2 == 0, 1.0, -1.0)
        return np.clip(self.reference * (1.0 + 0.25 * s), self.lower, self.upper)

    def random_starts(self, n: int, seed: int) -> np.ndarray:
        """``n`` seeded Latin-hypercube points in the bounds, shape (n, n_params)."""
        unit = qmc.LatinHypercube(d=len(self.parameters), seed=np.random.default_rng(seed)).random(n)
        return qmc.scale(unit, self.lower, self.upper)

    def material_parameters(self, x) -> dict[str, float]:
        """Full material parameter dict (active values from ``x`` plus the fixed constants)."""
        x = np.asarray(x, float)
        if x.shape != (len(self.parameters),):
            raise ValueError(f"{self.name}: expected {len(self.parameters)} parameters {self.names}, got shape {x.shape}")
        return {**self.fixed, **dict(zip(self.names, map(float, x)))}

    def to_dict(self) -> dict:
        """The JSON form listed by ``femubench cases --json``."""
        return {
            "name": self.name, "form": self.form, "hardening": self.hardening,
            "parameters": [
                {"name": p.name, "unit": p.unit, "reference": p.reference, "lower": p.lower,
                 "upper": p.upper, "start": float(s)}
                for p, s in zip(self.parameters, self.start)
            ],
            "fixed": dict(self.fixed),
        }

"""What an identification case is: active parameters with reference, bounds and default start.

A :class:`Case` is a plain description of an identification problem; it knows nothing of FE or
solvers. ``kind`` says which forward model family it belongs to (``"fe"``: the cube test of a
Drucker-Prager variant; ``"analytic"``: a cheap test problem of :mod:`problems.inverse.analytic`).

Units: MPa for E, sigma0, H, pt0; degrees for beta and psi; ``a`` in MPa^(1-b); K, b, nu -.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

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
            raise ValueError(
                f"{self.name}: reference {self.reference} outside [{self.lower}, {self.upper}]"
            )


@dataclass(frozen=True)
class Case:
    """An identification problem: active parameters, bounds, default start and fixed constants.

    derive     : picklable ``values -> (material values, d material / d identified)`` when the
                 identified parameters are not the material's own (e.g. the exponent form's
                 ``pt0`` in place of ``a``); None when they are
    initial    : the start, when it is set rather than derived from the reference (a lab's case:
                 problems/inverse/experiment.py, whose ``reference`` is that same start since no
                 reference is known); None: :attr:`start`'s rule
    """

    name: str
    form: str
    hardening: str
    parameters: tuple[Parameter, ...]
    fixed: dict = field(default_factory=dict)
    kind: str = "fe"
    derive: Callable | None = None
    initial: tuple[float, ...] | None = None

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
        """Default start: :attr:`initial` if set, else reference x (1 + 0.25 s),
        s = +1, -1, +1, ... in listed order, clipped to the bounds."""
        if self.initial is not None:
            return np.clip(np.array(self.initial, float), self.lower, self.upper)
        s = np.where(np.arange(len(self.parameters)) % 2 == 0, 1.0, -1.0)
        return np.clip(self.reference * (1.0 + 0.25 * s), self.lower, self.upper)

    def random_starts(self, n: int, seed: int) -> np.ndarray:
        """``n`` seeded Latin-hypercube points in the bounds, shape (n, n_params)."""
        unit = qmc.LatinHypercube(d=len(self.parameters), seed=np.random.default_rng(seed)).random(
            n
        )
        return qmc.scale(unit, self.lower, self.upper)

    def identified(self, x) -> dict[str, float]:
        """``{name: value}`` of the identified parameters at ``x``."""
        x = np.asarray(x, float)
        if x.shape != (len(self.parameters),):
            raise ValueError(
                f"{self.name}: expected {len(self.parameters)} parameters {self.names}, "
                f"got shape {x.shape}"
            )
        return dict(zip(self.names, map(float, x)))

    def material_parameters(self, x) -> dict[str, float]:
        """Full material parameter dict at ``x``: the identified values (or what they derive)
        plus the fixed constants."""
        values = self.identified(x)
        if self.derive is not None:
            values = self.derive(values)[0]
        return {**self.fixed, **values}

    def derived(self, x) -> dict[str, float]:
        """``{name: value}`` of the material parameters the case derives from the identified ones
        at ``x`` (the exponent cases' ``a``, MPa^(1-b)); empty without a derivation."""
        if self.derive is None:
            return {}
        values = self.derive(self.identified(x))[0]
        return {k: float(v) for k, v in values.items() if k not in self.names}

    def material_jacobian(self, x, material_names) -> np.ndarray:
        """d (material parameters ``material_names``) / d (identified parameters), shape (P, n)."""
        values = self.identified(x)
        chain = self.derive(values)[1] if self.derive is not None else {}
        J = np.zeros((len(material_names), len(self.names)))
        for i, m in enumerate(material_names):
            for j, c in enumerate(self.names):
                J[i, j] = chain[m].get(c, 0.0) if m in chain else float(m == c)
        return J

    def to_dict(self) -> dict:
        """The JSON form listed by ``femubench cases --json``."""
        return {
            "name": self.name,
            "form": self.form,
            "hardening": self.hardening,
            "parameters": [
                {
                    "name": p.name,
                    "unit": p.unit,
                    "reference": p.reference,
                    "lower": p.lower,
                    "upper": p.upper,
                    "start": float(s),
                }
                for p, s in zip(self.parameters, self.start)
            ],
            "fixed": dict(self.fixed),
        }

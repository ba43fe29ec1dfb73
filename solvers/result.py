"""The uniform result of one identification run (cf. scipy's OptimizeResult, pymoo's Result)."""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field, fields
from typing import Any

from problems.io import jsonio


@dataclass
class RunResult:
    """Everything one solver run returns; serialises to JSON and back without loss.

    Points are lists of floats in physical units (MPa, degrees, ...), in the order of
    ``parameter_names``; ``x_normalised = x / reference``.

    ``n_evals`` counts *every* call the run made (Jacobian columns, failed and infeasible points
    and, under ``repeats = "charged"`` (COCO's rule, the default), repeated points served from
    the cache); ``n_cache_hits`` counts the calls served from the cache and ``n_repeats`` those
    of them charged (the model ran ``n_evals - n_repeats`` times); ``repeats = "free"`` when the
    run was made with ``free_repeats`` (repeats not counted; records made before the rule
    existed read as "free", the rule they were made under).
    ``trace``: ``[[n_evals, best cost], ...]`` at every charged evaluation that lowered the best
    cost (the best-so-far cost after every evaluation, exactly; see the evaluator).
    ``forward_equivalents`` is ``n_evals`` in plain-forward-run units (a run with exact
    sensitivities weighs its measured wall time over the median plain run);
    ``forward_equivalents_nominal`` the same with the declared price of such a run (the model's
    ``jacobian_cost``, ``extra["jacobian_cost"]``; deterministic), the unit of the budget when
    ``budget_unit`` is ``"forward-equivalents"`` (else ``budget`` counts ``n_evals``);
    ``charges`` holds the runs made on the run's behalf outside the objective (``{kind: {"n",
    "wall_s", "forward_equivalents"}}``: high-fidelity corrections, surrogate training);
    ``provenance`` says which case, data (tier, hash, discretisation), inverse model and
    treatment were used.
    ``history`` has one row per iteration or generation: ``{"iteration", "n_evals",
    "best_cost", "cost", "x"}``.
    """

    method: str
    options: dict[str, Any]
    seed: int | None
    budget: int
    parameter_names: list[str]
    reference: list[float]
    x0: list[float]
    x: list[float]
    x_normalised: list[float]
    cost: float
    status: str  # "converged" | "budget" | "max_iterations" | "failed" | "stalled"
    success: bool
    message: str
    n_evals: int
    n_failed: int = 0
    n_infeasible: int = 0
    n_cache_hits: int = 0
    n_repeats: int = 0
    repeats: str = "free"
    n_iterations: int = 0
    wall_s: float = 0.0
    forward_equivalents: float = 0.0
    forward_equivalents_nominal: float = 0.0
    budget_unit: str = "evaluations"
    charges: dict[str, Any] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)
    history: list[dict[str, Any]] = field(default_factory=list)
    trace: list[list[float]] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON dict; non-finite floats become the strings "inf", "-inf", "nan"."""
        return jsonio.encode(asdict(self))

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "RunResult":
        names = {f.name for f in fields(cls)}
        unknown = set(d) - names
        if unknown:
            raise ValueError(
                f"RunResult: unknown fields {sorted(unknown)}; allowed: {sorted(names)}"
            )
        return cls(**jsonio.decode(d))

    def to_json(self, **kw) -> str:
        return jsonio.dumps(self.to_dict(), **kw)

    @classmethod
    def from_json(cls, text: str) -> "RunResult":
        return cls.from_dict(json.loads(text))

    def errors_percent(self) -> dict[str, float]:
        """Signed error of each parameter with respect to its reference, in percent."""
        return {n: 100.0 * (xn - 1.0) for n, xn in zip(self.parameter_names, self.x_normalised)}

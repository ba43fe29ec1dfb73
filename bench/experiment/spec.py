"""The run spec: the one description of a run, its record form and its hash.

A :class:`RunSpec` says everything that decides a run's answer: the case (or a user problem), the
solver with its options, budget and seed, the start, the inverse mesh, the measured data
(:class:`DataSpec`), the model-error treatment (:class:`Treatment`), the track (the FE model, or a
stored surrogate and an FE polish) and the Jacobian and budget rules. ``femubench identify`` builds
one from its arguments, a suite (:mod:`bench.experiment.suite`) expands into a list of them,
the runner (:mod:`bench.experiment.runner`) runs them through
:func:`bench.experiment.identify.identify`, the studies build theirs, and the store
(:mod:`bench.experiment.store`) keys each record by :func:`config_hash` of
:meth:`RunSpec.to_dict`.

The record form is flat (``tier``, ``data``, ``treatment``, ``plate_margin_mm``, ``track``, ...)
and keys added after schema 2 appear only when they differ from their defaults, so the hashes of
records written by earlier versions (tests/test_bench_shipped_hashes.py) never change.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field, replace
from typing import Any

from problems.inverse.evaluator import BUDGET_UNITS
from problems.inverse.model_error import TREATMENTS

#: version of the run-configuration schema; part of every config hash
CONFIG_SCHEMA = 2
#: ``start``: the case's default start, or the ``start_index``-th seeded random start
START_KINDS = ("default", "random")
#: ``jacobian``: the model's exact Jacobians, or finite differences with that scheme
JACOBIANS = ("exact", "forward", "central")
#: the track of a run in its record: the FE model, or a stored surrogate (then an FE polish)
TRACKS = ("fe", "surrogate")
#: the stored surrogate of a run's (case, mesh) that a suite's surrogate track uses
DEFAULT_SURROGATE = "default"


@dataclass(frozen=True)
class DataSpec:
    """Which measured data a run fits.

    tier     : ``model-error`` (made on a finer discretisation than any model of the loop) or
               ``consistent`` (made on the inverse mesh: judges the optimiser alone)
    settings : data settings that differ from the tier's defaults (a suite's ``[data]`` table:
               fields of :class:`problems.inverse.data.DataSettings`); such a data set is made on
               first use and cached
    file     : an explicit data file (``identify --data``), used in place of the tier's data set
    """

    tier: str = "model-error"
    settings: dict = field(default_factory=dict)
    file: str | None = None

    def data_settings(self, mesh: str):
        """The :class:`~problems.inverse.data.DataSettings` of the tier's data set for the
        inverse ``mesh`` (the consistent tier is made on it)."""
        from problems.inverse.data import tier_settings

        return tier_settings(self.tier, inverse_mesh=mesh, **self.settings)

    def load(self, case: str, mesh: str, *, progress: bool = False):
        """The data set: the file, else the tier's (loaded, or made once and cached by
        :func:`problems.inverse.data.get_data`)."""
        from problems.inverse.data import get_data, load

        if self.file is not None:
            return load(self.file)
        return get_data(case, self.data_settings(mesh), progress=progress)


@dataclass(frozen=True)
class Treatment:
    """The model-error treatment of a run's objective.

    name            : ``none``, ``one-point``, ``iterated``, ``first-order`` or ``bae`` (a
                      correction: problems/inverse/model_error.py), or ``default``: the case's
                      default treatment (:func:`problems.inverse.cases.default_treatment`), which
                      sets the four fields below itself (:meth:`resolved`)
    plate_margin_mm : the measurement region (:class:`problems.inverse.build.Region`)
    hifi_mesh       : high-fidelity mesh of the correction (None: the next finer preset of the
                      inverse mesh, :func:`problems.inverse.build.hifi_mesh_for`)
    bae_samples, bae_seed : prior samples and seed of the BAE statistics
    """

    name: str = "none"
    plate_margin_mm: float = 0.0
    hifi_mesh: str | None = None
    bae_samples: int = 32
    bae_seed: int = 0

    def __post_init__(self):
        if self.name not in TREATMENTS:
            raise ValueError(
                f"treatment = {self.name!r} is unknown; allowed: {', '.join(TREATMENTS)}"
            )
        if int(self.bae_samples) < 2:
            raise ValueError(
                f"bae_samples = {self.bae_samples!r} is out of range: a whole number >= 2"
            )

    def resolved(self, case: str, mesh: str, tier: str) -> "Treatment":
        """This treatment with ``default`` replaced by the case's default and its settings (the
        high-fidelity mesh only when ``mesh`` is the default's inverse mesh); data of the
        ``consistent`` ``tier`` have no model error and get ``none``. Any other name: unchanged."""
        from problems.inverse.cases import default_treatment

        if self.name != "default":
            return self
        d = default_treatment(case)
        if tier == "consistent" or d.treatment == "none":
            return replace(self, name="none", hifi_mesh=None, plate_margin_mm=0.0)
        return replace(
            self,
            name=d.treatment,
            plate_margin_mm=d.plate_margin_mm,
            hifi_mesh=d.hifi_mesh if mesh == d.inverse_mesh else None,
            bae_samples=d.bae_samples,
        )


@dataclass(frozen=True)
class RunSpec:
    """One run: what to identify and how (the record of a run is keyed by its hash).

    case, method   : case name (or a user problem's name in its suite), solver method name
    seed           : seed of the solver and of random starts
    start, start_index : ``default`` (the case's start) or ``random`` (the ``start_index``-th
                     seeded Latin-hypercube point of ``seed``)
    budget         : the solver's budget, in ``budget_unit``
    mesh           : inverse-model mesh spec
    options        : solver options (only those given; defaults are the solver's)
    data           : the measured data (:class:`DataSpec`)
    treatment      : the model-error treatment (:class:`Treatment`)
    surrogate      : None (the solver runs on the FE model), or a stored surrogate (a path or a
                     name; ``default``: the shipped surrogate of (case, mesh) in
                     results/surrogates/) the solver runs on; its training runs are charged
    polish_budget  : with a surrogate, FE evaluations of an ``lm`` polish (exact Jacobians) from
                     the surrogate's optimum; 0: no polish
    jacobian       : ``exact`` (the forward model's own Jacobians, where it offers them),
                     ``forward`` or ``central`` (finite differences: the solver option ``scheme``)
    budget_unit    : ``evaluations`` (``n_evals``) or ``forward-equivalents`` (a response + exact
                     Jacobian counts the model's ``jacobian_cost``; problems/inverse/evaluator.py)
    free_repeats   : repeated points served free (FE economy) instead of charged (every call
                     counts, the default)
    problem        : empty for the FE and analytic cases; a user problem's
                     ``{"entry": ..., "args": {...}}`` (problems/user.py)
    """

    case: str
    method: str
    seed: int = 0
    start: str = "default"
    start_index: int = 0
    budget: int = 300
    mesh: str = "coarse"
    options: dict = field(default_factory=dict)
    data: DataSpec = DataSpec()
    treatment: Treatment = Treatment()
    surrogate: str | None = None
    polish_budget: int = 0
    jacobian: str = "exact"
    budget_unit: str = "evaluations"
    free_repeats: bool = False
    problem: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.start not in START_KINDS:
            raise ValueError(
                f"start = {self.start!r} is unknown; allowed: {', '.join(START_KINDS)}"
            )
        if int(self.budget) < 1:
            raise ValueError(f"budget = {self.budget!r} is out of range: a whole number >= 1")
        if self.jacobian not in JACOBIANS:
            raise ValueError(
                f"jacobian = {self.jacobian!r} is unknown; allowed: {', '.join(JACOBIANS)}"
            )
        if self.budget_unit not in BUDGET_UNITS:
            raise ValueError(
                f"budget_unit = {self.budget_unit!r} is unknown; allowed: {', '.join(BUDGET_UNITS)}"
            )
        if int(self.polish_budget) < 0:
            raise ValueError(
                f"polish_budget = {self.polish_budget!r} is out of range: a whole number >= 0"
            )
        if self.polish_budget and not self.surrogate:
            raise ValueError(
                "an FE polish (polish_budget > 0) follows a run on a surrogate: give one"
            )

    @property
    def track(self) -> str:
        """``surrogate`` when the solver runs on a surrogate, else ``fe``."""
        return "surrogate" if self.surrogate else "fe"

    def to_dict(self) -> dict[str, Any]:
        """The record form (flat; see the module docstring)."""
        later = {
            "track": self.track,
            "jacobian": self.jacobian,
            "budget_unit": self.budget_unit,
            "polish_budget": self.polish_budget,
            "problem": self.problem,
            "free_repeats": self.free_repeats,
            "surrogate": self.surrogate if self.surrogate != DEFAULT_SURROGATE else None,
            "data_file": self.data.file,
            "hifi_mesh": self.treatment.hifi_mesh,
            "bae_samples": self.treatment.bae_samples,
            "bae_seed": self.treatment.bae_seed,
        }
        return {k: v for k, v in later.items() if v != _LATER_KEYS[k]} | {
            "case": self.case,
            "method": self.method,
            "seed": self.seed,
            "start": self.start,
            "start_index": self.start_index,
            "budget": self.budget,
            "mesh": self.mesh,
            "data": dict(sorted(self.data.settings.items())),
            "options": dict(sorted(self.options.items())),
            "tier": self.data.tier,
            "treatment": self.treatment.name,
            "plate_margin_mm": self.treatment.plate_margin_mm,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "RunSpec":
        """The spec of a record's ``config`` (:meth:`to_dict`; keys left out take defaults)."""
        g = {k: d.get(k, v) for k, v in _LATER_KEYS.items()}
        surrogate = g["surrogate"] or (DEFAULT_SURROGATE if g["track"] == "surrogate" else None)
        return cls(
            case=d["case"],
            method=d["method"],
            seed=int(d["seed"]),
            start=d["start"],
            start_index=int(d["start_index"]),
            budget=int(d["budget"]),
            mesh=d["mesh"],
            options=dict(d.get("options") or {}),
            data=DataSpec(d.get("tier", "model-error"), dict(d.get("data") or {}), g["data_file"]),
            treatment=Treatment(
                d.get("treatment", "none"),
                float(d.get("plate_margin_mm", 0.0)),
                g["hifi_mesh"],
                int(g["bae_samples"]),
                int(g["bae_seed"]),
            ),
            surrogate=surrogate,
            polish_budget=int(g["polish_budget"]),
            jacobian=g["jacobian"],
            budget_unit=g["budget_unit"],
            free_repeats=bool(g["free_repeats"]),
            problem=dict(g["problem"]),
        )

    @property
    def hash(self) -> str:
        """:func:`config_hash` of this spec."""
        return config_hash(self)

    @property
    def label(self) -> str:
        """Short human-readable label, e.g.
        ``linear-shear/lm/s0/default0/b200/model-error/none`` (a user problem has no data tier
        and treatment: ``rosenbrock/cma/s0/default0/b3000``)."""
        start = f"{self.start}{self.start_index}"
        head = f"{self.case}/{self.method}/s{self.seed}/{start}/b{self.budget}"
        if self.problem:
            return head
        return (
            f"{head}/{self.data.tier}/{self.treatment.name}"
            + (f"/{self.track}" if self.track != "fe" else "")
            + (f"/jac-{self.jacobian}" if self.jacobian != "exact" else "")
        )


#: record keys added after schema 2, with their defaults (left out of the record, and so of the
#: hash, when default)
_LATER_KEYS = {
    "track": "fe",
    "jacobian": "exact",
    "budget_unit": "evaluations",
    "polish_budget": 0,
    "problem": {},
    "free_repeats": False,
    "surrogate": None,
    "data_file": None,
    "hifi_mesh": None,
    "bae_samples": 32,
    "bae_seed": 0,
}


def canonical_json(obj: Any) -> str:
    """Canonical JSON (sorted keys, no whitespace) used for hashing."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), ensure_ascii=True, allow_nan=True)


def config_hash(spec: RunSpec) -> str:
    """sha256 hex digest of the canonical JSON of the run's record form."""
    payload = {"schema": CONFIG_SCHEMA, **spec.to_dict()}
    return hashlib.sha256(canonical_json(payload).encode()).hexdigest()

"""One identification of a case, with its data tier, measurement region and model-error treatment.

The one place where a case, its data, the inverse model, a correction and a solver are joined;
``femubench identify``, the suite runner and the studies call :func:`identify`. Every run it
triggers is counted in the returned :class:`~solvers.result.RunResult`: the solver's evaluations
(``n_evals``, ``forward_equivalents``) and the runs made on its behalf (``charges``: the
high-fidelity runs of a correction, the BAE statistics), and ``provenance`` says where the data
and the models came from.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path

from problems.inverse.evaluator import BUDGET_UNITS
from problems.inverse.model_error import TREATMENTS

#: the values of ``Identification.jacobian``: the model's exact Jacobians, or finite differences
JACOBIANS = ("exact", "forward", "central")


def jacobian_options(method: str, options: dict, jacobian: str) -> dict:
    """``options`` of ``method`` with the finite-difference ``scheme`` that ``jacobian`` asks
    (methods without a ``scheme`` option, and ``exact``, get them unchanged). A ``scheme`` given
    in the options that contradicts ``jacobian`` raises ValueError."""
    from solvers.base import get_method

    if jacobian == "exact" or "scheme" not in get_method(method).options:
        return dict(options)
    given = options.get("scheme", jacobian)
    if given != jacobian:
        raise ValueError(
            f"option scheme = {given!r} contradicts jacobian = {jacobian!r}; give one of them"
        )
    return {**options, "scheme": jacobian}


@dataclass(frozen=True)
class Identification:
    """What to identify and how.

    case, method     : case name, solver method name
    mesh             : inverse-model mesh spec
    tier             : ``model-error`` or ``consistent`` data (ignored with ``data``)
    data             : an explicit data file (path), else the tier's default data set
    treatment        : ``none``, ``one-point``, ``iterated`` or ``bae`` (model-error correction),
                       or ``default``: the case's default treatment
                       (:func:`problems.inverse.cases.default_treatment`), which also sets
                       ``plate_margin_mm``, ``hifi_mesh`` and ``bae_samples`` (the given ones are
                       replaced; ``none`` on consistent-tier data, which have no model error)
    hifi_mesh        : high-fidelity mesh of the correction (default: the next finer preset)
    plate_margin_mm  : leave out front-face points closer than this to the plates, mm
    budget, seed     : forward evaluations of the solver; seed of the solver and of random starts
    start, start_index : ``default`` or ``random`` (the ``start_index``-th seeded LHS point)
    options          : solver options
    bae_samples, bae_seed : prior samples and seed of the BAE statistics
    surrogate        : a stored surrogate (path or name; ``default``: the shipped surrogate of
                       (case, mesh) in results/surrogates/) used as the forward model of the
                       solver's run; its training runs are charged (``surrogate-training``)
    polish, polish_budget : after the run on the surrogate, an FE ``lm`` (exact Jacobians) from
                       its optimum with at most ``polish_budget`` FE evaluations
    jacobian         : how gradient-based methods get Jacobians: ``exact`` (the forward model's
                       own, by direct differentiation, where it offers them), ``forward`` or
                       ``central`` (finite differences with that scheme: the solver option
                       ``scheme`` is set to it)
    budget_unit      : ``evaluations`` (budget counts forward evaluations, ``n_evals``) or
                       ``forward-equivalents`` (nominal: a response + exact Jacobian counts the
                       model's ``jacobian_cost``; see problems/inverse/evaluator.py)
    free_repeats     : repeated points served free (FE economy) instead of charged (every call
                       counts, the default; see problems/inverse/evaluator.py)
    """

    case: str
    method: str
    mesh: str = "coarse"
    tier: str = "model-error"
    data: str | None = None
    treatment: str = "none"
    hifi_mesh: str | None = None
    plate_margin_mm: float = 0.0
    budget: int = 300
    seed: int = 0
    start: str = "default"
    start_index: int = 0
    options: dict = field(default_factory=dict)
    bae_samples: int = 32
    bae_seed: int = 0
    surrogate: str | None = None
    polish: bool = False
    polish_budget: int = 60
    jacobian: str = "exact"
    budget_unit: str = "evaluations"
    free_repeats: bool = False

    def __post_init__(self):
        if self.treatment not in TREATMENTS:
            raise ValueError(
                f"treatment = {self.treatment!r} is unknown; allowed: {', '.join(TREATMENTS)}"
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
        if self.polish and not self.surrogate:
            raise ValueError("polish = True needs a surrogate (the polish follows its run)")
        if int(self.polish_budget) < 1:
            raise ValueError(
                f"polish_budget = {self.polish_budget!r} is out of range: a whole number >= 1"
            )
        if int(self.bae_samples) < 2:
            raise ValueError(
                f"bae_samples = {self.bae_samples!r} is out of range: a whole number >= 2"
            )


def with_default_treatment(spec: Identification, tier: str | None = None) -> Identification:
    """``spec`` with ``treatment = "default"`` replaced by the case's default treatment and its
    settings (unchanged for any other treatment). ``tier``: the data's tier when known (default
    ``spec.tier``); consistent-tier data get ``none``."""
    from dataclasses import replace

    from problems.inverse.cases import default_treatment

    if spec.treatment != "default":
        return spec
    d = default_treatment(spec.case)
    if (tier or spec.tier) == "consistent" or d.treatment == "none":
        return replace(spec, treatment="none", hifi_mesh=None, plate_margin_mm=0.0)
    return replace(
        spec,
        treatment=d.treatment,
        plate_margin_mm=d.plate_margin_mm,
        hifi_mesh=d.hifi_mesh if spec.mesh == d.inverse_mesh else None,
        bae_samples=d.bae_samples,
    )


def bae_path(spec: Identification, hifi_mesh: str, data) -> Path:
    """Where the BAE statistics of ``spec`` are kept (results/model_error/, keyed by what makes
    them)."""
    import hashlib
    import json

    from bench.paths import results_root

    key = {
        "case": spec.case,
        "mesh": spec.mesh,
        "hifi": hifi_mesh,
        "margin": spec.plate_margin_mm,
        "samples": spec.bae_samples,
        "seed": spec.bae_seed,
        "loading": asdict(data.settings.loading),
        "points": data.points.tolist(),
    }
    digest = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:12]
    return (
        results_root()
        / "model_error"
        / f"{spec.case}__{spec.mesh}__{hifi_mesh}__bae{spec.bae_samples}__{digest}.npz"
    )


def bae_correction(spec: Identification, hifi, inverse, hifi_mesh: str, data, mapper=None):
    """The BAE statistics of ``spec``: loaded when stored (hash-checked), else computed and
    stored."""
    from problems.inverse.cases import get_case
    from problems.inverse.model_error import Correction, bae_statistics

    path = bae_path(spec, hifi_mesh, data)
    if path.exists():
        try:
            return Correction.load(path)
        except ValueError as exc:  # a torn cache: set it aside and compute it again
            import warnings

            from problems.io.atomic import set_aside_torn

            moved = set_aside_torn(path)
            warnings.warn(f"{exc}; moved to {moved} and computed again", stacklevel=2)
    case = get_case(spec.case)
    corr = bae_statistics(
        hifi,
        inverse,
        case.lower,
        case.upper,
        samples=spec.bae_samples,
        seed=spec.bae_seed,
        mapper=mapper,
        provenance={"case": spec.case, "inverse_mesh": spec.mesh, "hifi_mesh": hifi_mesh},
    )
    corr.save(path)
    return corr

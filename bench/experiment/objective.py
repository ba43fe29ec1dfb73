"""The one assembly of a run's objective: data, measurement region, inverse model (FE or a
surrogate), model-error correction, and the honesty check.

``femubench identify``, the suite runner, the studies and the model-error and posterior studies
all go through :func:`prepare` (or :func:`assemble`, its treated objective): the spec's data are
resolved once, ``treatment = "default"`` is replaced by the case's default, and the honesty rule
(the discretisation that made model-error data is used by no model of the inverse loop:
:func:`problems.inverse.build.check_discretisations`) is checked once, before any high-fidelity
run, for the inverse mesh, the correction's high-fidelity mesh and the surrogate.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from bench.experiment.spec import RunSpec, Treatment
from problems.inverse.model_error import ITERATED


@dataclass
class Assembly:
    """A spec joined to its data, region and models; makes its objectives.

    spec      : the resolved spec (treatment ``default`` replaced: :meth:`Treatment.resolved
                <bench.experiment.spec.Treatment.resolved>`)
    case      : the problems.inverse Case
    data      : the measured Dataset (None for an analytic case)
    region    : the measurement region (problems.inverse.build.Region; None for analytic)
    hifi_mesh : the correction's high-fidelity mesh (None without a correction)
    mapper    : the objectives' mapper (FE runs of a batch)
    surrogate : the spec's stored surrogate (problems.surrogate; None: the solver runs on the FE
                model)
    """

    spec: RunSpec
    case: Any
    data: Any = None
    region: Any = None
    hifi_mesh: str | None = None
    mapper: Any = None
    surrogate: Any = None
    _pair: tuple | None = field(default=None, repr=False)
    _fixed: Any = field(default=None, repr=False)

    def objective(self, correction=None, *, forward=None, mapper=None, observers=()):
        """The Evaluator with ``correction`` (None: uncorrected) on ``forward`` (a surrogate;
        None: the FE model); ``mapper`` overrides the assembly's. ``observers`` are added."""
        from problems.inverse.build import build_objective

        s = self.spec
        flags = {
            "exact_jacobian": s.jacobian == "exact",
            "budget_unit": s.budget_unit,
            "free_repeats": s.free_repeats,
            "mapper": self.mapper if mapper is None else mapper,
        }
        if self.case.is_analytic:
            obj = build_objective(self.case, **flags)
        else:
            obj = build_objective(
                self.case,
                mesh=s.mesh,
                data=self.data,
                region=self.region,
                correction=correction,
                hifi_mesh=self.hifi_mesh,
                forward=forward,
                **flags,
            )
        obj.observers.extend(observers)
        return obj

    def models(self):
        """``(hifi, inverse)`` FE forward models of the correction (made once)."""
        from problems.inverse.build import model_pair

        if self._pair is None:
            s = self.spec
            self._pair = model_pair(self.case, s.mesh, self.hifi_mesh, self.data, self.region)
        return self._pair

    def one_point(self, at):
        """The one-point correction (high-fidelity minus inverse model) at the physical ``at``."""
        from problems.inverse.model_error import one_point

        return one_point(*self.models(), at, mapper=self.mapper)

    def first_order(self, at):
        """The first-order correction (shift and Jacobian difference of the high-fidelity and
        inverse models) at the physical ``at``."""
        from problems.inverse.model_error import first_order

        return first_order(*self.models(), at, mapper=self.mapper)

    def correction(self):
        """The spec's fixed correction (made once): None for ``none``, the one-point correction at
        the spec's start, or the BAE statistics; ``iterated`` and ``first-order`` have none (they
        follow a solver)."""
        s = self.spec
        if s.treatment.name == "none" or self.case.is_analytic:
            return None
        if s.treatment.name in ITERATED:
            raise ValueError(
                f"treatment {s.treatment.name!r} re-evaluates the correction at a solver's "
                "solutions: it exists for identifications only; allowed here: none, one-point, "
                "bae, default"
            )
        if self._fixed is None:
            if s.treatment.name == "one-point":
                self._fixed = self.one_point(self.start())
            else:
                hifi, inverse = self.models()
                self._fixed = bae_correction(
                    s, hifi, inverse, self.hifi_mesh, self.data, self.mapper
                )
        return self._fixed

    def start(self):
        """The spec's physical start point."""
        from problems.inverse.starts import start_point

        s = self.spec
        return start_point(self.case, kind=s.start, seed=s.seed, index=s.start_index)

    def treated(self, *, forward=None, mapper=None, observers=()):
        """The objective with the spec's fixed correction (see :meth:`correction`)."""
        return self.objective(
            self.correction(), forward=forward, mapper=mapper, observers=observers
        )


def prepare(spec: RunSpec, *, mapper=None, dataset=None, forward=None) -> Assembly:
    """The :class:`Assembly` of ``spec``: its data (``dataset`` when the caller prepared it: a
    Dataset or a data file; else :meth:`spec.data.load <bench.experiment.spec.DataSpec.load>`),
    the default treatment resolved (an analytic case has none), the region, the high-fidelity
    mesh and the surrogate (``forward`` when the caller loaded it, else ``spec.surrogate``'s);
    the honesty rule checked once, for all of them. No model is run."""
    from problems.inverse.build import Region, check_discretisations, hifi_mesh_for
    from problems.inverse.cases import get_case
    from problems.inverse.data import Dataset, load

    case = get_case(spec.case)
    if case.is_analytic:
        if forward is not None or spec.surrogate:
            raise ValueError(f"case {case.name} is analytic: a surrogate is for the FE cases")
        return Assembly(replace(spec, treatment=Treatment()), case, mapper=mapper)
    if forward is None and spec.surrogate:
        from bench.experiment.surrogate_track import load_for

        forward = load_for(spec.surrogate, case.name, spec.mesh)
    if dataset is None:
        data = spec.data.load(case.name, spec.mesh)
    else:
        data = dataset if isinstance(dataset, Dataset) else load(dataset)
    t = spec.treatment.resolved(case.name, spec.mesh, data.settings.tier)
    spec = replace(spec, treatment=t)
    hifi_mesh = None if t.name == "none" else t.hifi_mesh or hifi_mesh_for(spec.mesh)
    check_discretisations(case, data, spec.mesh, hifi_mesh=hifi_mesh, forward=forward)
    return Assembly(spec, case, data, Region(t.plate_margin_mm), hifi_mesh, mapper, forward)


def assemble(spec: RunSpec, *, mapper=None, dataset=None, forward=None):
    """The objective of ``spec`` with its data, region and fixed model-error correction (the
    studies' objective; see :func:`prepare` and :meth:`Assembly.correction`)."""
    return prepare(spec, mapper=mapper, dataset=dataset, forward=forward).treated(forward=forward)


def bae_path(spec: RunSpec, hifi_mesh: str, data) -> Path:
    """Where the BAE statistics of ``spec`` are kept (results/model_error/, keyed by what makes
    them: case, meshes, region, samples, seed, loading and measurement points)."""
    import hashlib
    import json

    from bench.paths import results_root

    t = spec.treatment
    key = {
        "case": spec.case,
        "mesh": spec.mesh,
        "hifi": hifi_mesh,
        "margin": t.plate_margin_mm,
        "samples": t.bae_samples,
        "seed": t.bae_seed,
        "loading": asdict(data.settings.loading),
        "points": data.points.tolist(),
    }
    digest = hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:12]
    return (
        results_root()
        / "model_error"
        / f"{spec.case}__{spec.mesh}__{hifi_mesh}__bae{t.bae_samples}__{digest}.npz"
    )


def bae_correction(spec: RunSpec, hifi, inverse, hifi_mesh: str, data, mapper=None):
    """The BAE statistics of ``spec``: loaded when stored (hash-checked; found in the results root
    or the artefact directory by :func:`bench.artefacts.locate`, checked against the release
    manifest), else computed and stored at :func:`bae_path` (a release artefact that is missing
    is named with a one-line warning first: how to get it instead, and how long computing takes).
    """
    import warnings

    from bench import artefacts
    from problems.inverse.cases import get_case
    from problems.inverse.model_error import Correction, bae_statistics

    path = bae_path(spec, hifi_mesh, data)
    rel = f"{path.parent.name}/{path.name}"
    found = artefacts.locate(rel)
    if found is not None:
        try:
            return Correction.load(found)
        except ValueError as exc:  # a torn cache: set it aside and compute it again
            from problems.io.atomic import set_aside_torn

            moved = set_aside_torn(found)
            warnings.warn(f"{exc}; moved to {moved} and computed again", stacklevel=2)
    elif artefacts.listed(rel):
        warnings.warn(f"{artefacts.missing(rel)}; computing them now", stacklevel=2)
    case = get_case(spec.case)
    corr = bae_statistics(
        hifi,
        inverse,
        case.lower,
        case.upper,
        samples=spec.treatment.bae_samples,
        seed=spec.treatment.bae_seed,
        mapper=mapper,
        provenance={"case": spec.case, "inverse_mesh": spec.mesh, "hifi_mesh": hifi_mesh},
    )
    corr.save(path)
    return corr

"""The inverse problem of a case: the evaluated least-squares problem against a data set.

:func:`build_objective` joins a case, a data set (a tier, or an explicit file), a measurement
region, the FE forward model on the inverse mesh and a model-error correction into one
:class:`~problems.inverse.evaluator.Evaluator`, and records where everything came from in its
``provenance``. The honesty rule is enforced here: a model-error data set's discretisation is
never used by a model of the loop (:func:`problems.inverse.model_error.check_honest`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from problems.fe.mesh import SIZE_MM, discretisation_key, parse_mesh_spec
from problems.inverse import layout
from problems.inverse.case import Case
from problems.inverse.cases import get_case
from problems.inverse.data import Dataset, get_data, load, tier_settings
from problems.inverse.evaluator import Evaluator
from problems.inverse.model_error import Correction, check_honest, corrected_model
from problems.inverse.problem import LeastSquaresProblem

#: high-fidelity mesh of a model-error correction for each inverse mesh (a finer mesh of the same
#: family; never the discretisation of the model-error data): the presets take the next finer
#: preset; the model-error tier's default inverse model (27-node, graded) a finer graded 27-node
#: mesh (docs/fe_model.md, "Table 1 on the reference tier")
DEFAULT_HIFI = {"coarse": "paper", "paper": "fine", "6,6,12:g8:hex27": "9,9,18:g8:hex27"}


#: what the plate margin is, in one line (help texts of the CLI, suites and experiment files)
PLATE_MARGIN_TEXT = "front-face points closer than this to either plate are left out, mm"


@dataclass(frozen=True)
class Region:
    """The measurement region: which front-face points the objective uses. The force is always
    used.

    plate_margin_mm : the plate margin, mm: the front-face points closer than this to either plate
                      (z < margin or z > height - margin) are left out, where the plates'
                      friction and the mesh's corners make the model least faithful. The one
                      definition of the concept: every ``plate_margin_mm`` (a treatment, a case's
                      default treatment, a suite, a study, an experiment file) is this value,
                      checked by :meth:`range_error` (0 <= margin < 75 mm, half the standard
                      specimen, unless a specimen's own height is given there).
    """

    plate_margin_mm: float = 0.0

    def __post_init__(self):
        why = self.range_error(self.plate_margin_mm)
        if why:
            raise ValueError(why)

    @staticmethod
    def range_error(margin, height_mm: float = SIZE_MM[2]) -> str | None:
        """Why ``margin`` is no plate margin of a specimen ``height_mm`` tall, or None."""
        if isinstance(margin, bool) or not isinstance(margin, (int, float)):
            return f"plate_margin_mm = {margin!r} is not a number of mm"
        if not (np.isfinite(margin) and 0.0 <= margin < height_mm / 2):
            limit = f"0 <= margin < {height_mm / 2:g} mm"
            return f"plate_margin_mm = {margin!r} is out of range: {limit}"
        return None

    def mask(self, points, height_mm: float = SIZE_MM[2]) -> np.ndarray:
        """Boolean mask over front-face points (m, 2) = (y, z) mm of a specimen ``height_mm``
        tall."""
        return plate_margin_mask(points, self.plate_margin_mm, height_mm)


#: the automatic plate margin (``plate_margin_mm = "auto"``), as a fraction of the specimen's
#: smallest dimension (:func:`auto_plate_margin_mm`)
AUTO_PLATE_MARGIN_FRACTION = 0.1


def auto_plate_margin_mm(width_mm: float, depth_mm: float, height_mm: float) -> float:
    """The automatic plate margin, mm, of a specimen ``width_mm x depth_mm x height_mm`` (mm):
    :data:`AUTO_PLATE_MARGIN_FRACTION` (10 %) of its smallest dimension: 15 mm on a 150 mm cube,
    10 mm on a 100 mm cube and on a 100 x 100 x 300 mm prism. Never from parameter values.

    Why: the discretisation bias of a coarse inverse model sits in the DIC rows nearest the
    bonded plate edges, where the stress is singular. The singular field is self-similar: on a
    geometrically similar specimen, and on the inverse meshes (a number of elements per edge,
    so an element size proportional to the specimen) its zone of poor resolution scales with
    the specimen, and with the cross-section (the smallest dimension) on a prism, whose
    plate-edge field is that of a cube of the same section. Measured on the 150 mm cube
    (inverse ``6,6,12:g8:hex27`` against data ``12,12,24:g8:hex27``): a 10 mm margin takes the
    linearised ``pt0`` bias of the hyperbolic cases from -8.5 to -11.2 % to within 2.3 %; with
    the one-point or iterated correction a 15-20 mm margin gives <= 1 % on all of them
    (docs/calibrating.md). 10 % of the smallest dimension is the smallest margin of that
    measurement scaled by size, and leaves ~80 % of a cube's face height measured. Measured in
    the hyperbolic-compression coverage study (results/calibration/coverage/
    hyperbolic-compression-hex27-margin): the errors are the noise's on every specimen (rms
    error / Laplace sd 0.7-1.4 per parameter); the two 100 mm cubes with pt0 off by 9.5 and
    13.3 % are 1.8 and 2.2 sd off, and the noise-free twin of the worse one has pt0 within 0.3 %.
    """
    return AUTO_PLATE_MARGIN_FRACTION * min(float(width_mm), float(depth_mm), float(height_mm))


def resolve_plate_margin(value, specimen_mm) -> float:
    """The plate margin, mm, that ``value`` (a number of mm, or ``"auto"``:
    :func:`auto_plate_margin_mm`) means on a specimen ``specimen_mm`` = (width, depth, height)
    mm; ValueError (one line, :meth:`Region.range_error`) when it is none."""
    margin = auto_plate_margin_mm(*specimen_mm) if value == "auto" else value
    why = Region.range_error(margin, float(specimen_mm[2]))
    if why:
        raise ValueError(f"{why} (or auto)")
    return float(margin)


def plate_margin_mask(points, margin_mm: float, height_mm: float) -> np.ndarray:
    """The front-face points (m, 2) = (y, z) mm at least ``margin_mm`` from both plates of a
    specimen ``height_mm`` tall (:class:`Region`)."""
    z = np.asarray(points, float)[:, 1]
    return (z >= margin_mm - 1e-9) & (z <= height_mm - margin_mm + 1e-9)


def hifi_mesh_for(mesh: str) -> str:
    """The default high-fidelity mesh of a correction for inverse mesh ``mesh``
    (:data:`DEFAULT_HIFI`, matched by discretisation: ``coarse:quarter`` is ``coarse``)."""
    key = discretisation_key(mesh)
    for inverse, hifi in DEFAULT_HIFI.items():
        if discretisation_key(inverse) == key:
            return hifi
    raise ValueError(
        f"no default high-fidelity mesh for inverse mesh {mesh!r}; allowed inverse meshes: "
        f"{', '.join(DEFAULT_HIFI)} (or name the high-fidelity mesh explicitly)"
    )


def check_finer(hifi_mesh: str, mesh: str, name: str = "--hifi-mesh") -> None:
    """ValueError (one line, naming the option ``name``) unless the high-fidelity mesh
    ``hifi_mesh`` is finer than the inverse ``mesh``: at least as many elements along x, y and z
    and more along one (a coarser or equal "high-fidelity" model corrects nothing, or the wrong
    way)."""
    hi, lo = parse_mesh_spec(hifi_mesh).shape, parse_mesh_spec(mesh).shape
    if not (all(h >= n for h, n in zip(hi, lo)) and hi != lo):
        raise ValueError(
            f"{name} {hifi_mesh!r} ({','.join(map(str, hi))} elements) is not finer than "
            f"the inverse mesh {mesh!r} ({','.join(map(str, lo))}); allowed: a mesh with at least "
            "as many elements along x, y and z and more along one"
        )


def resolve_data(case: Case, mesh: str, tier: str, data: Dataset | str | Path | None) -> Dataset:
    """The data set: explicit (a Dataset or a file) or the tier's default for the inverse
    ``mesh``."""
    if data is None:
        return get_data(case.name, tier_settings(tier, inverse_mesh=mesh))
    return data if isinstance(data, Dataset) else load(data)


def subset(data: Dataset, region: Region) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(points, values, sigma_displacement)`` of the data restricted to ``region``."""
    keep = region.mask(data.points, data.settings.specimen_mm[2])
    if not keep.any():
        raise ValueError(
            f"the measurement region (plate margin {region.plate_margin_mm:g} mm) leaves no point"
        )
    std = data.std_u_mm[:, :, keep]
    values = layout.stack(data.u_h[:, keep], data.u_v[:, keep], data.reaction_kN)
    return data.points[keep], values, std


def model_pair(
    case: Case | str, mesh: str, hifi_mesh: str, data: Dataset, region: Region = Region()
):
    """``(hifi, inverse)`` FE forward models of a correction on the objective's points and
    loading."""
    from problems.inverse.forward import FEForwardModel

    case = get_case(case) if isinstance(case, str) else case
    points = data.points[region.mask(data.points, data.settings.specimen_mm[2])]
    return (
        FEForwardModel(
            case, hifi_mesh, data.settings.loading, points, specimen_mm=data.settings.specimen_mm
        ),
        FEForwardModel(
            case, mesh, data.settings.loading, points, specimen_mm=data.settings.specimen_mm
        ),
    )


def check_discretisations(
    case: Case, ds: Dataset, mesh: str, *, hifi_mesh: str | None = None, forward=None
) -> None:
    """Raise ValueError unless the data ``ds`` may be fitted with the inverse model on ``mesh``,
    a correction's high-fidelity model on ``hifi_mesh`` (None: no correction) and the surrogate
    ``forward`` (None: the FE model): the data are ``case``'s, consistent-tier data were made on
    the inverse mesh, and no model of the inverse loop uses the discretisation that made
    model-error data (the honesty rule, :func:`~problems.inverse.model_error.check_honest`).
    Cheap (no model run): call it before a correction's high-fidelity runs."""
    if ds.case != case.name:
        raise ValueError(f"data set is for case {ds.case!r}, not {case.name!r}")
    tier = ds.settings.tier
    data_key, inverse_key = discretisation_key(ds.settings.mesh), discretisation_key(mesh)
    if tier == "consistent" and data_key != inverse_key:
        raise ValueError(
            f"consistent-tier data were made on mesh {ds.settings.mesh} ({data_key}); the inverse "
            f"model uses {mesh} ({inverse_key}): use data made on the inverse mesh"
        )
    hifi_key = discretisation_key(hifi_mesh) if hifi_mesh else None
    check_honest(data_key, tier, forward=inverse_key, hifi=hifi_key)
    if forward is not None:
        from problems.surrogate.model import discretisation_of

        trained_on = discretisation_of(forward)
        if trained_on is None:
            raise ValueError("the surrogate does not say which discretisation it was trained on")
        check_honest(data_key, tier, surrogate=trained_on)
        if trained_on != inverse_key:
            raise ValueError(
                f"the surrogate was trained on discretisation {trained_on}; the inverse mesh "
                f"{mesh} is {inverse_key}: use a surrogate of the inverse mesh"
            )


def build_objective(
    case: Case | str,
    *,
    mesh: str = "coarse",
    tier: str = "model-error",
    data: Dataset | str | Path | None = None,
    region: Region = Region(),
    correction: Correction | None = None,
    hifi_mesh: str | None = None,
    mapper=None,
    sigma_force_kN: float = 1.0,
    cache: bool = True,
    forward=None,
    exact_jacobian: bool = True,
    budget_unit: str = "evaluations",
    free_repeats: bool = False,
) -> Evaluator:
    """The evaluator (a solver's objective) of ``case`` with the FE model on ``mesh``.

    tier       : ``model-error`` or ``consistent`` data (ignored when ``data`` is given: its own
                 tier is used); analytic cases ignore mesh, tier and data
    region     : the front-face points used (:class:`Region`)
    correction : a model-error correction (see :mod:`problems.inverse.model_error`) made with the
                 high-fidelity model on ``hifi_mesh``: its mean shifts the data, its low-rank
                 covariance is added to the noise's, a first-order correction's slope adds
                 ``slope (x - anchor)`` to the model (and ``slope`` to its Jacobian, physical
                 units: the scaling to ``z`` is the problem's); its runs are charged to the
                 evaluator
    sigma_force_kN : standard deviation of the plate force, kN
    forward    : a surrogate of the FE model on ``mesh`` (a ``problems.surrogate.SurrogateModel``)
                 used in its place, restricted to the region's points; refused when it was
                 trained on another discretisation than ``mesh``, or on the one that made
                 model-error data (the honesty rule)
    exact_jacobian : the model's exact Jacobians where it provides them (False: finite
                 differences with the solver's ``scheme``, as for models without them)
    free_repeats : repeated points served free (FE economy) instead of charged (every call
                 counts, the default; :class:`~problems.inverse.evaluator.Evaluator`)
    budget_unit : ``"evaluations"`` or ``"forward-equivalents"``: what a solver's budget counts
                 (:class:`~problems.inverse.evaluator.Evaluator`; forward-equivalents charge a
                 response + exact Jacobian the model's declared ``jacobian_cost``)
    """
    from problems.inverse.forward import FEForwardModel

    case = get_case(case) if isinstance(case, str) else case
    if case.is_analytic:
        from problems.inverse.analytic import analytic_objective

        evaluator = analytic_objective(case.name, mapper=mapper)
        return Evaluator(
            evaluator.problem,
            mapper=mapper,
            cache=evaluator.cache,
            exact_jacobian=exact_jacobian,
            budget_unit=budget_unit,
            free_repeats=free_repeats,
        )
    ds = resolve_data(case, mesh, tier, data)
    if ds.snapshot_rho != 0.0:  # never dropped silently: this objective's noise is diagonal
        raise ValueError(
            f"data set {ds.case}: snapshot_rho = {ds.snapshot_rho:g} (errors correlated between "
            "snapshots) is modelled by `femubench calibrate` only; allowed here: 0"
        )
    tier = ds.settings.tier
    check_discretisations(
        case, ds, mesh, hifi_mesh=hifi_mesh if correction is not None else None, forward=forward
    )
    points, values, std = subset(ds, region)
    sigma = np.concatenate([std.ravel(), np.full(len(ds.reaction_kN), sigma_force_kN)])
    if not sigma_force_kN > 0:
        raise ValueError(f"sigma_force_kN = {sigma_force_kN!r} is out of range: must be > 0 kN")
    if forward is None:
        model = FEForwardModel(
            case, mesh, ds.settings.loading, points, specimen_mm=ds.settings.specimen_mm
        )
    else:
        from problems.surrogate.model import restricted

        model = restricted(forward, case, points, ds.settings.loading)
    model = corrected_model(model, correction)  # a first-order correction's slope
    shift = 0.0 if correction is None or correction.shift is None else correction.shift
    problem = LeastSquaresProblem(
        model,
        values - shift,
        case.lower,
        case.upper,
        case.reference,
        sigma=sigma,
        covariance_factor=None if correction is None else correction.factor,
        blocks=layout.blocks(len(ds.snapshots_mm), len(points)),
        provenance={
            "case": case.name,
            "data_tier": tier,
            "data_hash": ds.hash,
            "data_mesh": ds.settings.mesh,
            "data_route": ds.settings.route,
            "inverse_mesh": mesh,
            "region_plate_margin_mm": region.plate_margin_mm,
            "treatment": "none" if correction is None else correction.treatment,
            "hifi_mesh": hifi_mesh if correction is not None else None,
            "correction_hash": None if correction is None else correction.hash,
            **(
                {}
                if forward is None
                else {"forward": "surrogate", "surrogate_hash": getattr(forward, "hash", None)}
            ),
        },
    )
    evaluator = Evaluator(
        problem,
        mapper=mapper,
        cache=cache,
        exact_jacobian=exact_jacobian,
        budget_unit=budget_unit,
        free_repeats=free_repeats,
    )
    if correction is not None:
        evaluator.charge("hifi", correction.n_hifi, correction.hifi_wall_s)
        evaluator.charge("inverse-for-correction", correction.n_inverse, correction.inverse_wall_s)
    return evaluator

"""Build a surrogate once: design -> training runs -> POD -> regression (selected) -> hold-out
validation.

Model selection never sees the hold-out points:

* ``regression="rbf"``: kernel, shape parameter and smoothing by k-fold cross-validation on the
  training points;
* ``regression="gp"``: GP hyper-parameters by maximum marginal likelihood on the training points;
* ``regression="auto"``: a seeded ``selection_fraction`` of the training points is set aside, the
  POD, the RBF (with its cross-validation) and the GP are fitted on the rest, and the family with
  the lower error on the set-aside points (mean over the blocks of the mean square in units of
  sigma) wins; it is then refitted on all training points.

Cost: every training and hold-out run is counted (``info["cost"]``), so that identifications using
the surrogate can be charged for it.
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import asdict, dataclass

import numpy as np

from problems.surrogate.design import make_design
from problems.surrogate.model import SurrogateModel
from problems.surrogate.pod import fit_pod
from problems.surrogate.regression import (
    RBF_KERNELS,
    RBF_SMOOTHING,
    Scorer,
    fit_gp,
    fit_rbf,
    select_rbf,
)
from problems.surrogate.training import Runs, run_points
from problems.surrogate.validation import FE_UNITS, validate

REGRESSIONS = ("auto", "rbf", "gp")


@dataclass(frozen=True)
class SurrogateSettings:
    """How a surrogate is built.

    n_train            : points of the global training design
    n_holdout          : points of the hold-out design (its own seed stream; 0: no validation)
    seed               : seed of the designs, the selection split and the GP restarts
    design             : ``lhs`` or ``sobol``
    n_local, local_scale, center : optional local design of ``n_local`` points in
                         ``center +- local_scale (upper - lower)`` (center in physical units);
                         without a centre and with a ``target`` (the data), a second stage:
                         the centre is the optimum of the first-stage surrogate fitted to the
                         data (the data's own search, never the reference values), then the
                         surrogate is refitted on both designs (:func:`surrogate_optimum`)
    separate           : blocks kept out of the POD, each value its own coefficient with its own
                         GP (default: the force)
    tol_sigma          : POD truncation: RMS projection error per block <= tol_sigma sigma
    max_modes          : cap on the number of POD modes (None: none)
    regression         : ``auto``, ``rbf`` or ``gp``
    selection_fraction : share of the training points set aside to choose the family (auto)
    cv_folds           : folds of the RBF cross-validation
    rbf_kernels, rbf_smoothing : candidates of the RBF cross-validation ((kernel, eps) pairs;
                         smoothing values, ``(0.0,)`` forces interpolation of the training points)
    gp_nu, gp_individual, gp_restarts : GP kernel smoothness (1.5, 2.5 or inf), number of leading
                         modes with a GP each, optimiser restarts
    batch              : points per mapper call
    """

    n_train: int = 200
    n_holdout: int = 50
    seed: int = 0
    design: str = "lhs"
    n_local: int = 0
    local_scale: float = 0.1
    center: tuple | None = None
    tol_sigma: float = 0.1
    max_modes: int | None = None
    regression: str = "auto"
    selection_fraction: float = 0.2
    cv_folds: int = 5
    rbf_kernels: tuple = RBF_KERNELS
    rbf_smoothing: tuple = RBF_SMOOTHING
    gp_nu: float = 2.5
    gp_individual: int = 8
    gp_restarts: int = 2
    batch: int = 16
    separate: tuple = ("force",)

    def __post_init__(self):
        if self.regression not in REGRESSIONS:
            raise ValueError(
                f"regression {self.regression!r} is unknown; allowed: {', '.join(REGRESSIONS)}"
            )
        if self.n_train < 1:
            raise ValueError(f"n_train = {self.n_train} is out of range: must be >= 1")
        if self.n_holdout < 0:
            raise ValueError(f"n_holdout = {self.n_holdout} is out of range: must be >= 0")
        if not 0 < self.selection_fraction < 1:
            raise ValueError(
                f"selection_fraction = {self.selection_fraction} is out of range: 0 < f < 1"
            )

    def to_dict(self) -> dict:
        d = asdict(self)
        d["center"] = None if self.center is None else [float(v) for v in self.center]
        return d


def training_hash(runs: Runs, settings: dict) -> str:
    """SHA-256 of the training set (points, values, failed and infeasible points) and the
    settings."""
    h = hashlib.sha256()
    for a in (
        runs.X,
        runs.Y,
        np.array([x for x, _ in runs.failed]),
        np.array([x for x, _ in runs.infeasible]),
    ):
        a = np.ascontiguousarray(a, dtype="<f8")
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    import json

    h.update(json.dumps(settings, sort_keys=True, default=str).encode())
    return h.hexdigest()


def _fit_family(kind: str, Z, A, scorer, s: SurrogateSettings, individual=()):
    if kind == "rbf":
        cfg, table = select_rbf(
            Z,
            A,
            scorer,
            kernels=s.rbf_kernels,
            smoothing=s.rbf_smoothing,
            folds=s.cv_folds,
            seed=s.seed,
        )
        return fit_rbf(Z, A, **cfg), {"rbf_cv": table, "rbf_choice": cfg}
    return fit_gp(
        Z,
        A,
        nu=s.gp_nu,
        n_individual=s.gp_individual,
        restarts=s.gp_restarts,
        seed=s.seed,
        individual=individual,
    ), {}


def _separate_columns(pod, blocks, separate) -> tuple[int, ...]:
    """Coefficient indices of the separate blocks' values (the last columns of the modes)."""
    m = pod.modes.shape[0]
    k = sum(len(range(*blocks[b].indices(m))) for b in separate if b in blocks)
    return tuple(range(pod.n_modes - k, pod.n_modes))


def fit_surrogate(
    runs: Runs,
    lower,
    upper,
    sigma,
    *,
    names,
    settings: SurrogateSettings = SurrogateSettings(),
    blocks: dict[str, slice] | None = None,
    design_box=None,
    checker=None,
) -> SurrogateModel:
    """POD + regression of successful training ``runs`` (no validation; see
    :func:`build_surrogate`).

    sigma  : (m,) scale of each measurement (the data's standard deviations)
    blocks : disjoint blocks of the truncation rule and of the scores (default: one block)
    """
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    s = settings
    n, m = runs.Y.shape
    if n < lower.size + 3:
        raise ValueError(
            f"only {n} successful training runs for {lower.size} parameters: need at least "
            f"{lower.size + 3} (more training points, or a smaller box)"
        )
    blocks = blocks or {"all": slice(0, m)}
    separate = tuple(b for b in s.separate if b in blocks)
    Z = (runs.X - lower) / (upper - lower)
    selection = {}
    kind = s.regression
    if kind == "auto":
        perm = np.random.default_rng(s.seed).permutation(n)
        n_sel = max(1, int(round(s.selection_fraction * n)))
        sel, fit = perm[:n_sel], perm[n_sel:]
        pod = fit_pod(
            runs.Y[fit],
            sigma,
            tol_sigma=s.tol_sigma,
            blocks=blocks,
            max_modes=s.max_modes,
            separate=separate,
        )
        A = pod.coefficients(runs.Y[fit])
        scorer = Scorer(pod.modes, blocks)
        scores = {}
        for family in ("rbf", "gp"):
            reg, _ = _fit_family(
                family, Z[fit], A, scorer, s, _separate_columns(pod, blocks, separate)
            )
            E = (pod.reconstruct(reg.predict(Z[sel])) - runs.Y[sel]) / pod.scale
            ms = scorer.scaled_ms(E)
            scores[family] = {
                "score": scorer.score(ms),
                "rms_sigma": {k: float(np.sqrt(v)) for k, v in ms.items()},
                "settings": reg.settings() if family == "rbf" else {"kind": "gp"},
            }
        kind = min(scores, key=lambda k: scores[k]["score"])
        selection = {"n_fit": len(fit), "n_selection": n_sel, "scores": scores, "chosen": kind}
    pod = fit_pod(
        runs.Y,
        sigma,
        tol_sigma=s.tol_sigma,
        blocks=blocks,
        max_modes=s.max_modes,
        separate=separate,
    )
    A = pod.coefficients(runs.Y)
    reg, extra = _fit_family(
        kind, Z, A, Scorer(pod.modes, blocks), s, _separate_columns(pod, blocks, separate)
    )
    selection.update(extra)
    box = design_box or (lower, upper)
    info = {
        "settings": s.to_dict(),
        "regression": kind,
        "n_modes": pod.n_modes,
        "pod": {
            "tol_sigma": pod.tol_sigma,
            "projection_rms_sigma": pod.projection_rms,
            "energy_fraction": pod.energy_fraction(),
            "n_snapshots": n,
        },
        "selection": selection,
        "training_hash": training_hash(runs, s.to_dict()),
        "training": runs.cost(),
        "failed": [[*map(float, x), msg] for x, msg in runs.failed],
        "infeasible": [[*map(float, x), msg] for x, msg in runs.infeasible],
    }
    return SurrogateModel(
        tuple(names),
        lower,
        upper,
        pod,
        reg,
        Z,
        (np.asarray(box[0], float), np.asarray(box[1], float)),
        checker,
        None,
        info,
    )


def runs_dir():
    """Where the training and hold-out runs of built surrogates are kept (for refits without new
    FE runs): ``<femubench cache>/surrogate_runs`` (next to the data cache, never shipped)."""
    from problems.inverse.data import cache_dir

    return cache_dir().parent / "surrogate_runs"


def keep_runs(runs: Runs, hold: Runs | None, training_hash: str, description: dict) -> str | None:
    """Save the snapshots (``X``, ``Y``, and the hold-out ``hold_X``, ``hold_Y``) as
    ``<runs_dir>/<case>__<mesh>__<training hash[:12]>.npz``; returns the path (None when it
    cannot be written)."""
    try:
        folder = runs_dir()
        folder.mkdir(parents=True, exist_ok=True)
        name = f"{description.get('case', 'model')}__{description.get('mesh', '')}"
        path = folder / f"{name}__{training_hash[:12]}.npz"
        extra = {} if hold is None else {"hold_X": hold.X, "hold_Y": hold.Y}
        np.savez(path, X=runs.X, Y=runs.Y, wall_s=runs.wall_s, **extra)
        return str(path)
    except OSError:
        return None


def merge_runs(a: Runs, b: Runs) -> Runs:
    """The runs of ``a`` then ``b`` (counts and times added)."""
    return Runs(
        np.vstack([a.X, b.X]),
        np.vstack([a.Y, b.Y]),
        np.concatenate([a.wall_s, b.wall_s]),
        a.failed + b.failed,
        a.infeasible + b.infeasible,
        a.fe_wall_s + b.fe_wall_s,
        a.elapsed_s + b.elapsed_s,
    )


def surrogate_optimum(sur: SurrogateModel, values, sigma, *, n_starts: int = 5):
    """The least-squares optimum of ``sur`` against data ``values`` with standard deviations
    ``sigma``: bounded trust-region (scipy ``least_squares``, the surrogate's exact Jacobian) from
    the ``n_starts`` training points that fit the data best. Returns ``(x, cost)``, cost = the
    sum of squared whitened residuals. Uses only the data and the surrogate (no reference)."""
    from scipy.optimize import least_squares

    values, sigma = np.asarray(values, float), np.asarray(sigma, float)
    span = sur.upper - sur.lower
    train_x = sur.lower + sur.train_z * span
    misfit = np.sum(((sur.predict(train_x) - values) / sigma) ** 2, axis=1)
    best = (None, np.inf)
    for x0 in train_x[np.argsort(misfit)[:n_starts]]:
        res = least_squares(
            lambda z: (sur.predict(sur.lower + z * span)[0] - values) / sigma,
            (x0 - sur.lower) / span,
            jac=lambda z: sur(sur.lower + z * span, jacobian=True).jacobian
            * span[None]
            / sigma[:, None],
            bounds=(0.0, 1.0),
            method="trf",
            max_nfev=200,
        )
        cost = 2.0 * res.cost
        if cost < best[1]:
            best = (sur.lower + res.x * span, cost)
    return best


def build_surrogate(
    model,
    lower,
    upper,
    sigma,
    *,
    settings: SurrogateSettings = SurrogateSettings(),
    blocks: dict[str, slice] | None = None,
    report_blocks: dict[str, slice] | None = None,
    units: dict | None = None,
    mapper=None,
    progress: bool = False,
    description: dict | None = None,
    target=None,
) -> SurrogateModel:
    """Design, run (through ``mapper``), fit and validate a surrogate of ``model`` over
    ``[lower, upper]``.

    target        : ``(values, sigma)`` of the data: with ``n_local`` and no ``center``, the
                    local design is centred on the optimum of the first-stage surrogate fitted
                    to them (two stages, see :class:`SurrogateSettings`)

    sigma         : (m,) the data's standard deviations (mm, kN for the FE model)
    blocks        : disjoint blocks of the truncation rule and of the selection score
    report_blocks : blocks of the validation (default: ``blocks``); units: their display units
    description   : what the surrogate stands for (case, mesh, data hash), kept in ``info``
    """
    import dataclasses

    t0 = time.perf_counter()
    s = settings
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    two_stage = bool(s.n_local and s.center is None)
    if two_stage and target is None:
        raise ValueError("a local design needs a centre, or the data (target) to search")
    design = make_design(
        lower,
        upper,
        s.n_train,
        seed=s.seed,
        method=s.design,
        center=s.center,
        n_local=0 if two_stage else s.n_local,
        local_scale=s.local_scale,
    )
    runs = run_points(
        model, design.X, mapper=mapper, batch=s.batch, progress=progress, desc="training"
    )
    if runs.n_ok == 0:
        reasons = [m for _, m in runs.failed[:3]] + [m for _, m in runs.infeasible[:3]]
        raise ValueError(
            f"no successful training run out of {len(design)} points: {'; '.join(reasons)}"
        )
    enrichment = None
    if two_stage:
        first = fit_surrogate(
            runs,
            lower,
            upper,
            sigma,
            names=model.names,
            settings=dataclasses.replace(
                s, regression="gp" if s.regression == "auto" else s.regression
            ),
            blocks=blocks,
            checker=model,
        )
        centre, cost0 = surrogate_optimum(first, *target)
        local = make_design(
            lower,
            upper,
            0,
            seed=[s.seed, 2],
            method=s.design,
            center=centre,
            n_local=s.n_local,
            local_scale=s.local_scale,
        )
        more = run_points(
            model,
            local.X,
            mapper=mapper,
            batch=s.batch,
            progress=progress,
            desc="enrichment",
            n_values=runs.Y.shape[1],
        )
        runs = merge_runs(runs, more)
        enrichment = {
            "centre": [float(v) for v in centre],
            "centre_cost": float(cost0),
            "local_box": [[float(v) for v in b] for b in local.local_box],
            "runs": more.cost(),
        }
    sur = fit_surrogate(
        runs,
        lower,
        upper,
        sigma,
        names=model.names,
        settings=s,
        blocks=blocks,
        design_box=design.box,
        checker=model,
    )
    info = dict(sur.info, description=description or {})
    if enrichment is not None:
        info["enrichment"] = enrichment
    cost = {"training": runs.cost()}
    variance = None
    if s.n_holdout:
        hold_design = make_design(*design.box, s.n_holdout, seed=[s.seed, 1], method=s.design)
        hold = run_points(
            model,
            hold_design.X,
            mapper=mapper,
            batch=s.batch,
            progress=progress,
            desc="hold-out",
            n_values=runs.Y.shape[1],
        )
        cost["holdout"] = hold.cost()
        val = validate(
            sur,
            hold,
            sigma,
            report_blocks or blocks or {"all": slice(0, runs.Y.shape[1])},
            units,
            model=model,
        )
        info["validation"] = val.summary()
        variance = val.variance
    cost["build_wall_s"] = time.perf_counter() - t0
    info["cost"] = cost
    info["runs_file"] = keep_runs(
        runs, hold if s.n_holdout else None, info["training_hash"], description or {}
    )
    return dataclasses.replace(sur, hold_out_variance=variance, info=info)


def build_case_surrogate(
    case,
    *,
    mesh: str = "coarse",
    data=None,
    settings: SurrogateSettings = SurrogateSettings(),
    sigma_force_kN: float = 1.0,
    mapper=None,
    progress: bool = False,
) -> SurrogateModel:
    """Surrogate of the FE forward model of ``case`` on ``mesh`` for the loading and points of
    ``data`` (default: the case's shipped data set); measurements scaled by the data's sigma. A
    local design without a centre is centred on the data set's parameters."""
    from problems.fe.mesh import discretisation_key
    from problems.inverse import layout
    from problems.inverse.cases import get_case
    from problems.inverse.data import Dataset, get_data, load
    from problems.inverse.forward import FEForwardModel

    case = get_case(case) if isinstance(case, str) else case
    if case.is_analytic:
        raise ValueError(f"case {case.name} is analytic: a surrogate is for the FE cases")
    if data is None:
        data = get_data(case.name)
    elif not isinstance(data, Dataset):
        data = load(data)
    if data.case != case.name:
        raise ValueError(f"data set is for case {data.case!r}, not {case.name!r}")
    model = FEForwardModel(case, mesh, data.settings.loading, data.points)
    N, m = len(data.snapshots_mm), len(data.points)
    all_blocks = layout.blocks(N, m)
    blocks = {k: all_blocks[k] for k in layout.BLOCK_NAMES}
    report = {k: all_blocks[k] for k in ("u_h", "u_v", "displacement", "force")}
    description = {
        "case": case.name,
        "mesh": mesh,
        "discretisation": discretisation_key(mesh),
        "data_hash": data.hash,
        "data_tier": data.settings.tier,
        "sigma_force_kN": sigma_force_kN,
        "n_snapshots": N,
        "n_points": m,
    }
    return build_surrogate(
        model,
        case.lower,
        case.upper,
        data.sigma(sigma_force_kN),
        settings=settings,
        blocks=blocks,
        report_blocks=report,
        units=FE_UNITS,
        mapper=mapper,
        progress=progress,
        description=description,
        target=(data.values, data.sigma(sigma_force_kN)),
    )

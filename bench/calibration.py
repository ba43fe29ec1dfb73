"""Calibrate a real test: identify each Drucker-Prager variant on an experiment, then report.

:func:`calibrate` imports an experiment (problems/inverse/experiment.py), and for each chosen
variant builds its lab case (bounds and start from the test, problems/inverse/lab.py) and the
objective (the FE model of the specimen on the inverse mesh, with the data's rigid-motion
removal), runs the default local method (``lm`` with exact Jacobians) from the start, and at the
optimum takes the exact Jacobian for the Laplace covariance and the Fisher information
(problems/analysis/identifiability.py). Each variant's result is written atomically to
``<out>/variants/<variant>.json`` keyed by what makes it (data hash, mesh, budget, bounds and
start): a calibration interrupted resumes with the variants not done. The report
(``report.json``, ``report.md``, ``force_displacement.png``, ``residuals.png``) ranks the
variants by AIC and BIC (``chi2 + 2 k`` and ``chi2 + k ln n``; the noise model is known, so
``-2 ln L = chi2`` up to a constant common to all variants) with Akaike weights, and gives each
variant's Laplace evidence and the posterior model probabilities
(bench/calibration_evidence.py); with a correction, the parameters and the ranking carry the
inverse model's discretisation band (:func:`with_error_band`, :func:`ranking_band`). A virtual
experiment's data mesh is never a mesh of the calibration (:func:`check_meshes`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from problems.fe.presets import spell_out
from problems.inverse import layout
from problems.inverse.data import Dataset
from problems.io.atomic import atomic_write_text

FORMAT = "femubench-calibration/1"
#: condition number of the Fisher information (in z = x / start) above which a warning is given
CONDITION_WARNING = 1e8
#: Laplace standard deviation (% of the value) above which a parameter is called poorly identified
STD_WARNING_PERCENT = 25.0
#: discretisation treatments of a calibration (:class:`CalibrationSettings`)
CORRECTIONS = ("none", "one-point", "iterated", "first-order")
#: discretisation error bands of the identified parameters (:func:`with_error_band`)
ERROR_BANDS = ("gci", "none")


@dataclass(frozen=True)
class CalibrationSettings:
    """mesh: inverse mesh spec; budget: evaluations of ``lm`` per variant; seed of the method;
    check_mesh: a finer mesh on which the best variant is run once at its optimum to state the
    inverse mesh's discretisation error next to the fit (``auto``: the next finer preset of a
    preset inverse mesh, problems/inverse/build.py; ``""``: none);
    correction: ``none``; ``one-point``: the discretisation error at the untreated optimum, from
    one run on ``check_mesh``, subtracted from the data and the problem re-solved once;
    ``iterated``: the same, repeated at each new optimum until the parameters move less than
    0.1 % (at most ``correction_rounds`` rounds; solvers/corrected.py); ``first-order``: the
    iterated correction made first-order consistent (each round also subtracts
    ``(J_fine - J_inverse)(x - x_k)``, exact Jacobians of both meshes at the round's start ``x_k``;
    its fixed point is the check mesh's own optimum). Do not use the mesh that
    made a virtual experiment's data as ``check_mesh``;
    error_band: ``gci`` (default): with a correction, each parameter's discretisation band
    (:func:`problems.analysis.convergence.gci_band` from the untreated and the corrected
    estimate) stated next to the fit and added to the Laplace 95 % half-width
    (:func:`with_error_band`); ``none``: Laplace intervals alone."""

    mesh: str = "coarse"
    budget: int = 80
    seed: int = 0
    check_mesh: str = "auto"
    correction: str = "none"
    correction_rounds: int = 5
    error_band: str = "gci"

    def __post_init__(self):
        if self.correction not in CORRECTIONS:
            raise ValueError(
                f"--correction {self.correction!r} is unknown; allowed: {', '.join(CORRECTIONS)}"
            )
        if self.error_band not in ERROR_BANDS:
            raise ValueError(
                f"--error-band {self.error_band!r} is unknown; allowed: {', '.join(ERROR_BANDS)}"
            )
        if self.correction != "none" and not self.fine_mesh:
            raise ValueError(
                f"--correction {self.correction} needs a finer mesh: --check-mesh "
                f"{self.check_mesh or 'none'} names none for inverse mesh {self.mesh!r}"
            )

    @property
    def fine_mesh(self) -> str:
        """The finer mesh of the discretisation check and correction ('' for none)."""
        from problems.inverse.build import hifi_mesh_for

        if self.check_mesh == "auto":
            try:
                return hifi_mesh_for(self.mesh)
            except ValueError:
                return ""
        return self.check_mesh


def check_meshes(data_mesh: str, settings: CalibrationSettings) -> None:
    """ValueError (one line naming the option) when the inverse mesh or the finer mesh of the
    check or correction is the discretisation that made a virtual experiment's data
    (``data_mesh``; "" for a real test: nothing to check): the honesty rule."""
    if not data_mesh:
        return
    from problems.fe.mesh import discretisation_key

    made = discretisation_key(data_mesh)
    named = [("--mesh", settings.mesh, settings.mesh)]
    if settings.fine_mesh:
        shown = f"auto (= {settings.fine_mesh})" if settings.check_mesh == "auto" else None
        named.append(("--check-mesh", shown or settings.fine_mesh, settings.fine_mesh))
    for option, shown, mesh in named:
        if discretisation_key(mesh) == made:
            raise ValueError(
                f"{option} {shown}: the discretisation {made} made this virtual experiment's data "
                f"([virtual] data_mesh = {data_mesh!r}); no model of a calibration may use it "
                "(the honesty rule): choose another mesh"
            )


def model_for(data: Dataset, case, mesh: str):
    """The FE model of the specimen of ``data`` on ``mesh`` at its points and machine loading,
    with the data's rigid-motion removal applied."""
    from problems.inverse.experiment import rigid_free_model
    from problems.inverse.forward import FEForwardModel

    fe = FEForwardModel(
        case, mesh, data.settings.loading, data.points, specimen_mm=data.settings.specimen_mm
    )
    return rigid_free_model(fe, data)


def objective_for(data: Dataset, case, mesh: str, correction=None):
    """The evaluator of ``case`` (a lab case) on the imported ``data``: :func:`model_for`, the
    data's noise model (:meth:`Dataset.noise`: per-point and per-force standard deviations, the
    points' correlation between snapshots); with a ``correction``
    (problems/inverse/model_error.py) its shift subtracted from the data (and a first-order
    correction's ``slope (x - anchor)``: :func:`~problems.inverse.model_error.corrected_model`)
    and its runs charged."""
    from problems.inverse.evaluator import Evaluator
    from problems.inverse.model_error import corrected_model
    from problems.inverse.problem import LeastSquaresProblem

    model = corrected_model(model_for(data, case, mesh), correction)
    shift = 0.0 if correction is None else correction.shift
    problem = LeastSquaresProblem(
        model,
        data.values - shift,
        case.lower,
        case.upper,
        case.reference,
        **data.noise(),
        blocks=layout.blocks(len(data.snapshots_mm), len(data.points)),
        provenance={
            "case": case.name,
            "data_tier": data.settings.tier,
            "data_hash": data.hash,
            "inverse_mesh": mesh,
        },
    )
    evaluator = Evaluator(problem, exact_jacobian=True)
    if correction is not None:
        evaluator.charge("hifi", correction.n_hifi, correction.hifi_wall_s)
        evaluator.charge("inverse-for-correction", correction.n_inverse, correction.inverse_wall_s)
    return evaluator


def done_before(path: Path, key: str) -> dict | None:
    """The JSON record at ``path`` when it holds ``key`` (a resumable result of the same inputs),
    else None: missing, torn or made from other inputs."""
    try:
        old = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return None
    return old if isinstance(old, dict) and old.get("key") == key else None


def variant_key(data: Dataset, case, settings: CalibrationSettings) -> str:
    """Hash of what makes one variant's result: data, case box and start, mesh, budget, seed."""
    body = {
        "data": data.hash,
        "variant": case.name,
        "lower": case.lower.tolist(),
        "upper": case.upper.tolist(),
        "start": case.start.tolist(),
        "mesh": spell_out(settings.mesh),  # a re-pointed preset is another model
        "budget": settings.budget,
        "seed": settings.seed,
        **({"correction": spell_out(settings.fine_mesh)} if settings.correction != "none" else {}),
        **(
            {"treatment": settings.correction}
            if settings.correction in ("one-point", "first-order")
            else {}
        ),
    }
    return hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()[:16]


def calibrate_variant(data: Dataset, case, settings: CalibrationSettings) -> dict:
    """Identify ``case`` on ``data`` (``lm`` from ``case.start``), then the Laplace covariance,
    the Fisher information and the fit at the optimum, as a JSON-ready dict."""
    from bench.calibration_evidence import laplace_log_evidence
    from problems.analysis.identifiability import analyse_jacobian
    from solvers import solve

    ev = objective_for(data, case, settings.mesh)
    result = solve(ev, "lm", budget=settings.budget, seed=settings.seed, x0=case.start)
    rounds, first, untreated, chi2_untreated = [], 0, None, None
    if settings.correction != "none" and result.cost < math.inf:
        first = result.n_evals  # the uncorrected run the rounds start from
        untreated = [float(v) for v in result.x]
        chi2_untreated = float(result.cost)  # the evaluator's cost is R^T R = chi2 (no 1/2)
        from problems.inverse.model_error import first_order, one_point
        from solvers.corrected import solve_iterated

        fine, coarse = (
            model_for(data, case, settings.fine_mesh),
            model_for(data, case, settings.mesh),
        )
        built = []

        def make_objective(correction):
            built.append(objective_for(data, case, settings.mesh, correction))
            return built[-1]

        result = solve_iterated(
            make_objective,
            lambda x: (first_order if settings.correction == "first-order" else one_point)(
                fine, coarse, x
            ),
            "lm",
            budget=settings.budget,
            x0=result.x,
            seed=settings.seed,
            max_rounds=1 if settings.correction == "one-point" else settings.correction_rounds,
        )
        ev, rounds = built[-1], result.extra["correction_rounds"]
    solved = ev.n_evals  # the run's evaluations on the last objective (in result.n_evals)
    x = np.asarray(result.x, float)
    z = ev.to_scaled(x)
    J = ev.jacobian(z)
    best = ev.evaluate(z)
    n_evals = first + result.n_evals + ev.n_evals - solved  # every run, the final Jacobian
    out = {
        "variant": case.name,
        "names": list(case.names),
        "units": [p.unit for p in case.parameters],
        "start": case.start.tolist(),
        "lower": case.lower.tolist(),
        "upper": case.upper.tolist(),
        "status": result.status,
        "message": result.message,
        "n_evals": int(n_evals),
        "wall_s": float(result.wall_s),
        "ok": bool(best.usable),
        "correction": settings.correction,
        "correction_rounds": rounds,
        "n_fine_runs": len(rounds),
        "fine_mesh": settings.fine_mesh if rounds else "",
        # the untreated optimum on the inverse mesh: the coarser estimate of the error band
        "x_untreated": untreated,
    }
    if chi2_untreated is not None:  # its fit on the raw data: the ranking's coarser estimate
        out |= untreated_fit(chi2_untreated, len(untreated))
    if not best.usable:
        return out | {"x": x.tolist(), "chi2": math.inf}
    ident = analyse_jacobian(J, ev.reference, x=x, names=case.names)
    chi2 = float(best.cost)
    n_data, k = len(best.residual), len(x)
    # a fit worse than the noise model (model error) widens the intervals by the Birge ratio
    birge = max(1.0, math.sqrt(chi2 / max(n_data - k, 1)))
    std = ident.std_x * birge
    N, m = len(data.snapshots_mm), len(data.points)
    r = best.residual
    split = {k: float(np.sum(r[s] ** 2)) for k, s in layout.blocks(N, m).items()}
    counts = {k: len(range(len(r))[s]) for k, s in layout.blocks(N, m).items()}
    model_values = data.values - r * data.sigma()  # the model (plus a correction's shift)
    _, _, model_force = layout.unstack(model_values, N, m)
    warnings = list(ident.warnings)
    if ident.condition > CONDITION_WARNING:
        warnings.append(
            f"Fisher information condition number {ident.condition:.3g} > "
            f"{CONDITION_WARNING:g}: weakest direction "
            + ", ".join(f"{k} {v:+.2f}" for k, v in ident.weakest.items() if abs(v) > 0.2)
        )
    std_pct = 100.0 * std / np.abs(x)
    poor = [f"{n} ({s:.3g} %)" for n, s in zip(case.names, std_pct) if s > STD_WARNING_PERCENT]
    if poor:
        warnings.append(
            f"poorly identified (Laplace sd > {STD_WARNING_PERCENT:g} %): " + ", ".join(poor)
        )
    at_bound = [
        n
        for n, v, lo, hi in zip(case.names, x, case.lower, case.upper)
        if min(v - lo, hi - v) <= 1e-6 * (hi - lo)
    ]
    if at_bound:
        warnings.append(f"at a bound of its box: {', '.join(at_bound)}")
    return out | {
        "x": x.tolist(),
        "std": std.tolist(),
        "std_noise_only": ident.std_x.tolist(),
        "birge_ratio": birge,
        "std_percent": std_pct.tolist(),
        "ci95_lower": (x - 1.96 * std).tolist(),
        "ci95_upper": (x + 1.96 * std).tolist(),
        "correlation": np.nan_to_num(ident.correlation).tolist(),
        "condition": float(ident.condition),
        "warnings": warnings,
        "chi2": chi2,
        "n_data": n_data,
        "rms_sigma": math.sqrt(chi2 / n_data),
        "rms_sigma_blocks": {b: math.sqrt(split[b] / counts[b]) for b in ("u_h", "u_v", "force")},
        "aic": chi2 + 2 * k,
        "bic": chi2 + k * math.log(n_data),
        "evidence": laplace_log_evidence(chi2, ident.fisher_x, x, case.lower, case.upper),
        "model_force_kN": model_force.tolist(),
        "residual_last_sigma": {
            "u_h": layout.unstack(r, N, m)[0][-1].tolist(),
            "u_v": layout.unstack(r, N, m)[1][-1].tolist(),
        },
    }


def untreated_fit(chi2_untreated: float, k: int) -> dict:
    """The untreated optimum's fit to the raw data: ``chi2_untreated`` and its AIC
    (``chi2 + 2 k``, as the corrected fit's), the coarser estimate of :func:`ranking_band`."""
    return {"chi2_untreated": chi2_untreated, "aic_untreated": chi2_untreated + 2 * k}


def backfill_untreated(path: Path, result: dict, objective) -> dict:
    """A stored variant ``result`` written before :func:`calibrate_variant` kept the untreated
    fit (it holds ``x_untreated`` but no ``chi2_untreated``) gets it from one forward
    evaluation of ``objective()`` (the variant's evaluator on the inverse mesh and the raw data,
    :func:`objective_for`) at ``x_untreated``, written back atomically to ``path`` so that it
    is done once. Any other result is returned unchanged, with no evaluation."""
    untreated = result.get("x_untreated")
    if not untreated or "chi2_untreated" in result or not result.get("ok"):
        return result
    ev = objective()
    e = ev.evaluate(ev.to_scaled(np.asarray(untreated, float)))
    chi2 = float(e.cost) if e.usable else math.inf
    result = result | untreated_fit(chi2, len(untreated))
    atomic_write_text(path, json.dumps(result, indent=1, allow_nan=True) + "\n")
    return result


def with_error_band(result: dict, settings: CalibrationSettings) -> dict:
    """A variant's ``result`` with the discretisation error of its inverse model stated and
    used (docs/calibrating.md, "Discretisation error band").

    With ``settings.error_band == "gci"`` and a correction that ran (the result holds the
    untreated optimum ``x_untreated`` on the inverse mesh and the corrected ``x``, which stands
    for the estimate on the finer mesh ``fine_mesh``): per parameter the band
    ``U = gci_band(x_untreated, x, r, p)`` (r from the two meshes' element counts, p the
    inverse mesh family's order and the safety factor of :mod:`problems.analysis.convergence`),
    and the 95 % interval
    ``x +- (1.96 sd + U)``: the Laplace half-width (noise, Birge-widened) and the band added,
    not in quadrature (the band is a bound on a bias, not an independent noise). The Laplace
    interval alone is kept as ``ci95_laplace_lower/upper``. Otherwise the result unchanged
    (``band`` says why). Values in the parameters' units."""
    from problems.analysis.convergence import GCI_SAFETY, gci_band, gci_order, refinement_ratio

    if not result.get("ok") or "std" not in result:
        return result
    if settings.error_band == "none":
        return result | {"band": {"method": "none", "reason": "turned off (--error-band none)"}}
    untreated = result.get("x_untreated")
    if not untreated or not result.get("fine_mesh"):
        return result | {
            "band": {"method": "none", "reason": "no correction ran: one estimate only"}
        }
    x, std = np.asarray(result["x"], float), np.asarray(result["std"], float)
    r = refinement_ratio(settings.mesh, result["fine_mesh"])
    p = gci_order(settings.mesh)
    u = gci_band(untreated, x, r, p)
    half = 1.96 * std + u
    return result | {
        "band": {
            "method": "gci",
            "order": p,
            "safety": GCI_SAFETY,
            "ratio": r,
            "inverse_mesh": settings.mesh,
            "fine_mesh": result["fine_mesh"],
        },
        "band_abs": u.tolist(),
        "band_percent": (100.0 * u / np.abs(x)).tolist(),
        "ci95_laplace_lower": result["ci95_lower"],
        "ci95_laplace_upper": result["ci95_upper"],
        "ci95_lower": (x - half).tolist(),
        "ci95_upper": (x + half).tolist(),
    }


def calibrate(
    experiment_path,
    out_dir,
    *,
    models=None,
    settings: CalibrationSettings | None = None,
    progress=print,
    figures: bool = True,
    mcmc: McmcSettings | None = None,
    mcmc_models="best",
    plate_margin_mm=None,
) -> dict:
    """Calibrate every chosen variant of the experiment at ``experiment_path`` into ``out_dir``
    (module docstring); returns the report dict. ``models``: variant names (default: the
    experiment file's ``[calibration] models``); ``settings`` default from the file too. Variants
    whose result is already in ``out_dir`` with the same key are read, not rerun. ``figures``:
    draw the figures (else report.md and report.json only). ``mcmc``: run
    :func:`mcmc_variant` on ``mcmc_models`` (``best``: the first by AIC, ``all``, or a list of
    variants), each kept in ``<out>/variants/<variant>.mcmc.json`` keyed like the variant.
    ``plate_margin_mm``: the plate margin, mm, or ``"auto"``
    (:func:`problems.inverse.build.auto_plate_margin_mm`), in place of the file's
    ``[calibration] plate_margin_mm`` (None: the file's); the points it leaves out change the
    data's hash, so a calibration of another margin never reads these results."""
    from problems.inverse.experiment import import_experiment, load_experiment
    from problems.inverse.lab import curve_summary, lab_case

    exp = load_experiment(experiment_path)
    if plate_margin_mm is not None:
        from problems.inverse.build import resolve_plate_margin

        try:
            margin = resolve_plate_margin(
                plate_margin_mm, (exp.width_mm, exp.depth_mm, exp.height_mm)
            )
        except ValueError as exc:
            raise ValueError(f"--plate-margin-mm {plate_margin_mm!r}: {exc}") from None
        exp = dataclasses.replace(exp, plate_margin_mm=margin)
    out = Path(out_dir)
    if out.resolve() in (exp.path.parent, exp.log.parent, *(f.parent for f in exp.dic_files)):
        raise ValueError(
            f"--out {out_dir}: the folder of the experiment's files; outputs never go among the "
            "inputs (name a new folder)"
        )
    settings = settings or CalibrationSettings(exp.mesh, exp.budget)
    check_meshes(exp.data_mesh, settings)
    if mcmc is not None and settings.correction != "none":
        raise ValueError(
            f"--mcmc with --correction {settings.correction}: the posterior of corrected data "
            "is not supported (allowed: --correction none)"
        )
    models = list(models or exp.models)
    data = import_experiment(exp)
    summary = curve_summary(data)
    results = {}
    for name in models:
        case = lab_case(name, data, summary)
        key = variant_key(data, case, settings)
        path = out / "variants" / f"{name}.json"
        old = done_before(path, key)
        if old is not None:
            progress(f"{name}: done before ({path})")
            if old.get("x_untreated") and "chi2_untreated" not in old and old.get("ok"):
                progress(f"{name}: chi2 of the untreated optimum on the raw data (one run) ...")
            results[name] = backfill_untreated(
                path, old, lambda case=case: objective_for(data, case, settings.mesh)
            )
            continue
        progress(f"{name}: identifying from the test's start on mesh {settings.mesh} ...")
        res = calibrate_variant(data, case, settings) | {"key": key}
        atomic_write_text(path, json.dumps(res, indent=1, allow_nan=True) + "\n")
        results[name] = res
        progress(
            f"{name}: chi2 {res['chi2']:.6g}, rms {res.get('rms_sigma', math.nan):.3g} sigma, "
            f"{res['n_evals']} evaluations"
        )
    results = {name: with_error_band(res, settings) for name, res in results.items()}
    report = assemble(exp, data, summary, results, settings)
    if report["ranking_band"].get("warning"):
        progress(f"warning: {report['ranking_band']['warning']}")
    if mcmc is not None and report["ranking"]:
        ranked = [r["variant"] for r in report["ranking"]]
        chosen = (
            ranked[:1]
            if mcmc_models == "best"
            else ranked
            if mcmc_models == "all"
            else [n for n in mcmc_models if n in ranked]
        )
        chains = {}
        for name in chosen:
            case = lab_case(name, data, summary)
            key = (
                variant_key(data, case, settings)
                + "|"
                + json.dumps(dataclasses.asdict(mcmc), sort_keys=True)
            )
            path = out / "variants" / f"{name}.mcmc.json"
            old = _read_json(path)
            if old.get("key") == key:
                progress(f"{name}: MCMC done before ({path})")
                chains[name] = old
                continue
            progress(f"{name}: MCMC ({mcmc.forward}, {mcmc.n_steps} steps) ...")
            chains[name] = mcmc_variant(data, case, results[name], settings, mcmc) | {"key": key}
            atomic_write_text(path, json.dumps(chains[name], indent=1, allow_nan=True) + "\n")
            c = chains[name]
            progress(
                f"{name}: MCMC log Z {c['log_evidence_bridge']:.6g} (Laplace "
                f"{c['log_evidence_laplace']:.6g}), tau multiple {c['tau_multiple']:.3g}"
            )
        add_mcmc(report, chains)
    if report["ranking"] and settings.check_mesh:
        best = report["ranking"][0]["variant"]
        report["discretisation"] = discretisation_check(
            data, lab_case(best, data, summary), results[best], settings, out, progress
        )
    write_report(report, data, out, figures=figures)
    return report


@dataclass(frozen=True)
class McmcSettings:
    """MCMC on a calibrated variant (bench/calibration_evidence.py).

    forward   : ``fe`` (the inverse mesh's FE model at every draw: for small models) or
                ``surrogate`` (a POD + regression surrogate of it, problems/surrogate, trained by
                ``n_train`` FE runs in the local box and validated by ``n_holdout``)
    n_walkers, n_steps : emcee's ensemble (0 walkers: max(16, 2 k + 2)) and steps, half burnt
    n_bridge  : proposal draws of the bridge-sampling evidence (log posterior evaluations)
    local_sd  : the sampled box is the prior box cut to the optimum +- local_sd Laplace standard
                deviations (Birge-widened); the prior's volume stays the whole box's
    """

    forward: str = "surrogate"
    n_walkers: int = 0
    n_steps: int = 2000
    n_bridge: int = 2000
    n_train: int = 120
    n_holdout: int = 30
    local_sd: float = 8.0
    seed: int = 0

    def __post_init__(self):
        if self.forward not in ("fe", "surrogate"):
            raise ValueError(f"--mcmc-forward {self.forward!r} is unknown; allowed: fe, surrogate")


def mcmc_variant(data: Dataset, case, result: dict, settings, mcmc: McmcSettings) -> dict:
    """emcee on ``case``'s posterior (uniform prior on its box, the data's noise model; the
    uncorrected data) around the calibrated ``result``, its 95 % intervals against Laplace's,
    and the bridge-sampling evidence against the Laplace evidence (same convention: the
    prior's density is 1 / volume of the whole box, the noise normalisation left out)."""
    from bench.calibration_evidence import (
        bridge_log_evidence,
        posterior_summary,
        sample_posterior,
    )

    problem = objective_for(data, case, settings.mesh).problem
    lo_box, hi_box = np.asarray(case.lower, float), np.asarray(case.upper, float)
    log_volume = float(np.sum(np.log(hi_box - lo_box)))
    x = np.asarray(result["x"], float)
    std = np.asarray(result["std"], float)
    lo = np.maximum(lo_box, x - mcmc.local_sd * std)
    hi = np.minimum(hi_box, x + mcmc.local_sd * std)
    out = {"forward": mcmc.forward, "local_box": [lo.tolist(), hi.tolist()]}
    if mcmc.forward == "surrogate":
        from problems.surrogate.build import SurrogateSettings, build_surrogate

        N, m = len(data.snapshots_mm), len(data.points)
        sur = build_surrogate(
            problem.model,
            lo,
            hi,
            data.sigma(),
            settings=SurrogateSettings(
                n_train=mcmc.n_train, n_holdout=mcmc.n_holdout, seed=mcmc.seed
            ),
            blocks=layout.blocks(N, m),
            description={"case": case.name, "mesh": settings.mesh, "data_hash": data.hash},
        )
        val = (sur.info.get("validation") or {}).get("blocks") or {}
        out["surrogate"] = {
            "n_train": mcmc.n_train,
            "n_holdout": mcmc.n_holdout,
            "holdout_rms_sigma": {b: v.get("rms_sigma") for b, v in val.items()},
            "build_wall_s": sur.info.get("cost", {}).get("build_wall_s"),
        }

        def values(X):
            return sur.predict(X)
    else:

        def values(X):
            rows = []
            for xi in X:
                res = problem.model(xi)
                rows.append(res.values if res.ok else np.full(problem.data.shape, np.nan))
            return np.array(rows)

    def log_post(X):
        X = np.atleast_2d(X)
        lp = np.full(len(X), -np.inf)
        ok = [
            i
            for i, xi in enumerate(X)
            if np.all((xi >= lo) & (xi <= hi)) and problem.check(xi) is None
        ]
        if ok:
            R = problem.whiten((problem.data[None, :] - values(X[ok])).T)
            chi2 = np.sum(R * R, axis=0)
            lp[ok] = np.where(np.isfinite(chi2), -0.5 * chi2 - log_volume, -np.inf)
        return lp

    sd0 = np.asarray(result["std_noise_only"], float)
    cov0 = np.asarray(result["correlation"], float) * np.outer(sd0, sd0)
    chain = sample_posterior(
        log_post,
        x,
        cov0,
        lo,
        hi,
        n_walkers=mcmc.n_walkers,
        n_steps=mcmc.n_steps,
        seed=mcmc.seed,
    )
    rng = np.random.default_rng([mcmc.seed, 1])
    bridge = bridge_log_evidence(
        chain["log_prob"], chain["samples"], log_post, rng, n_proposal=mcmc.n_bridge
    )
    summary = posterior_summary(case.names, chain["samples"])
    laplace = laplace_evidence(result)["log_evidence"]
    # a surrogate's chi2 is offset from the FE model's; at the optimum and at the best draw the
    # FE model tells a surrogate's error from an optimum short of the posterior's mode
    best = chain["samples"][int(np.argmax(chain["log_prob"]))]
    fe_chi2 = []
    for xi in (x, best):
        res = problem.model(xi)
        r, _ = problem.residual(res.values if res.ok else None)
        fe_chi2.append(math.inf if r is None else float(r @ r))
    sampled_chi2_opt = float(-2.0 * (log_post(x[None, :])[0] + log_volume))
    return out | {
        **{k: v for k, v in chain.items() if k not in ("samples", "log_prob")},
        "converged": chain["tau_multiple"] >= 50.0,
        **summary,
        # a draw fitting better than the optimum by more than a unit of chi2: lm stopped short
        # of the posterior's mode (or the surrogate errs there)
        "chi2_best_draw": float(-2.0 * (np.max(chain["log_prob"]) + log_volume)),
        "chi2_best_draw_fe": fe_chi2[1],
        "chi2_optimum": result["chi2"],
        "chi2_optimum_fe": fe_chi2[0],
        "chi2_optimum_sampled": sampled_chi2_opt,
        "laplace_sd_noise_only": sd0.tolist(),
        "sd_ratio": (np.asarray(summary["sd"]) / sd0).tolist(),
        "bridge": bridge,
        "log_evidence_bridge": bridge["log_evidence"],
        "log_evidence_laplace": laplace,
        "evidence_difference": bridge["log_evidence"] - laplace,
        # the difference with the sampled model's chi2 offset at the optimum taken out
        "evidence_difference_offset_removed": bridge["log_evidence"]
        - laplace
        - 0.5 * (fe_chi2[0] - sampled_chi2_opt),
    }


def discretisation_check(data, case, result, settings, out: Path, progress) -> dict:
    """The inverse mesh's discretisation error at the best fit: the best variant's response on a
    finer mesh minus the inverse mesh's, in sigma units (rms over each block); stored in
    ``<out>/variants/discretisation.json`` keyed like a variant. ``{}`` when no finer mesh."""
    fine = settings.fine_mesh
    if not fine or not result.get("ok"):
        return {}
    key = variant_key(data, case, settings) + f"|{fine}"
    path = out / "variants" / "discretisation.json"
    if path.exists():
        try:
            old = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError):
            old = {}
        if old.get("key") == key:
            return old
    progress(f"discretisation error: {case.name} at its optimum on mesh {fine} ...")
    x = np.asarray(result["x"], float)
    values = {}
    for mesh in (settings.mesh, fine):
        res = model_for(data, case, mesh)(x)
        if not res.ok:
            return {"mesh": fine, "message": res.message}
        values[mesh] = res.values
    d = (values[fine] - values[settings.mesh]) / data.sigma()
    N, m = len(data.snapshots_mm), len(data.points)
    blocks = layout.blocks(N, m)
    out_d = {
        "key": key,
        "variant": case.name,
        "mesh": fine,
        "rms_sigma": float(np.sqrt(np.mean(d**2))),
        "rms_sigma_blocks": {
            b: float(np.sqrt(np.mean(d[blocks[b]] ** 2))) for b in ("u_h", "u_v", "force")
        },
    }
    atomic_write_text(path, json.dumps(out_d, indent=1) + "\n")
    return out_d


def laplace_evidence(result: dict) -> dict:
    """The Laplace evidence of a variant's result (bench/calibration_evidence.py); results
    written before it was stored get it from their stored noise-only covariance (the inverse of
    the Fisher information, full rank) and box."""
    if "evidence" in result:
        return result["evidence"]
    from bench.calibration_evidence import laplace_log_evidence

    sd = np.asarray(result["std_noise_only"], float)
    cov = np.asarray(result["correlation"], float) * np.outer(sd, sd)
    return laplace_log_evidence(
        result["chi2"], np.linalg.inv(cov), result["x"], result["lower"], result["upper"]
    )


def _read_json(path: Path) -> dict:
    """A stored JSON object, ``{}`` when missing or torn."""
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return {}


def add_mcmc(report: dict, chains: dict) -> None:
    """The MCMC results into the report: ``mcmc`` per variant, each ranking row's bridge log
    evidence, and the posterior model probabilities from the bridge evidences when every ranked
    variant has one."""
    from bench.calibration_evidence import model_probabilities

    report["mcmc"] = chains
    for row in report["ranking"]:
        c = chains.get(row["variant"])
        row["log_evidence_bridge"] = c["log_evidence_bridge"] if c else None
    if chains and all(row["log_evidence_bridge"] is not None for row in report["ranking"]):
        p = model_probabilities({r["variant"]: r["log_evidence_bridge"] for r in report["ranking"]})
        for row in report["ranking"]:
            row["model_probability_bridge"] = p[row["variant"]]


def assemble(exp, data: Dataset, summary: dict, results: dict, settings) -> dict:
    """The report dict: experiment, import, heuristics, each variant, model selection."""
    from bench.calibration_evidence import model_probabilities

    ok = {k: v for k, v in results.items() if v.get("ok") and math.isfinite(v["chi2"])}
    ranking = []
    if ok:
        aic_min = min(v["aic"] for v in ok.values())
        w = {k: math.exp(-0.5 * (v["aic"] - aic_min)) for k, v in ok.items()}
        total = sum(w.values())
        log_z = {k: laplace_evidence(v)["log_evidence"] for k, v in ok.items()}
        prob = model_probabilities(log_z)
        z_max = max(log_z.values())
        for name in sorted(ok, key=lambda k: ok[k]["aic"]):
            v = ok[name]
            ranking.append(
                {
                    "variant": name,
                    "aic": v["aic"],
                    "bic": v["bic"],
                    "delta_aic": v["aic"] - aic_min,
                    "akaike_weight": w[name] / total,
                    "log_evidence": log_z[name],
                    "delta_log_evidence": log_z[name] - z_max,
                    "model_probability": prob[name],
                    "chi2": v["chi2"],
                    "rms_sigma": v["rms_sigma"],
                }
            )
    band = ranking_band(ranking, ok, settings)
    meta = data.meta
    return {
        "format": FORMAT,
        "experiment": exp.name,
        "description": exp.description,
        "specimen_mm": {"width": exp.width_mm, "depth": exp.depth_mm, "height": exp.height_mm},
        "platens": exp.platens,
        "inverse_mesh": settings.mesh,
        "budget": settings.budget,
        "data_hash": data.hash,
        "import": {
            k: meta[k]
            for k in (
                "files_sha256",
                "calibration",
                "points_read",
                "dropped_not_in_every_image",
                "dropped_off_face",
                "plate_margin_mm",  # with a margin alone
                "dropped_plate_margin",
                "dropped_non_finite_rows",
                "images_used",
                "rigid_motion_removed",
                "force_accuracy_percent",
                "correlation",  # the [images] route only
            )
            if k in meta
        }
        | {
            "points_used": len(data.points),
            "images": len(data.snapshots_mm),
            "snapshot_rho": data.snapshot_rho,
        },
        "test": summary,
        "displacement_mm": data.snapshots_mm.tolist(),
        "force_kN": data.reaction_kN.tolist(),
        "force_sigma_kN": np.asarray(data.std_force_kN).tolist(),
        "variants": results,
        "ranking": ranking,
        "ranking_band": band,
    }


def ranking_band(ranking: list[dict], results: dict, settings) -> dict:
    """The discretisation band of the model ranking (docs/calibrating.md, "Reading the
    report"), by the rule of the parameters' band (:func:`with_error_band`): a correction gives
    two rankings, the corrected AICs (standing for the finer check mesh) and the untreated AICs
    on the inverse mesh (``aic_untreated``). For each variant behind the first (by the
    corrected AIC) its ``delta_aic`` and ``delta_aic_untreated`` (both against the first), the
    band ``U = GCI_SAFETY |delta_aic - delta_aic_untreated| / (r^p - 1)`` with the parameters'
    r and p (:func:`problems.analysis.convergence.gci_band`), and ``resolved``: ``delta_aic > U``.
    The rows of ``ranking`` get ``delta_aic_untreated``, ``band_delta_aic`` and ``resolved``
    (None for the first and without a band); returns the band's description, with a
    ``warning`` when the first is not resolved from the second (the model probabilities are
    then conditional on the inverse model: ``probabilities_conditional``). Without a
    correction, one ranking only: no band (``reason`` says why). AIC units (chi2)."""
    from problems.analysis.convergence import GCI_SAFETY, gci_band, gci_order, refinement_ratio

    for row in ranking:
        row |= {"delta_aic_untreated": None, "band_delta_aic": None, "resolved": None}
    reason = ""
    if settings.error_band == "none":
        reason = "turned off (--error-band none)"
    elif not ranking or any(not results[r["variant"]].get("fine_mesh") for r in ranking):
        reason = "no correction ran: one estimate only"
    else:
        lacking = [
            r["variant"]
            for r in ranking
            if not math.isfinite(results[r["variant"]].get("aic_untreated", math.nan))
        ]
        if lacking:
            reason = f"no finite untreated fit of {', '.join(lacking)}"
    if reason:
        return {"method": "none", "reason": reason, "probabilities_conditional": False}
    fine = results[ranking[0]["variant"]]["fine_mesh"]
    r, p = refinement_ratio(settings.mesh, fine), gci_order(settings.mesh)
    first = ranking[0]
    first_u = results[first["variant"]]["aic_untreated"]
    for row in ranking[1:]:
        d_u = results[row["variant"]]["aic_untreated"] - first_u
        u = float(gci_band(d_u, row["delta_aic"], r, p))
        row |= {"delta_aic_untreated": d_u, "band_delta_aic": u, "resolved": row["delta_aic"] > u}
    out = {
        "method": "gci",
        "order": p,
        "safety": GCI_SAFETY,
        "ratio": r,
        "inverse_mesh": settings.mesh,
        "fine_mesh": fine,
        "warning": None,
        "probabilities_conditional": False,
    }
    if len(ranking) > 1 and not ranking[1]["resolved"]:
        from problems.inverse.model_error import ITERATED

        second = ranking[1]
        todo = (
            "refine the inverse mesh"
            if settings.correction in ITERATED
            else "refine the inverse mesh or use --correction iterated"
        )
        out |= {
            "warning": f"{first['variant']} vs {second['variant']}: dAIC "
            f"{second['delta_aic']:.3g} within the discretisation band "
            f"{second['band_delta_aic']:.3g}: not resolved by this inverse model; {todo}",
            "probabilities_conditional": True,
        }
    return out


def write_report(report: dict, data: Dataset, out: Path, *, figures: bool = True) -> None:
    """``report.json``, ``report.md`` and (with ``figures``) the figures into ``out`` (atomic
    writes)."""
    from bench.plotting import line_style, pyplot, save

    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "report.json", json.dumps(report, indent=1, allow_nan=True) + "\n")
    atomic_write_text(out / "report.md", render_markdown(report))
    if not figures:
        return
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.0, 4.0))
    d = np.array(report["displacement_mm"])
    ax.errorbar(
        d,
        report["force_kN"],
        yerr=2 * np.array(report["force_sigma_kN"]),
        fmt="ko",
        label="measured (2 sd)",
        zorder=3,
    )
    for i, row in enumerate(report["ranking"][:4]):
        v = report["variants"][row["variant"]]
        style = line_style(i) | {"marker": None}
        ax.plot(
            d, v["model_force_kN"], label=f"{row['variant']} (dAIC {row['delta_aic']:.3g})", **style
        )
    ax.set_xlabel("plate displacement (mm)")
    ax.set_ylabel("force (kN)")
    ax.legend(fontsize=7)
    save(fig, out / "force_displacement.png")
    if report["ranking"]:
        best = report["variants"][report["ranking"][0]["variant"]]
        s = np.array(data.meta["face_s_mm"])
        rho = report["import"].get("snapshot_rho")  # correlated: R^-1/2 D^-1, not r / sigma
        what = f"whitened residual (rho {rho:g})" if rho else "residual / sigma"
        fig, axes = plt.subplots(1, 2, figsize=(8.0, 3.6))
        for ax, comp in zip(axes, ("u_h", "u_v")):
            r = np.array(best["residual_last_sigma"][comp])
            sc = ax.scatter(s, data.points[:, 1], c=r, cmap="RdBu_r", vmin=-3, vmax=3, s=12)
            ax.set_title(f"{comp} {what}, last image")
            ax.set_xlabel("s (mm)")
            ax.set_aspect("equal")
        axes[0].set_ylabel("z (mm)")
        fig.colorbar(sc, ax=axes)
        save(fig, out / "residuals.png")


def _correlation_lines(c: dict | None) -> list[str]:
    """The report's line on the DIC of the ``[images]`` route (none for a DIC export)."""
    if not c:
        return []
    return [
        f"- DIC of the images (femubench, IC-GN): subsets {c['subset_px']} px every "
        f"{c['step_px']} px in ROI {c['roi_px']}, {c['subsets_correlated']} on the face "
        f"({c['subsets_off_face']} off it), not converged per image "
        f"{c['not_converged_per_image']}, grey-level noise "
        f"{min(c['grey_noise_per_image']):.3g}-{max(c['grey_noise_per_image']):.3g}"
    ]


def _fmt(v: float) -> str:
    return f"{v:.4g}"


def render_markdown(report: dict) -> str:
    """The calibration report as Markdown."""
    imp, t = report["import"], report["test"]
    sp = report["specimen_mm"]
    lines = [
        f"# Calibration of {report['experiment']}",
        "",
        report["description"],
        "",
        f"Specimen {sp['width']:g} x {sp['depth']:g} x {sp['height']:g} mm (width x depth x "
        f"height), {report['platens']} platens; inverse mesh `{report['inverse_mesh']}`, `lm` "
        f"with exact Jacobians, {report['budget']} evaluations per variant.",
        "",
        "## Import",
        f"- {imp['images']} images, {imp['points_used']} face points used of "
        f"{imp['points_read']} read: {imp['dropped_off_face']} off the face, "
        + (
            f"{imp['dropped_plate_margin']} within the plate margin of "
            f"{imp['plate_margin_mm']:g} mm, "
            if "plate_margin_mm" in imp
            else ""
        )
        + f"{imp['dropped_not_in_every_image']} not in every image, "
        f"{imp['dropped_non_finite_rows']} rows with non-finite values dropped",
        f"- calibration: {json.dumps(imp['calibration'])}",
        f"- force sd from a load-cell accuracy of {imp['force_accuracy_percent']:g} % of reading",
        "- files (SHA-256, first 12 digits): "
        + ", ".join(
            f"`{k}` {v[:12]}"
            for group in ("experiment", "machine_log")
            for k, v in imp["files_sha256"][group].items()
        )
        + (
            f" and {len(imp['files_sha256']['dic'])} DIC exports (all in report.json)"
            if "dic" in imp["files_sha256"]
            else f" and {len(imp['files_sha256']['images'])} images, the reference included "
            "(all in report.json)"
        ),
        *_correlation_lines(imp.get("correlation")),
        *(
            [
                f"- noise model: a point's errors correlated between two images, rho = "
                f"{imp['snapshot_rho']:g} (the reference's share); the residuals in sigma units "
                "are whitened by the correlation (R^-1/2 D^-1 per point)"
            ]
            if imp.get("snapshot_rho")
            else []
        ),
        "",
        "## What the test says (start and bounds, never a reference)",
        f"- E {_fmt(t['E_MPa'])} MPa (DIC strain; from the force curve {_fmt(t['E_force_MPa'])}), "
        f"yield in compression {_fmt(t['sigma_c_MPa'])} MPa, hardening {_fmt(t['H_c_MPa'])} MPa, "
        f"peak stress {_fmt(t['f_c_MPa'])} MPa, f_ctm {_fmt(t['f_ctm_MPa'])} MPa",
        "",
        "## Model selection",
        "",
        "Ranked by AIC. log Z: the Laplace log evidence (uniform prior on the variant's box, up "
        "to the noise normalisation common to all variants; docs/calibrating.md); p(M|D): the "
        "posterior probability of the variant from it, equal prior probabilities.",
        "",
        "| rank | variant | chi2 | rms (sigma) | AIC | BIC | dAIC | Akaike weight | log Z | "
        "dlog Z | p(M\\|D) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for i, r in enumerate(report["ranking"], 1):
        lines.append(
            f"| {i} | {r['variant']} | {_fmt(r['chi2'])} | {r['rms_sigma']:.3f} | "
            f"{_fmt(r['aic'])} | {_fmt(r['bic'])} | {r['delta_aic']:.3g} | "
            f"{r['akaike_weight']:.3g} | {r['log_evidence']:.6g} | "
            f"{r['delta_log_evidence']:.3g} | {r['model_probability']:.3g} |"
        )
    lines += _ranking_band_lines(report)
    near = [r["variant"] for r in report["ranking"][1:] if r["delta_aic"] < 2.0]
    if near:
        lines += [
            "",
            f"dAIC < 2: {', '.join(near)} fit(s) this test as well as the first (not told apart; "
            "the linear surface's three hardening tests are one material reparametrised).",
        ]
    disc = report.get("discretisation") or {}
    if "rms_sigma" in disc:
        b = disc["rms_sigma_blocks"]
        lines += [
            "",
            f"Discretisation error of the inverse mesh at the best fit ({disc['variant']}, "
            f"against mesh `{disc['mesh']}`): rms {disc['rms_sigma']:.3g} sigma (u_h "
            f"{b['u_h']:.3g}, u_v {b['u_v']:.3g}, force {b['force']:.3g}); an rms fit above 1 "
            "sigma of that size is the model's, not the test's.",
        ]
    lines += render_mcmc(report)
    lines += [
        "",
        "## Parameters (Laplace 95 % intervals from the exact Jacobian)",
        "",
        "Standard deviations are widened by the Birge ratio sqrt(chi2 / (n - k)) when it "
        "exceeds 1.",
    ]
    for name, v in report["variants"].items():
        lines += ["", f"### {name}: {v['status']} after {v['n_evals']} evaluations"]
        if v.get("correction", "none") != "none":
            lines.append(
                f"- {v['correction']} discretisation correction"
                + (f" on mesh `{v['fine_mesh']}`" if v.get("fine_mesh") else "")
                + f": {len(v['correction_rounds'])} round(s), last move "
                f"{v['correction_rounds'][-1]['move']:.2g} (relative)"
            )
        if not v.get("ok"):
            lines.append(f"- failed: {v['message']}")
            continue
        blocks = v["rms_sigma_blocks"]
        lines.append(
            f"- fit: rms {v['rms_sigma']:.3f} sigma (u_h {blocks['u_h']:.3f}, u_v "
            f"{blocks['u_v']:.3f}, force {blocks['force']:.3f}); Fisher condition "
            f"{v['condition']:.3g}; Birge ratio {v['birge_ratio']:.3g}"
        )
        lines += _parameter_table(v)
        for w in v["warnings"]:
            lines.append(f"- warning: {w}")
    lines += [
        "",
        "Figures: `force_displacement.png` (measured against the best variants), `residuals.png`"
        " (residuals of the best variant on the face, last image, in sigma units).",
    ]
    return "\n".join(lines) + "\n"


def _ranking_band_lines(report: dict) -> list[str]:
    """The report's lines on the ranking's discretisation band (:func:`ranking_band`): the rule,
    per variant behind the first dAIC, the band and whether it is resolved, and the warning."""
    band = report.get("ranking_band") or {}
    if band.get("method") != "gci":
        return ["", f"No discretisation band of the ranking: {band['reason']}."] if band else []
    lines = [
        "",
        f"Discretisation band of the ranking (GCI, as the parameters'): U = {band['safety']:g} "
        f"|dAIC - dAIC_untreated| / (r^p - 1), r = {band['ratio']:.3g} "
        f"(`{band['inverse_mesh']}` -> `{band['fine_mesh']}`), p = {band['order']:g}; a variant "
        "with dAIC <= U is not resolved from the first at this discretisation.",
        "",
        "| variant | dAIC | dAIC untreated | band U | resolved from the first |",
        "|---|---|---|---|---|",
    ]
    for r in report["ranking"][1:]:
        lines.append(
            f"| {r['variant']} | {r['delta_aic']:.3g} | {r['delta_aic_untreated']:.3g} | "
            f"{r['band_delta_aic']:.3g} | {'yes' if r['resolved'] else 'NO'} |"
        )
    if band.get("warning"):
        lines += [
            "",
            f"**Warning: {band['warning']}.** The Akaike weights and p(M|D) above are "
            "conditional on the inverse model.",
        ]
    return lines


def _parameter_table(v: dict) -> list[str]:
    """A variant's parameter table (Markdown lines): value, Laplace sd and interval and, when
    the discretisation band was taken (:func:`with_error_band`), the untreated value on the
    inverse mesh, the band and the interval with it."""
    band = v.get("band") or {}
    if band.get("method") != "gci":
        lines = [
            "",
            "| parameter | start | value | sd | sd % | 95 % interval |",
            "|---|---|---|---|---|---|",
        ]
        for j, n in enumerate(v["names"]):
            lines.append(
                f"| {n} ({v['units'][j]}) | {_fmt(v['start'][j])} | {_fmt(v['x'][j])} | "
                f"{_fmt(v['std'][j])} | {v['std_percent'][j]:.3g} | "
                f"[{_fmt(v['ci95_lower'][j])}, {_fmt(v['ci95_upper'][j])}] |"
            )
        if band.get("reason"):
            lines.append(f"- no discretisation band: {band['reason']}")
        return lines
    lines = [
        f"- discretisation error of the inverse model (GCI): U = {band['safety']:g} |x - "
        f"x_untreated| / (r^p - 1), r = {band['ratio']:.3g} (`{band['inverse_mesh']}` -> "
        f"`{band['fine_mesh']}`), p = {band['order']:g} (the smallest order the convergence "
        "studies observed for this mesh family); 95 % interval = value +- (1.96 sd + U)",
        "",
        "| parameter | start | value | untreated (inverse mesh) | sd | sd % | band U | U % | "
        "95 % interval (Laplace) | 95 % interval with the band |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for j, n in enumerate(v["names"]):
        lines.append(
            f"| {n} ({v['units'][j]}) | {_fmt(v['start'][j])} | {_fmt(v['x'][j])} | "
            f"{_fmt(v['x_untreated'][j])} | {_fmt(v['std'][j])} | {v['std_percent'][j]:.3g} | "
            f"{_fmt(v['band_abs'][j])} | {v['band_percent'][j]:.3g} | "
            f"[{_fmt(v['ci95_laplace_lower'][j])}, {_fmt(v['ci95_laplace_upper'][j])}] | "
            f"[{_fmt(v['ci95_lower'][j])}, {_fmt(v['ci95_upper'][j])}] |"
        )
    return lines


def render_mcmc(report: dict) -> list[str]:
    """The report's MCMC section (Markdown lines; none without MCMC)."""
    chains = report.get("mcmc") or {}
    if not chains:
        return []
    lines = [
        "",
        "## MCMC (emcee) and the bridge-sampling evidence",
        "",
        "Uniform prior on the variant's box, the data's noise model (no Birge widening); "
        "evidence by bridge sampling with a Gaussian proposal fitted to the chain "
        "(docs/calibrating.md), against the Laplace evidence.",
    ]
    for name, c in chains.items():
        sur = c.get("surrogate")
        fwd = (
            "the FE model"
            if c["forward"] == "fe"
            else f"a surrogate ({sur['n_train']} FE runs; hold-out rms "
            + ", ".join(
                f"{b} {v:.2g}" for b, v in sur["holdout_rms_sigma"].items() if v is not None
            )
            + " sigma)"
        )
        b = c["bridge"]
        lines += [
            "",
            f"### {name}: on {fwd}",
            f"- {c['n_walkers']} walkers x {c['n_steps']} steps ({c['burn']} burnt), acceptance "
            f"{c['acceptance']:.2f}, kept steps / largest autocorrelation time "
            f"{c['tau_multiple']:.3g} ({'converged' if c['converged'] else 'NOT converged: < 50'}),"
            f" {c['n_evals']} + {b['n_proposal']} (bridge) evaluations, {c['wall_s']:.0f} s",
            f"- log Z: bridge {c['log_evidence_bridge']:.6g} (relative error "
            f"{b['relative_error']:.2g}), Laplace {c['log_evidence_laplace']:.6g}: difference "
            f"{c['evidence_difference']:+.3g} ({c['evidence_difference_offset_removed']:+.3g} "
            "with the sampled model's chi2 offset at the optimum taken out)",
            f"- chi2 at the optimum: FE {c['chi2_optimum_fe']:.6g}, sampled model "
            f"{c['chi2_optimum_sampled']:.6g}; at the best draw: sampled model "
            f"{c['chi2_best_draw']:.6g}, FE {c['chi2_best_draw_fe']:.6g} ("
            + (
                "the FE model fits the best draw better: lm stopped short of the mode)"
                if c["chi2_best_draw_fe"] < c["chi2_optimum_fe"] - 1.0
                else "not better on the FE model: the optimum is the mode)"
            ),
            "",
            "| parameter | MCMC mean | MCMC sd | sd / Laplace sd (noise only) | MCMC 95 % |",
            "|---|---|---|---|---|",
        ]
        for j, n in enumerate(c["names"]):
            lines.append(
                f"| {n} | {_fmt(c['mean'][j])} | {_fmt(c['sd'][j])} | {c['sd_ratio'][j]:.3g} | "
                f"[{_fmt(c['q025'][j])}, {_fmt(c['q975'][j])}] |"
            )
    probs = [r for r in report["ranking"] if "model_probability_bridge" in r]
    if probs:
        lines += [
            "",
            "Posterior model probabilities from the bridge evidences: "
            + ", ".join(f"{r['variant']} {r['model_probability_bridge']:.3g}" for r in probs),
        ]
    return lines

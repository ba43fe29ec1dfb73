"""Uncertainty study: MCMC posterior (the ``mcmc`` solver) against the Laplace approximation.

Steps (all evaluations through the objective, counted):

1. Laplace: Gauss-Newton polishing of the start point (reference or ``x``) to the nearest minimum
   (:func:`problems.analysis.identifiability.refine_mode`, up to ``refine`` steps), Jacobian there,
   covariance ``(J^T J)^-1``; mean = that point, 95 % interval = mean +- 1.96 sd. Notes flag a mode
   on a box bound (truncated posterior), a misfit dominated by model error (cost / (m - n) > 2) and
   an MCMC sample better than the polished mode (polishing not converged).
2. MCMC: ``solve(objective, "mcmc")`` started at the polished point, walkers in a ball of the
   smallest Laplace standard deviation (in z), uniform prior on the box; mean, sd and the 2.5/97.5
   percentiles of the kept chain.
3. Verdict per parameter (:func:`verdict`): "agree" when the means differ by less than
   ``0.5`` posterior (MCMC) standard deviations and the sd ratio Laplace/MCMC lies in
   ``[0.67, 1.5]``; otherwise what disagrees. An MCMC chain shorter than the solver's
   autocorrelation criterion is flagged: its numbers are then unreliable, not the Laplace ones.

:func:`run_uncertainty` writes ``uncertainty.csv/md/json`` and the chain, ``chain.npz`` (an emcee
backend, :class:`solvers.npz_backend.NpzBackend`, filled while sampling); :func:`render_uncertainty`
draws ``corner.png`` from ``uncertainty.json`` and ``chain.npz`` alone.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bench.studies import (
    as_float,
    markdown_table,
    output_dir,
    outside_bounds,
    read_json,
    study_objective,
    write_csv,
    write_json,
)

CHAIN_FILE = "chain.npz"

MEAN_TOL = 0.5  # |mean_L - mean_MCMC| / sd_MCMC below this: means agree
SD_RATIO = (0.67, 1.5)  # sd_L / sd_MCMC inside this: spreads agree
Z95 = 1.959963984540054


def verdict(
    mean_mcmc: float,
    sd_mcmc: float,
    mean_laplace: float,
    sd_laplace: float,
    mean_tol: float = MEAN_TOL,
    ratio: tuple[float, float] = SD_RATIO,
) -> str:
    """``"agree"`` or a short statement of what disagrees (see the module docstring)."""
    if not all(map(math.isfinite, (mean_mcmc, sd_mcmc, mean_laplace, sd_laplace))):
        return "not comparable (non-finite estimate)"
    if sd_mcmc <= 0:
        return "not comparable (MCMC standard deviation is zero)"
    shift = abs(mean_laplace - mean_mcmc) / sd_mcmc
    r = sd_laplace / sd_mcmc
    issues = []
    if not shift < mean_tol:
        issues.append(f"means differ by {shift:.2g} posterior sd")
    if not ratio[0] <= r <= ratio[1]:
        issues.append(
            f"Laplace sd is {r:.2g} x the MCMC sd ({'too narrow' if r < ratio[0] else 'too wide'})"
        )
    return "agree" if not issues else "; ".join(issues)


def compare(names, mcmc: dict, laplace_mean, laplace_sd) -> list[dict]:
    """Table rows: mean, sd, 95 % interval from both, and the verdict, per parameter.

    ``mcmc`` holds dicts ``mean``, ``std``, ``q2.5``, ``q97.5`` keyed by parameter name (the
    ``extra`` of the ``mcmc`` solver's RunResult).
    """
    rows = []
    for i, n in enumerate(names):
        mL, sL = float(laplace_mean[i]), float(laplace_sd[i])
        mM, sM = float(mcmc["mean"][n]), float(mcmc["std"][n])
        rows.append(
            {
                "parameter": n,
                "mcmc_mean": mM,
                "mcmc_std": sM,
                "mcmc_q2.5": float(mcmc["q2.5"][n]),
                "mcmc_q97.5": float(mcmc["q97.5"][n]),
                "laplace_mean": mL,
                "laplace_std": sL,
                "laplace_q2.5": mL - Z95 * sL,
                "laplace_q97.5": mL + Z95 * sL,
                "verdict": verdict(mM, sM, mL, sL),
            }
        )
    return rows


@dataclass
class UncertaintyRun:
    """What :func:`run_uncertainty` computed and wrote."""

    rows: list[dict]  # per parameter: MCMC and Laplace mean, sd, 95 % interval, verdict
    overall: str  # one-line verdict
    laplace: object  # problems.analysis.identifiability.Identifiability at the mode
    run: object  # the mcmc solver's RunResult
    x_map: np.ndarray  # the polished mode (physical units)
    cost: dict  # evaluations and wall times (s) of both phases
    chi2_per_dof: float  # cost / (m - n) at the mode
    mcmc_warnings: list[str]
    notes: list[str]
    dir: Path
    paths: list[Path] = field(default_factory=list)


def run_uncertainty(
    case_name: str,
    *,
    mesh: str = "coarse",
    data: str = "auto",
    tier: str | None = None,
    correction: str = "none",
    plate_margin_mm: float = 0.0,
    budget: int = 2000,
    seed: int = 0,
    x: dict | None = None,
    refine: int = 10,
    n_walkers: int | None = None,
    mapper=None,
    out=None,
    workers: int = 1,
    scheme: str = "forward",
    observers=(),
) -> UncertaintyRun:
    """Laplace at the polished mode, then MCMC from there (chain kept in ``chain.npz`` of the output
    folder); write the comparison table, markdown and JSON. ``observers`` are added to the
    objective's observers (progress bars, :class:`bench.progress.EvaluationProgress`)."""
    from problems.analysis.identifiability import analyse_jacobian, refine_mode
    from problems.inverse.cases import get_case
    from solvers import solve

    t_start = time.perf_counter()
    obj, text = study_objective(
        case_name,
        mesh=mesh,
        data=data,
        mapper=mapper,
        tier=tier,
        correction=correction,
        plate_margin_mm=plate_margin_mm,
    )
    obj.observers.extend(observers)
    names, ref = obj.names, obj.reference
    z0 = np.ones(obj.n_params)
    for name, value in (x or {}).items():
        z0[names.index(name)] = value / ref[names.index(name)]
    why = outside_bounds("start point", case_name, obj, z0)
    if why:
        raise ValueError(why)
    start_usable = obj.evaluate(z0)
    if not start_usable.usable:
        raise ValueError(f"the start point cannot be evaluated: {start_usable.message}")

    # 1. Laplace at the (polished) mode
    t0 = time.perf_counter()
    if refine > 0:
        pol = refine_mode(obj, z0, max_steps=refine, scheme=scheme)
        z_map, J, cost_map, polish_msg = (
            pol.z,
            pol.jacobian,
            pol.cost,
            f"{pol.steps} Gauss-Newton step(s), {pol.message}",
        )
    else:
        ev = obj.evaluate(z0)
        J = obj.jacobian(z0, scheme=scheme, r0=ev.residual)
        z_map, cost_map, polish_msg = z0, ev.cost, "no polishing (Laplace at the start point)"
    lap = analyse_jacobian(J, ref, x=obj.to_physical(z_map), names=names)
    dof = max(obj.n_residuals - obj.n_params, 1)
    chi2_dof = cost_map / dof
    span = obj.upper_z - obj.lower_z
    at_bound = [
        n
        for n, z, lo, hi, w in zip(names, z_map, obj.lower_z, obj.upper_z, span)
        if min(z - lo, hi - z) <= 1e-6 * w
    ]
    notes = []
    if at_bound:
        notes.append(
            f"the mode lies on the box bound of {', '.join(at_bound)}: the posterior is truncated "
            "there and the Laplace Gaussian (which ignores the bound) is not valid for those "
            "parameters"
        )
    if chi2_dof > 2.0:
        notes.append(
            f"cost / (m - n) = {chi2_dof:.3g} >> 1 at the mode: the misfit is dominated by model "
            "error (e.g. coarse mesh against fine-mesh data), not by the measurement noise both "
            f"posteriors assume; their sd describe the noise only (sd x sqrt({chi2_dof:.3g}) = "
            f"x{math.sqrt(chi2_dof):.3g} is the usual rough allowance)"
        )
    laplace_evals, laplace_wall = obj.n_evals, time.perf_counter() - t0
    lap.n_evals = laplace_evals
    x_map = obj.to_physical(z_map)

    # 2. MCMC (solve() resets the objective's counters)
    sd_z = np.sqrt(np.clip(np.diag(lap.cov_z), 0, None))
    finite = sd_z[sd_z > 0]
    ball = float(min(1e-2, finite.min())) if finite.size else 1e-3
    options = {"ball_size": ball}
    if n_walkers:
        options["n_walkers"] = int(n_walkers)
    d = output_dir("uncertainty", case_name, out)
    (d / CHAIN_FILE).unlink(missing_ok=True)  # no stale chain if this run produces none
    t1 = time.perf_counter()
    run = solve(
        obj, "mcmc", budget=budget, seed=seed, x0=x_map, chain_path=str(d / CHAIN_FILE), **options
    )
    mcmc_wall = time.perf_counter() - t1
    ex = run.extra
    if "mean" not in ex:
        raise ValueError(
            f"MCMC produced no samples ({run.status}: {run.message}); raise --budget above "
            f"{2 * max(16, 4 * obj.n_params)} evaluations"
        )

    rows = compare(names, ex, x_map, lap.std_x)
    mcmc_warnings = list(ex.get("warnings", []))
    all_agree = all(r["verdict"] == "agree" for r in rows)
    overall = (
        "MCMC and Laplace agree on every parameter"
        if all_agree
        else "MCMC and Laplace disagree on "
        + ", ".join(r["parameter"] for r in rows if r["verdict"] != "agree")
    )
    if mcmc_warnings:
        overall += " (MCMC chain too short for reliable estimates: see the warnings)"
    if ex.get("map_cost", math.inf) < cost_map - 1.0:
        notes.append(
            f"MCMC found a lower cost ({ex['map_cost']:.6g}) than the polished mode "
            f"({cost_map:.6g}): the Gauss-Newton polishing did not reach the mode (raise "
            "--refine), so the Laplace mean is off"
        )
    total_wall = time.perf_counter() - t_start
    cost = {
        "laplace_evaluations": laplace_evals,
        "laplace_wall_s": laplace_wall,
        "mcmc_evaluations": run.n_evals,
        "mcmc_wall_s": mcmc_wall,
        "total_evaluations": laplace_evals + run.n_evals,
        "total_wall_s": total_wall,
        "workers": workers,
    }

    paths = [write_csv(d / "uncertainty.csv", rows)]
    fmt = {k: ".6g" for k in rows[0] if k not in ("parameter", "verdict")}
    md = [
        f"# Uncertainty of {case_name} (mesh {mesh}): MCMC against Laplace",
        "",
        f"Data: {text}.",
        "",
        "Laplace at the mode x_MAP = "
        + ", ".join(f"{n} = {v:.6g}" for n, v in zip(names, x_map))
        + f" (cost {cost_map:.6g}; {polish_msg}); condition number of J^T J {lap.condition:.3g}.",
        "",
        f"MCMC: {ex['n_walkers']} walkers x {ex['n_steps']} steps (burn-in {ex['burn']}), "
        f"acceptance {ex['acceptance_fraction']:.2f}, autocorrelation times "
        + ", ".join(f"{n} {t:.3g}" for n, t in ex["autocorr_time"].items())
        + f"; status {run.status}.",
        "",
        markdown_table(rows, fmt),
        f"Verdict rule: agree when |mean_L - mean_MCMC| < {MEAN_TOL} sd_MCMC and sd_L / sd_MCMC in "
        f"[{SD_RATIO[0]}, {SD_RATIO[1]}].",
        "",
        f"**{overall}.**",
        "",
        f"Cost: Laplace {laplace_evals} evaluations ({laplace_wall:.1f} s), MCMC {run.n_evals} "
        f"evaluations ({mcmc_wall:.1f} s), total {total_wall:.1f} s with {workers} worker(s).",
    ]
    md += [f"- MCMC warning: {w}" for w in mcmc_warnings] + [
        f"- Laplace warning: {w}" for w in lap.warnings
    ]
    md += [f"- note: {w}" for w in notes]
    (d / "uncertainty.md").write_text("\n".join(md) + "\n")
    paths.append(d / "uncertainty.md")
    units = {p.name: p.unit for p in get_case(case_name).parameters}
    paths.append(
        write_json(
            d / "uncertainty.json",
            {
                "case": case_name,
                "mesh": mesh,
                "data": text,
                "budget": budget,
                "seed": seed,
                "names": list(names),
                "units": units,
                "reference": dict(zip(names, ref)),
                "x_map": dict(zip(names, x_map)),
                "cost_map": cost_map,
                "chi2_per_dof": chi2_dof,
                "at_bound": at_bound,
                "notes": notes,
                "laplace": {
                    "mean": dict(zip(names, x_map)),
                    "std": dict(zip(names, lap.std_x)),
                    "cov": lap.cov_x,
                    "condition": lap.condition,
                    "warnings": lap.warnings,
                },
                "mcmc": {
                    k: v for k, v in ex.items() if k not in ("chain", "log_prob", "chain_path")
                },
                "chain_file": CHAIN_FILE,
                "table": rows,
                "overall": overall,
                "cost": cost,
                "status": run.status,
            },
        )
    )
    paths.append(d / CHAIN_FILE)
    return UncertaintyRun(
        rows, overall, lap, run, x_map, cost, chi2_dof, mcmc_warnings, notes, Path(d), paths
    )


def render_uncertainty(folder) -> list[Path]:
    """Draw ``corner.png`` from ``folder/uncertainty.json`` and the chain in ``folder/chain.npz``
    (burn-in discarded; chain in z times its ``scale``, or physical in files without one)."""
    from bench.studies.figures import corner_plot
    from solvers.npz_backend import NpzBackend

    d = Path(folder)
    doc = read_json(d / "uncertainty.json")
    backend = NpzBackend.load(d / doc.get("chain_file", CHAIN_FILE))
    names = doc.get("names") or list(doc["x_map"])
    scale = np.asarray(backend.metadata.get("scale", np.ones(len(names))), float)
    kept = backend.get_chain(discard=int(doc["mcmc"]["burn"]), flat=True) * scale
    lap = doc["laplace"]
    mean = np.array([as_float(lap["mean"][n]) for n in names])
    cov = np.array([[as_float(v) for v in r] for r in lap["cov"]])
    reference = [as_float(doc["reference"][n]) for n in names] if "reference" in doc else None
    title = (
        f"{doc['case']}, mesh {doc['mesh']}: MCMC ({doc['cost']['mcmc_evaluations']} evaluations) "
        "vs Laplace"
    )
    return [
        corner_plot(
            kept,
            names,
            d / "corner.png",
            reference=reference,
            laplace_mean=mean,
            laplace_cov=cov,
            units=doc.get("units"),
            seed=int(doc.get("seed", 0)),
            title=title,
        )
    ]

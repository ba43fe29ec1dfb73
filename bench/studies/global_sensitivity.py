"""Global sensitivity study of one case: Sobol (Saltelli) or Morris over the (scaled) parameter box.

:func:`run_gsa` samples, evaluates, analyses and writes ``gsa_<method>.csv/md/json`` and
``samples_<method>.csv``; :func:`render_gsa` draws ``gsa_<method>.png`` from ``gsa_<method>.json``
alone.
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
    read_json,
    study_objective,
    write_csv,
    write_json,
)

METHODS = ("sobol", "morris")


@dataclass
class GSARun:
    """What :func:`run_gsa` computed and wrote."""

    result: object  # problems.analysis.global_sensitivity.SobolResult or MorrisResult
    cost: dict  # evaluations, failures, wall times (s), workers
    box_scale: float  # scale of the case's box about the reference (-)
    data: str  # description of the data of the cost
    X: np.ndarray  # sample points (physical units), (evaluations, parameters)
    Y: np.ndarray  # outputs at the sample points, (evaluations, outputs)
    dir: Path
    paths: list[Path] = field(default_factory=list)


def planned_evaluations(method: str, samples: int, n_params: int) -> int:
    """FE evaluations of a study: Sobol ``N (d + 2)``, Morris ``r (d + 1)``."""
    if method == "sobol":
        return samples * (n_params + 2)
    if method == "morris":
        return samples * (n_params + 1)
    raise ValueError(f"method {method!r} is unknown; allowed: sobol, morris")


class CostOnly:
    """Vectorised ``X -> cost`` of an objective (cases without the FE layout, e.g. analytic
    ones)."""

    outputs = ("cost",)

    def __init__(self, objective):
        self.objective = objective
        self.n_evals = self.n_failed = self.n_infeasible = 0

    def __call__(self, X):
        obj = self.objective
        evs = obj.evaluate_many(obj.to_scaled(np.atleast_2d(X)))
        self.n_evals += len(evs)
        self.n_failed += sum(not e.ok for e in evs)
        self.n_infeasible += sum(not e.feasible for e in evs)
        return np.array([[e.cost if e.usable else np.nan] for e in evs])


def _chunked(f, X, chunk: int, progress: bool, desc: str) -> np.ndarray:
    from tqdm import tqdm

    out = []
    with tqdm(total=len(X), desc=desc, unit="run", disable=not progress) as bar:
        for i in range(0, len(X), chunk):
            out.append(np.asarray(f(X[i : i + chunk]), float))
            bar.update(min(chunk, len(X) - i))
    return np.concatenate(out)


def run_gsa(
    case_name: str,
    *,
    method: str = "sobol",
    samples: int = 32,
    mesh: str = "coarse",
    data: str = "auto",
    tier: str | None = None,
    correction: str = "none",
    plate_margin_mm: float = 0.0,
    box_scale: str | float = "auto",
    seed: int = 0,
    mapper=None,
    workers: int = 1,
    out=None,
    progress: bool = True,
    confirm=None,
) -> GSARun | None:
    """Sample, evaluate (through ``mapper``), analyse and write ``gsa_<method>.csv/md/json`` and the
    samples (``samples_<method>.csv``). ``confirm(planned_evals, box, scale, n_infeasible)`` may
    veto (return False): then nothing is evaluated or written and the result is None."""
    from problems.analysis.global_sensitivity import (
        FE_OUTPUT_LABELS,
        FESummaries,
        feasible_scale,
        morris_analyze,
        morris_sample,
        scaled_box,
        sobol_analyze,
        sobol_sample,
    )
    from problems.inverse.cases import get_case

    case = get_case(case_name)
    if method not in ("sobol", "morris"):
        raise ValueError(f"method {method!r} is unknown; allowed: sobol, morris")
    t0 = time.perf_counter()
    obj, text = study_objective(
        case.name,
        mesh=mesh,
        data=data,
        mapper=mapper,
        tier=tier,
        correction=correction,
        plate_margin_mm=plate_margin_mm,
    )
    names, ref = case.names, case.reference
    d = len(names)
    if method == "sobol":
        X_full = sobol_sample(names, case.lower, case.upper, samples, seed=seed)
    else:
        X_full = morris_sample(names, case.lower, case.upper, samples, seed=seed)
    U = (X_full - case.lower) / (case.upper - case.lower)
    n_infeasible_full = 0
    if box_scale == "auto":
        scale, n_infeasible_full = feasible_scale(obj.model.check, case.lower, case.upper, ref, U)
        scale = math.floor(scale * 1000) / 1000 if scale < 1 else 1.0
    else:
        scale = float(box_scale)
    lower, upper = scaled_box(case.lower, case.upper, ref, scale)
    X = lower + U * (upper - lower)
    planned = len(X)
    if confirm is not None and confirm(planned, (lower, upper), scale, n_infeasible_full) is False:
        return None
    fe = not case.is_analytic
    if fe:
        model = obj.model
        f = FESummaries(obj, model.loading.snapshots, len(model.points), mapper=mapper)
        labels = FE_OUTPUT_LABELS
    else:
        f = CostOnly(obj)
        labels = {"cost": "cost (chi-square, -)"}
    t_eval = time.perf_counter()
    Y = _chunked(f, X, max(1, 2 * workers) if fe else len(X), progress, f"gsa {method} {case.name}")
    eval_wall = time.perf_counter() - t_eval
    if method == "sobol":
        res = sobol_analyze(names, lower, upper, Y, outputs=f.outputs, seed=seed, n_evals=f.n_evals)
    else:
        res = morris_analyze(
            names, lower, upper, X, Y, outputs=f.outputs, seed=seed, n_evals=f.n_evals
        )
    res.wall_s = time.perf_counter() - t0
    if scale < 1:
        res.warnings.insert(
            0,
            f"box scaled by {scale:g} about the reference: {n_infeasible_full} of {planned} sample "
            f"points of the full box are infeasible (check() rejects them)",
        )
    out_dir = output_dir("gsa", case.name, out)
    stem = f"gsa_{method}"
    paths = [write_csv(out_dir / f"{stem}.csv", res.rows())]
    paths.append(
        write_csv(
            out_dir / f"samples_{method}.csv",
            [
                {**dict(zip(names, map(float, x))), **dict(zip(f.outputs, map(float, y)))}
                for x, y in zip(X, Y)
            ],
        )
    )
    cost = {
        "planned_evaluations": planned,
        "fe_evaluations": f.n_evals,
        "failed": f.n_failed,
        "infeasible": f.n_infeasible,
        "evaluation_wall_s": eval_wall,
        "total_wall_s": res.wall_s,
        "workers": workers,
        "mean_run_s": getattr(f, "fe_wall_s", 0.0) / max(f.n_evals, 1),
    }
    settings = (
        {
            "n_base": samples,
            "evaluations": f"N (d + 2) = {samples} x {d + 2}",
            "sampler": "Saltelli/Sobol' (SALib.sample.sobol, scrambled, no second order)",
            "bootstrap_resamples": 200,
            "conf_level": 0.95,
        }
        if method == "sobol"
        else {
            "trajectories": samples,
            "num_levels": 4,
            "evaluations": f"r (d + 1) = {samples} x {d + 1}",
            "sampler": "SALib.sample.morris",
        }
    )
    box_rows = [
        {"parameter": n, "reference": float(r), "lower": float(lo), "upper": float(hi)}
        for n, r, lo, hi in zip(names, ref, lower, upper)
    ]
    fmt = {
        "S1": ".3f",
        "S1_conf": ".3f",
        "ST": ".3f",
        "ST_conf": ".3f",
        "mu": ".4g",
        "mu_star": ".4g",
        "mu_star_conf": ".3g",
        "sigma": ".4g",
    }
    md = [
        f"# {method.capitalize()} global sensitivity of {case.name} (mesh {mesh})",
        "",
        f"Data for the cost: {text}.",
        "",
        "Settings: " + "; ".join(f"{k} {v}" for k, v in settings.items()) + ".",
        "",
        f"Box (scale {scale:g} of the case bounds about the reference):",
        "",
        markdown_table(box_rows, {"reference": ".6g", "lower": ".6g", "upper": ".6g"}),
        markdown_table(res.rows(), fmt),
        f"Cost: {f.n_evals} forward evaluations ({f.n_failed} failed, {f.n_infeasible} "
        f"infeasible), {eval_wall:.1f} s of evaluation with {workers} worker(s), {res.wall_s:.1f} "
        "s in total.",
    ]
    md += [f"- warning: {w}" for w in res.warnings]
    (out_dir / f"{stem}.md").write_text("\n".join(md) + "\n")
    paths.append(out_dir / f"{stem}.md")
    paths.append(
        write_json(
            out_dir / f"{stem}.json",
            {
                "case": case.name,
                "mesh": mesh,
                "method": method,
                "data": text,
                "settings": settings,
                "box_scale": scale,
                "box": box_rows,
                "names": list(names),
                "outputs": list(f.outputs),
                "output_labels": {o: labels.get(o, o) for o in f.outputs},
                "indices": res.rows(),
                "cost": cost,
                "warnings": res.warnings,
            },
        )
    )
    return GSARun(res, cost, scale, text, X, Y, Path(out_dir), paths)


def render_gsa(folder, methods=METHODS) -> list[Path]:
    """Draw ``gsa_<method>.png`` from each ``gsa_<method>.json`` of ``folder`` (of ``methods``)."""
    from bench.studies.figures import morris_plot, sobol_bars

    d = Path(folder)
    found = [m for m in methods if (d / f"gsa_{m}.json").is_file()]
    if not found:
        raise FileNotFoundError(f"no gsa_{{{','.join(methods)}}}.json in {d}: run the study first")
    paths = []
    for method in found:
        doc = read_json(d / f"gsa_{method}.json")
        rows = doc["indices"]
        names = doc.get("names") or list(dict.fromkeys(r["parameter"] for r in rows))
        outputs = doc.get("outputs") or list(dict.fromkeys(r["output"] for r in rows))

        def table(key):
            t = np.full((len(outputs), len(names)), np.nan)
            for r in rows:
                t[outputs.index(r["output"]), names.index(r["parameter"])] = as_float(r[key])
            return t

        labels = doc.get("output_labels")
        if labels is None:  # written before the labels were stored
            from problems.analysis.global_sensitivity import FE_OUTPUT_LABELS as labels
        title = f"{doc['case']}, mesh {doc['mesh']}, {doc['cost']['fe_evaluations']} evaluations"
        path = d / f"gsa_{method}.png"
        if method == "sobol":
            conf = float(doc["settings"].get("conf_level", 0.95))
            paths.append(
                sobol_bars(
                    names,
                    outputs,
                    table("S1"),
                    table("S1_conf"),
                    table("ST"),
                    table("ST_conf"),
                    conf,
                    path,
                    labels,
                    title,
                )
            )
        else:
            paths.append(
                morris_plot(
                    names,
                    outputs,
                    table("mu_star"),
                    table("mu_star_conf"),
                    table("sigma"),
                    path,
                    labels,
                    title,
                )
            )
    return paths

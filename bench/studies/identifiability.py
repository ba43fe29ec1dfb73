"""Identifiability study: Fisher information and Laplace covariance per case.

:func:`run_identifiability` writes, per case, ``identifiability.csv/md/json``, ``correlation.csv``
and ``fisher_eigen.csv`` and, for several cases, ``summary.md/csv/json``;
:func:`render_identifiability` draws ``correlation.png`` (per case) and ``std_percent.png``
(summary) from those files alone.
"""

from __future__ import annotations

import csv
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


@dataclass
class IdentifiabilityRun:
    """What :func:`run_identifiability` computed and wrote."""

    # case -> problems.analysis.identifiability.Identifiability
    results: dict
    # one row per case (condition, rank, sd %, cost)
    summary: list[dict]
    dirs: dict[str, Path]  # case -> its output folder
    # folder of summary.md/csv/json (several cases only)
    summary_dir: Path | None = None
    paths: list[Path] = field(default_factory=list)


def case_identifiability(
    case_name: str,
    *,
    mesh: str = "coarse",
    data: str = "auto",
    tier: str | None = None,
    correction: str = "none",
    plate_margin_mm: float = 0.0,
    x: dict | None = None,
    scheme: str = "forward",
    rel_step: float = 1e-6,
    mapper=None,
):
    """``(Identifiability, objective, data description)`` at the reference
    (or at ``x`` overrides)."""
    from problems.analysis.identifiability import identifiability

    obj, text = study_objective(
        case_name,
        mesh=mesh,
        data=data,
        mapper=mapper,
        tier=tier,
        correction=correction,
        plate_margin_mm=plate_margin_mm,
    )
    z = np.ones(obj.n_params)
    for name, value in (x or {}).items():
        z[obj.names.index(name)] = value / obj.reference[obj.names.index(name)]
    why = outside_bounds("the point", case_name, obj, z)
    if why:
        raise ValueError(why)
    return identifiability(obj, z, scheme=scheme, rel_step=rel_step), obj, text


def write_case(ident, case_name: str, d, *, mesh: str, data_text: str, wall_s: float) -> list:
    """Write the tables and ``identifiability.json`` of one case into ``d``."""
    names = ident.names
    paths = [write_csv(d / "identifiability.csv", ident.rows())]
    rho = ident.correlation
    paths.append(
        write_csv(
            d / "correlation.csv",
            [
                {"parameter": n, **{m: float(rho[i, j]) for j, m in enumerate(names)}}
                for i, n in enumerate(names)
            ],
        )
    )
    paths.append(
        write_csv(
            d / "fisher_eigen.csv",
            [
                {
                    "k": k + 1,
                    "eigenvalue": float(lam),
                    **{n: float(ident.eigenvectors[i, k]) for i, n in enumerate(names)},
                }
                for k, lam in enumerate(ident.eigenvalues)
            ],
        )
    )
    md = [
        f"# Identifiability of {case_name} (mesh {mesh})",
        "",
        f"Data: {data_text}.",
        "Jacobian of the whitened residual at x = "
        + ", ".join(f"{n} = {v:.6g}" for n, v in zip(names, ident.x))
        + ".",
        "",
        "Fisher information J^T J (in z = x / reference): eigenvalues "
        + ", ".join(f"{v:.3g}" for v in ident.eigenvalues)
        + f"; condition number {ident.condition:.3g}; rank {ident.rank} of {len(names)}.",
        "",
        "Least identifiable direction (unit eigenvector of the smallest eigenvalue, z units): "
        + ", ".join(f"{n} {v:+.3f}" for n, v in ident.weakest.items())
        + ".",
        "",
        "Laplace approximation (J^T J)^-1: predicted standard deviations",
        "",
        markdown_table(
            ident.rows(), {"x": ".6g", "reference": ".6g", "std": ".3g", "std_percent": ".3g"}
        ),
        "Correlation matrix",
        "",
        markdown_table(
            [
                {"": n, **{m: float(rho[i, j]) for j, m in enumerate(names)}}
                for i, n in enumerate(names)
            ],
            {m: "+.3f" for m in names},
        ),
        f"Cost: {ident.n_evals} forward evaluations, {wall_s:.1f} s wall.",
    ]
    md += [f"- warning: {w}" for w in ident.warnings]
    (d / "identifiability.md").write_text("\n".join(md) + "\n")
    paths.append(d / "identifiability.md")
    paths.append(
        write_json(
            d / "identifiability.json",
            {
                "case": case_name,
                "mesh": mesh,
                "data": data_text,
                "x": dict(zip(names, ident.x)),
                **ident.summary(),
                "std": dict(zip(names, ident.std_x)),
                "correlation": rho,
                "fisher_z": ident.fisher_z,
                "cov_x": ident.cov_x,
                "wall_s": wall_s,
            },
        )
    )
    return paths


def run_identifiability(
    cases: list[str],
    *,
    mesh: str = "coarse",
    data: str = "auto",
    tier: str | None = None,
    correction: str = "none",
    plate_margin_mm: float = 0.0,
    x: dict | None = None,
    scheme: str = "forward",
    rel_step: float = 1e-6,
    mapper=None,
    out=None,
    progress: bool = True,
) -> IdentifiabilityRun:
    """One folder per case (``out`` itself for one case, ``out/<case>`` for several) plus, for
    several cases, a summary folder (``out``, or the default ``.../identifiability/summary``)."""
    from tqdm import tqdm

    run = IdentifiabilityRun({}, [], {})
    t_all = time.perf_counter()
    for name in tqdm(cases, desc="identifiability", disable=not progress or len(cases) < 2):
        t0 = time.perf_counter()
        ident, obj, text = case_identifiability(
            name,
            mesh=mesh,
            data=data,
            x=x,
            scheme=scheme,
            rel_step=rel_step,
            mapper=mapper,
            tier=tier,
            correction=correction,
            plate_margin_mm=plate_margin_mm,
        )
        wall = time.perf_counter() - t0
        d = output_dir(
            "identifiability", name, out if out is None or len(cases) == 1 else Path(out) / name
        )
        run.paths += write_case(ident, name, d, mesh=mesh, data_text=text, wall_s=wall)
        run.results[name], run.dirs[name] = ident, d
        run.summary.append(
            {
                "case": name,
                "condition": ident.condition,
                "rank": ident.rank,
                "lambda_min": float(ident.eigenvalues[-1]),
                "lambda_max": float(ident.eigenvalues[0]),
                **{f"sd% {n}": float(s) for n, s in zip(ident.names, ident.std_percent)},
                "n_evals": ident.n_evals,
                "wall_s": wall,
            }
        )
    if len(cases) > 1:
        run.summary_dir = root = output_dir("identifiability", "summary", out)
        compact = [
            {
                "case": r["case"],
                "condition": r["condition"],
                "rank": r["rank"],
                "std % (param: value)": ", ".join(
                    f"{k[4:]}: {v:.3g}" for k, v in r.items() if k.startswith("sd% ")
                ),
                "n_evals": r["n_evals"],
                "wall_s": r["wall_s"],
            }
            for r in run.summary
        ]
        (root / "summary.md").write_text(
            f"# Identifiability summary (mesh {mesh})\n\nCondition number of J^T J in z = x / "
            "reference and Laplace standard deviations in % of the reference.\n\n"
            + markdown_table(compact, {"condition": ".3g", "wall_s": ".1f"})
            + f"\nTotal wall time {time.perf_counter() - t_all:.1f} s.\n"
        )
        run.paths.append(root / "summary.md")
        with (root / "summary.csv").open("w") as fh:  # ragged columns across forms: long format
            fh.write("case,parameter,std_percent,condition\n")
            for name, ident in run.results.items():
                for n, s in zip(ident.names, ident.std_percent):
                    fh.write(f"{name},{n},{s:.6g},{ident.condition:.6g}\n")
        run.paths.append(root / "summary.csv")
        run.paths.append(
            write_json(
                root / "summary.json",
                {
                    "mesh": mesh,
                    "data": data,
                    "cases": run.summary,
                    "dirs": {k: str(v) for k, v in run.dirs.items()},
                },
            )
        )
    return run


def render_identifiability(folder) -> list[Path]:
    """Draw ``correlation.png`` from ``folder/identifiability.json`` (one case's folder)."""
    from bench.studies.figures import correlation_heatmap

    d = Path(folder)
    doc = read_json(d / "identifiability.json")
    rho = [[as_float(v) for v in r] for r in doc["correlation"]]
    return [
        correlation_heatmap(
            doc["names"],
            rho,
            d / "correlation.png",
            f"{doc['case']}: Laplace correlation, cond = {as_float(doc['condition']):.3g}",
        )
    ]


def render_summary(folder) -> list[Path]:
    """Draw ``std_percent.png`` from ``folder/summary.csv`` (and the mesh from ``summary.json``)."""
    from bench.studies.figures import std_percent_bars

    d = Path(folder)
    if not (d / "summary.csv").is_file():
        raise FileNotFoundError(
            f"{d / 'summary.csv'} does not exist: run the study on several cases first"
        )
    table: dict[str, dict[str, float]] = {}
    with (d / "summary.csv").open() as fh:
        for r in csv.DictReader(fh):
            table.setdefault(r["case"], {})[r["parameter"]] = float(r["std_percent"])
    mesh = read_json(d / "summary.json").get("mesh") if (d / "summary.json").is_file() else None
    title = "Laplace standard deviations" + (f", mesh {mesh}" if mesh else "")
    return [std_percent_bars(table, d / "std_percent.png", title)]

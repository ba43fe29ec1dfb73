"""Identifiability study: Fisher information and Laplace covariance per case; tables and heat maps."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from bench.studies import markdown_table, output_dir, study_objective, write_csv, write_json


def case_identifiability(case_name: str, *, mesh: str = "coarse", data: str = "auto", x: dict | None = None,
                         scheme: str = "forward", rel_step: float = 1e-6, mapper=None):
    """``(Identifiability, objective, data description)`` at the reference (or at ``x`` overrides)."""
    from problems.analysis.identifiability import identifiability

    obj, text = study_objective(case_name, mesh=mesh, data=data, mapper=mapper)
    z = np.ones(obj.n_params)
    for name, value in (x or {}).items():
        z[obj.names.index(name)] = value / obj.reference[obj.names.index(name)]
    if np.any(z < obj.lower_z) or np.any(z > obj.upper_z):
        raise ValueError(f"the point {dict(zip(obj.names, obj.to_physical(z)))} lies outside the case's bounds")
    return identifiability(obj, z, scheme=scheme, rel_step=rel_step), obj, text


def write_case(ident, case_name: str, d, *, mesh: str, data_text: str, wall_s: float, figures: bool = True) -> list:
    names = ident.names
    paths = [write_csv(d / "identifiability.csv", ident.rows())]
    rho = ident.correlation
    paths.append(write_csv(d / "correlation.csv", [{"parameter": n, **{m: float(rho[i, j]) for j, m in enumerate(names)}}
                                                   for i, n in enumerate(names)]))
    paths.append(write_csv(d / "fisher_eigen.csv", [
        {"k": k + 1, "eigenvalue": float(lam), **{n: float(ident.eigenvectors[i, k]) for i, n in enumerate(names)}}
        for k, lam in enumerate(ident.eigenvalues)]))
    md = [f"# Identifiability of {case_name} (mesh {mesh})", "",
          f"Data: {data_text}.", "Jacobian of the whitened residual at x = "
          + ", ".join(f"{n} = {v:.6g}" for n, v in zip(names, ident.x)) + ".", "",
          "Fisher information J^T J (in z = x / reference): eigenvalues "
          + ", ".join(f"{v:.3g}" for v in ident.eigenvalues)
          + f"; condition number {ident.condition:.3g}; rank {ident.rank} of {len(names)}.", "",
          "Least identifiable direction (unit eigenvector of the smallest eigenvalue, z units): "
          + ", ".join(f"{n} {v:+.3f}" for n, v in ident.weakest.items()) + ".", "",
          "Laplace approximation (J^T J)^-1: predicted standard deviations", "",
          markdown_table(ident.rows(), {"x": ".6g", "reference": ".6g", "std": ".3g", "std_percent": ".3g"}),
          "Correlation matrix", "",
          markdown_table([{"": n, **{m: float(rho[i, j]) for j, m in enumerate(names)}} for i, n in enumerate(names)],
                         {m: "+.3f" for m in names}),
          f"Cost: {ident.n_evals} forward evaluations, {wall_s:.1f} s wall."]
    md += [f"- warning: {w}" for w in ident.warnings]
    (d / "identifiability.md").write_text("\n".join(md) + "\n")
    paths.append(d / "identifiability.md")
    paths.append(write_json(d / "identifiability.json", {
        "case": case_name, "mesh": mesh, "data": data_text, "x": dict(zip(names, ident.x)), **ident.summary(),
        "std": dict(zip(names, ident.std_x)), "correlation": rho, "fisher_z": ident.fisher_z,
        "cov_x": ident.cov_x, "wall_s": wall_s}))
    if figures:
        from bench.studies.figures import correlation_heatmap

        paths.append(correlation_heatmap(ident, d / "correlation.png",
                                         f"{case_name}: Laplace correlation, cond = {ident.condition:.3g}"))
    return paths


def run_identifiability(cases: list[str], *, mesh: str = "coarse", data: str = "auto", x: dict | None = None,
                        scheme: str = "forward", rel_step: float = 1e-6, mapper=None, out=None,
                        figures: bool = True, progress: bool = True) -> dict:
    """One directory per case plus, for several cases, a summary (``summary.csv/md``, ``std_percent.png``)."""
    from tqdm import tqdm

    results, paths, summary = {}, [], []
    t_all = time.perf_counter()
    for name in tqdm(cases, desc="identifiability", disable=not progress or len(cases) < 2):
        t0 = time.perf_counter()
        ident, obj, text = case_identifiability(name, mesh=mesh, data=data, x=x, scheme=scheme, rel_step=rel_step,
                                                mapper=mapper)
        wall = time.perf_counter() - t0
        d = output_dir("identifiability", name, out if out is None or len(cases) == 1 else Path(out) / name)
        paths += write_case(ident, name, d, mesh=mesh, data_text=text, wall_s=wall, figures=figures)
        results[name] = ident
        summary.append({"case": name, "condition": ident.condition, "rank": ident.rank,
                        "lambda_min": float(ident.eigenvalues[-1]), "lambda_max": float(ident.eigenvalues[0]),
                        **{f"sd% {n}": float(s) for n, s in zip(ident.names, ident.std_percent)},
                        "n_evals": ident.n_evals, "wall_s": wall})
    if len(cases) > 1:
        root = Path(out) if out else output_dir("identifiability", "summary")
        root.mkdir(parents=True, exist_ok=True)
        compact = [{"case": r["case"], "condition": r["condition"], "rank": r["rank"],
                    "std % (param: value)": ", ".join(f"{k[4:]}: {v:.3g}" for k, v in r.items() if k.startswith("sd% ")),
                    "n_evals": r["n_evals"], "wall_s": r["wall_s"]} for r in summary]
        (root / "summary.md").write_text(
            f"# Identifiability summary (mesh {mesh})\n\nCondition number of J^T J in z = x / reference and "
            "Laplace standard deviations in % of the reference.\n\n"
            + markdown_table(compact, {"condition": ".3g", "wall_s": ".1f"})
            + f"\nTotal wall time {time.perf_counter() - t_all:.1f} s.\n")
        paths.append(root / "summary.md")
        with (root / "summary.csv").open("w") as fh:  # ragged columns across forms: long format
            fh.write("case,parameter,std_percent,condition\n")
            for name, ident in results.items():
                for n, s in zip(ident.names, ident.std_percent):
                    fh.write(f"{name},{n},{s:.6g},{ident.condition:.6g}\n")
        paths.append(root / "summary.csv")
        if figures:
            from bench.studies.figures import std_percent_bars

            paths.append(std_percent_bars({k: dict(zip(v.names, v.std_percent)) for k, v in results.items()},
                                          root / "std_percent.png", f"Laplace standard deviations, mesh {mesh}"))
    return {"results": results, "summary": summary, "paths": paths}

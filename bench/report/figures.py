"""Report figures from the tidy DataFrames (matplotlib Agg, readable in black and white).

* :func:`history_figure` — like the paper's Figs 6–14 for one case and method: (a) normalised
  parameters x_i/x_i^REF against iteration, each parameter's box [lower, upper]/x_i^REF drawn as
  a bracket in the parameter's line style right of the last iteration, and a ring around a final
  value that lies on a bound (within ``BOUND_TOL`` of the box width), (b) cost against iteration
  (log scale), for the representative run (median final cost over seeds and starts).
* :func:`convergence_figure` — per case, across methods: best cost so far against forward
  evaluations (median over runs), log-log.
* :func:`ecdf_figure` — COCO-style empirical cumulative distribution of the forward
  evaluations needed to reach targets, per method: (a) cost targets
  ``J - J_best <= 10^-k (J_init - J_best)`` (``J_best`` the best cost any run reached on the
  case, ``J_init`` the median initial cost), (b) parameter targets
  ``max_i |x_i/x_i^REF - 1| <= 10 %, 1 %, 0.1 %``. One (run, target) pair counts once, at the
  first evaluation count where the target is met; pairs never met keep the curve below 1.

Every line differs by line style *and* marker (greys only), so the figures survive printing; style,
labels and saving: :mod:`bench.plotting`.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from bench.plotting import (
    DOUBLE,
    REFERENCE_LINE,
    SINGLE,
    integer_axis,
    line_style,
    log_axis,
    normalised_label,
    pyplot,
    save,
)
from bench.report.tables import bound_side, case_order, identified, method_order, normalised_box

COST_KS = (1, 2, 3, 4, 6, 8)
ERR_TARGETS = (10.0, 1.0, 0.1)
COST_LABEL = "cost $J$ (-)"


def _save(fig, path: Path, pdf: bool) -> list[Path]:
    png = save(fig, path.with_suffix(".png"), pdf=pdf)
    return [png] + ([png.with_suffix(".pdf")] if pdf else [])


def safe(name: str) -> str:
    """A file-name-safe version of a case or method name (``nlopt:BOBYQA`` -> ``nlopt-BOBYQA``)."""
    return "".join(
        c if c.isalnum() or c in "-_." else ("plus" if c == "+" else "-") for c in str(name)
    )


def _markevery(n: int) -> int:
    return max(1, n // 10)


def representative(runs: pd.DataFrame) -> pd.Series | None:
    """The run with the median final cost (lower median) among the identified runs."""
    ok = identified(runs)
    if not len(ok):
        return None
    ok = ok.assign(_c=ok["cost"].fillna(np.inf)).sort_values(
        ["_c", "seed", "start", "start_index"], kind="stable"
    )
    return ok.iloc[(len(ok) - 1) // 2]


def history_figure(
    run: pd.Series,
    hist: pd.DataFrame,
    params: list[str],
    path: Path,
    *,
    n_runs: int = 1,
    pdf: bool = False,
    bounds: dict | None = None,
) -> list[Path]:
    """(a) x_i/x_i^REF and (b) cost against iteration for one run.

    ``bounds``: ``{parameter: (lower, upper)}`` divided by the reference (default: the box of the
    run's case, :func:`bench.report.tables.normalised_box`); each is drawn as a bracket right of
    the last iteration, and a final value on a bound is ringed.
    """
    plt = pyplot()
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(DOUBLE[0], 3.4), constrained_layout=True)
    active = [p for p in params if f"xn.{p}" in hist and hist[f"xn.{p}"].notna().any()]
    it = hist["iteration"].to_numpy()
    bounds = normalised_box(str(run["case"])) if bounds is None else bounds
    x_end = float(np.nanmax(it)) if len(it) else 0.0
    dx = 0.035 * max(x_end - (float(np.nanmin(it)) if len(it) else 0.0), 1.0)
    ringed = []  # (iteration, value) of final values on a bound
    for i, p in enumerate(active):
        y = hist[f"xn.{p}"].to_numpy(float)
        style = line_style(i)
        ax1.plot(it, y, label=normalised_label(p), markevery=_markevery(len(it)), **style)
        if p not in bounds:
            continue
        lo, hi = bounds[p]
        xb = x_end + (i + 1) * dx  # the box of parameter i: a bracket in its own line style
        ax1.plot(
            [xb, xb], [lo, hi], color=style["color"], linestyle=style["linestyle"], linewidth=0.8
        )
        ax1.plot(
            [xb, xb],
            [lo, hi],
            color=style["color"],
            linestyle="none",
            marker=style["marker"],
            markersize=3,
        )
        ax1.plot(
            [xb - 0.4 * dx, xb + 0.4 * dx] * 2,
            [lo, lo, hi, hi],
            color=style["color"],
            linestyle="none",
            marker="_",
            markersize=6,
        )
        finite = np.flatnonzero(np.isfinite(y))
        if len(finite) and bound_side(float(y[finite[-1]]), lo, hi):
            ringed.append((it[finite[-1]], y[finite[-1]]))
    if ringed:
        ax1.plot(
            *zip(*ringed),
            linestyle="none",
            marker="o",
            markersize=10,
            markerfacecolor="none",
            markeredgecolor="0.0",
            markeredgewidth=0.8,
            label="on a bound",
        )
    if bounds and active:
        from matplotlib.lines import Line2D

        ax1.add_line(
            Line2D(
                [],
                [],
                color="0.0",
                linestyle="-",
                marker="_",
                markersize=6,
                linewidth=0.8,
                label="box [lower, upper]",
            )
        )  # legend proxy of the brackets
    ax1.axhline(1.0, **REFERENCE_LINE)
    ax1.set_xlabel("iteration (-)")
    integer_axis(ax1, "x")
    if bounds and active:  # the brackets sit right of the last iteration: no iteration ticks there
        ax1.axvline(x_end + 0.5 * dx, color="0.8", linewidth=0.6)
        ticks = [t for t in ax1.get_xticks() if t <= x_end + 1e-9 and t >= ax1.get_xlim()[0]]
        ax1.set_xticks(ticks)
    ax1.set_ylabel(r"normalised parameter $x_i/x_i^{\mathrm{REF}}$ (-)")
    ax1.set_title("(a) parameters", loc="left")
    if active:
        ax1.legend(ncols=2 if len(active) > 3 else 1)
    cost = hist["cost"].to_numpy(float)
    best = hist["best_cost"].to_numpy(float)
    if np.any(np.isfinite(cost) & (cost > 0)):
        ax2.plot(
            it,
            np.where(cost > 0, cost, np.nan),
            color="0.55",
            linestyle="none",
            marker="o",
            markersize=3,
            label="cost of iterate",
        )
    if np.any(np.isfinite(best) & (best > 0)):
        ax2.plot(
            it,
            np.where(best > 0, best, np.nan),
            color="0.0",
            linestyle="-",
            label="best cost so far",
        )
        log_axis(ax2, "y")
    ax2.set_xlabel("iteration (-)")
    integer_axis(ax2, "x")
    ax2.set_ylabel(COST_LABEL)
    ax2.set_title("(b) cost", loc="left")
    ax2.legend()
    start = (
        "default start" if run["start"] == "default" else f"random start {int(run['start_index'])}"
    )
    what = f"median-cost run of {n_runs}" if n_runs > 1 else "single run"
    fig.suptitle(
        f"{run['case']} — {run['method']} (budget {int(run['budget'])}, seed {int(run['seed'])}, "
        f"{start}; {what}; {int(run['n_evals'])} evaluations, status {run['status']})",
        fontsize=8,
    )
    return _save(fig, path, pdf)


def _best_curve(h: pd.DataFrame, final: pd.Series | None = None) -> tuple[np.ndarray, np.ndarray]:
    ev = h["n_evals"].to_numpy(float)
    bc = h["best_cost"].to_numpy(float)
    if final is not None:
        ev = np.append(ev, float(final["n_evals"]))
        bc = np.append(bc, float(final["cost"]))
    order = np.argsort(ev, kind="stable")
    ev, bc = ev[order], bc[order]
    bc = np.fmin.accumulate(np.where(np.isnan(bc), np.inf, bc))
    return ev, bc


def convergence_figure(
    case: str,
    runs: pd.DataFrame,
    history: pd.DataFrame,
    path: Path,
    *,
    methods: list[str],
    pdf: bool = False,
) -> list[Path]:
    """Best cost so far against forward evaluations, median over the runs of each method."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=SINGLE, constrained_layout=True)
    hist_by = dict(tuple(history.groupby("config_hash"))) if len(history) else {}
    emax = max(
        2.0, float(runs["n_evals"].max()), float(history["n_evals"].max()) if len(history) else 0.0
    )
    grid = np.unique(np.round(np.geomspace(1.0, emax, 80)))
    for i, m in enumerate(methods):
        rm = identified(runs[runs["method"] == m])
        curves = []
        for _, r in rm.iterrows():
            h = hist_by.get(r["config_hash"])
            ev, bc = _best_curve(h if h is not None else history.iloc[0:0], r)
            idx = np.searchsorted(ev, grid, side="right") - 1
            y = np.where(idx >= 0, bc[np.clip(idx, 0, None)], np.nan)
            curves.append(np.where(np.isfinite(y), y, np.nan))
        if not curves:
            continue
        arr = np.array(curves)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns before the first row
            med = np.nanmedian(arr, axis=0)
        med = np.where(med > 0, med, np.nan)
        if np.isfinite(med).any():
            ax.plot(
                grid,
                med,
                label=f"{m} ({len(curves)})",
                markevery=_markevery(len(grid)),
                **line_style(i),
            )
    log_axis(ax, "x")
    if any(line.get_ydata().size for line in ax.get_lines()):
        log_axis(ax, "y")
    ax.set_xlabel("forward evaluations (-)")
    ax.set_ylabel("best " + COST_LABEL)
    ax.set_title(f"{case}: best cost, median over runs", fontsize=9)
    ax.legend(loc="center left", bbox_to_anchor=(1.01, 0.5))
    return _save(fig, path, pdf)


def cost_targets(runs_case: pd.DataFrame, hist_case: pd.DataFrame) -> np.ndarray:
    """The cost targets of one case (empty when they cannot be defined)."""
    costs = [runs_case["cost"].to_numpy(float)]
    if len(hist_case):
        costs.append(hist_case["best_cost"].to_numpy(float))
    allc = np.concatenate(costs)
    allc = allc[np.isfinite(allc)]
    if not len(allc) or not len(hist_case):
        return np.array([])
    first = (
        hist_case.sort_values("iteration").groupby("config_hash")["cost"].first().to_numpy(float)
    )
    first = first[np.isfinite(first)]
    if not len(first):
        return np.array([])
    f_best, f_init = float(allc.min()), float(np.median(first))
    if not f_init > f_best:
        return np.array([])
    return np.array([f_best + 10.0 ** (-k) * (f_init - f_best) for k in COST_KS])


def runtimes(runs: pd.DataFrame, history: pd.DataFrame) -> dict[str, dict[str, list]]:
    """Per method: evaluations to reach each (run, target) pair (inf if never) for the cost and
    parameter targets, pooled over the cases present in ``runs``."""
    out: dict[str, dict[str, list]] = {}
    hist_by = dict(tuple(history.groupby("config_hash"))) if len(history) else {}
    for case, rc in runs.groupby("case", sort=False):
        hc = history[history["case"] == case] if len(history) else history
        targets = cost_targets(rc, hc)
        for _, r in rc.iterrows():
            d = out.setdefault(r["method"], {"cost": [], "err": []})
            h = hist_by.get(r["config_hash"])
            if r.get("crashed", False):
                d["cost"] += [math.inf] * len(targets)
                d["err"] += [math.inf] * len(ERR_TARGETS)
                continue
            ev, bc = _best_curve(h if h is not None else history.iloc[0:0], r)
            for t in targets:
                hit = np.nonzero(bc <= t)[0]
                d["cost"].append(float(ev[hit[0]]) if len(hit) else math.inf)
            if h is not None and len(h):
                hev = np.append(h["n_evals"].to_numpy(float), float(r["n_evals"]))
                herr = np.append(h["max_abs_err"].to_numpy(float), float(r["max_abs_err"]))
            else:
                hev, herr = np.array([float(r["n_evals"])]), np.array([float(r["max_abs_err"])])
            for t in ERR_TARGETS:
                hit = np.nonzero(herr <= t)[0]
                d["err"].append(float(hev[hit[0]]) if len(hit) else math.inf)
    return out


def _ecdf(ax, hits: list[float], xmax: float, **kw) -> None:
    hits = np.asarray(hits, float)
    if not len(hits):
        return
    finite = np.sort(hits[np.isfinite(hits)])
    x = np.concatenate([[1.0], np.maximum(finite, 1.0), [xmax]])
    y = np.concatenate(
        [[0.0], np.arange(1, len(finite) + 1) / len(hits), [len(finite) / len(hits)]]
    )
    ax.step(x, y, where="post", markevery=_markevery(len(x)), **kw)


def ecdf_figure(
    title: str,
    runs: pd.DataFrame,
    history: pd.DataFrame,
    path: Path,
    *,
    methods: list[str],
    pdf: bool = False,
) -> list[Path]:
    """Runtime ECDFs: (a) cost targets, (b) parameter-error targets, one line per method."""
    plt = pyplot()
    rt = runtimes(runs, history)
    xmax = max(2.0, float(runs["budget"].max()), float(runs["n_evals"].max()))
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=DOUBLE, sharey=True, constrained_layout=True)
    for i, m in enumerate(methods):
        if m not in rt:
            continue
        _ecdf(ax1, rt[m]["cost"], xmax, label=m, **line_style(i))
        _ecdf(ax2, rt[m]["err"], xmax, label=m, **line_style(i))
    ks = ", ".join(str(k) for k in COST_KS)
    ax1.set_title(
        rf"(a) $J - J_\mathrm{{best}} \leq 10^{{-k}}(J_\mathrm{{init}} - J_\mathrm{{best}})$, k = "
        rf"{ks}",
        loc="left",
        fontsize=8,
    )
    ax2.set_title(
        "(b) max$_i$ |x$_i$/x$_i^\\mathrm{REF}$ − 1| ≤ "
        + ", ".join(f"{t:g}" for t in ERR_TARGETS)
        + " %",
        loc="left",
        fontsize=8,
    )
    for ax in (ax1, ax2):
        log_axis(ax, "x")
        ax.set_xlim(1.0, xmax * 1.05)
        ax.set_ylim(-0.02, 1.02)
        ax.set_xlabel("forward evaluations (-)")
    ax1.set_ylabel("fraction of (run, target) pairs reached (-)")
    ax2.legend(loc="center left", bbox_to_anchor=(1.01, 0.5))
    fig.suptitle(title, fontsize=9)
    return _save(fig, path, pdf)


def write_figures(
    runs: pd.DataFrame,
    history: pd.DataFrame,
    fig_dir: Path,
    *,
    pdf: bool = False,
    progress: bool = False,
) -> dict:
    """All figures; returns ``{"history": {(case, method, budget): path}, "convergence":
    {case: path}, "ecdf": {case: path}, "ecdf_all": path}`` (PNG paths). ``progress``: a tqdm bar on
    stderr."""
    import sys

    from tqdm import tqdm

    params = runs.attrs.get("parameters") or []
    cases, methods = case_order(runs["case"].unique()), method_order(runs["method"].unique())
    hist_by = dict(tuple(history.groupby("config_hash"))) if len(history) else {}
    out: dict = {"history": {}, "convergence": {}, "ecdf": {}, "ecdf_all": None}
    groups = list(runs.groupby(["case", "method", "budget"], sort=False))
    bar = tqdm(
        total=len(groups) + 2 * len(cases) + (len(cases) > 1),
        desc="report figures",
        unit="fig",
        file=sys.stderr,
        disable=not progress,
        leave=False,
    )
    for (case, method, budget), g in groups:
        bar.update()
        rep = representative(g)
        if rep is None:
            continue
        h = hist_by.get(rep["config_hash"])
        if h is None or not len(h):
            continue
        several = runs[(runs["case"] == case) & (runs["method"] == method)]["budget"].nunique() > 1
        name = f"{safe(case)}__{safe(method)}" + (f"__b{int(budget)}" if several else "")
        p = history_figure(rep, h, params, fig_dir / "history" / name, n_runs=len(g), pdf=pdf)
        out["history"][(case, method, int(budget))] = p[0]
    for case in cases:
        bar.update(2)
        rc = runs[runs["case"] == case]
        hc = history[history["case"] == case] if len(history) else history
        ms = [m for m in methods if m in set(rc["method"])]
        out["convergence"][case] = convergence_figure(
            case, rc, hc, fig_dir / f"{safe(case)}__convergence", methods=ms, pdf=pdf
        )[0]
        out["ecdf"][case] = ecdf_figure(
            f"{case}: runtime ECDF over {len(rc)} runs",
            rc,
            hc,
            fig_dir / f"{safe(case)}__ecdf",
            methods=ms,
            pdf=pdf,
        )[0]
    if len(cases) > 1:
        bar.update()
        out["ecdf_all"] = ecdf_figure(
            f"all {len(cases)} cases: runtime ECDF over {len(runs)} runs",
            runs,
            history,
            fig_dir / "all__ecdf",
            methods=methods,
            pdf=pdf,
        )[0]
    bar.close()
    return out

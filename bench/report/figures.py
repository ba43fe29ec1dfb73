"""Report figures from the tidy DataFrames (matplotlib Agg, readable in black and white).

* :func:`family_figures` — like the paper's Figs 6–14, one figure per case and method family
  (local / global / sampling), one row per method: (a) normalised parameters x_i/x_i^REF (and the
  derived a) against iteration of the run with the median final cost, a ring and a title note at
  every final value on a bound of the case's box; (b) cost against iteration with the range of
  the best cost over the method's runs. More than :data:`FAMILY_ROWS` methods: further pages.
* :func:`ecdf_figure` — COCO-style runtime ECDFs, one column per (track, tier): the fraction of
  (run, target) pairs reached within a number of forward-equivalents (forward evaluations for
  frames not prepared by :func:`bench.report.metrics.prepare`); (a) cost targets
  ``J - J_best <= 10^-k (J_init - J_best)`` per objective
  (:func:`bench.report.metrics.cost_targets`), (b) parameter targets ``max_i |x_i/x_i^REF - 1| <=
  10 %, 1 %, 0.1 %``. One (run, target) pair counts once, at the first point where the target is
  met; pairs never met keep the curve below 1.
* :func:`posterior_figure` — per case the posterior intervals against the Laplace approximation.
* :func:`convergence_figure` — per case: best cost so far against forward-equivalents (median
  over the runs of each method), one panel per (track, tier) (``write_figures(best_cost=True)``).
* :func:`history_figure` — one run's (a) x_i/x_i^REF with the box as brackets and (b) cost.

Many-panel figures are drawn on a fixed :func:`grid` without a layout engine and saved once at
:data:`REPORT_DPI` (:func:`_save_fast`) so that hundreds of runs report in about a minute. Every
line differs by line style *and* marker (greys only); style and labels: :mod:`bench.plotting`.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from bench.experiment.store import parameter_order
from bench.plotting import (
    DOUBLE,
    LABELS,
    REFERENCE_LINE,
    integer_axis,
    line_style,
    log_axis,
    normalised_label,
    pyplot,
    save,
)
from bench.report.catalogue import family
from bench.report.metrics import (
    COST_KS,
    ERR_TARGETS,
    FAMILIES,
    cost_targets,
    fe_at,
    objective_targets,
)
from bench.report.tables import (
    BOUND_MARK,
    bound_side,
    case_order,
    identified,
    method_order,
    normalised_box,
)

COST_LABEL = "cost $J$ (-)"


def _save(fig, path: Path, pdf: bool, **kw) -> list[Path]:
    """Save ``fig`` as ``path`` with the suffix ``.png`` (and a PDF with ``pdf``; ``kw``: see
    :func:`bench.plotting.save`); return the files written."""
    png = save(fig, Path(path).with_suffix(".png"), pdf=pdf, **kw)
    return [png] + ([png.with_suffix(".pdf")] if pdf else [])


#: resolution of the report's many-panel figures (PNG): they are drawn once, without a tight
#: bounding box or constrained layout, so that a folder of hundreds of runs reports in a minute
REPORT_DPI = 110


def grid(
    nrows: int,
    ncols: int,
    *,
    panel: tuple[float, float],
    top: float = 0.5,
    bottom: float = 0.55,
    left: float = 0.75,
    right: float = 0.25,
    hgap: float = 0.55,
    wgap: float = 0.6,
    **kw,
):
    """``(fig, axes)``: an ``nrows`` x ``ncols`` grid of ``panel``-sized axes (inches) with fixed
    margins and gaps (inches); no layout engine (cheap to draw)."""
    plt = pyplot()
    w = left + right + ncols * panel[0] + (ncols - 1) * wgap
    h = top + bottom + nrows * panel[1] + (nrows - 1) * hgap
    fig, axes = plt.subplots(nrows, ncols, figsize=(w, h), squeeze=False, **kw)
    fig.subplots_adjust(
        left=left / w,
        right=1 - right / w,
        bottom=bottom / h,
        top=1 - top / h,
        hspace=hgap / panel[1],
        wspace=wgap / panel[0],
    )
    return fig, axes


def _save_fast(fig, path: Path, pdf: bool) -> list[Path]:
    """Save a :func:`grid` figure: PNG at :data:`REPORT_DPI` (and PDF), one draw, no tight box."""
    return _save(fig, path, pdf, dpi=REPORT_DPI, tight=False)


def light_log(ax, axis: str = "y") -> None:
    """A log axis that is cheap to draw (decades only, no minor ticks): for many-panel figures."""
    from matplotlib.ticker import LogLocator, NullLocator

    getattr(ax, f"set_{axis}scale")("log")
    a = getattr(ax, f"{axis}axis")
    lim = ax.dataLim.intervaly if axis == "y" else ax.dataLim.intervalx
    lo, hi = float(min(lim)), float(max(lim))
    narrow = lo > 0 and np.isfinite(hi) and hi / lo < 100.0  # under 2 decades: 1, 2, 5
    subs = (1.0, 2.0, 5.0) if narrow else (1.0,)
    a.set_major_locator(LogLocator(base=10.0, subs=subs, numticks=4 if not narrow else 8))
    a.set_minor_locator(NullLocator())
    if narrow:
        from matplotlib.ticker import FuncFormatter

        a.set_major_formatter(FuncFormatter(_mantissa_tick))


def _mantissa_tick(v: float, pos=None) -> str:
    """``2×10^6`` style (``10^6`` for a decade), plain between 0.01 and 10 000."""
    if not v > 0:
        return ""
    if 1e-2 <= v < 1e4:
        return f"{v:g}"
    k = int(np.floor(np.log10(v) + 1e-9))
    m = v / 10.0**k
    return f"$10^{{{k}}}$" if abs(m - 1) < 1e-6 else f"${m:.0f}\\times10^{{{k}}}$"


def light_int(ax, axis: str = "x") -> None:
    """At most five integer ticks."""
    from matplotlib.ticker import MaxNLocator

    getattr(ax, f"{axis}axis").set_major_locator(MaxNLocator(nbins=4, integer=True))


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
    if "n_evals" in h and "best_cost" in h:
        ev = h["n_evals"].to_numpy(float)
        bc = h["best_cost"].to_numpy(float)
    else:  # no history rows
        ev, bc = np.array([]), np.array([])
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
    """Best cost so far against forward-equivalents (forward evaluations for unprepared frames),
    median over the runs of each method; one panel per (track, tier)."""

    fcs = facets(runs)
    nc = len(fcs)
    n_leg = max((runs[_facet_mask(runs, *f)]["method"].nunique() for f in fcs), default=1)
    fig, axes = grid(1, nc, panel=(3.6, 3.0), bottom=0.75 + 0.13 * n_leg, top=0.6)
    hist_by = dict(tuple(history.groupby("config_hash"))) if len(history) else {}
    use_fe = "fe_total" in runs
    xcol = "fe_total" if use_fe else "n_evals"
    emax = max(2.0, float(np.nanmax(runs[xcol].to_numpy(float))) if len(runs) else 2.0)
    xs = np.unique(np.round(np.geomspace(1.0, emax, 80)))
    for j, (track, tier) in enumerate(fcs):
        ax = axes[0, j]
        rf = _facet(runs, track, tier)
        for i, m in enumerate([m for m in methods if m in set(rf["method"])]):
            rm = identified(rf[rf["method"] == m])
            curves = []
            for _, r in rm.iterrows():
                h = hist_by.get(r["config_hash"])
                ev, bc = _best_curve(h if h is not None else history.iloc[0:0], r)
                if use_fe:
                    ev = fe_at(r, ev)
                idx = np.searchsorted(ev, xs, side="right") - 1
                y = np.where(idx >= 0, bc[np.clip(idx, 0, None)], np.nan)
                curves.append(np.where(np.isfinite(y), y, np.nan))
            if not curves:
                continue
            arr = np.array(curves)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN before the first row
                med = np.nanmedian(arr, axis=0)
            med = np.where(med > 0, med, np.nan)
            if np.isfinite(med).any():
                ax.plot(
                    xs,
                    med,
                    label=f"{m} ({len(curves)})",
                    markevery=_markevery(len(xs)),
                    **line_style(i),
                )
        log_axis(ax, "x")
        if any(line.get_ydata().size for line in ax.get_lines()):
            log_axis(ax, "y")
        ax.set_xlabel("forward-equivalents (-)" if use_fe else "forward evaluations (-)")
        ax.set_title(f"{track} track, {tier} data", loc="left", fontsize=8)
        if ax.get_lines():
            ax.legend(loc="upper left", bbox_to_anchor=(0.0, -0.16), ncols=1, fontsize=6)
    axes[0, 0].set_ylabel("best " + COST_LABEL)
    fig.suptitle(f"{case}: best cost, median over runs (number of runs)", fontsize=9)
    return _save_fast(fig, path, pdf)


def runtimes(runs: pd.DataFrame, history: pd.DataFrame) -> dict[str, dict[str, list]]:
    """Per method: the runtime to reach each (run, target) pair (inf if never) for the cost and
    parameter targets, pooled over the objectives present in ``runs``.

    With the report's prepared frames (:func:`bench.report.metrics.prepare`) the targets are those
    of each objective (case | tier | treatment: runs on different data never share a best known
    cost) and the runtime is in forward-equivalents (:func:`bench.report.metrics.fe_at`: charges
    up front, then the run's measured forward-equivalents per evaluation); otherwise per case and
    in forward evaluations."""

    out: dict[str, dict[str, list]] = {}
    hist_by = dict(tuple(history.groupby("config_hash"))) if len(history) else {}
    by = "objective" if "objective" in runs else "case"
    use_fe = "fe_solver" in runs
    hist_obj = dict(tuple(history.groupby(by))) if len(history) and by in history else {}
    for key, rc in runs.groupby(by, sort=False):
        hc = hist_obj.get(key, history.iloc[0:0])
        targets = objective_targets(rc, hc) if use_fe else cost_targets(rc, hc)
        for _, r in rc.iterrows():
            d = out.setdefault(r["method"], {"cost": [], "err": []})
            h = hist_by.get(r["config_hash"])
            if r.get("crashed", False):
                d["cost"] += [math.inf] * len(targets)
                d["err"] += [math.inf] * len(ERR_TARGETS)
                continue
            ev, bc = _best_curve(h if h is not None else history.iloc[0:0], r)
            if use_fe:
                ev = fe_at(r, ev)
            for t in targets:
                hit = np.nonzero(bc <= t)[0]
                d["cost"].append(float(ev[hit[0]]) if len(hit) else math.inf)
            if h is not None and len(h):
                hev = np.append(h["n_evals"].to_numpy(float), float(r["n_evals"]))
                herr = np.append(h["max_abs_err"].to_numpy(float), float(r["max_abs_err"]))
            else:
                hev, herr = np.array([float(r["n_evals"])]), np.array([float(r["max_abs_err"])])
            if use_fe:
                hev = fe_at(r, hev)
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


def facets(runs: pd.DataFrame) -> list[tuple[str, str]]:
    """The (track, tier) combinations present, FE track first (``("fe", tier)`` when the frame
    has no track column)."""
    tracks = runs["track"] if "track" in runs else pd.Series("fe", index=runs.index)
    tiers = runs["tier"] if "tier" in runs else pd.Series("model-error", index=runs.index)
    pairs = set(zip(tracks.astype(str), tiers.astype(str)))
    return sorted(pairs, key=lambda p: (p[0] != "fe", p[0], p[1]))


def _facet_mask(runs: pd.DataFrame, track: str, tier: str) -> pd.Series:
    sel = pd.Series(True, index=runs.index)
    if "track" in runs:
        sel &= runs["track"].astype(str) == track
    if "tier" in runs:
        sel &= runs["tier"].astype(str) == tier
    return sel


def _facet(runs: pd.DataFrame, track: str, tier: str) -> pd.DataFrame:
    return runs[_facet_mask(runs, track, tier)]


def ecdf_figure(
    title: str,
    runs: pd.DataFrame,
    history: pd.DataFrame,
    path: Path,
    *,
    methods: list[str],
    pdf: bool = False,
) -> list[Path]:
    """Runtime ECDFs, one column per (track, tier): (a) cost targets, (b) parameter-error targets,
    one line per method (the same style for a method in every figure: its index in
    ``methods``)."""
    use_fe = "fe_total" in runs
    xcol = "fe_total" if use_fe else "n_evals"
    xmax = max(2.0, float(np.nanmax(runs[xcol].to_numpy(float))) if len(runs) else 2.0)
    if not use_fe:
        xmax = max(xmax, float(runs["budget"].max()))
    fcs = facets(runs)
    nc = len(fcs)
    n_leg = max((runs[_facet_mask(runs, *f)]["method"].nunique() for f in fcs), default=1)
    fig, axes = grid(
        2, nc, panel=(3.6, 2.6), bottom=0.75 + 0.13 * n_leg, top=0.95, hgap=0.75, sharey=True
    )
    ks = ", ".join(str(k) for k in COST_KS)
    for j, (track, tier) in enumerate(fcs):
        rf = _facet(runs, track, tier)
        hf = history[history["config_hash"].isin(rf["config_hash"])] if len(history) else history
        rt = runtimes(rf, hf)
        ax1, ax2 = axes[0, j], axes[1, j]
        for i, m in enumerate([m for m in methods if m in rt]):
            st = line_style(i)  # distinct within the panel (each column has its own legend)
            _ecdf(ax1, rt[m]["cost"], xmax, label=m, **st)
            _ecdf(ax2, rt[m]["err"], xmax, **st)
        head = f"{track} track, {tier} data" if nc > 1 or "track" in runs else ""
        ax1.set_title(
            (head + "\n" if head else "")
            + r"(a) $J - J_\mathrm{best} \leq 10^{-k}(J_\mathrm{init} - J_\mathrm{best})$,"
            + f" k = {ks}",
            loc="left",
            fontsize=7,
        )
        ax2.set_title(
            "(b) max$_i$ |x$_i$/x$_i^\\mathrm{REF}$ − 1| ≤ "
            + ", ".join(f"{t:g}" for t in ERR_TARGETS)
            + " %",
            loc="left",
            fontsize=7,
        )
        for ax in (ax1, ax2):
            light_log(ax, "x")
            ax.set_xlim(1.0, xmax * 1.05)
            ax.set_ylim(-0.02, 1.02)
        ax2.set_xlabel("forward-equivalents (-)" if use_fe else "forward evaluations (-)")
        if ax1.get_lines():
            ax2.legend(
                *ax1.get_legend_handles_labels(),
                loc="upper left",
                bbox_to_anchor=(0.0, -0.2),
                ncols=1,
                fontsize=6,
            )
    for i in range(2):
        axes[i, 0].set_ylabel("fraction of pairs reached (-)")
    fig.suptitle(title, fontsize=9)
    return _save_fast(fig, path, pdf)


FAMILY_ROWS = 8  # method rows per convergence figure (more go onto a second page)


def _final_bound_hits(case: str, hist: pd.DataFrame, params: list[str]) -> list[tuple[str, int]]:
    """``(parameter, side)`` of the final history values that lie on a bound of the case's box."""
    box = case_box_normalised(case)
    out = []
    for p in params:
        col = f"xn.{p}"
        if p not in box or col not in hist:
            continue
        y = hist[col].to_numpy(float)
        fin = y[np.isfinite(y)]
        if len(fin):
            side = bound_side(float(fin[-1]), *box[p])
            if side:
                out.append((p, side))
    return out


def case_box_normalised(case: str) -> dict[str, tuple[float, float]]:
    return normalised_box(case)


def family_figures(
    case: str,
    fam: str,
    runs: pd.DataFrame,
    history: pd.DataFrame,
    path: Path,
    *,
    methods: list[str],
    params: list[str],
    pdf: bool = False,
) -> list[Path]:
    """Like the paper's Figs 6–14 for one case and one method family: one row per method, (a)
    normalised parameters x_i/x_i^REF (and the derived a, thin) against iteration of the method's
    representative run (median final cost), a ring and a note at every final value on a bound of
    the case's box; (b) cost against iteration: the representative run's iterates and best cost,
    and the range of the best cost over all runs of the method (band). More than
    :data:`FAMILY_ROWS` methods go onto further pages (``path__2`` ...). Returns the PNG paths."""
    from matplotlib.lines import Line2D
    from matplotlib.ticker import MaxNLocator

    hist_by = dict(tuple(history.groupby("config_hash"))) if len(history) else {}
    rows = []
    for m in methods:
        g = runs[runs["method"] == m]
        rep = representative(g)
        if rep is None:
            continue
        h = hist_by.get(rep["config_hash"])
        if h is None or not len(h):
            continue
        rows.append((m, g, rep, h))
    if not rows:
        return []
    active = [
        p for p in params if any(f"xn.{p}" in h and h[f"xn.{p}"].notna().any() for *_, h in rows)
    ]
    styles = {p: line_style(i) for i, p in enumerate(active)}
    out = []
    pages = [rows[i : i + FAMILY_ROWS] for i in range(0, len(rows), FAMILY_ROWS)]
    for k, page in enumerate(pages):
        fig, axes = grid(len(page), 2, panel=(3.8, 1.55), top=1.0, bottom=0.5, hgap=0.5, wgap=0.95)
        for i, (m, g, rep, h) in enumerate(page):
            ax1, ax2 = axes[i]
            it, phases = continued_iterations(h["iteration"].to_numpy(float))
            for x in phases:  # e.g. the FE polish after the surrogate phase
                ax1.axvline(x, color="0.4", linewidth=0.7, linestyle=(0, (4, 2)))
                ax1.text(
                    x,
                    1.0,
                    " FE polish" if rep.get("track") == "surrogate" else " next phase",
                    transform=ax1.get_xaxis_transform(),
                    fontsize=6,
                    va="top",
                    ha="left",
                    color="0.3",
                )
            for p in active:
                col = f"xn.{p}"
                if col not in h or not h[col].notna().any():
                    continue
                st = dict(styles[p])
                if p == "a":  # derived, not identified: thinner
                    st = st | {"linewidth": 0.7}
                ax1.plot(it, h[col].to_numpy(float), markevery=_markevery(len(it)), **st)
            hits = _final_bound_hits(case, h, active)
            notes = []
            for p, side in hits:
                y = h[f"xn.{p}"].to_numpy(float)
                j = np.flatnonzero(np.isfinite(y))[-1]
                ax1.plot(
                    [it[j]],
                    [y[j]],
                    linestyle="none",
                    marker="o",
                    markersize=10,
                    markerfacecolor="none",
                    markeredgecolor="0.0",
                    markeredgewidth=0.9,
                )
                notes.append(f"{p} on {'upper' if side > 0 else 'lower'} bound")
            ax1.axhline(1.0, **REFERENCE_LINE)
            ax1.yaxis.set_major_locator(MaxNLocator(nbins=4))
            ax1.set_ylabel(r"$x_i/x_i^{\mathrm{REF}}$ (-)")
            light_int(ax1)
            start = "default" if rep["start"] == "default" else f"random {int(rep['start_index'])}"
            note = f" — {BOUND_MARK} " + "; ".join(notes) if notes else ""
            ax1.set_title(
                f"{m}: run of median cost of {len(g)} (seed {int(rep['seed'])}, {start} start)"
                + note,
                loc="left",
                fontsize=7,
            )
            _cost_panel(ax2, g, h, hist_by)
            light_int(ax2)
            ax2.set_ylabel(COST_LABEL)
            if i == len(page) - 1:
                ax1.set_xlabel("iteration (-)")
                ax2.set_xlabel("iteration (-)")
        handles = [Line2D([], [], **styles[p], label=LABELS.get(p, p)) for p in active]
        handles.append(
            Line2D(
                [],
                [],
                linestyle="none",
                marker="o",
                markersize=8,
                markerfacecolor="none",
                markeredgecolor="0.0",
                label="final value on a bound",
            )
        )
        handles += [
            Line2D(
                [],
                [],
                color="0.55",
                linestyle="none",
                marker="o",
                markersize=3,
                label="cost of iterate",
            ),
            Line2D([], [], color="0.0", linestyle="-", label="best cost so far"),
            Line2D([], [], color="0.85", linewidth=6, label="best cost, range over runs"),
        ]
        page_note = f" (page {k + 1} of {len(pages)})" if len(pages) > 1 else ""
        fig.legend(
            handles=handles,
            loc="upper center",
            ncols=min(6, len(handles)),
            title=f"{case}: {fam} methods{page_note}",
            title_fontsize=9,
        )
        name = path if k == 0 else path.with_name(f"{path.name}__{k + 1}")
        out.append(_save_fast(fig, name, pdf)[0])
    return out


def continued_iterations(it) -> tuple[np.ndarray, list[float]]:
    """Iterations made increasing: a phase that counts from the start again (the surrogate track's
    FE polish after the surrogate phase) continues after the previous phase's last iteration.
    Returns the continued iterations and where each new phase starts (between two iterations)."""
    it = np.asarray(it, float)
    out = it.copy()
    starts, offset = [], 0.0
    for i in range(1, len(it)):
        if np.isfinite(it[i]) and np.isfinite(it[i - 1]) and it[i] < it[i - 1]:
            offset = out[i - 1] + 1.0 - it[i]
            starts.append(out[i - 1] + 0.5)
        out[i] = it[i] + offset
    return out, starts


def _cost_panel(ax, g: pd.DataFrame, h: pd.DataFrame, hist_by: dict) -> None:
    """Cost against iteration: the band of the best cost over the runs ``g``, the representative
    run's iterate costs (dots) and best cost (line); log scale when positive."""
    curves = []
    for ch in g["config_hash"]:
        hh = hist_by.get(ch)
        if hh is not None and len(hh):
            c = hh[["iteration", "best_cost"]].to_numpy(float)
            c[:, 0] = continued_iterations(c[:, 0])[0]
            curves.append(c)
    if len(curves) > 1:
        n = int(max(c[:, 0].max() for c in curves)) + 1
        n = min(n, 5000)
        grid = np.arange(n, dtype=float)
        arr = np.full((len(curves), n), np.nan)
        for i, c in enumerate(curves):
            idx = np.searchsorted(c[:, 0], grid, side="right") - 1
            bc = np.fmin.accumulate(np.where(np.isfinite(c[:, 1]), c[:, 1], np.inf))
            arr[i] = np.where(idx >= 0, bc[np.clip(idx, 0, None)], np.nan)
        arr = np.where(np.isfinite(arr) & (arr > 0), arr, np.nan)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            lo, hi = np.nanmin(arr, axis=0), np.nanmax(arr, axis=0)
        ax.fill_between(grid, lo, hi, color="0.85", linewidth=0, step="post")
    it, phases = continued_iterations(h["iteration"].to_numpy(float))
    for x in phases:
        ax.axvline(x, color="0.4", linewidth=0.7, linestyle=(0, (4, 2)))
    cost = h["cost"].to_numpy(float)
    best = h["best_cost"].to_numpy(float)
    ax.plot(
        it,
        np.where(cost > 0, cost, np.nan),
        color="0.55",
        linestyle="none",
        marker="o",
        markersize=2.5,
    )
    ax.plot(it, np.where(best > 0, best, np.nan), color="0.0", linestyle="-")
    if np.any(np.isfinite(best) & (best > 0)):
        light_log(ax, "y")


def write_figures(
    runs: pd.DataFrame,
    history: pd.DataFrame,
    fig_dir: Path,
    *,
    pdf: bool = False,
    progress: bool = False,
    posterior: pd.DataFrame | None = None,
    best_cost: bool = False,
) -> dict:
    """All figures; returns ``{"family": {(case, family): [paths]}, "convergence": {case: path},
    "ecdf": {case: path}, "ecdf_all": path, "posterior": {case: path}}`` (PNG paths).
    ``posterior``: :func:`bench.report.posterior.posterior_frame` (a panel per case).
    ``best_cost``: also the best-cost-against-forward-equivalents figure of each case.
    ``progress``: a tqdm bar on stderr."""
    import sys

    from tqdm import tqdm

    params = runs.attrs.get("parameters") or []
    cases, methods = case_order(runs["case"].unique()), method_order(runs["method"].unique())
    fams = runs["family"] if "family" in runs else runs["method"].map(lambda m: family(m))
    fam_list = [f for f in FAMILIES if f in set(fams)] + sorted(set(fams) - set(FAMILIES))
    post_cases = [] if posterior is None or not len(posterior) else list(posterior["case"].unique())
    out: dict = {"family": {}, "convergence": {}, "ecdf": {}, "ecdf_all": None, "posterior": {}}
    bar = tqdm(
        total=len(cases) * (2 + len(fam_list)) + (len(cases) > 1) + len(post_cases),
        desc="report figures",
        unit="fig",
        file=sys.stderr,
        disable=not progress,
        leave=False,
    )
    hist_case = dict(tuple(history.groupby("case"))) if len(history) else {}
    for case in cases:
        rc = runs[runs["case"] == case]
        hc = hist_case.get(case, history.iloc[0:0])
        ms = [m for m in methods if m in set(rc["method"])]
        for fam in fam_list:
            bar.update()
            rcf = rc[fams.loc[rc.index] == fam]
            if not len(rcf):
                continue
            mf = [m for m in ms if m in set(rcf["method"])]
            paths = family_figures(
                case,
                fam,
                rcf,
                hc[hc["config_hash"].isin(rcf["config_hash"])] if len(hc) else hc,
                fig_dir / "convergence" / f"{safe(case)}__{safe(fam)}",
                methods=mf,
                params=params,
                pdf=pdf,
            )
            if paths:
                out["family"][(case, fam)] = paths
        bar.update(2)
        if best_cost:
            out["convergence"][case] = convergence_figure(
                case, rc, hc, fig_dir / f"{safe(case)}__best_cost", methods=methods, pdf=pdf
            )[0]
        out["ecdf"][case] = ecdf_figure(
            f"{case}: runtime ECDF over {len(rc)} runs",
            rc,
            hc,
            fig_dir / f"{safe(case)}__ecdf",
            methods=methods,
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
    if post_cases:
        for case in case_order(post_cases):
            bar.update()
            out["posterior"][case] = posterior_figure(
                case,
                posterior[posterior["case"] == case],
                fig_dir / "posterior" / safe(case),
                pdf=pdf,
            )
    bar.close()
    return out


def posterior_figure(case: str, post_case: pd.DataFrame, path: Path, *, pdf: bool = False):
    """One panel per data tier; per parameter (rows) the posterior 95 % interval (line) and mean
    (marker) divided by the reference, one line per source, with the Laplace mean ± 2 sd beside
    it (dashed grey) where known. Returns the PNG path."""
    from bench.plotting import REFERENCE_LINE

    params = parameter_order(post_case["parameter"].unique())
    tiers = sorted(post_case["tier"].astype(str).unique())
    sources = sorted(post_case["source"].astype(str).unique())
    ns = max(1, max(post_case[post_case["tier"] == t]["source"].nunique() for t in tiers))
    fig, axes = grid(
        1,
        len(tiers),
        panel=(3.6, 0.3 + len(params) * (0.2 + 0.22 * ns)),
        top=0.55,
        bottom=0.75 + 0.14 * (len(sources) + 1),
        left=0.55,
        sharey=True,
    )
    markers = ("o", "s", "^", "D", "v", "x", "P", "*")
    step = 0.8 / ns
    for ti, tier in enumerate(tiers):
        ax = axes[0, ti]
        pt = post_case[post_case["tier"] == tier]
        srcs = [x for x in sources if x in set(pt["source"])]
        for gi, source in enumerate(srcs):
            gp = pt[pt["source"] == source].set_index("parameter")
            mk = markers[sources.index(source) % len(markers)]
            labelled = False
            for pi, p in enumerate(params):
                if p not in gp.index:
                    continue
                r = gp.loc[p]
                y = pi + (gi - (ns - 1) / 2.0) * step - 0.15 * step
                if np.isfinite(r["q025_n"]) and np.isfinite(r["q975_n"]):
                    ax.plot([r["q025_n"], r["q975_n"]], [y, y], color="0.0", linewidth=1.6)
                    ax.plot(
                        [r["mean_n"]],
                        [y],
                        linestyle="none",
                        marker=mk,
                        color="0.0",
                        markerfacecolor="white",
                        label=None if labelled else f"95 % interval and mean: {source}",
                    )
                    labelled = True
                if np.isfinite(r["laplace_lo_n"]) and np.isfinite(r["laplace_hi_n"]):
                    yl = y + 0.35 * step
                    ax.plot(
                        [r["laplace_lo_n"], r["laplace_hi_n"]],
                        [yl, yl],
                        color="0.45",
                        linestyle="--",
                        linewidth=1.2,
                        marker="|",
                        label="Laplace mean ± 2 sd",
                    )
        ax.axvline(1.0, **REFERENCE_LINE)
        ax.set_title(f"{tier} data", loc="left", fontsize=8)
        ax.set_xlabel(r"$x_i/x_i^{\mathrm{REF}}$ (-)")
    ax0 = axes[0, 0]
    ax0.set_yticks(range(len(params)))
    ax0.set_yticklabels([LABELS.get(p, p) for p in params])
    ax0.set_ylim(len(params) - 0.5, -0.5)
    handles, labels = [], []
    for ax in axes[0]:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    if handles:
        fig.legend(handles, labels, loc="lower left", bbox_to_anchor=(0.02, 0.0), fontsize=7)
    fig.suptitle(f"{case}: posterior (MCMC) and Laplace approximation", fontsize=9)
    return _save_fast(fig, Path(path), pdf)[0]

"""Figures of the studies (matplotlib, Agg backend; readable in black and white: hatches, markers,
annotated numbers; units in the labels)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

HATCHES = ("", "///", "...", "xxx", "\\\\\\", "ooo", "---", "+++", "***")
MARKERS = ("o", "s", "^", "v", "D", "x", "+", "*", "P")
LINESTYLES = ("-", "--", "-.", ":", (0, (5, 1)), (0, (3, 1, 1, 1, 1, 1)), (0, (1, 3)), (0, (8, 2)), "-")
GREYS = ("0.15", "0.45", "0.75", "white", "0.3", "0.6", "0.9", "0.05", "0.5")

MEASURE_TITLES = {"ux": r"$s_{ux}$: horizontal displacement field",
                  "uy": r"$s_{uy}$: vertical displacement field",
                  "r": r"$s_r$: reaction force"}

_LATEX = {"sigma0": r"$\sigma_0$", "beta": r"$\beta$", "psi": r"$\psi$", "pt0": r"$p_{t0}$"}


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def label(name: str, unit: str | None = None) -> str:
    text = _LATEX.get(name, f"${name}$" if len(name) == 1 else name)
    return f"{text} ({unit})" if unit else text


def _save(fig, path) -> Path:
    path = Path(path)
    fig.savefig(path, dpi=150, bbox_inches="tight")
    _plt().close(fig)
    return path


def sensitivity_bars(sens, path, title: str = "") -> Path:
    """Fig. 5 of the paper: three panels (s_ux, s_uy, s_r), one bar per parameter, summed over snapshots."""
    plt = _plt()
    summed = sens.summed
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6), sharey=False)
    xs = np.arange(len(sens.names))
    for ax, m in zip(axes, ("ux", "uy", "r")):
        vals = summed[m]
        for i, v in enumerate(vals):
            ax.bar(xs[i], 0.0 if not np.isfinite(v) else v, color=GREYS[i % len(GREYS)], edgecolor="black",
                   hatch=HATCHES[i % len(HATCHES)], width=0.7)
            if np.isfinite(v):
                ax.annotate(f"{v:.3g}", (xs[i], v), ha="center", va="bottom" if v >= 0 else "top", fontsize=7,
                            xytext=(0, 2 if v >= 0 else -2), textcoords="offset points")
        ax.axhline(0.0, color="black", lw=0.8)
        ax.set_xticks(xs, [label(n) for n in sens.names])
        ax.set_title(MEASURE_TITLES[m], fontsize=10)
        ax.margins(y=0.15)
    axes[0].set_ylabel(f"sum over {sens.n_snapshots} snapshots (-)")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)


def sensitivity_snapshots(sens, path, snapshots_mm=None, title: str = "") -> Path:
    """Per-snapshot terms of eqs. 16-18: three panels, one line per parameter."""
    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.6))
    N = sens.n_snapshots
    t = np.arange(1, N + 1) if snapshots_mm is None else np.asarray(snapshots_mm, float)
    for ax, m in zip(axes, ("ux", "uy", "r")):
        for i, n in enumerate(sens.names):
            ax.plot(t, sens.per_snapshot[m][i], color="black", ls=LINESTYLES[i % len(LINESTYLES)],
                    marker=MARKERS[i % len(MARKERS)], ms=4, lw=1, label=label(n))
        ax.axhline(0.0, color="0.5", lw=0.6)
        ax.set_xlabel("snapshot" if snapshots_mm is None else "top-plate displacement (mm)")
        ax.set_title(MEASURE_TITLES[m], fontsize=10)
    axes[0].set_ylabel("sensitivity per snapshot (-)")
    axes[-1].legend(fontsize=8, frameon=False, loc="best")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)


def correlation_heatmap(ident, path, title: str = "") -> Path:
    """Heat map of the Laplace correlation matrix with the values printed in the cells."""
    plt = _plt()
    rho = ident.correlation
    n = len(ident.names)
    fig, ax = plt.subplots(figsize=(1.0 + 0.75 * n, 0.6 + 0.75 * n))
    im = ax.imshow(rho, cmap="RdBu_r", vmin=-1, vmax=1)
    for i in range(n):
        for j in range(n):
            v = rho[i, j]
            ax.text(j, i, "nan" if not np.isfinite(v) else f"{v:+.2f}", ha="center", va="center", fontsize=8,
                    color="white" if np.isfinite(v) and abs(v) > 0.6 else "black")
    labels = [label(x) for x in ident.names]
    ax.set_xticks(range(n), labels)
    ax.set_yticks(range(n), labels)
    fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04, label="correlation (-)")
    ax.set_title(title or f"Laplace correlation (cond J^T J = {ident.condition:.3g})", fontsize=10)
    fig.tight_layout()
    return _save(fig, path)


def std_percent_bars(table: dict[str, dict[str, float]], path, title: str = "") -> Path:
    """Predicted standard deviation (% of reference, log scale), one group per case."""
    plt = _plt()
    cases = list(table)
    fig, ax = plt.subplots(figsize=(max(6.0, 1.7 * len(cases)), 4.5))
    width = 0.8 / max(len(v) for v in table.values())
    values = [v for t in table.values() for v in t.values() if v > 0]
    for c, case in enumerate(cases):
        for i, (name, v) in enumerate(table[case].items()):
            x = c + (i - (len(table[case]) - 1) / 2) * width
            ax.bar(x, v, width=width, color=GREYS[i % len(GREYS)], edgecolor="black", hatch=HATCHES[i % len(HATCHES)])
            ax.annotate(label(name), (x, v), xytext=(0, 2), textcoords="offset points", rotation=90, ha="center",
                        va="bottom", fontsize=8)
    ax.set_yscale("log")
    if values:
        ax.set_ylim(min(values) / 2, max(values) * 4)
    ax.set_xticks(range(len(cases)), cases, rotation=30, ha="right")
    ax.set_ylabel("Laplace sd (% of reference)")
    if title:
        ax.set_title(title)
    fig.tight_layout()
    return _save(fig, path)


def sobol_bars(res, path, labels: dict[str, str] | None = None, title: str = "") -> Path:
    """One panel per output: first-order (plain) and total (hatched) Sobol indices with bootstrap CIs."""
    plt = _plt()
    k = len(res.outputs)
    fig, axes = plt.subplots(1, k, figsize=(4.2 * k, 3.6), squeeze=False)
    xs = np.arange(len(res.names))
    for j, (ax, out) in enumerate(zip(axes[0], res.outputs)):
        ax.bar(xs - 0.18, res.S1[j], 0.36, yerr=res.S1_conf[j], color="0.8", edgecolor="black", capsize=2,
               label="first order $S_1$")
        ax.bar(xs + 0.18, res.ST[j], 0.36, yerr=res.ST_conf[j], color="white", edgecolor="black", hatch="///",
               capsize=2, label="total $S_T$")
        ax.axhline(0.0, color="black", lw=0.6)
        ax.set_xticks(xs, [label(n) for n in res.names])
        ax.set_title((labels or {}).get(out, out), fontsize=10)
        finite = np.isfinite(res.S1[j]).any()
        ax.set_ylim(min(-0.05, np.nanmin(res.S1[j] - res.S1_conf[j]) if finite else 0),
                    max(1.05, np.nanmax(res.ST[j] + res.ST_conf[j]) + 0.05 if finite else 0))
    axes[0][0].set_ylabel(f"Sobol index (-), {int(100 * res.conf_level)} % bootstrap CI")
    axes[0][0].legend(fontsize=8, frameon=False)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)


def morris_plot(res, path, labels: dict[str, str] | None = None, title: str = "") -> Path:
    """One panel per output: mu* (horizontal) against sigma (vertical), parameters labelled."""
    plt = _plt()
    k = len(res.outputs)
    fig, axes = plt.subplots(1, k, figsize=(4.2 * k, 3.8), squeeze=False)
    for j, (ax, out) in enumerate(zip(axes[0], res.outputs)):
        for i, n in enumerate(res.names):
            ax.errorbar(res.mu_star[j, i], res.sigma[j, i], xerr=res.mu_star_conf[j, i], fmt=MARKERS[i % len(MARKERS)],
                        color="black", mfc="white", capsize=2)
            ax.annotate(label(n), (res.mu_star[j, i], res.sigma[j, i]), xytext=(4, 4), textcoords="offset points",
                        fontsize=8)
        lim = np.nanmax([res.mu_star[j].max(), res.sigma[j].max()]) * 1.15 if np.isfinite(res.mu_star[j]).any() else 1
        ax.plot([0, lim], [0, lim], color="0.6", ls=":", lw=0.8)
        unit = (labels or {}).get(out, out)
        ax.set_xlabel(rf"$\mu^*$ ({unit} per full range)")
        ax.set_ylabel(r"$\sigma$ (same unit)")
        ax.set_title(unit, fontsize=10)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)


def corner_plot(samples, names, path, *, reference=None, laplace_mean=None, laplace_cov=None, units=None,
                seed: int = 0, title: str = "") -> Path:
    """Corner plot of the MCMC samples (black), Laplace Gaussian (grey dashed), reference marked."""
    _plt()  # Agg backend before corner imports pyplot
    import corner

    samples = np.asarray(samples, float)
    labels = [label(n, (units or {}).get(n)) for n in names]
    ranges = None
    if laplace_mean is not None and laplace_cov is not None:
        sd_l = np.sqrt(np.clip(np.diag(laplace_cov), 0, None))
        lo = np.minimum(samples.min(axis=0), laplace_mean - 4 * sd_l)
        hi = np.maximum(samples.max(axis=0), laplace_mean + 4 * sd_l)
        span = np.where(hi > lo, hi - lo, np.abs(hi) * 1e-6 + 1e-12)
        if reference is not None:  # widen to show the reference unless it is far off (then say so)
            ref = np.asarray(reference, float)
            near = (ref >= lo - span) & (ref <= hi + span)
            lo, hi = np.where(near, np.minimum(lo, ref), lo), np.where(near, np.maximum(hi, ref), hi)
            span = np.where(hi > lo, hi - lo, span)
            far = [label(n) for n, ok in zip(names, near) if not ok]
            if far:
                title = (title + "\n" if title else "") + f"reference outside the plotted range for {', '.join(far)}"
        ranges = list(zip(lo - 0.05 * span, hi + 0.05 * span))
    fig = corner.corner(samples, labels=labels, truths=None if reference is None else list(reference),
                        truth_color="black", color="black", range=ranges, bins=30, smooth=1.0,
                        plot_datapoints=False, plot_density=False, fill_contours=False, levels=(0.393, 0.865),
                        show_titles=False, label_kwargs={"fontsize": 9}, hist_kwargs={"lw": 1.2},
                        weights=np.full(len(samples), 1.0 / len(samples)))
    if laplace_mean is not None and laplace_cov is not None:
        rng = np.random.default_rng(seed)
        draws = rng.multivariate_normal(laplace_mean, laplace_cov, size=max(20000, len(samples)),
                                        check_valid="ignore")
        corner.corner(draws, fig=fig, color="0.5", range=ranges, bins=30, smooth=1.0, plot_datapoints=False,
                      plot_density=False, fill_contours=False, levels=(0.393, 0.865),
                      contour_kwargs={"linestyles": "--"}, hist_kwargs={"ls": "--", "lw": 1.2},
                      weights=np.full(len(draws), 1.0 / len(draws)))
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color="black", label="MCMC posterior"),
               Line2D([], [], color="0.5", ls="--", label="Laplace approximation")]
    if reference is not None:
        handles.append(Line2D([], [], color="black", marker="s", ls="-", lw=0.8, label="reference"))
    fig.legend(handles=handles, loc="upper right", bbox_to_anchor=(0.97, 0.85), frameon=False, fontsize=10)
    if title:
        fig.suptitle(title)
    return _save(fig, path)

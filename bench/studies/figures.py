"""Figures of the studies, drawn from the numbers their ``render_*`` step read back from the output
folder (plain arrays and dicts, no result objects). Style, labels and saving: :mod:`bench.plotting`
(black and white: hatches, markers, annotated numbers; units in the labels).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bench.plotting import (
    HATCHES,
    LINESTYLES,
    MARKERS,
    REFERENCE_LINE,
    bar_style,
    integer_axis,
    label,
    log_axis,
    place_labels,
    pyplot,
    row,
    save,
)

MEASURE_TITLES = {
    "ux": r"$s_{ux}$: horizontal displacement field",
    "uy": r"$s_{uy}$: vertical displacement field",
    "r": r"$s_r$: reaction force",
}
MEASURES = ("ux", "uy", "r")


def sensitivity_bars(names, summed: dict, n_snapshots: int, path, title: str = "") -> Path:
    """Fig. 5 of the paper: three panels (s_ux, s_uy, s_r), one bar per parameter, summed over the
    ``n_snapshots`` snapshots (dimensionless), values printed on the bars."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=row(3, 3.6))
    xs = np.arange(len(names))
    for ax, m in zip(axes, MEASURES):
        vals = np.asarray(summed[m], float)
        for i, v in enumerate(vals):
            ax.bar(xs[i], v if np.isfinite(v) else 0.0, width=0.7, **bar_style(i))
            if np.isfinite(v):
                ax.annotate(
                    f"{v:.3g}",
                    (xs[i], v),
                    ha="center",
                    va="bottom" if v >= 0 else "top",
                    fontsize=7,
                    xytext=(0, 2 if v >= 0 else -2),
                    textcoords="offset points",
                )
        ax.axhline(0.0, color="black", lw=0.8)
        ax.set_xticks(xs, [label(n) for n in names])
        ax.grid(axis="x", visible=False)
        ax.set_title(MEASURE_TITLES[m])
        ax.margins(y=0.15)
    axes[0].set_ylabel(f"sum over {n_snapshots} snapshots (-)")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return save(fig, path)


def sensitivity_snapshots(
    names, per_snapshot: dict, path, snapshots_mm=None, title: str = ""
) -> Path:
    """Per-snapshot terms of eqs. 16-18 (dimensionless): three panels, one line per parameter,
    against the top-plate displacement (mm) or, without it, the snapshot number."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 3, figsize=row(3, 3.6))
    first = np.asarray(per_snapshot[MEASURES[0]], float)
    N = first.shape[1]
    t = np.arange(1, N + 1) if snapshots_mm is None else np.asarray(snapshots_mm, float)
    for ax, m in zip(axes, MEASURES):
        for i, n in enumerate(names):
            ax.plot(
                t,
                np.asarray(per_snapshot[m][i], float),
                color="black",
                ls=LINESTYLES[i % len(LINESTYLES)],
                marker=MARKERS[i % len(MARKERS)],
                ms=4,
                lw=1,
                label=label(n),
            )
        ax.axhline(0.0, **REFERENCE_LINE)
        if snapshots_mm is None:
            ax.set_xlabel("snapshot (-)")
            integer_axis(ax, "x")
        else:
            ax.set_xlabel("top-plate displacement (mm)")
        ax.set_title(MEASURE_TITLES[m])
    axes[0].set_ylabel("sensitivity per snapshot (-)")
    axes[-1].legend(loc="best")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return save(fig, path)


def correlation_heatmap(names, correlation, path, title: str = "") -> Path:
    """Heat map of the Laplace correlation matrix (dimensionless) with the values printed in the
    cells."""
    plt = pyplot()
    rho = np.asarray(correlation, float)
    n = len(names)
    fig, ax = plt.subplots(figsize=(1.0 + 0.75 * n, 0.6 + 0.75 * n))
    im = ax.imshow(rho, cmap="RdBu_r", vmin=-1, vmax=1)
    for i in range(n):
        for j in range(n):
            v = rho[i, j]
            ax.text(
                j,
                i,
                "nan" if not np.isfinite(v) else f"{v:+.2f}",
                ha="center",
                va="center",
                fontsize=8,
                color="white" if np.isfinite(v) and abs(v) > 0.6 else "black",
            )
    labels = [label(x) for x in names]
    ax.set_xticks(range(n), labels)
    ax.set_yticks(range(n), labels)
    ax.grid(False)
    fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04, label="correlation (-)")
    ax.set_title(title or "Laplace correlation")
    fig.tight_layout()
    return save(fig, path)


def std_percent_bars(table: dict[str, dict[str, float]], path, title: str = "") -> Path:
    """Predicted standard deviation (% of the reference, log axis), one group of bars per case."""
    plt = pyplot()
    cases = list(table)
    fig, ax = plt.subplots(figsize=(max(6.0, 1.7 * len(cases)), 4.5))
    width = 0.8 / max(len(v) for v in table.values())
    values = [v for t in table.values() for v in t.values() if np.isfinite(v) and v > 0]
    for c, case in enumerate(cases):
        for i, (name, v) in enumerate(table[case].items()):
            if not (np.isfinite(v) and v > 0):
                continue
            x = c + (i - (len(table[case]) - 1) / 2) * width
            ax.bar(x, v, width=width, **bar_style(i))
            ax.annotate(
                label(name),
                (x, v),
                xytext=(0, 2),
                textcoords="offset points",
                rotation=90,
                ha="center",
                va="bottom",
                fontsize=8,
            )
    log_axis(ax, "y")
    if values:
        ax.set_ylim(min(values) / 2, max(values) * 4)
    ax.set_xticks(range(len(cases)), cases, rotation=30, ha="right")
    ax.grid(axis="x", visible=False)
    ax.set_ylabel("Laplace sd (% of reference)")
    if title:
        ax.set_title(title)
    fig.tight_layout()
    return save(fig, path)


def sobol_bars(
    names,
    outputs,
    S1,
    S1_conf,
    ST,
    ST_conf,
    conf_level: float,
    path,
    labels: dict[str, str] | None = None,
    title: str = "",
) -> Path:
    """One panel per output: first-order (plain) and total (hatched) Sobol indices (dimensionless),
    arrays (outputs, parameters), with their bootstrap confidence intervals."""
    plt = pyplot()
    S1, S1_conf, ST, ST_conf = (np.asarray(a, float) for a in (S1, S1_conf, ST, ST_conf))
    k = len(outputs)
    fig, axes = plt.subplots(1, k, figsize=row(k, 3.6), squeeze=False)
    xs = np.arange(len(names))
    for j, (ax, out) in enumerate(zip(axes[0], outputs)):
        ax.bar(
            xs - 0.18,
            S1[j],
            0.36,
            yerr=S1_conf[j],
            color="0.8",
            edgecolor="black",
            label="first order $S_1$",
        )
        ax.bar(
            xs + 0.18,
            ST[j],
            0.36,
            yerr=ST_conf[j],
            color="white",
            edgecolor="black",
            hatch=HATCHES[1],
            label="total $S_T$",
        )
        ax.axhline(0.0, color="black", lw=0.6)
        ax.set_xticks(xs, [label(n) for n in names])
        ax.grid(axis="x", visible=False)
        ax.set_title((labels or {}).get(out, out))
        finite = np.isfinite(S1[j]).any()
        ax.set_ylim(
            min(-0.05, np.nanmin(S1[j] - S1_conf[j]) if finite else 0),
            max(1.05, np.nanmax(ST[j] + ST_conf[j]) + 0.05 if finite else 0),
        )
    axes[0][0].set_ylabel(f"Sobol index (-), {int(round(100 * conf_level))} % bootstrap CI")
    axes[0][0].legend()
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return save(fig, path)


def morris_plot(
    names,
    outputs,
    mu_star,
    mu_star_conf,
    sigma,
    path,
    labels: dict[str, str] | None = None,
    title: str = "",
) -> Path:
    """One panel per output: mu* (horizontal, output unit per full range of the box) against sigma
    (vertical, same unit), arrays (outputs, parameters); one marker per parameter, labels placed so
    that they do not overlap, the line sigma = mu* dotted."""
    plt = pyplot()
    mu_star, mu_star_conf, sigma = (np.asarray(a, float) for a in (mu_star, mu_star_conf, sigma))
    k = len(outputs)
    fig, axes = plt.subplots(1, k, figsize=row(k, 3.8), squeeze=False)
    for j, (ax, out) in enumerate(zip(axes[0], outputs)):
        ok = np.isfinite(mu_star[j]) & np.isfinite(sigma[j])
        for i, _n in enumerate(names):
            if ok[i]:
                ax.errorbar(
                    mu_star[j, i],
                    sigma[j, i],
                    xerr=mu_star_conf[j, i],
                    fmt=MARKERS[i % len(MARKERS)],
                    color="black",
                    mfc="white",
                )
        lim = (
            1.15
            * max(np.max(mu_star[j][ok] + np.nan_to_num(mu_star_conf[j][ok])), np.max(sigma[j][ok]))
            if ok.any()
            else 1.0
        )
        ax.plot([0, lim], [0, lim], color="0.6", ls=":", lw=0.8)
        ax.set_xlim(0, lim)
        ax.set_ylim(0, lim)
        unit = (labels or {}).get(out, out)
        ax.set_xlabel(rf"$\mu^*$ ({unit} per full range)")
        ax.set_ylabel(r"$\sigma$ (same unit)")
        ax.set_title(unit)
    fig.tight_layout()
    for j, ax in enumerate(axes[0]):
        ok = np.isfinite(mu_star[j]) & np.isfinite(sigma[j])
        idx = np.flatnonzero(ok)
        place_labels(ax, mu_star[j, idx], sigma[j, idx], [label(names[i]) for i in idx])
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return save(fig, path)


def corner_plot(
    samples,
    names,
    path,
    *,
    reference=None,
    laplace_mean=None,
    laplace_cov=None,
    units=None,
    seed: int = 0,
    title: str = "",
) -> Path:
    """Corner plot of the MCMC samples (black), the Laplace Gaussian (grey dashed) and the
    reference; samples (n, d) in physical units (``units[name]``)."""
    plt = pyplot()  # Agg back-end and style before corner imports pyplot
    import corner
    from matplotlib.lines import Line2D

    samples = np.asarray(samples, float)
    axis_labels = [label(n, (units or {}).get(n)) for n in names]
    ranges = None
    if laplace_mean is not None and laplace_cov is not None:
        laplace_mean, laplace_cov = np.asarray(laplace_mean, float), np.asarray(laplace_cov, float)
        sd_l = np.sqrt(np.clip(np.diag(laplace_cov), 0, None))
        lo = np.minimum(samples.min(axis=0), laplace_mean - 4 * sd_l)
        hi = np.maximum(samples.max(axis=0), laplace_mean + 4 * sd_l)
        span = np.where(hi > lo, hi - lo, np.abs(hi) * 1e-6 + 1e-12)
        if reference is not None:  # widen to show the reference unless it is far off (then say so)
            ref = np.asarray(reference, float)
            near = (ref >= lo - span) & (ref <= hi + span)
            lo, hi = (
                np.where(near, np.minimum(lo, ref), lo),
                np.where(near, np.maximum(hi, ref), hi),
            )
            span = np.where(hi > lo, hi - lo, span)
            far = [label(n) for n, ok in zip(names, near) if not ok]
            if far:
                title = (
                    title + "\n" if title else ""
                ) + f"reference outside the plotted range for {', '.join(far)}"
        ranges = list(zip(lo - 0.05 * span, hi + 0.05 * span))
    with plt.rc_context({"axes.grid": False}):
        fig = corner.corner(
            samples,
            labels=axis_labels,
            truths=None if reference is None else list(reference),
            truth_color="black",
            color="black",
            range=ranges,
            bins=30,
            smooth=1.0,
            plot_datapoints=False,
            plot_density=False,
            fill_contours=False,
            levels=(0.393, 0.865),
            show_titles=False,
            label_kwargs={"fontsize": 9},
            hist_kwargs={"lw": 1.2},
            weights=np.full(len(samples), 1.0 / len(samples)),
        )
        if laplace_mean is not None and laplace_cov is not None:
            rng = np.random.default_rng(seed)
            draws = rng.multivariate_normal(
                laplace_mean, laplace_cov, size=max(20000, len(samples)), check_valid="ignore"
            )
            corner.corner(
                draws,
                fig=fig,
                color="0.5",
                range=ranges,
                bins=30,
                smooth=1.0,
                plot_datapoints=False,
                plot_density=False,
                fill_contours=False,
                levels=(0.393, 0.865),
                contour_kwargs={"linestyles": "--"},
                hist_kwargs={"ls": "--", "lw": 1.2},
                weights=np.full(len(draws), 1.0 / len(draws)),
            )
    handles = [
        Line2D([], [], color="black", label="MCMC posterior"),
        Line2D([], [], color="0.5", ls="--", label="Laplace approximation"),
    ]
    if reference is not None:
        handles.append(Line2D([], [], color="black", marker="s", ls="-", lw=0.8, label="reference"))
    fig.legend(handles=handles, loc="upper right", bbox_to_anchor=(0.97, 0.85), fontsize=9)
    if title:
        fig.suptitle(title)
    return save(fig, path)

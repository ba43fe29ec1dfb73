"""The one plotting style of femubench: rc settings, greys/markers/hatches, colours, figure sizes,
parameter labels, axis helpers and :func:`save`.

Every figure module (:mod:`bench.report.figures`, :mod:`bench.studies.figures`,
:mod:`bench.crosscheck.figures`, :mod:`bench.dic_figures`) draws through :func:`pyplot` and
writes through :func:`save`. Figures are meant to survive black-and-white printing: lines differ
by line style *and* marker (:func:`line_style`), bars by grey *and* hatch; colour
(:data:`COLOURS`) is only used where a series also differs otherwise. Sizes are in inches,
resolution in dots per inch.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: matplotlib rc settings of every figure (font sizes in points, line widths in points)
RC = {
    "font.size": 9,
    "axes.titlesize": 9,
    "axes.labelsize": 9,
    "xtick.labelsize": 8,
    "ytick.labelsize": 8,
    "legend.fontsize": 7,
    "legend.frameon": False,
    "figure.titlesize": 9,
    "axes.grid": True,
    "grid.color": "0.85",
    "grid.linewidth": 0.5,
    "lines.linewidth": 1.2,
    "lines.markersize": 4,
    "errorbar.capsize": 2,
    "image.cmap": "gray",
    "savefig.dpi": 150,
    "svg.hashsalt": "femubench",
    "pdf.compression": 6,  # reproducible vector files
}
DPI = 150

#: black-and-white series: line styles, markers, greys (lines) and hatches (bars)
LINESTYLES = ("-", "--", ":", "-.", (0, (5, 1)), (0, (3, 1, 1, 1, 1, 1)), (0, (1, 3)), (0, (8, 2)))
MARKERS = ("o", "s", "^", "v", "D", "x", "+", "*", "<", ">", "p", "h")
LINE_GREYS = ("0.0", "0.45", "0.7")
BAR_GREYS = ("0.15", "0.45", "0.75", "white", "0.3", "0.6", "0.9", "0.05", "0.5")
HATCHES = ("", "///", "...", "xxx", "\\\\\\", "ooo", "---", "+++", "***")
#: colours of a few series that also differ by marker or line style (e.g. two dilatancy angles)
COLOURS = ("C0", "C3", "C2", "C4", "C1", "C5")
#: the reference value / zero line
REFERENCE_LINE = {"color": "0.3", "linewidth": 0.8, "linestyle": (0, (1, 1))}

#: figure sizes (width, height) in inches
SINGLE = (5.2, 3.6)  # one panel with a legend beside it
DOUBLE = (9.0, 3.6)  # two panels side by side
PANEL_WIDTH = 4.2  # width of one panel in a row of k panels


def row(k: int, height: float = 3.6) -> tuple[float, float]:
    """Size of a row of ``k`` panels (inches)."""
    return (PANEL_WIDTH * k, height)


def pyplot():
    """``matplotlib.pyplot`` on the Agg back-end with :data:`RC` applied."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    plt.rcParams.update(RC)
    return plt


def save(fig, path, *, pdf: bool = False) -> Path:
    """Write ``fig`` to ``path`` (the suffix picks the format; PNG at :data:`DPI`), and a PDF beside
    it with ``pdf``; no time stamps or software names in the files; close the figure."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=DPI, bbox_inches="tight", metadata=_metadata(path.suffix))
    if pdf and path.suffix != ".pdf":
        fig.savefig(path.with_suffix(".pdf"), bbox_inches="tight", metadata=_metadata(".pdf"))
    pyplot().close(fig)
    return path


def _metadata(suffix: str) -> dict:
    if suffix == ".pdf":
        return {"Creator": None, "Producer": None, "CreationDate": None}
    if suffix == ".svg":
        return {"Date": None}
    return {"Software": None}


def line_style(i: int) -> dict:
    """The ``i``-th black-and-white line: line style x marker, then grey."""
    return {
        "linestyle": LINESTYLES[i % 4],
        "marker": MARKERS[i % len(MARKERS)],
        "color": LINE_GREYS[(i // len(MARKERS)) % len(LINE_GREYS)],
    }


def bar_style(i: int) -> dict:
    """The ``i``-th black-and-white bar: grey fill and hatch, black edge."""
    return {
        "color": BAR_GREYS[i % len(BAR_GREYS)],
        "hatch": HATCHES[i % len(HATCHES)],
        "edgecolor": "black",
    }


# --- parameter labels ---------------------------------------------------------------------------

_GREEK = {
    "alpha",
    "beta",
    "gamma",
    "delta",
    "epsilon",
    "zeta",
    "eta",
    "theta",
    "kappa",
    "lambda",
    "mu",
    "nu",
    "xi",
    "pi",
    "rho",
    "sigma",
    "tau",
    "phi",
    "chi",
    "psi",
    "omega",
}


#: TeX label of each parameter the cases identify (math mode, with dollars): the one table of
#: parameter symbols of every figure and table (studies and report)
LABELS: dict[str, str] = {
    "E": r"$E$",
    "nu": r"$\nu$",
    "beta": r"$\beta$",
    "K": r"$K$",
    "psi": r"$\psi$",
    "sigma0": r"$\sigma_0$",
    "H": r"$H$",
    "pt0": r"$p_{t0}$",
    "a": r"$a$",
    "b": r"$b$",
}


def tex(name: str) -> str:
    """The TeX symbol of a parameter, without dollars: :data:`LABELS`, else a single letter or
    Greek name in math italics, else the name upright."""
    if name in LABELS:
        return LABELS[name].strip("$")
    if len(name) == 1 or name in _GREEK:
        return f"\\{name}" if name in _GREEK else name
    return r"\mathrm{" + name.replace("_", r"\_") + "}"


def label(name: str, unit: str | None = None) -> str:
    """Axis or tick label of a parameter, e.g. ``$\\sigma_0$ (MPa)``."""
    text = f"${tex(name)}$"
    return f"{text} ({unit})" if unit else text


def normalised_label(name: str) -> str:
    """``$x/x^{REF}$`` label of a parameter divided by its reference value."""
    sym = tex(name)
    return rf"${sym}/{sym}^{{\mathrm{{REF}}}}$"


# --- axes ---------------------------------------------------------------------------------------


def integer_axis(ax, axis: str = "x") -> None:
    """Ticks at integers only (iterations, snapshots, steps)."""
    from matplotlib.ticker import MaxNLocator

    getattr(ax, f"{axis}axis").set_major_locator(MaxNLocator(integer=True, min_n_ticks=2))


def log_axis(ax, axis: str = "y") -> None:
    """Log scale labelled for reading: decades (at most about seven, thinned over wide ranges),
    written as plain numbers (``0.01``, ``100``) when the whole axis lies between 0.001 and 10 000
    and as ``10^k`` otherwise; unlabelled minor ticks at 2..9, of which the 2 and 5 multiples are
    labelled when the axis spans at most 2.5 decades, and all when it spans less than half a
    decade."""
    from matplotlib.ticker import FuncFormatter, LogLocator

    getattr(ax, f"set_{axis}scale")("log")
    a = getattr(ax, f"{axis}axis")
    a.set_major_locator(LogLocator(base=10.0, numticks=8))
    a.set_minor_locator(LogLocator(base=10.0, subs=tuple(range(2, 10)), numticks=12))

    def view():
        lo, hi = sorted(a.get_view_interval())
        return lo, hi, lo > 0 and 1e-3 * (1 - 1e-9) <= lo and hi <= 1e4 * (1 + 1e-9)

    def major(v, pos=None):
        return _log_tick(v, view()[2])

    def minor(v, pos=None):
        lo, hi, plain = view()
        if not (lo > 0 and v > 0):
            return ""
        span = np.log10(hi / lo)
        digit = int(round(v / 10.0 ** np.floor(np.log10(v) + 1e-9)))
        return _log_tick(v, plain) if span < 0.5 or (span <= 2.5 and digit in (2, 5)) else ""

    a.set_major_formatter(FuncFormatter(major))
    a.set_minor_formatter(FuncFormatter(minor))


def _log_tick(v: float, plain: bool) -> str:
    if not v > 0:
        return ""
    if plain:
        return f"{v:g}"
    k = int(np.floor(np.log10(v) + 1e-9))
    digit = v / 10.0**k
    return f"$10^{{{k}}}$" if abs(digit - 1) < 1e-6 else f"${digit:.0f}\\times10^{{{k}}}$"


def place_labels(
    ax, xs, ys, texts, *, offset=(4, 4), fontsize: float = 8, pad: float = 1.5
) -> list:
    """Annotate points ``(xs[i], ys[i])`` with ``texts[i]`` so that no two labels overlap: each
    label starts up-right of its point (``offset`` in points) and is pushed upwards past any label
    it would cover (``pad`` points apart); a pushed label gets a thin leader line to its point.
    Call after the axes limits are final. Returns the annotations."""
    from matplotlib.text import Text

    fig = ax.figure
    fig.canvas.draw()  # text extents need a renderer
    renderer = fig.canvas.get_renderer()
    to_points = 72.0 / fig.dpi
    placed, boxes = [], []
    for i in np.argsort(np.asarray(ys, float), kind="stable"):
        ann = ax.annotate(
            texts[i],
            (xs[i], ys[i]),
            xytext=offset,
            textcoords="offset points",
            fontsize=fontsize,
            va="bottom",
            ha="left",
            arrowprops={"arrowstyle": "-", "color": "0.5", "lw": 0.5, "shrinkA": 0, "shrinkB": 3},
        )
        dy = float(offset[1])
        for _ in range(100):
            ann.update_positions(renderer)
            box = Text.get_window_extent(ann, renderer)
            hit = next(
                (
                    b
                    for b in boxes
                    if box.x0 < b.x1
                    and b.x0 < box.x1
                    and box.y0 < b.y1 + pad / to_points
                    and b.y0 < box.y1 + pad / to_points
                ),
                None,
            )
            if hit is None:
                break
            dy += (hit.y1 - box.y0) * to_points + pad
            ann.xyann = (offset[0], dy)
        ann.arrow_patch.set_visible(dy > offset[1])
        ann.update_positions(renderer)
        boxes.append(Text.get_window_extent(ann, renderer))
        placed.append(ann)
    return placed

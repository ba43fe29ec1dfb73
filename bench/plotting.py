"""The one plotting style of femubench: rc settings, greys/markers/hatches, colours, figure sizes,
parameter labels, axis helpers and :func:`save`.

Every figure module (:mod:`bench.report.figures`, :mod:`bench.studies.figures`,
:mod:`bench.crosscheck.figures`, :mod:`bench.dic_figures`) draws through :func:`pyplot` and
writes through :func:`save` (atomically; a PNG as the palette PNG of :func:`palette_png`, which
``femubench figures compact`` also applies to existing files). Figures are meant to survive
black-and-white printing: lines differ by line style *and* marker (:func:`line_style`), bars by
grey *and* hatch; colour (:data:`COLOURS`) is only used where a series also differs otherwise.
Sizes are in inches, resolution in dots per inch.
"""

from __future__ import annotations

import io
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


def save(
    fig,
    path,
    *,
    pdf: bool = False,
    dpi: float = DPI,
    tight: bool = True,
    palette: bool = True,
) -> Path:
    """Write ``fig`` to ``path`` atomically (temporary file + rename) and close the figure: the
    one way femubench writes a figure. The suffix picks the format; a PNG is rendered at ``dpi``
    (dots per inch) and written as :func:`palette_png` of matplotlib's 8-bit RGBA PNG (plain RGBA
    with ``palette=False``); with ``pdf`` a PDF is written beside it. ``tight`` crops to the drawn
    area (``bbox_inches="tight"``; many-panel report figures with fixed margins skip it: one draw
    instead of two). No time stamps or software names in the files. Returns ``path``."""
    from matplotlib import pyplot as plt

    from bench.experiment.store import atomic_write  # the one atomic writer

    path = Path(path)
    bbox = "tight" if tight else None
    if path.suffix == ".png":
        data = rgba_png(fig, dpi=dpi, tight=tight)
        if palette:
            data = palette_png(data)
        atomic_write(path, lambda fh: fh.write(data))
    else:
        atomic_write(
            path,
            lambda fh: fig.savefig(
                fh,
                format=path.suffix[1:],
                dpi=dpi,
                bbox_inches=bbox,
                metadata=_metadata(path.suffix),
            ),
        )
    if pdf and path.suffix != ".pdf":
        atomic_write(
            path.with_suffix(".pdf"),
            lambda fh: fig.savefig(fh, format="pdf", bbox_inches=bbox, metadata=_metadata(".pdf")),
        )
    plt.close(fig)
    return path


def rgba_png(fig, *, dpi: float = DPI, tight: bool = True) -> bytes:
    """matplotlib's 8-bit RGBA PNG of ``fig`` at ``dpi`` (dots per inch), in memory, without a
    software name (see :func:`save`)."""
    buf = io.BytesIO()
    fig.savefig(
        buf,
        format="png",
        dpi=dpi,
        bbox_inches="tight" if tight else None,
        metadata=_metadata(".png"),
    )
    return buf.getvalue()


#: the PNG colour types :func:`palette_png` reads: 6 = RGBA (matplotlib, 8 bits per channel),
#: 3 = palette (a figure already converted)
_RGBA, _PALETTE = 6, 3


def palette_png(data: bytes) -> bytes:
    """The palette form of a femubench figure: ``data`` (the bytes of an opaque PNG as matplotlib
    writes it, 8-bit RGBA, or of one already in palette form) as an 8-bit-or-less palette PNG,
    optimised (zlib level 9, the fewest bits per pixel), with the resolution (``pHYs``) of
    ``data`` and no other metadata. A figure of at most 256 colours (every grey-only figure)
    keeps every pixel exactly; one of more colours is reduced to 256 by Pillow's
    maximum-coverage quantizer without dithering (on the shipped figures: every colour channel
    within 10 of 255, white kept white). The palette is ordered by frequency (ties by colour), so
    the bytes depend only on the pixels and the resolution: the same figure always gives the same
    bytes, a figure rendered straight to palette form equals its RGBA PNG converted, and
    converting a palette figure again changes nothing. A PNG that is not such a figure (other
    colour type or bit depth, transparent pixels, not a PNG, corrupt) raises ``ValueError``."""
    from PIL import Image

    if len(data) < 26 or data[:8] != b"\x89PNG\r\n\x1a\n" or data[12:16] != b"IHDR":
        raise ValueError("not a PNG file")
    depth, colour = data[24], data[25]
    if not ((colour == _RGBA and depth == 8) or colour == _PALETTE):
        raise ValueError(
            f"not a femubench figure: PNG colour type {colour} with {depth} bits per sample "
            "(allowed: 8-bit RGBA as matplotlib writes it, or a palette PNG)"
        )
    try:
        with Image.open(io.BytesIO(data)) as im:
            im.load()
            dpi = im.info.get("dpi")
            rgba = np.asarray(im.convert("RGBA"))
    except (OSError, SyntaxError, ValueError, EOFError) as exc:
        raise ValueError(f"corrupt PNG ({' '.join(str(exc).split())})") from None
    if not (rgba[..., 3] == 255).all():
        raise ValueError("not a femubench figure: it has transparent pixels (figures are opaque)")
    rgb = np.ascontiguousarray(rgba[..., :3])
    colours = _packed(rgb)
    if len(np.unique(colours)) > 256:
        quantized = Image.fromarray(rgb).quantize(
            256, method=Image.Quantize.MAXCOVERAGE, dither=Image.Dither.NONE
        )
        colours = _packed(np.asarray(quantized.convert("RGB")))
    table, index, counts = np.unique(colours, return_inverse=True, return_counts=True)
    order = np.lexsort((table, -counts))  # most frequent first, then by colour
    rank = np.empty(len(order), np.uint8)
    rank[order] = np.arange(len(order))
    out = Image.frombytes("P", (rgb.shape[1], rgb.shape[0]), rank[index].tobytes())
    table = table[order]
    out.putpalette(np.stack([table >> 16, table >> 8, table], -1).astype(np.uint8).tobytes())
    buf = io.BytesIO()
    out.save(buf, format="PNG", optimize=True, **({"dpi": dpi} if dpi else {}))
    return buf.getvalue()


def _packed(rgb: np.ndarray) -> np.ndarray:
    """``(rows, cols, 3)`` uint8 colours as one flat ``0xRRGGBB`` uint32 array."""
    c = rgb.reshape(-1, 3).astype(np.uint32)
    return (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]


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

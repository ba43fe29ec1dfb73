"""``femubench dic``: subset DIC (IC-GN, ZNSSD) of deformed images against a reference image."""

from __future__ import annotations

import argparse

NAME = "dic"
HELP = "Correlate deformed images against a reference image (subset DIC, IC-GN, ZNSSD)."

#: CSV columns; the suffix names the unit (px: pixels, x right, y down; zncc dimensionless;
#: converged 0/1)
COLUMNS = ("x_px", "y_px", "u_px", "v_px", "std_u_px", "std_v_px", "zncc", "converged")


def _roi(text: str) -> tuple[int, int, int, int]:
    try:
        vals = tuple(int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"ROI {text!r} must be four integers X0,Y0,X1,Y1"
        ) from None
    if len(vals) != 4:
        raise argparse.ArgumentTypeError(f"ROI {text!r} must be four integers X0,Y0,X1,Y1")
    return vals  # type: ignore[return-value]


def _odd_subset(text: str) -> int:
    from bench.commands._args import int_at_least

    value = int_at_least(5)(text)
    if value % 2 == 0:
        raise argparse.ArgumentTypeError(
            f"{value} is even: the subset side must be an odd integer >= 5 px"
        )
    return value


def _figure_file(text: str) -> str:
    from pathlib import Path

    from bench.commands._args import output_file

    if Path(text).suffix.lower() not in (".png", ".pdf", ".svg"):
        raise argparse.ArgumentTypeError(
            f"{text!r}: the figure format is taken from the suffix; allowed: .png, .pdf, .svg"
        )
    return output_file(text)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from bench.commands._args import float_in, input_file, nonneg_int, output_file, positive_int

    parser.add_argument(
        "ref",
        metavar="REF",
        type=input_file,
        help="reference image (TIFF, PNG or BMP; 8 or 16 bit)",
    )
    parser.add_argument(
        "deformed",
        metavar="DEF",
        nargs="+",
        type=input_file,
        help="deformed image(s), same size as REF",
    )
    parser.add_argument(
        "--subset", type=_odd_subset, default=21, help="subset side in px, odd, >= 5 (default 21)"
    )
    parser.add_argument(
        "--step", type=positive_int, default=10, help="grid step in px, >= 1 (default 10)"
    )
    parser.add_argument(
        "--roi",
        type=_roi,
        default=None,
        metavar="X0,Y0,X1,Y1",
        help="region of interest in px, half-open (X0 <= x < X1); default: the whole image",
    )
    parser.add_argument(
        "--csv",
        default=None,
        metavar="FILE",
        type=output_file,
        help="write one row per point: x_px, y_px (subset centre), u_px, v_px (displacement), "
        "std_u_px, std_v_px (its standard deviation from the IC-GN covariance), zncc, converged "
        "(0/1); px, x right, y down; NaN where not converged. With several DEF images one file "
        "per image, FILE's stem suffixed _1, _2, ...",
    )
    parser.add_argument(
        "--order",
        type=int,
        choices=(3, 5),
        default=3,
        help="B-spline order: 3 bicubic, 5 biquintic",
    )
    parser.add_argument(
        "--zncc-min",
        type=float_in(-1.0, 1.0),
        default=0.9,
        help="flag points whose final ZNCC is lower, in [-1, 1] (default 0.9)",
    )
    parser.add_argument(
        "--search",
        type=nonneg_int,
        default=32,
        help="integer search radius of the FFT seed guess, px (default 32; 0: no search)",
    )
    parser.add_argument(
        "--figure",
        default=None,
        metavar="PNG",
        type=_figure_file,
        help="subset figure (reference / warped / deformed) of the last image (.png, .pdf or .svg)",
    )
    parser.add_argument(
        "--no-progress",
        action="store_true",
        help="no progress bar (there is none either when stderr is not a terminal)",
    )


def _csv_paths(base: str, n: int) -> list:
    from pathlib import Path

    p = Path(base)
    if n == 1:
        return [p]
    return [p.with_name(f"{p.stem}_{k}{p.suffix or '.csv'}") for k in range(1, n + 1)]


def write_csv(path, result) -> None:
    """One row per point (:data:`COLUMNS`): subset centre x, y (px), displacement u, v (px), their
    standard deviations std_u, std_v (px; square roots of the IC-GN covariance diagonal), zncc and
    converged (0/1); u, v and the standard deviations are NaN where not converged."""
    import numpy as np

    from problems.io.atomic import atomic_write_text

    data = np.column_stack(
        [
            result.x,
            result.y,
            result.u,
            result.v,
            result.std_u,
            result.std_v,
            result.zncc,
            result.converged.astype(float),
        ]
    )
    lines = [",".join(COLUMNS)] + [
        f"{row[0]:.0f},{row[1]:.0f},{row[2]:.6f},{row[3]:.6f},{row[4]:.6g},{row[5]:.6g},"
        f"{row[6]:.6f},{int(row[7])}"
        for row in data
    ]
    atomic_write_text(path, "\n".join(lines) + "\n")


def main(args: argparse.Namespace) -> int:
    import numpy as np
    from tqdm import tqdm

    from bench.outputs import refuse_inputs
    from bench.progress import enabled
    from problems.dic.correlate import Correlator, DICConfig, as_grey, check_not_blank, grid_points
    from problems.dic.imageio import read_image

    outs = _csv_paths(args.csv, len(args.deformed)) if args.csv else [None] * len(args.deformed)
    for option, path in [*(("--csv", o) for o in outs), ("--figure", args.figure)]:
        refuse_inputs(option, path, [args.ref, *args.deformed])
    cfg = DICConfig(
        subset=args.subset,
        step=args.step,
        order=args.order,
        zncc_min=args.zncc_min,
        search_radius=args.search,
    )
    ref = read_image(args.ref)
    check_not_blank(as_grey(ref, args.ref), f"reference image {args.ref}")
    # read everything first: bad inputs fail before any work
    images = []
    for path in args.deformed:
        img = read_image(path)
        if img.shape != ref.shape:
            raise ValueError(
                f"image sizes differ: {args.ref} is {ref.shape[1]} x {ref.shape[0]} px, "
                f"{path} is {img.shape[1]} x {img.shape[0]} px"
            )
        check_not_blank(as_grey(img, path), f"deformed image {path}")
        images.append(img)
    pts = grid_points(ref.shape, cfg.subset, cfg.step, args.roi)
    corr = Correlator(ref, pts, cfg)
    prev = None
    res = None
    for path, img, out in tqdm(
        list(zip(args.deformed, images, outs)),
        desc="DIC",
        unit="img",
        disable=not enabled(args.no_progress),
    ):
        res = corr.correlate(img, initial=prev)
        if np.any(res.converged):
            prev = res
        c = res.converged
        msg = f"{path}: {int(c.sum())}/{len(c)} points converged"
        if np.any(c):
            msg += (
                f", mean u = {np.mean(res.u[c]):+.4f} px, mean v = {np.mean(res.v[c]):+.4f} px, "
                f"median ZNCC = {np.median(res.zncc[c]):.5f}, median std(u) = "
                f"{np.median(res.std_u[c]):.4f} px"
            )
        tqdm.write(msg)
        if out is not None:
            write_csv(out, res)
            tqdm.write(f"  -> {out}")
    if args.figure and res is not None and np.any(res.converged):
        from bench.dic_figures import subsets_figure
        from problems.dic.subsets import subset_figure_data

        conv = np.flatnonzero(res.converged)
        pick = conv[np.linspace(0, len(conv) - 1, min(4, len(conv))).round().astype(int)]
        subsets_figure(
            subset_figure_data(ref, images[-1], res, pick, cfg.subset, cfg.order), args.figure
        )
        tqdm.write(f"figure -> {args.figure}")
    return 0

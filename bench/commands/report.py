"""``femubench report DIR``: tables and figures of a results directory."""

from __future__ import annotations

NAME = "report"
HELP = "write the tables (Table 1, comparison) and figures of a results directory into DIR/report/"

FORMATS = ("md", "csv", "tex", "pdf", "parquet", "ioh", "coco", "stats")


def add_arguments(parser) -> None:
    from bench.commands._args import float_in

    parser.add_argument("dir", metavar="DIR", help="results directory written by 'femubench run'")
    parser.add_argument(
        "--format",
        default="md,csv,tex",
        metavar="LIST",
        help="comma-separated: md, csv, tex (tables), pdf (figures also as PDF), "
        "parquet (the tidy DataFrames), ioh (IOHprofiler folders for IOHanalyzer), coco (COCO "
        "data folders for cocopp), stats (rank tests, fixed-target and fixed-budget tables of "
        "the FE runs); default md,csv,tex",
    )
    parser.add_argument(
        "--tol",
        type=float_in(0.0, low_open=True, unit="%"),
        default=2.0,
        metavar="PERCENT",
        help="a run succeeds when every identified |parameter error| <= PERCENT, > 0 (default 2)",
    )
    parser.add_argument(
        "--tol-a",
        type=float_in(0.0, low_open=True, unit="%"),
        default=20.0,
        metavar="PERCENT",
        help="... and the exponent cases' derived |error of a| <= PERCENT (default 20)",
    )
    parser.add_argument(
        "--out",
        default=None,
        metavar="DEST",
        help="write the report into DEST instead of DIR/report (replaced as a whole, so refused "
        "when it is DIR, DIR/runs, a folder holding DIR or an input, or a non-empty folder that "
        "no report wrote)",
    )
    parser.add_argument(
        "--posterior",
        action="append",
        default=None,
        metavar="FOLDER",
        help="folder with the posterior study's <case>/summary.json (repeatable; default: "
        "DIR/posterior, DIR/studies/posterior and DIR/../studies/posterior when present)",
    )
    parser.add_argument("--no-figures", action="store_true", help="tables only")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def main(args) -> int:
    from pathlib import Path

    formats = [f.strip().lower() for f in args.format.split(",") if f.strip()]
    bad = [f for f in formats if f not in FORMATS]
    if bad or not formats:
        raise ValueError(
            f"--format {args.format!r}: unknown format(s) {', '.join(bad) or '(none given)'}; "
            f"allowed: a comma-separated list of {', '.join(FORMATS)}"
        )
    if not Path(args.dir).is_dir():
        what = "is a file, not a directory" if Path(args.dir).exists() else "does not exist"
        raise FileNotFoundError(f"results directory {args.dir!r} {what}")

    from bench.progress import enabled
    from bench.report import write_report

    out = write_report(
        args.dir,
        formats,
        tol=args.tol,
        tol_a=args.tol_a,
        figures=not args.no_figures,
        progress=enabled(args.quiet),
        dest=args.out,
        posterior_dirs=args.posterior,
    )
    print(f"report: {out}")
    return 0

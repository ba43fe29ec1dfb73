"""``femubench report DIR``: tables and figures of a results directory."""
from __future__ import annotations

NAME = "report"
HELP = "write the tables (Table 1, comparison) and figures of a results directory into DIR/report/"

FORMATS = ("md", "csv", "tex", "pdf", "parquet")


def add_arguments(parser) -> None:
    parser.add_argument("dir", metavar="DIR", help="results directory written by 'femubench run'")
    parser.add_argument("--format", default="md,csv,tex", metavar="LIST",
                        help="comma-separated: md, csv, tex (tables), pdf (figures also as PDF), "
                             "parquet (the tidy DataFrames); default md,csv,tex")
    parser.add_argument("--tol", type=float, default=1.0, metavar="PERCENT",
                        help="a run succeeds when every |parameter error| <= PERCENT (default 1)")
    parser.add_argument("--no-figures", action="store_true", help="tables only")


def main(args) -> int:
    from pathlib import Path

    formats = [f.strip().lower() for f in args.format.split(",") if f.strip()]
    bad = [f for f in formats if f not in FORMATS]
    if bad or not formats:
        raise ValueError(f"--format: unknown format(s) {', '.join(bad) or '(none)'}; allowed: {', '.join(FORMATS)}")
    if not (args.tol > 0):
        raise ValueError(f"--tol must be a positive percentage, got {args.tol}")
    if not Path(args.dir).is_dir():
        raise FileNotFoundError(f"results directory {args.dir!r} does not exist")

    from bench.report import write_report

    out = write_report(args.dir, formats, tol=args.tol, figures=not args.no_figures)
    print(f"report: {out}")
    return 0

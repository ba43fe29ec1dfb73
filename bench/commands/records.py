"""``femubench records compact DIR``: convert one-file run records to the compact form."""

from __future__ import annotations

NAME = "records"
HELP = "maintain the run records of a results directory (compact: split the history off)"


def add_arguments(parser) -> None:
    parser.add_argument("action", choices=("compact",), help="compact: write DIR/runs compact")
    parser.add_argument("dir", metavar="DIR", help="results directory written by 'femubench run'")
    parser.add_argument(
        "--dry-run", action="store_true", help="convert and verify in a temporary folder only"
    )


def main(args) -> int:
    import sys
    from pathlib import Path

    from bench import store

    if not store.runs_dir(args.dir).is_dir():
        print(f"femubench records: DIR {args.dir!r} has no runs/ folder", file=sys.stderr)
        return 2
    done = store.compact_records(Path(args.dir), dry_run=args.dry_run)
    before, after = sum(b for _, b, _ in done), sum(a for _, _, a in done)
    verb = "would convert" if args.dry_run else "converted"
    for path, b, a in done:
        print(f"{path.name}: {b} -> {a} bytes")
    print(f"{verb} {len(done)} record(s): {before} -> {after} bytes")
    return 0

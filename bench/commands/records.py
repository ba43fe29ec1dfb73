"""``femubench records compact DIR``: convert run records to the compact form of today."""

from __future__ import annotations

NAME = "records"
HELP = "maintain the run records of a results directory (compact: split the history off)"
#: Bytes of diff text per byte of a binary file added (git's base85 ``--binary`` patch).
BINARY_DIFF_FACTOR = 1.3
#: Bytes of diff text per file a conversion changes (``diff --git``, index and hunk headers with
#: the record's path; measured 405 on the 738 files of the FE consistent-tier conversion of
#: ``results/comparison``).
FILE_DIFF_BYTES = 400


def add_arguments(parser) -> None:
    parser.add_argument("action", choices=("compact",), help="compact: write DIR/runs compact")
    parser.add_argument("dir", metavar="DIR", help="results directory written by 'femubench run'")
    parser.add_argument(
        "--dry-run",
        action="store_true",
        help="convert and verify in a temporary folder only; print the bytes that would be "
        "deleted and added",
    )
    parser.add_argument(
        "--track",
        help="only records of this track: 'fe' (no surrogate) or a track name such as 'surrogate'",
    )
    parser.add_argument(
        "--tier", help="only records of this data tier, e.g. 'consistent' or 'model-error'"
    )
    parser.add_argument("--method", help="only records of this solver, e.g. 'mcmc' or 'sa'")
    parser.add_argument("--limit", type=int, help="convert at most this many records (N >= 1)")
    parser.add_argument(
        "--record",
        action="append",
        metavar="FILE",
        help="only this record (file name or hash; repeatable)",
    )


def main(args) -> int:
    import sys
    from pathlib import Path

    from bench.experiment import store

    if not store.runs_dir(args.dir).is_dir():
        print(f"femubench records: DIR {args.dir!r} has no runs/ folder", file=sys.stderr)
        return 2
    if args.limit is not None and args.limit < 1:
        print(f"femubench records: --limit {args.limit} must be >= 1", file=sys.stderr)
        return 2
    done = store.compact_records(
        Path(args.dir),
        dry_run=args.dry_run,
        track=args.track,
        tier=args.tier,
        method=args.method,
        limit=args.limit,
        only=args.record,
    )
    before = sum(d[1] for d in done)
    text, binary = sum(d[2] for d in done), sum(d[3] for d in done)
    verb = "would convert" if args.dry_run else "converted"
    for path, b, j, c in done:
        print(f"{path.name}: {b} -> {j + c} bytes")
    print(f"{verb} {len(done)} record(s): {before} -> {text + binary} bytes")
    files = 2 * len(done)  # the JSON rewritten, its companion added
    diff = before + text + BINARY_DIFF_FACTOR * binary + FILE_DIFF_BYTES * files
    print(
        f"deleted {before} bytes, added {text} bytes of JSON and {binary} bytes of companions "
        f"(diff text ~{diff:.0f} bytes, {diff / 2**20:.1f} MiB)"
    )
    return 0

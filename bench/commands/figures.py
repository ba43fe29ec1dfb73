"""``femubench figures compact PATH...``: rewrite PNG figures in the palette form of today."""

from __future__ import annotations

NAME = "figures"
HELP = "maintain figures (compact: rewrite PNG figures as the palette PNGs a render writes now)"
#: Bytes of diff text per byte of a rewritten PNG deflated: git's ``--binary`` patch of a
#: rewritten file holds the new and the old file, each deflated and in base85 (measured 1.24 on
#: the 200 shipped figures: 39.6 MB of ``git diff --cached --binary``)
DEFLATED_DIFF_FACTOR = 1.25


def add_arguments(parser) -> None:
    parser.add_argument(
        "action",
        choices=("compact",),
        help="compact: rewrite each PNG as bench.plotting.palette_png of itself (in place)",
    )
    parser.add_argument(
        "paths",
        nargs="+",
        metavar="PATH",
        help="a PNG file, or a folder (every *.png below it)",
    )
    parser.add_argument(
        "--dry-run",
        action="store_true",
        help="convert in memory only; print the bytes before and after and the diff text",
    )


def main(args) -> int:
    """Convert every PNG in memory first (a bad file stops the command before anything is
    written), then write the changed ones atomically; print per file the bytes before -> after,
    the totals and an estimate of the diff text of committing the change (bytes)."""
    import zlib
    from pathlib import Path

    from bench.commands.records import FILE_DIFF_BYTES
    from bench.experiment.store import atomic_write
    from bench.plotting import palette_png

    files = []
    for p in map(Path, args.paths):
        if p.is_dir():
            files += sorted(p.rglob("*.png"))
        elif p.is_file():
            files.append(p)
        else:
            raise ValueError(f"PATH {str(p)!r} is neither a file nor a folder")
    converted = []
    for path in files:
        old = path.read_bytes()
        try:
            new = palette_png(old)
        except ValueError as exc:
            raise ValueError(f"{path}: {exc}") from None
        converted.append((path, old, new))
    changed = [(p, old, new) for p, old, new in converted if new != old]
    for path, old, new in converted:
        print(f"{path}: {len(old)} -> {len(new)} bytes" + ("" if new != old else " (unchanged)"))
        if not args.dry_run and new != old:
            atomic_write(path, lambda fh, data=new: fh.write(data))
    before = sum(len(old) for _, old, _ in changed)
    after = sum(len(new) for _, _, new in changed)
    deflated = sum(len(zlib.compress(old)) + len(zlib.compress(new)) for _, old, new in changed)
    diff = DEFLATED_DIFF_FACTOR * deflated + FILE_DIFF_BYTES * len(changed)
    verb = "would rewrite" if args.dry_run else "rewrote"
    print(
        f"{verb} {len(changed)} of {len(converted)} figure(s): {before} -> {after} bytes "
        f"(diff text ~{diff:.0f} bytes, {diff / 2**20:.1f} MiB)"
    )
    return 0

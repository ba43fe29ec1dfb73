"""``femubench artefacts list|verify|pack|unpack|add``: the release artefacts (stored default
surrogates, BAE statistics) that may live outside the source tree (see bench/artefacts.py)."""

from __future__ import annotations

NAME = "artefacts"
HELP = (
    "release artefacts kept outside the tree (surrogates, BAE statistics): list, verify, "
    "pack into / unpack from a .tar.xz or the git history, add to the manifest"
)


def add_arguments(p) -> None:
    p.add_argument(
        "action",
        choices=("list", "verify", "pack", "unpack", "add"),
        help="list: each artefact, its size, where it is and its rebuild command; verify: check "
        "the sha256 of every artefact present (exit 1 on a mismatch); pack ARCHIVE: write them "
        "all into a .tar.xz; unpack ARCHIVE: check an archive against the manifest and put its "
        "artefacts in place (or, with --from-git, take them from a commit of this repository); add "
        "PATH: list PATH in the manifest with --rebuild and --rebuild-s",
    )
    p.add_argument("path", nargs="?", metavar="ARCHIVE|PATH", help="for pack, unpack and add")
    p.add_argument(
        "--to",
        metavar="DIR",
        help="unpack into DIR (default: the artefact directory, $FEMUBENCH_ARTEFACT_DIR, else "
        "~/.cache/femubench/artefacts; give the results root to put them back in the tree)",
    )
    p.add_argument(
        "--from-git",
        nargs="?",
        const="",
        metavar="REV",
        help="unpack: read the artefacts from commit REV of the git history of this checkout "
        "(default: the manifest's git_commit, the last commit that holds them) instead of an "
        "archive; every sha256 is checked against the manifest before anything is put in place",
    )
    p.add_argument("--rebuild", metavar="CMD", help="add: the femubench command that rebuilds it")
    p.add_argument("--rebuild-s", type=float, metavar="S", help="add: wall time of that command, s")


def main(args) -> int:
    import sys

    from bench import artefacts as A

    from_git = args.from_git is not None
    if from_git and args.action != "unpack":
        raise ValueError("--from-git goes with 'unpack' only")
    if from_git and args.path:
        raise ValueError(f"femubench artefacts unpack: give ARCHIVE {args.path} or --from-git")
    if args.action in ("pack", "unpack", "add") and not args.path and not from_git:
        raise ValueError(f"femubench artefacts {args.action}: give the ARCHIVE or PATH")
    if args.action != "add" and (args.rebuild or args.rebuild_s is not None):
        raise ValueError("--rebuild and --rebuild-s go with 'add' only")
    if args.to and args.action != "unpack":
        raise ValueError("--to goes with 'unpack' only")
    if args.action == "add":
        if not args.rebuild or args.rebuild_s is None:
            raise ValueError("femubench artefacts add: give --rebuild CMD and --rebuild-s S")
        rel, entry = A.add(args.path, args.rebuild, args.rebuild_s)
        print(f"listed {rel}: {entry['bytes'] / 1e6:.2f} MB, sha256 {entry['sha256'][:16]}")
        return 0
    if args.action == "pack":
        archive, packed = A.pack(args.path)
        print(
            f"wrote {archive}: {len(packed)} artefacts, {archive.stat().st_size / 1e6:.2f} MB, "
            f"sha256 {A.file_sha256(archive)}"
        )
        return 0
    if args.action == "unpack":
        where = args.to or A.search_roots()[1]
        if from_git:
            commit, done = A.unpack_from_git(args.from_git or None, args.to)
            print(
                f"unpacked {len(done)} artefacts of commit {commit[:12]} (sha256 checked) "
                f"into {where}"
            )
            return 0
        done = A.unpack(args.path, args.to)
        print(f"unpacked {len(done)} artefacts (sha256 checked) into {where}")
        return 0

    entries = A.read_manifest()
    if not entries:
        print(f"{A.manifest_path()} lists no artefacts")
        return 0
    roots = A.search_roots()
    bad, absent, total = 0, 0, 0.0
    for rel, entry in sorted(entries.items()):
        total += entry["bytes"]
        where = next((r for r in roots if (r / rel).exists()), None)
        if args.action == "list":
            place = "missing" if where is None else ("tree" if where == roots[0] else "cache")
            print(
                f"{rel}  {entry['bytes'] / 1e6:.2f} MB  {place}  rebuild: `{entry['rebuild']}` "
                f"({A.duration(entry['rebuild_s'])})"
            )
            continue
        if where is None:
            absent += 1
            print(f"missing  {A.missing(rel)}")
            continue
        problems = A.mismatches(where / rel, entry)
        bad += bool(problems)
        print(f"{'MISMATCH' if problems else 'ok'}  {where / rel}")
        for line in problems:
            print(f"  {line}", file=sys.stderr)
    rebuild_s = sum(e["rebuild_s"] for e in entries.values())
    print(
        f"{len(entries)} artefacts, {total / 1e6:.1f} MB, rebuilt in "
        f"{A.duration(rebuild_s)} in all; looked for in {roots[0]}, then {roots[1]}"
        + (f"; {bad} differ from the manifest, {absent} missing" if args.action == "verify" else "")
    )
    return 1 if bad else 0

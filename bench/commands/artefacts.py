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
    p.add_argument(
        "--track",
        metavar="T",
        help="add: PATH is a folder of records; list the group of the .history.xz companions "
        "its records of track T name (e.g. surrogate)",
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
    if args.action != "add" and (args.rebuild or args.rebuild_s is not None or args.track):
        raise ValueError("--rebuild, --rebuild-s and --track go with 'add' only")
    if args.to and args.action != "unpack":
        raise ValueError("--to goes with 'unpack' only")
    if args.action == "add":
        if not args.rebuild or args.rebuild_s is None:
            raise ValueError("femubench artefacts add: give --rebuild CMD and --rebuild-s S")
        rel, entry = A.add(args.path, args.rebuild, args.rebuild_s, args.track)
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
        found = A.found_members(rel, entry)
        if args.action == "list":
            place = _place(found, roots, A.is_group(entry))
            print(
                f"{rel}  {entry['bytes'] / 1e6:.2f} MB  {place}  rebuild: "
                f"`{entry['rebuild']}` ({A.duration(entry['rebuild_s'])})"
            )
            continue
        if found is None:
            absent += 1
            print(f"missing  {A.missing(rel)}")
            continue
        problems = [p for p in [A.index_problem(rel, entry)] if p]
        problems += A.check(found, A.members(rel, entry))
        bad += bool(problems)
        if A.is_group(entry):
            where = f"{rel} ({_place(found, roots, True)})"
        else:
            where = next(r / rel for r in roots if (r / rel).exists())
        print(f"{'MISMATCH' if problems else 'ok'}  {where}")
        for line in problems:
            print(f"  {line}", file=sys.stderr)
    rebuild_s = sum(e["rebuild_s"] for e in entries.values())
    print(
        f"{len(entries)} artefacts, {total / 1e6:.1f} MB, rebuilt in "
        f"{A.duration(rebuild_s)} in all; looked for in {roots[0]}, then {roots[1]}"
        + (f"; {bad} differ from the manifest, {absent} missing" if args.action == "verify" else "")
    )
    return 1 if bad else 0


def _place(found, roots, group: bool) -> str:
    """Where an artefact's files are: ``missing``, ``tree`` or ``cache``; for a group, the count
    of its files in each (``N tree + M cache + K missing of T files``)."""
    if found is None:
        return "missing"
    if not group:
        return "tree" if next(iter(found.values())).is_relative_to(roots[0]) else "cache"
    places = [
        "missing" if not p.is_file() else "tree" if p.is_relative_to(roots[0]) else "cache"
        for p in found.values()
    ]
    counts = {k: places.count(k) for k in ("tree", "cache", "missing") if k in places}
    return " + ".join(f"{n} {k}" for k, n in counts.items()) + f" of {len(places)} files"

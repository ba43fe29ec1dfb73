"""Release artefacts: the large inputs the shipped results were made with (the stored default
surrogates, ``surrogates/<name>/``, and the BAE statistics, ``model_error/<file>.npz``) that can
live outside the source tree.

The manifest ``<results root>/artefacts.json`` (format ``femubench-artefacts/1``) lists each
artefact by its path relative to the results root with its size (``bytes``), its ``sha256``, the
``femubench`` command that rebuilds it (``rebuild``) and how long that took (``rebuild_s``, s of
wall time). A file artefact's ``sha256`` is that of its bytes; a folder's is that of the lines
``<sha256>  <name>\\n`` of its files in name order (as ``sha256sum`` prints them), each file also
listed under ``files`` with its own ``sha256`` and ``bytes``. A *group* (key
``<folder>/*.history.xz``, field ``group: {"track": T}``) is the history companions that the
records ``<folder>/*.json`` of track ``T`` name: each record holds its companion's sha256
(``history_file``), so the records in the tree are the group's index; the manifest keeps their
``count``, ``bytes`` and the ``sha256`` of the index lines (as for a folder, names relative to
``<folder>``). A group's files are looked for one by one (results root, then artefact directory);
:func:`find_companion` is the store's lookup of one of them.

:func:`locate` is the one lookup of every loader (:func:`bench.experiment.surrogate_track.load_for`,
:func:`bench.experiment.objective.bae_correction`): the artefact in the results root if it is
there, else in :func:`~problems.inverse.user_cache.artefact_dir` (``$FEMUBENCH_ARTEFACT_DIR``,
default ``~/.cache/femubench/artefacts``). A listed artefact found with other bytes than the
manifest's is used with a one-line warning naming both hashes (a rebuild need not be bit-identical);
a missing one is named with its rebuild command by :func:`missing`. :func:`pack` writes the
listed artefacts into one ``.tar.xz`` (attached to a release), :func:`unpack` verifies every file
of such an archive against the manifest before anything is put in place; :func:`unpack_from_git`
does the same from a commit of the repository's own history (the manifest's ``git_commit``, the
last commit whose tree holds them: a clone always has them, its history is the source that
cannot be lost).
"""

from __future__ import annotations

import fnmatch
import hashlib
import json
import os
import shutil
import subprocess
import tarfile
import tempfile
import warnings
from pathlib import Path

FORMAT = "femubench-artefacts/1"
#: File name of the manifest in the results root.
MANIFEST = "artefacts.json"

_digests: dict[tuple, str] = {}


class MissingArtefact(FileNotFoundError):
    """A file of a listed artefact that is in neither place (one-line message with the way out)."""


def manifest_path(root: str | Path | None = None) -> Path:
    """The manifest of the results root ``root`` (default :func:`bench.paths.results_root`)."""
    from bench.paths import results_root

    return Path(root if root is not None else results_root()) / MANIFEST


def read_doc(root: str | Path | None = None) -> dict:
    """The whole manifest of ``root`` (``{"format", "artefacts", "git_commit"?}``; {} when it has
    none); ValueError naming the file when it is not a manifest."""
    path = manifest_path(root)
    if not path.is_file():
        return {}
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path} is not valid JSON: {exc}") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise ValueError(f"{path} is not an artefact manifest (format {FORMAT})")
    return doc


def read_manifest(root: str | Path | None = None) -> dict[str, dict]:
    """``{relative path: entry}`` of the manifest of ``root`` ({} when it has none); ValueError
    naming the file when it is not a manifest."""
    return read_doc(root).get("artefacts", {})


def write_manifest(
    entries: dict[str, dict], root: str | Path | None = None, git_commit: str | None = None
) -> Path:
    """Write the manifest of ``root`` (atomically, sorted, one key per line), keeping its
    ``git_commit`` unless ``git_commit`` gives a new one."""
    from problems.io.atomic import atomic_write_text

    doc = {"format": FORMAT, "artefacts": dict(sorted(entries.items()))}
    commit = git_commit or read_doc(root).get("git_commit")
    if commit:
        doc["git_commit"] = commit
    return atomic_write_text(manifest_path(root), json.dumps(doc, indent=1, sort_keys=True) + "\n")


def file_sha256(path: str | Path) -> str:
    """SHA-256 (hex) of the bytes of ``path``; remembered per (path, size, mtime) in this
    process, so a loader that reads the same file again does not hash it again."""
    st = os.stat(path)
    key = (str(Path(path).resolve()), st.st_size, st.st_mtime_ns)
    if key not in _digests:
        h = hashlib.sha256()
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
        _digests[key] = h.hexdigest()
    return _digests[key]


def folder_sha256(files: dict[str, dict]) -> str:
    """SHA-256 of a folder artefact: of the ``sha256sum`` lines of its ``files``, in name order."""
    lines = "".join(f"{files[n]['sha256']}  {n}\n" for n in sorted(files))
    return hashlib.sha256(lines.encode()).hexdigest()


def describe(path: str | Path) -> dict:
    """``{"sha256", "bytes"}`` of the file ``path``, or of the folder ``path`` with ``files``
    (its regular files, recursively, by relative POSIX name)."""
    path = Path(path)
    if path.is_file():
        return {"sha256": file_sha256(path), "bytes": path.stat().st_size}
    if not path.is_dir():
        raise FileNotFoundError(f"artefact {path} does not exist")
    files = {
        p.relative_to(path).as_posix(): {"sha256": file_sha256(p), "bytes": p.stat().st_size}
        for p in sorted(path.rglob("*"))
        if p.is_file()
    }
    return {
        "files": files,
        "sha256": folder_sha256(files),
        "bytes": sum(f["bytes"] for f in files.values()),
    }


def mismatches(path: str | Path, entry: dict) -> list[str]:
    """One line per file of ``path`` whose bytes are not the manifest ``entry``'s (both hashes
    named), or that is missing; [] when ``path`` is the listed artefact (:func:`check`)."""
    path = Path(path)
    if "files" not in entry:
        return check({"": path}, {"": entry["sha256"]})
    want = {name: f["sha256"] for name, f in sorted(entry["files"].items())}
    return check({name: path / name for name in want}, want)


def _mismatch(path: Path, got: str | None, want: str) -> str:
    if got is None:
        return f"{path} is missing (the release's sha256 {want[:16]})"
    return f"{path}: sha256 {got[:16]} is not the release's {want[:16]} ({MANIFEST})"


def search_roots() -> list[Path]:
    """Where :func:`locate` looks, in order: the results root, then the artefact directory."""
    from bench.paths import results_root
    from problems.inverse.user_cache import artefact_dir

    return [results_root(), artefact_dir()]


def locate(rel: str) -> Path | None:
    """The artefact ``rel`` (a path relative to the results root, e.g. ``surrogates/x__coarse``):
    in the results root if there, else in the artefact directory; None when in neither. A listed
    artefact whose bytes differ from the manifest's is returned with a one-line warning naming
    both hashes (and how many files differ)."""
    entry = read_manifest().get(rel)
    for root in search_roots():
        path = root / rel
        if path.exists():
            bad = mismatches(path, entry) if entry is not None else []
            if bad:
                more = f" (and {len(bad) - 1} more file(s))" if len(bad) > 1 else ""
                warnings.warn(
                    f"{bad[0]}{more}: not the artefact the shipped results were made with "
                    "(rebuilt or changed); results made with it may differ",
                    stacklevel=2,
                )
            return path
    return None


def listed(rel: str) -> dict | None:
    """The manifest entry of ``rel``, or None when the manifest does not list it."""
    return read_manifest().get(rel)


def duration(seconds: float) -> str:
    """``seconds`` as ``~N min`` (or ``~N.N h`` from 90 min on)."""
    minutes = seconds / 60.0
    return f"~{minutes / 60:.1f} h" if minutes >= 90 else f"~{max(1, round(minutes))} min"


def missing(rel: str) -> str:
    """One line for an artefact in neither place: where it was looked for and, when the manifest
    lists it, how to get it (the release archive, or its rebuild command and its duration)."""
    roots = " nor in ".join(str(r) for r in search_roots())
    entry = listed(rel)
    if entry is None:
        return f"{rel} is neither in {roots}"
    return (
        f"{rel} is neither in {roots}: restore it from the git history "
        f"(`femubench artefacts unpack --from-git`) or the release archive "
        f"(`femubench artefacts unpack FILE.tar.xz`), or rebuild it with `{entry['rebuild']}` "
        f"({duration(entry['rebuild_s'])})"
    )


def add(
    path: str | Path, rebuild: str, rebuild_s: float, track: str | None = None
) -> tuple[str, dict]:
    """List (or re-list) the artefact ``path`` (inside the results root) in its manifest with
    its sizes and hashes of now, the command ``rebuild`` and its duration ``rebuild_s`` (s).
    With ``track``, ``path`` is a folder of records and the artefact the group of the
    ``.history.xz`` companions its records of that track name (all present beside them)."""
    from bench.paths import results_root

    root = results_root()
    path = Path(path).resolve()
    try:
        rel = path.relative_to(root.resolve()).as_posix()
    except ValueError:
        raise ValueError(f"PATH {path} is not inside the results root {root}") from None
    if not rebuild.startswith("femubench "):
        raise ValueError(f"--rebuild {rebuild!r}: give the femubench command that rebuilds it")
    if not rebuild_s > 0:
        raise ValueError(f"--rebuild-s {rebuild_s}: must be > 0 (s of wall time)")
    entries = read_manifest(root)
    if track is not None:
        rel, entry = f"{rel}/*.history.xz", {"group": {"track": track}}
        index = group_index(rel, entry, root)
        if not index:
            raise ValueError(f"--track {track}: no record of {path} of that track has a companion")
        found = {m: root / m for m in index}
        bad = check(found, index)
        if bad:
            raise ValueError(f"PATH {path}: " + bad[0])
        entry |= {
            "count": len(index),
            "bytes": sum(p.stat().st_size for p in found.values()),
            "sha256": index_sha256(index),
        }
        entries[rel] = {**entry, "rebuild": rebuild, "rebuild_s": float(rebuild_s)}
        write_manifest(entries, root)
        return rel, entries[rel]
    entries[rel] = {**describe(path), "rebuild": rebuild, "rebuild_s": float(rebuild_s)}
    write_manifest(entries, root)
    return rel, entries[rel]


def pack(archive: str | Path) -> tuple[Path, list[str]]:
    """Write every listed artefact (found by :func:`locate`'s order) into the ``.tar.xz``
    ``archive`` under its relative path, atomically and reproducibly (sorted members, no owners,
    mtime 0). ValueError, before anything is written, when one is missing or differs from the
    manifest. Returns the archive and the artefacts packed."""
    from problems.io.atomic import atomic_write

    archive = Path(archive)
    if not archive.name.endswith(".tar.xz"):
        raise ValueError(f"ARCHIVE {archive.name!r}: the name must end in .tar.xz")
    entries = read_manifest()
    if not entries:
        raise ValueError(f"{manifest_path()} lists no artefacts")
    found: dict[str, dict[str, Path]] = {}
    problems = [p for rel, e in sorted(entries.items()) if (p := index_problem(rel, e))]
    for rel, entry in sorted(entries.items()):
        paths = found_members(rel, entry)
        if paths is None:
            problems.append(missing(rel))
            continue
        problems += check(paths, members(rel, entry))
        found[rel] = paths
    if problems:
        raise ValueError("cannot pack: " + "; ".join(problems))

    def write(fh):
        with tarfile.open(fileobj=fh, mode="w:xz", preset=6) as tar:
            for paths in found.values():
                for member, src in sorted(paths.items()):
                    info = tar.gettarinfo(str(src), arcname=member)
                    info.uid = info.gid = 0
                    info.uname = info.gname = ""
                    info.mtime = 0
                    info.mode = 0o644
                    with open(src, "rb") as data:
                        tar.addfile(info, data)

    atomic_write(archive, write)
    return archive, list(found)


def is_group(entry: dict) -> bool:
    """Whether the manifest ``entry`` is a group of history companions (see the module doc)."""
    return "group" in entry


def group_index(rel: str, entry: dict, root: str | Path | None = None) -> dict[str, str]:
    """``{path relative to the results root: sha256}`` of the members of the group ``rel``
    (``<folder>/<pattern>``): the companions matching ``pattern`` named in ``history_file`` by
    the records ``<folder>/*.json`` of the results root ``root`` (default the results root) whose
    ``config.track`` is the group's ``track``; unreadable records, and names that are not a plain
    file name of the folder (a ``/`` or ``\\``: a path out of it), are left out."""
    from bench.paths import results_root

    root = Path(root) if root is not None else results_root()
    folder, pattern = rel.rsplit("/", 1)
    out = {}
    for path in sorted((root / folder).glob("*.json")):
        try:
            rec = json.loads(path.read_text(encoding="utf-8"))
            ref, track = rec.get("history_file"), rec["config"].get("track")
            name, sha = ref["name"], ref["sha256"]
        except (ValueError, OSError, TypeError, KeyError, AttributeError):
            continue
        name = str(name)
        plain = "/" not in name and "\\" not in name
        if plain and track == entry["group"]["track"] and fnmatch.fnmatchcase(name, pattern):
            out[f"{folder}/{name}"] = str(sha)
    return out


def index_sha256(index: dict[str, str]) -> str:
    """SHA-256 of a group's index (:func:`group_index`): its ``sha256sum`` lines, as a folder's
    (:func:`folder_sha256`), names relative to the group's folder."""
    return folder_sha256({m.rsplit("/", 1)[1]: {"sha256": h} for m, h in index.items()})


def index_problem(rel: str, entry: dict) -> str | None:
    """One line when the records of the tree name other companions than the manifest's group
    ``rel`` (a rerun record: re-list it with ``femubench artefacts add``), else None."""
    if not is_group(entry):
        return None
    index = group_index(rel, entry)
    got = index_sha256(index)
    if got == entry["sha256"] and len(index) == entry["count"]:
        return None
    return (
        f"{rel}: the records name {len(index)} companions (index sha256 {got[:16]}), not the "
        f"release's {entry['count']} ({entry['sha256'][:16]}, {MANIFEST})"
    )


def members(rel: str, entry: dict) -> dict[str, str]:
    """``{file path relative to the results root: sha256}`` of the files of artefact ``rel``;
    ValueError (one line) when the manifest names a path that is not inside the results root
    (absolute, or with a ``..``, ``.`` or empty part): nothing is ever read or written there."""
    if is_group(entry):
        out = group_index(rel, entry)
    elif "files" in entry:
        out = {f"{rel}/{name}": f["sha256"] for name, f in sorted(entry["files"].items())}
    else:
        out = {rel: entry["sha256"]}
    for m in out:
        if m.startswith("/") or "\\" in m or {"", ".", ".."} & set(m.split("/")):
            raise ValueError(
                f"{manifest_path()}: artefact {rel!r} names {m!r}, not a path inside the "
                "results root"
            )
    return out


def found_members(rel: str, entry: dict) -> dict[str, Path] | None:
    """Where each file of artefact ``rel`` is: a file or folder artefact as a whole in the first
    root of :func:`search_roots` holding ``rel`` (its files' paths there, present or not); each
    file of a group in the first root holding it (the artefact directory's path when in
    neither). None when no file of it is in any root."""
    roots, want = search_roots(), members(rel, entry)
    if not is_group(entry):
        root = next((r for r in roots if (r / rel).exists()), None)
        return None if root is None else {m: root / m for m in want}
    found = {m: next((r / m for r in roots if (r / m).is_file()), None) for m in want}
    if not any(found.values()):
        return None
    return {m: p if p is not None else roots[-1] / m for m, p in found.items()}


def check(found: dict[str, Path], want: dict[str, str]) -> list[str]:
    """One line per file of ``want`` (``{member: sha256}``) whose path in ``found`` is missing or
    holds other bytes (both hashes named)."""
    out = []
    for m, sha in want.items():
        path = found[m]
        got = file_sha256(path) if path.is_file() else None
        if got != sha:
            out.append(_mismatch(path, got, sha))
    return out


def _place(tmp: Path, got: list[str], entries: dict[str, dict], dest: Path, source: str) -> None:
    """Check the artefacts ``got`` staged under ``tmp`` (laid out like the results root) against
    the manifest ``entries`` (ValueError naming ``source`` and every problem, nothing placed),
    then put each into ``dest``, a folder replacing its old copy as a unit."""
    from problems.io.atomic import atomic_dir

    if not got:
        raise ValueError(f"{source} holds no artefact")
    problems = [p for rel in sorted(got) if (p := index_problem(rel, entries[rel]))]
    for rel in sorted(got):
        want = members(rel, entries[rel])
        problems += check({m: tmp / m for m in want}, want)
    if problems:
        raise ValueError(f"{source}: " + "; ".join(problems))
    for rel in sorted(got):
        final = dest / rel
        if is_group(entries[rel]):
            for m in members(rel, entries[rel]):
                (dest / m).parent.mkdir(parents=True, exist_ok=True)
                os.replace(tmp / m, dest / m)
        elif "files" in entries[rel]:
            with atomic_dir(final) as staged:
                for name in entries[rel]["files"]:
                    (staged / name).parent.mkdir(parents=True, exist_ok=True)
                    os.replace(tmp / rel / name, staged / name)
        else:
            final.parent.mkdir(parents=True, exist_ok=True)
            os.replace(tmp / rel, final)


def _manifest_entries() -> dict[str, dict]:
    entries = read_manifest()
    if not entries:
        raise ValueError(f"{manifest_path()} lists no artefacts: nothing to check them by")
    return entries


def unpack(archive: str | Path, dest: str | Path | None = None) -> list[str]:
    """Put the artefacts of ``archive`` (written by :func:`pack`) into ``dest`` (default the
    artefact directory). Every member is checked first: it must be a regular file the manifest
    lists, and every artefact complete with the manifest's sha256 of each file; any problem is a
    ValueError naming it (both hashes for a mismatch) and nothing is put in place. Each artefact
    then replaces its old copy in ``dest`` as a unit. Returns the artefacts unpacked."""
    from problems.inverse.user_cache import artefact_dir

    archive = Path(archive)
    dest = Path(dest) if dest is not None else artefact_dir()
    entries = _manifest_entries()
    dest.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=dest, prefix=".unpack.") as tmp:
        tmp = Path(tmp)
        got: set[str] = set()
        owners = {m: rel for rel, e in entries.items() for m in members(rel, e)}
        try:
            tar = tarfile.open(archive, mode="r:xz")
        except (tarfile.TarError, EOFError, OSError) as exc:
            raise ValueError(f"ARCHIVE {archive} is not a .tar.xz ({exc})") from None
        with tar:
            try:
                listing = tar.getmembers()
            except (tarfile.TarError, EOFError, OSError) as exc:
                raise ValueError(f"ARCHIVE {archive} is torn ({exc})") from None
            for m in listing:
                if m.isdir():
                    continue
                owner = owners.get(m.name)
                if not m.isfile() or owner is None:
                    raise ValueError(
                        f"ARCHIVE {archive}: member {m.name!r} is not a file of an artefact "
                        f"listed in {manifest_path()}"
                    )
                target = tmp / m.name
                target.parent.mkdir(parents=True, exist_ok=True)
                with tar.extractfile(m) as src, open(target, "wb") as out:
                    shutil.copyfileobj(src, out)
                got.add(owner)
        _place(tmp, sorted(got), entries, dest, f"ARCHIVE {archive}")
    return sorted(got)


def _git(root: Path, *args: str, data: bytes | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        ["git", "-C", str(root), *args], input=data, capture_output=True, check=False
    )


def unpack_from_git(
    rev: str | None = None, dest: str | Path | None = None
) -> tuple[str, list[str]]:
    """Put every listed artefact, read from commit ``rev`` of the git repository holding the
    results root (default: the manifest's ``git_commit``, the last commit whose tree holds them),
    into ``dest`` (default the artefact directory), with the checks and the placing of
    :func:`unpack`: every file's sha256 against the manifest before anything is put in place.
    ValueError (one line naming the way out) when the results root is not in a git checkout, the
    commit is not in this clone (a shallow clone) or lacks a file. Returns ``(full commit hash,
    the artefacts unpacked)``."""
    from bench.paths import results_root
    from problems.inverse.user_cache import artefact_dir

    root = results_root()
    dest = Path(dest) if dest is not None else artefact_dir()
    entries = _manifest_entries()
    rev = rev or read_doc().get("git_commit")
    other = (
        "unpack the release archive (`femubench artefacts unpack FILE.tar.xz`) or rebuild each "
        "with the command `femubench artefacts list` names"
    )
    if not rev:
        raise ValueError(f"--from-git: give REV ({manifest_path()} records no git_commit)")
    try:
        top = _git(root, "rev-parse", "--show-toplevel")
    except OSError as exc:
        raise ValueError(f"--from-git: git cannot be run ({exc.strerror}): {other}") from None
    if top.returncode != 0:  # git's own first line: not a repository, dubious ownership, ...
        why = (top.stderr.decode(errors="replace").strip().splitlines() or ["no message"])[0]
        raise ValueError(
            f"--from-git: the results root {root} is not in a git checkout git can read ({why}): "
            f"{other}"
        )
    prefix = root.resolve().relative_to(Path(top.stdout.decode().strip()).resolve()).as_posix()
    commit = _git(root, "rev-parse", "--verify", "--quiet", f"{rev}^{{commit}}")
    if commit.returncode != 0:
        raise ValueError(
            f"--from-git: commit {rev} is not in this clone (a shallow clone? "
            f"`git fetch --unshallow`): {other}"
        )
    commit_hash = commit.stdout.decode().strip()
    wanted = [(rel, m) for rel, e in sorted(entries.items()) for m in members(rel, e)]
    paths = [
        f"{commit_hash}:{m}" if prefix == "." else f"{commit_hash}:{prefix}/{m}" for _, m in wanted
    ]
    out = _git(root, "cat-file", "--batch", data="".join(p + "\n" for p in paths).encode())
    if out.returncode != 0:
        raise ValueError(f"--from-git: git cat-file failed ({out.stderr.decode().strip()})")
    dest.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=dest, prefix=".unpack.") as tmp:
        tmp, buf, pos = Path(tmp), out.stdout, 0
        for (_, m), spec in zip(wanted, paths):
            end = buf.index(b"\n", pos)
            header = buf[pos:end].decode().split()
            if header[-1] == "missing" or len(header) != 3 or header[1] != "blob":
                raise ValueError(
                    f"--from-git: commit {rev} holds no file {spec.split(':', 1)[1]}: {other}"
                )
            size = int(header[2])
            target = tmp / m
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(buf[end + 1 : end + 1 + size])
            pos = end + 2 + size
        got = sorted({rel for rel, _ in wanted})
        _place(tmp, got, entries, dest, f"commit {commit_hash[:12]}")
    return commit_hash, got


def find_companion(record: str | Path, track: str | None, name: str, sha256: str) -> Path | None:
    """The history companion ``name`` (sha256 ``sha256``, from the record's ``history_file``) of
    the record file ``record`` of track ``track`` when it is not beside the record: for each group
    of that track whose pattern ``name`` matches, ``<folder>/name`` in the results root, then in
    the artefact directory (the caller checks the sha256). None when it is not a listed group
    member (the results root's record of that name must name the same companion); a listed one in
    neither place is a :class:`MissingArtefact` naming the record and the restore commands."""
    from bench.paths import results_root

    record = Path(record)
    for rel, entry in read_manifest().items():
        if not is_group(entry) or entry["group"]["track"] != track:
            continue
        folder, pattern = rel.rsplit("/", 1)
        if not fnmatch.fnmatchcase(name, pattern):
            continue
        roots = search_roots()
        path = next((r / folder / name for r in roots if (r / folder / name).is_file()), None)
        if path is not None:
            return path
        try:
            twin = json.loads((results_root() / folder / record.name).read_text(encoding="utf-8"))
            listed_member = twin["history_file"]["sha256"] == sha256
        except (ValueError, OSError, TypeError, KeyError):
            listed_member = False
        if listed_member:
            raise MissingArtefact(
                f"record {record}: its history companion {name} (release artefact {rel}) is "
                f"neither beside it nor in {roots[0] / folder} nor in {roots[1] / folder}: restore "
                "it with `femubench artefacts unpack --from-git` (or `femubench artefacts unpack "
                "FILE.tar.xz`)"
            )
    return None

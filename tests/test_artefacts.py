"""Release artefacts outside the tree (bench/artefacts.py, ``femubench artefacts``): the manifest's
hashes, the lookup (results root, then the artefact directory) with its mismatch warning and its
missing line, pack and unpack with their checks, and the loaders of surrogates and BAE statistics
that use it. All on small temporary artefacts."""

from __future__ import annotations

import hashlib
import io
import os
import shutil
import tarfile
import warnings
from pathlib import Path

import numpy as np
import pytest

from bench import artefacts as A
from bench.cli import main

ROOT = Path(__file__).resolve().parents[1]
SUR_CMD = "femubench surrogate linear-compression --mesh coarse"
BAE_CMD = "femubench identify linear-compression --solver lm --correction bae"


@pytest.fixture
def roots(tmp_path, monkeypatch):
    """A results root with one folder artefact (two files) and one file artefact, both listed;
    an empty artefact directory. Returns (results root, artefact directory)."""
    results, cache = tmp_path / "results", tmp_path / "cache"
    monkeypatch.setenv("FEMUBENCH_RESULTS_DIR", str(results))
    monkeypatch.setenv("FEMUBENCH_ARTEFACT_DIR", str(cache))
    monkeypatch.delenv("FEMUBENCH_SURROGATE_DIR", raising=False)
    folder = results / "surrogates" / "s__coarse"
    folder.mkdir(parents=True)
    (folder / "a.json").write_text('{"a": 1}\n')
    (folder / "b.npz").write_bytes(bytes(range(256)) * 40)
    (results / "model_error").mkdir()
    (results / "model_error" / "x.npz").write_bytes(b"statistics" * 100)
    assert main(["artefacts", "add", str(folder), "--rebuild", SUR_CMD, "--rebuild-s", "660"]) == 0
    assert (
        main(
            [
                "artefacts",
                "add",
                str(results / "model_error" / "x.npz"),
                "--rebuild",
                BAE_CMD,
                "--rebuild-s",
                "5400",
            ]
        )
        == 0
    )
    return results, cache


def test_the_manifest_holds_sizes_and_sha256_of_files_and_folders(roots):
    results, _ = roots
    entries = A.read_manifest()
    f = entries["model_error/x.npz"]
    assert f["sha256"] == hashlib.sha256(b"statistics" * 100).hexdigest() and f["bytes"] == 1000
    d = entries["surrogates/s__coarse"]
    lines = "".join(
        f"{hashlib.sha256((results / 'surrogates/s__coarse' / n).read_bytes()).hexdigest()}  {n}\n"
        for n in ("a.json", "b.npz")
    )
    assert d["sha256"] == hashlib.sha256(lines.encode()).hexdigest()
    assert d["bytes"] == 9 + 10240 and set(d["files"]) == {"a.json", "b.npz"}
    assert (d["rebuild"], d["rebuild_s"]) == (SUR_CMD, 660.0)


def test_locate_prefers_the_tree_then_the_cache_and_warns_on_other_bytes(roots, capsys):
    results, cache = roots
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert A.locate("model_error/x.npz") == results / "model_error" / "x.npz"
    want = A.read_manifest()["model_error/x.npz"]["sha256"]
    (results / "model_error" / "x.npz").write_bytes(b"rebuilt")
    got = hashlib.sha256(b"rebuilt").hexdigest()
    with pytest.warns(UserWarning) as caught:
        assert A.locate("model_error/x.npz") == results / "model_error" / "x.npz"
    msg = str(caught[0].message)
    assert got[:16] in msg and want[:16] in msg and "\n" not in msg
    assert main(["artefacts", "verify"]) == 1
    out, err = capsys.readouterr()
    assert "MISMATCH" in out and got[:16] in err and want[:16] in err
    # gone from the tree: found in the artefact directory
    (results / "model_error" / "x.npz").unlink()
    assert A.locate("model_error/x.npz") is None
    (cache / "model_error").mkdir(parents=True)
    (cache / "model_error" / "x.npz").write_bytes(b"statistics" * 100)
    assert A.locate("model_error/x.npz") == cache / "model_error" / "x.npz"
    assert main(["artefacts", "verify"]) == 0


def test_a_missing_artefact_is_one_line_with_its_rebuild_command_and_time(roots):
    results, _ = roots
    (results / "model_error" / "x.npz").unlink()
    line = A.missing("model_error/x.npz")
    assert "\n" not in line and f"`{BAE_CMD}` (~1.5 h)" in line
    assert "femubench artefacts unpack" in line and str(results) in line
    assert A.duration(660) == "~11 min" and A.duration(20) == "~1 min"


def test_pack_then_unpack_restores_the_same_bytes_reproducibly(roots, tmp_path, capsys):
    results, cache = roots
    a, b = tmp_path / "a.tar.xz", tmp_path / "b.tar.xz"
    assert main(["artefacts", "pack", str(a)]) == 0
    assert A.file_sha256(a) in capsys.readouterr().out
    assert main(["artefacts", "pack", str(b)]) == 0
    assert a.read_bytes() == b.read_bytes()  # same artefacts, same archive
    files = ("model_error/x.npz", "surrogates/s__coarse/a.json", "surrogates/s__coarse/b.npz")
    before = {rel: (results / rel).read_bytes() for rel in files}
    shutil.rmtree(results / "surrogates")
    (results / "model_error" / "x.npz").unlink()
    assert A.locate("surrogates/s__coarse") is None and A.locate("model_error/x.npz") is None
    assert main(["artefacts", "unpack", str(a)]) == 0
    for rel, data in before.items():
        assert (cache / rel).read_bytes() == data
    assert A.locate("surrogates/s__coarse") == cache / "surrogates" / "s__coarse"
    assert sorted(p.name for p in cache.iterdir()) == ["model_error", "surrogates"]  # no temp left


def _archive(path: Path, members: dict[str, bytes]) -> Path:
    with tarfile.open(path, "w:xz") as tar:
        for name, data in members.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
    return path


@pytest.mark.parametrize(
    "members, needle",
    [
        ({"model_error/x.npz": b"tampered"}, "is not the release's"),
        ({"../evil": b"x"}, "is not a file of an artefact"),
        ({"model_error/other.npz": b"x"}, "is not a file of an artefact"),
        ({"surrogates/s__coarse/a.json": b'{"a": 1}\n'}, "b.npz is missing"),
    ],
)
def test_unpack_refuses_an_archive_that_is_not_the_manifest(
    roots, tmp_path, capsys, members, needle
):
    _, cache = roots
    archive = _archive(tmp_path / "bad.tar.xz", members)
    assert main(["artefacts", "unpack", str(archive)]) == 2
    err = capsys.readouterr().err
    assert needle in err and len(err.strip().splitlines()) == 1, err
    if "tampered" in str(members):
        assert hashlib.sha256(b"tampered").hexdigest()[:16] in err
    assert not any(p.is_file() for p in cache.rglob("*"))  # nothing was put in place


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["pack", "out.zip"], "must end in .tar.xz"),
        (["pack"], "give the ARCHIVE or PATH"),
        (["add", "model_error/x.npz"], "--rebuild CMD and --rebuild-s S"),
        (["add", "/etc/hostname", "--rebuild", BAE_CMD, "--rebuild-s", "1"], "not inside"),
        (["verify", "--rebuild-s", "3"], "with 'add' only"),
        (["unpack", "missing.tar.xz"], "is not a .tar.xz"),
        (["pack", "a.tar.xz", "--from-git"], "with 'unpack' only"),
        (["unpack", "a.tar.xz", "--from-git", "HEAD"], "give ARCHIVE a.tar.xz or --from-git"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(roots, capsys, argv, needle):
    assert main(["artefacts", *argv]) == 2
    err = capsys.readouterr().err
    assert needle in err and len(err.strip().splitlines()) == 1, err


def test_the_shipped_manifest_lists_every_stored_surrogate_and_statistic():
    """Every shipped default surrogate and BAE statistic is a listed release artefact with a
    command and a time, and every listed one is one of those."""
    entries = A.read_manifest(ROOT / "results")
    sur = {k for k in entries if k.startswith("surrogates/")}
    bae = {k for k in entries if k.startswith("model_error/")}
    assert len(sur) == 10 and len(bae) == 18 and len(entries) == 29
    for rel, e in entries.items():
        assert e["rebuild"].startswith("femubench ") and e["rebuild_s"] > 60 and e["bytes"] > 1e5
        if (ROOT / "results" / rel).exists():
            assert A.mismatches(ROOT / "results" / rel, e) == [], rel
    # the group: the comparison's surrogate-track companions, indexed by the records in the tree
    group = entries["comparison/runs/*.history.xz"]
    assert group["group"] == {"track": "surrogate"} and group["count"] == 828
    index = A.group_index("comparison/runs/*.history.xz", group, ROOT / "results")
    assert len(index) == 828 and A.index_sha256(index) == group["sha256"]


def test_surrogates_are_loaded_from_the_artefact_directory(roots):
    from bench.experiment.surrogate_track import load_for
    from problems.surrogate.store import save
    from tests.test_surrogate_identify import fake_surrogate

    _, cache = roots
    with pytest.raises(FileNotFoundError, match="no default surrogate of linear-compression"):
        load_for("default", "linear-compression", "coarse")
    sur = fake_surrogate(n=12)
    folder = save(sur, cache / "surrogates" / "linear-compression__coarse")
    got = load_for("default", "linear-compression", "coarse")
    assert got.hash == sur.info["hash"] and got.info["path"] == str(folder)


def test_make_runs_suite_with_its_records_needs_no_surrogate(tmp_path, monkeypatch, capsys):
    """`make run` on the shipped records: every surrogate-track run has its record, so no
    surrogate is asked for even when none is anywhere."""
    monkeypatch.setenv("FEMUBENCH_SURROGATE_DIR", str(tmp_path / "none"))
    suite, out = ROOT / "suites" / "default.toml", ROOT / "results" / "default"
    assert main(["run", str(suite), "--out", str(out), "--dry-run", "--quiet"]) == 0
    assert " 0 to run" in capsys.readouterr().out


def test_missing_bae_statistics_are_named_before_they_are_computed(roots, monkeypatch):
    """A listed BAE statistic in neither place: one warning line with the way to get it, then
    the computation (stopped here)."""
    import problems.inverse.model_error as me
    from bench.experiment.objective import bae_path, prepare
    from bench.experiment.spec import RunSpec, Treatment

    results, cache = roots
    spec = RunSpec("linear-compression", "lm", treatment=Treatment("default"))
    asm = prepare(spec)
    rel = f"model_error/{bae_path(asm.spec, asm.hifi_mesh, asm.data).name}"
    m = asm.objective().problem.data.size
    corr = me.Correction(
        "bae", np.zeros(m), np.full((m, 1), 1e-6), n_hifi=7, points=np.ones((7, 6))
    )
    corr.save(results / rel)
    argv = ["artefacts", "add", str(results / rel), "--rebuild", BAE_CMD, "--rebuild-s", "300"]
    assert main(argv) == 0
    (cache / "model_error").mkdir(parents=True)
    (results / rel).replace(cache / rel)
    assert prepare(spec).correction().n_hifi == 7  # from the artefact directory, no run

    (cache / rel).unlink()

    def stop(*a, **k):
        raise RuntimeError("computing")

    monkeypatch.setattr(me, "bae_statistics", stop)
    with pytest.warns(UserWarning, match=r"~5 min\); computing them now") as caught:
        with pytest.raises(RuntimeError, match="computing"):
            prepare(spec).correction()
    assert BAE_CMD in str(caught[0].message)


def _commit(repo: Path, message: str) -> str:
    import subprocess

    def git(*args):
        return subprocess.run(
            ["git", "-C", str(repo), "-c", "user.name=t", "-c", "user.email=t@t", *args],
            check=True,
            capture_output=True,
            text=True,
        ).stdout.strip()

    git("add", "-A")
    git("commit", "-q", "--allow-empty", "-m", message)
    return git("rev-parse", "HEAD")


def test_unpack_from_git_restores_the_artefacts_of_an_older_commit(roots, tmp_path, capsys):
    """The artefacts committed once and deleted in a later commit come back from the history,
    checked against the manifest; other bytes in that commit are refused, nothing placed."""
    import subprocess

    results, cache = roots
    assert main(["artefacts", "unpack", "--from-git"]) == 2  # no git_commit, no REV
    assert "give REV" in capsys.readouterr().err
    assert main(["artefacts", "unpack", "--from-git", "HEAD"]) == 2
    err = capsys.readouterr().err
    assert "is not in a git checkout" in err and "artefacts unpack FILE.tar.xz" in err
    subprocess.run(["git", "init", "-q", str(tmp_path)], check=True)
    first = _commit(tmp_path, "artefacts in the tree")
    A.write_manifest(A.read_manifest(), git_commit=first)
    files = ("model_error/x.npz", "surrogates/s__coarse/a.json", "surrogates/s__coarse/b.npz")
    before = {rel: (results / rel).read_bytes() for rel in files}
    shutil.rmtree(results / "surrogates")
    (results / "model_error" / "x.npz").unlink()
    _commit(tmp_path, "artefacts out of the tree")
    assert "--from-git" in A.missing("model_error/x.npz")
    assert main(["artefacts", "unpack", "--from-git"]) == 0  # the manifest's commit
    assert f"of commit {first[:12]}" in capsys.readouterr().out
    for rel, data in before.items():
        assert (cache / rel).read_bytes() == data
    assert sorted(p.name for p in cache.iterdir()) == ["model_error", "surrogates"]  # no temp
    assert main(["artefacts", "verify"]) == 0
    # a commit whose bytes are not the manifest's: refused, nothing put in place
    shutil.rmtree(cache)
    (results / "model_error" / "x.npz").write_bytes(b"tampered")
    (results / "surrogates" / "s__coarse").mkdir(parents=True)
    for rel in files[1:]:
        (results / rel).write_bytes(before[rel])
    bad = _commit(tmp_path, "other bytes")
    shutil.rmtree(results / "surrogates")
    (results / "model_error" / "x.npz").unlink()
    assert main(["artefacts", "unpack", "--from-git", bad]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "is not the release's" in err
    assert hashlib.sha256(b"tampered").hexdigest()[:16] in err
    assert not cache.exists() or not any(p.is_file() for p in cache.rglob("*"))
    # a commit this clone does not hold (a shallow clone)
    assert main(["artefacts", "unpack", "--from-git", "0" * 40]) == 2
    err = capsys.readouterr().err
    assert "is not in this clone" in err and len(err.strip().splitlines()) == 1


@pytest.fixture
def runs(roots):
    """``comparison/runs`` of the temporary results root with two compact records made from a
    shipped FE-track record: that one and a copy on the surrogate track (its own hash), the
    surrogate one's companion listed as the group ``comparison/runs/*.history.xz``. Returns
    (results root, artefact directory, FE record path, surrogate record path)."""
    import json

    from bench.experiment import store
    from bench.experiment.spec import RunSpec

    results, cache = roots
    shipped = ROOT / "results" / "comparison" / "runs"
    path = next(
        p
        for p in sorted(shipped.glob("*.json"))
        if "history_file" in (r := json.loads(p.read_text())) and not r["config"].get("track")
    )
    rec = store.load_record(path)
    out = results / "comparison"
    fe = store.write_record(out, {k: v for k, v in rec.items() if k != "digest"})
    config = {**rec["config"], "track": "surrogate"}
    sur = {**rec, "config": config, "config_hash": RunSpec.from_dict(config).hash}
    sur = store.write_record(out, {k: v for k, v in sur.items() if k != "digest"})
    argv = ["artefacts", "add", str(out / "runs"), "--track", "surrogate"]
    assert main([*argv, "--rebuild", "femubench run S --out DIR", "--rebuild-s", "100"]) == 0
    return results, cache, fe, sur


def test_a_surrogate_track_companion_is_a_group_artefact_found_by_the_store(runs, capsys):
    """The group lists the companion of the surrogate-track record only; the store reads a
    record whose companion is in the artefact directory as before, refuses other bytes, and
    stops with one line naming the record and the restore command when it is in neither place
    (never skipping the record or using an empty history)."""
    from bench.experiment import store

    results, cache, fe, sur = runs
    entry = A.read_manifest()["comparison/runs/*.history.xz"]
    comp = store.companion_path(sur)
    assert entry["count"] == 1 and entry["bytes"] == comp.stat().st_size
    assert A.group_index("comparison/runs/*.history.xz", entry) == {
        f"comparison/runs/{comp.name}": hashlib.sha256(comp.read_bytes()).hexdigest()
    }
    want = store.load_record(sur)
    moved = cache / "comparison" / "runs" / comp.name
    moved.parent.mkdir(parents=True)
    comp.replace(moved)
    assert store.load_record(sur) == want  # from the artefact directory
    assert main(["artefacts", "verify"]) == 0
    assert "comparison/runs/*.history.xz (1 cache of 1 files)" in capsys.readouterr().out
    moved.write_bytes(moved.read_bytes()[:-1])
    with pytest.raises(ValueError, match="hash mismatch"):
        store.load_record(sur)
    moved.unlink()
    with pytest.raises(A.MissingArtefact) as caught:
        store.scan_records(results / "comparison")  # not an unreadable record: a stop
    msg = str(caught.value)
    assert sur.name in msg and "femubench artefacts unpack --from-git" in msg and "\n" not in msg
    assert main(["report", str(results / "comparison"), "--out", str(results / "r")]) == 2
    err = capsys.readouterr().err
    assert sur.name in err and len(err.strip().splitlines()) == 1
    # an FE-track companion is no artefact: missing, its record is unreadable as before
    store.companion_path(fe).unlink()
    with pytest.raises(ValueError, match="cannot be read"):
        store.load_record(fe)


def test_pack_unpack_and_the_git_history_cover_the_group(runs, tmp_path, capsys):
    import subprocess

    from bench.experiment import store

    results, cache, fe, sur = runs
    comp = store.companion_path(sur)
    data = comp.read_bytes()
    archive = tmp_path / "a.tar.xz"
    assert main(["artefacts", "pack", str(archive)]) == 0
    with tarfile.open(archive) as tar:
        assert f"comparison/runs/{comp.name}" in tar.getnames()
        assert f"comparison/runs/{store.companion_path(fe).name}" not in tar.getnames()
    subprocess.run(["git", "init", "-q", str(tmp_path)], check=True)
    first = _commit(tmp_path, "companions in the tree")
    A.write_manifest(A.read_manifest(), git_commit=first)
    comp.unlink()
    _commit(tmp_path, "the surrogate-track companion out of the tree")
    assert main(["artefacts", "verify"]) == 0
    assert "missing  comparison/runs/*.history.xz" in capsys.readouterr().out
    assert main(["artefacts", "unpack", "--from-git"]) == 0
    assert (cache / "comparison" / "runs" / comp.name).read_bytes() == data
    assert store.load_record(sur)["result"]["history"]
    other = tmp_path / "other"
    assert main(["artefacts", "unpack", str(archive), "--to", str(other)]) == 0
    assert (other / "comparison" / "runs" / comp.name).read_bytes() == data


def test_a_record_naming_a_companion_outside_its_folder_is_no_group_member(runs, tmp_path):
    """A record whose ``history_file`` name climbs out of its folder (``../``) is not indexed:
    an archive member of that name is refused and nothing is written outside the destination."""
    import json

    results, cache, fe, sur = runs
    evil = "../../../../escaped.history.xz"
    payload = b"outside"
    rec = {
        "config": {"track": "surrogate"},
        "history_file": {"name": evil, "sha256": hashlib.sha256(payload).hexdigest()},
    }
    (results / "comparison" / "runs" / "evil.json").write_text(json.dumps(rec))
    entry = A.read_manifest()["comparison/runs/*.history.xz"]
    assert all(
        ".." not in m.split("/") for m in A.group_index("comparison/runs/*.history.xz", entry)
    )
    assert A.index_problem("comparison/runs/*.history.xz", entry) is None
    archive = tmp_path / "evil.tar.xz"
    with tarfile.open(archive, "w:xz") as tar:
        info = tarfile.TarInfo(f"comparison/runs/{evil}")
        info.size = len(payload)
        tar.addfile(info, io.BytesIO(payload))
    dest = tmp_path / "deep" / "er" / "dest"
    assert main(["artefacts", "unpack", str(archive), "--to", str(dest)]) == 2
    assert not list(tmp_path.rglob("escaped.history.xz"))


def test_a_manifest_naming_a_path_outside_the_results_root_is_refused(roots, tmp_path, capsys):
    entries = A.read_manifest()
    entries["model_error/../../escaped.npz"] = entries.pop("model_error/x.npz")
    A.write_manifest(entries)
    with pytest.raises(ValueError, match=r"'model_error/../../escaped.npz', not a path inside"):
        A.members("model_error/../../escaped.npz", entries["model_error/../../escaped.npz"])
    assert (
        main(["artefacts", "unpack", str(tmp_path / "a.tar.xz"), "--to", str(tmp_path / "d")]) == 2
    )
    err = capsys.readouterr().err
    assert "not a path inside the results root" in err and len(err.strip().splitlines()) == 1


def test_unpack_from_git_names_what_git_said(roots, tmp_path, monkeypatch, capsys):
    """A git that refuses the checkout (here: its ownership) is named in the one line, not
    mistaken for a missing checkout without a reason."""
    fake = tmp_path / "bin"
    fake.mkdir()
    (fake / "git").write_text(
        "#!/bin/sh\necho 'fatal: detected dubious ownership in repository at /x' >&2\nexit 128\n"
    )
    (fake / "git").chmod(0o755)
    monkeypatch.setenv("PATH", f"{fake}:{os.environ['PATH']}")
    assert main(["artefacts", "unpack", "--from-git", "HEAD"]) == 2
    err = capsys.readouterr().err
    assert "detected dubious ownership" in err and len(err.strip().splitlines()) == 1

"""Fault injection (issue 28): outputs never overwrite inputs, writes are atomic, a full disk or a
read-only folder names the path, torn artefacts are detected, set aside and rebuilt."""

from __future__ import annotations

import errno
import os
from types import SimpleNamespace

import numpy as np
import pytest

from bench.cli import main as cli
from bench.experiment import store
from bench.experiment.runner import run_one
from bench.experiment.spec import RunSpec
from problems.io import atomic


def _full_disk(fh):
    raise OSError(errno.ENOSPC, "No space left on device")


def test_disk_full_names_the_path_and_keeps_the_old_file(tmp_path):
    path = tmp_path / "stats.npz"
    atomic.atomic_write_bytes(path, b"old")
    with pytest.raises(OSError) as info:
        atomic.atomic_write(path, _full_disk)
    assert info.value.errno == errno.ENOSPC
    assert str(path) in str(info.value) and "[Errno 28]" in str(info.value)
    assert path.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["stats.npz"]  # no temporary left


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_read_only_folder_names_the_path(tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        with pytest.raises(PermissionError, match=str(folder / "x.json")):
            atomic.atomic_write_text(folder / "x.json", "{}")
    finally:
        folder.chmod(0o700)


def test_atomic_dir_replaces_a_folder_as_one_unit_or_not_at_all(tmp_path):
    final = tmp_path / "model"
    with atomic.atomic_dir(final) as tmp:
        (tmp / "a.npz").write_bytes(b"1")
        (tmp / "build.json").write_text("1")
    with pytest.raises(RuntimeError), atomic.atomic_dir(final) as tmp:
        (tmp / "a.npz").write_bytes(b"2")
        raise RuntimeError("killed half way")
    assert (final / "a.npz").read_bytes() == b"1" and (final / "build.json").read_text() == "1"
    with atomic.atomic_dir(final) as tmp:
        (tmp / "a.npz").write_bytes(b"3")
    assert sorted(p.name for p in final.iterdir()) == ["a.npz"]  # no stale build.json
    assert [p.name for p in tmp_path.iterdir()] == ["model"]


def test_read_only_folder_names_the_path_even_as_root(tmp_path, monkeypatch):
    import tempfile

    def denied(*a, **k):  # what a read-only folder does to a writer (root ignores chmod)
        raise PermissionError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(tempfile, "mkstemp", denied)
    with pytest.raises(PermissionError, match=f"Permission denied: '{tmp_path / 'x.json'}'"):
        atomic.atomic_write_text(tmp_path / "x.json", "{}")


# --- BAE statistics: a torn cache is detected, set aside and computed again ------------------


def _correction():
    from problems.inverse.model_error import Correction

    return Correction("bae", np.arange(4.0), np.ones((4, 2)), n_hifi=3, points=np.ones((3, 2)))


def test_torn_bae_statistics_are_named_set_aside_and_recomputed(tmp_path, monkeypatch):
    import bench.experiment.objective as ident
    import problems.inverse.model_error as me

    path = tmp_path / "model_error" / "stats.npz"
    _correction().save(path)
    assert me.Correction.load(path).hash == _correction().hash
    whole = path.read_bytes()
    path.write_bytes(whole[: len(whole) // 2])  # killed while writing (before the fix: forever)
    with pytest.raises(ValueError, match=f"BAE statistics {path} are torn"):
        me.Correction.load(path)

    calls = []
    from bench import artefacts

    monkeypatch.setattr(ident, "bae_path", lambda *a: path)
    # where the statistics are looked up (results root, artefact directory): here
    monkeypatch.setattr(artefacts, "locate", lambda rel: path if path.exists() else None)
    monkeypatch.setattr(me, "bae_statistics", lambda *a, **k: calls.append(1) or _correction())
    spec = SimpleNamespace(
        case="linear-shear", mesh="coarse", treatment=SimpleNamespace(bae_samples=3, bae_seed=0)
    )
    with pytest.warns(UserWarning, match="torn.*moved to .*stats.npz.torn"):
        corr = ident.bae_correction(spec, None, None, "fine", None)
    assert calls == [1] and corr.hash == _correction().hash
    assert me.Correction.load(path).hash == corr.hash  # rebuilt, whole
    assert (path.parent / "stats.npz.torn").read_bytes() == whole[: len(whole) // 2]


def test_bae_statistics_on_a_full_disk_leave_no_torn_file(tmp_path, monkeypatch):
    path = tmp_path / "stats.npz"

    def full(fh, **arrays):
        fh.write(b"PK\x03\x04 half")
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(np, "savez_compressed", full)
    with pytest.raises(OSError, match=f"No space left on device: '{path}'"):
        _correction().save(path)
    assert not path.exists() and list(tmp_path.iterdir()) == []


# --- outputs never name inputs ------------------------------------------------------------


def test_dic_csv_naming_an_input_image_is_refused_before_any_work(tmp_path, capsys):
    ref, dfm = tmp_path / "ref.png", tmp_path / "def.png"
    ref.write_bytes(b"not even an image")  # refused before the images are read
    dfm.write_bytes(b"deformed")
    for option in ("--csv", "--figure"):
        for target in (ref, dfm):
            assert cli(["dic", str(ref), str(dfm), option, str(target)]) == 2
            err = capsys.readouterr().err.strip()
            assert err.count("\n") == 0 and f"{option} {target}: names the input" in err
    assert ref.read_bytes() == b"not even an image" and dfm.read_bytes() == b"deformed"


def test_identify_json_naming_the_data_file_is_refused(tmp_path, capsys):
    data = tmp_path / "data.json"
    data.write_text("{}")
    args = ["identify", "linear-shear", "--solver", "lm", "--data", str(data), "--json", str(data)]
    assert cli(args) == 2
    assert "--json" in capsys.readouterr().err and data.read_text() == "{}"


# --- report --out never deletes what the report did not write -----------------------------


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    out = tmp_path_factory.mktemp("res") / "suite"
    for seed in (0, 1):
        cfg = RunSpec("analytic-linear", "lm", seed, "default", 0, 50, "coarse")
        store.write_record(out, run_one(cfg, suite="t"))
    return out


def _files(folder):
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())


@pytest.mark.parametrize(
    "where", ["dir", "runs", "runs/sub", "parent", "foreign", "file", "posterior input"]
)
def test_report_out_refuses_inputs_and_foreign_folders(results, where, capsys):
    foreign = results.parent / "mine"
    foreign.mkdir(exist_ok=True)
    (foreign / "thesis.tex").write_text("keep me")
    (results.parent / "notes.txt").write_text("keep")
    dest = {
        "dir": results,
        "runs": results / "runs",
        "runs/sub": results / "runs" / "sub",
        "parent": results.parent,
        "foreign": foreign,
        "file": results.parent / "notes.txt",
        "posterior input": results.parent / "studies",  # holds DIR/../studies/posterior
    }[where]
    (results.parent / "studies" / "posterior").mkdir(parents=True, exist_ok=True)
    before = _files(results.parent)
    assert cli(["report", str(results), "--out", str(dest), "--no-figures", "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and f"--out {dest}:" in err
    assert ("input folder" in err) == (where == "posterior input")
    assert _files(results.parent) == before  # nothing deleted, nothing written


def test_report_out_replaces_only_its_own_folder_and_clears_stale_temporaries(results, capsys):
    dest = results.parent / "rep"
    stale = results.parent / ".report-k1ll3d_x"  # a report killed while writing
    stale.mkdir()
    (stale / "half.md").write_text("x")
    args = ["report", str(results), "--out", str(dest), "--no-figures", "--quiet", "--format", "md"]
    assert cli(args) == 0
    assert (dest / "report.md").is_file() and (dest / ".femubench-report").is_file()
    assert not stale.exists()
    assert cli(args) == 0  # its own folder: replaced
    assert len(store.load_records(results)) == 2
    assert not [p for p in results.parent.glob(".report-*") if p.is_dir()]


# --- surrogates: an existing one is replaced only with --force, and as one unit ------------


def test_surrogate_refuses_to_replace_a_stored_one_without_force(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("FEMUBENCH_SURROGATE_DIR", str(tmp_path))
    shipped = tmp_path / "linear-shear__coarse"  # the default folder of the case
    shipped.mkdir()
    for name in ("surrogate.json", "surrogate.npz", "build.json"):
        (shipped / name).write_text(name)
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("keep")
    for extra in ([], ["--out", str(shipped)], ["--out", str(mine), "--force"]):
        assert cli(["surrogate", "linear-shear", "--samples", "20", *extra]) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0, err
        assert ("--force" in err) if "--force" not in extra else ("notes.txt" in err)
    assert sorted(p.read_text() for p in shipped.iterdir()) == sorted(
        ["surrogate.json", "surrogate.npz", "build.json"]
    )
    assert (mine / "notes.txt").read_text() == "keep"


@pytest.fixture(scope="module")
def surrogate():
    from problems.surrogate import build_surrogate
    from tests.test_surrogate import BLOCKS, LOWER, SIGMA, UPPER, ToyModel, settings

    return build_surrogate(
        ToyModel(), LOWER, UPPER, SIGMA, settings=settings(rbf_smoothing=(0.0,)), blocks=BLOCKS
    )


def test_surrogate_files_are_written_as_one_unit(surrogate, tmp_path, monkeypatch):
    from problems.surrogate import store as sstore

    folder = tmp_path / "s"
    sstore.save(surrogate, folder, extra=lambda size: {"build.json": f'{{"size": {size}}}'})
    first = {p.name: p.read_bytes() for p in folder.iterdir()}
    assert sorted(first) == ["build.json", "surrogate.json", "surrogate.npz"]
    assert (
        first["build.json"]
        == f'{{"size": {len(first["surrogate.npz"]) + len(first["surrogate.json"])}}}'.encode()
    )

    def killed(fh, **arrays):  # the writer dies half way (disk full)
        fh.write(b"PK half")
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(np, "savez", killed)
    with pytest.raises(OSError, match="No space left"):
        sstore.save(surrogate, folder)
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == first  # the old unit, whole
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s"]
    monkeypatch.undo()
    sstore.save(surrogate, folder)  # no build.json given: none stale left behind
    assert sorted(p.name for p in folder.iterdir()) == ["surrogate.json", "surrogate.npz"]
    assert sstore.load(folder).hash == surrogate.hash

    (folder / "other.txt").write_text("x")
    with pytest.raises(ValueError, match="other.txt"):
        sstore.save(surrogate, folder)
    (folder / "other.txt").unlink()
    npz = folder / "surrogate.npz"
    npz.write_bytes(npz.read_bytes()[:100])
    with pytest.raises(ValueError, match=f"{npz} is torn"):
        sstore.load(folder)


def test_atomic_writes_keep_permissions_not_private_temporaries(tmp_path):
    mask = os.umask(0o022)
    try:
        new = atomic.atomic_write_text(tmp_path / "new.json", "{}")
        assert new.stat().st_mode & 0o777 == 0o644  # not mkstemp's 0600
        new.chmod(0o640)
        atomic.atomic_write_text(new, "{1}")
        assert new.stat().st_mode & 0o777 == 0o640  # a replacement keeps the file's mode
        with atomic.atomic_dir(tmp_path / "d") as tmp:
            (tmp / "a").write_text("1")
        assert (tmp_path / "d").stat().st_mode & 0o777 == 0o755  # not mkdtemp's 0700
    finally:
        os.umask(mask)

"""Data sets on disk: shipped as package data, overridable, never overwritten by accident, and a
bad data file is a one-line error (exit code 2), never a traceback."""

from __future__ import annotations

import fnmatch
import json
import shutil
import tomllib
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

import problems.inverse.data as D
from bench.cli import main
from problems.inverse.cases import CASES

ROOT = Path(__file__).resolve().parent.parent
FE_CASES = [name for name in CASES if not name.startswith("analytic-")]
SHIPPED = D.SHIPPED_DIR / "consistent" / "linear-compression.json"


@pytest.fixture(autouse=True)
def _no_overrides(monkeypatch, tmp_path):
    """The shipped data, and a cache inside the test's temporary directory."""
    monkeypatch.delenv(D.DATA_DIR_ENV, raising=False)
    monkeypatch.setenv(D.CACHE_DIR_ENV, str(tmp_path / "cache"))


@pytest.fixture
def fake_make_data(monkeypatch):
    """``make_data`` that returns the shipped data set at once and records its calls."""
    calls = []

    def fake(case, settings=None, *, progress=False, image_dir=None, **kw):
        calls.append({"case": case, "settings": settings, "image_dir": image_dir})
        return D.load(D.SHIPPED_DIR / "consistent" / f"{case}.json")

    monkeypatch.setattr(D, "make_data", fake)
    return calls


# --- where the data sets are ----------------------------------------------------------------


def test_the_shipped_data_sets_are_declared_package_data():
    package_data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"][
        "package-data"
    ]
    globs = package_data["problems.inverse"]
    for tier in D.TIERS:
        shipped = sorted(
            p.relative_to(D.SHIPPED_DIR.parent).as_posix()
            for p in (D.SHIPPED_DIR / tier).glob("*.json")
        )
        assert len(shipped) == len(FE_CASES) == 9
        assert all(any(fnmatch.fnmatch(f, g) for g in globs) for f in shipped)
        for case in FE_CASES:
            res = resources.files("problems.inverse").joinpath("datasets", tier, f"{case}.json")
            assert res.is_file() and D.default_path(case, tier) == Path(str(res)).resolve()
            doc = json.loads(res.read_text())
            assert doc["case"] == case and doc["settings"]["tier"] == tier
    assert not (ROOT / "results" / "data" / "linear-compression.json").exists()  # one copy only


def test_FEMUBENCH_DATA_DIR_points_the_default_data_elsewhere(monkeypatch, tmp_path):
    mine = tmp_path / "mine"
    (mine / "consistent").mkdir(parents=True)
    shutil.copy(SHIPPED, mine / "consistent")
    monkeypatch.setenv(D.DATA_DIR_ENV, str(mine))
    path = D.default_path("linear-compression", "consistent")
    assert path == mine / "consistent" / "linear-compression.json"
    consistent = D.tier_settings("consistent")
    assert D.get_data("linear-compression", consistent).hash == D.load(SHIPPED).hash


def test_the_cache_is_a_user_directory_never_the_package(monkeypatch, tmp_path):
    monkeypatch.delenv(D.CACHE_DIR_ENV)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    path = D.cached_path("linear-compression", D.DataSettings(noise_um=1.0))
    assert path.parent == tmp_path / "xdg" / "femubench" / "data"
    monkeypatch.setenv(D.CACHE_DIR_ENV, str(tmp_path / "c"))
    assert (
        D.cached_path("linear-compression", D.DataSettings(noise_um=1.0)).parent == tmp_path / "c"
    )


def test_a_computed_dic_data_set_keeps_its_images_next_to_it_in_the_cache(fake_make_data, tmp_path):
    settings = D.DataSettings(route="dic", mesh="coarse")
    D.get_data("linear-compression", settings)
    path = D.cached_path("linear-compression", settings)
    assert path.is_file() and path.parent == tmp_path / "cache"
    assert fake_make_data[0]["image_dir"] == tmp_path / "cache" / f"{path.stem}__dic_images"


# --- femubench data: where it writes ---------------------------------------------------------


@pytest.mark.parametrize("out", ["sets.json", "existing-file"])
def test_data_all_refuses_a_file_for_out(tmp_path, capsys, fake_make_data, out):
    target = tmp_path / out
    if out == "existing-file":
        target.write_text("mine")
    assert main(["data", "all", "--out", str(target)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--out must be a directory" in err
    assert fake_make_data == [] and (not target.exists() or target.read_text() == "mine")


def test_data_all_writes_one_file_per_case_into_the_out_directory(tmp_path, capsys, fake_make_data):
    assert main(["data", "all", "--out", str(tmp_path / "sets")]) == 0
    written = sorted(p.name for p in (tmp_path / "sets").glob("*.json"))
    assert written == sorted(f"{c}.json" for c in FE_CASES)
    assert D.load(tmp_path / "sets" / "linear-compression.json").hash == D.load(SHIPPED).hash


def test_data_never_overwrites_the_shipped_file_without_force(
    tmp_path, capsys, fake_make_data, monkeypatch
):
    before = SHIPPED.read_bytes()
    assert main(["data", "linear-compression", "--tier", "consistent"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(SHIPPED) in err and "--force" in err
    assert main(["data", "linear-compression", "--out", str(SHIPPED)]) == 2
    assert fake_make_data == [] and SHIPPED.read_bytes() == before
    assert main(["data", "all", "--check", "--tier", "consistent"]) == 0  # compares, writes nothing

    # --force writes the default data set (here into an overriding directory)
    mine = tmp_path / "mine"
    (mine / "consistent").mkdir(parents=True)
    (mine / "consistent" / "linear-compression.json").write_text("old")
    monkeypatch.setenv(D.DATA_DIR_ENV, str(mine))
    assert main(["data", "linear-compression", "--tier", "consistent"]) == 2
    assert main(["data", "linear-compression", "--tier", "consistent", "--force"]) == 0
    assert (mine / "consistent" / "linear-compression.json").read_bytes() == before


def test_dic_images_go_next_to_the_users_output(tmp_path, capsys, fake_make_data):
    out = tmp_path / "my" / "lc_dic.json"
    assert (
        main(
            ["data", "linear-compression", "--route", "dic", "--mesh", "coarse", "--out", str(out)]
        )
        == 0
    )
    assert (
        out.is_file() and fake_make_data[-1]["image_dir"] == tmp_path / "my" / "lc_dic__dic_images"
    )
    # no --out: the cache
    assert main(["data", "linear-compression", "--route", "dic", "--mesh", "coarse"]) == 0
    assert fake_make_data[-1]["image_dir"].parent == tmp_path / "cache"
    for call in fake_make_data:
        # never into the package
        assert D.SHIPPED_DIR.parent not in call["image_dir"].resolve().parents


def test_make_data_hands_the_image_directory_to_the_dic_route(monkeypatch, tmp_path):
    import problems.dic.route as route

    seen = {}

    def fake_dic(response, points, *, seed=0, progress=True, image_dir=None):
        seen["image_dir"] = image_dir
        u = np.zeros((len(response.snapshots_mm), len(points)))
        return u, u, np.ones((2,) + u.shape), {"dic": {"seed": seed}}

    monkeypatch.setattr(route, "measure_by_dic", fake_dic)
    ds = D.make_data(
        "linear-compression", mesh="2,2,4", snapshots=1, route="dic", image_dir=tmp_path
    )
    assert seen["image_dir"] == tmp_path and ds.meta["dic"] == {"seed": 0}


# --- bad data files ----------------------------------------------------------------------------


def _doc() -> dict:
    return json.loads(SHIPPED.read_text())


def _rehash(doc: dict) -> dict:
    doc["hash"] = D._digest(doc)
    return doc


BAD = {
    "a JSON list": ("[1, 2, 3]", "expected a JSON object, got a list"),
    "not JSON": ('{"format": "femubench-data/1", "u_h": [[0.1, ', "not valid JSON"),
    "missing field": (lambda: {k: v for k, v in _doc().items() if k != "u_v"}, "u_v missing"),
    "wrong shape": (
        lambda: _rehash({**_doc(), "u_h": _doc()["u_h"][:3]}),
        "field u_h has shape (3, 406)",
    ),
    "ragged": (
        lambda: _rehash({**_doc(), "points": [[1.0, 2.0], [3.0]]}),
        "field points is not a rectangular",
    ),
    "not numbers": (
        lambda: _rehash({**_doc(), "reaction_kN": ["a"] * 10}),
        "field reaction_kN is not",
    ),
    "bad settings": (
        lambda: _rehash({**_doc(), "settings": {**_doc()["settings"], "colour": 1}}),
        "field settings: ",
    ),
    "out-of-range settings": (
        lambda: _rehash({**_doc(), "settings": {**_doc()["settings"], "noise_um": -1}}),
        "field settings: noise_um",
    ),
    "settings not an object": (
        lambda: _rehash({**_doc(), "settings": [1]}),
        "field settings must be",
    ),
}


@pytest.mark.parametrize("kind", sorted(BAD))
@pytest.mark.parametrize("command", ["objective", "identify"])
def test_a_bad_data_file_is_a_one_line_error_with_exit_code_2(tmp_path, capsys, kind, command):
    content, message = BAD[kind]
    bad = tmp_path / "bad.json"
    bad.write_text(content if isinstance(content, str) else json.dumps(content()))
    extra = ["--solver", "lm", "--budget", "1"] if command == "identify" else []
    assert main([command, "linear-compression", "--data", str(bad), *extra]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert f"data file {bad}" in err and message in err


def test_a_directory_or_a_missing_file_as_data_is_a_one_line_error(tmp_path, capsys):
    assert main(["objective", "linear-compression", "--data", str(tmp_path)]) == 2
    assert main(["objective", "linear-compression", "--data", str(tmp_path / "nope.json")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2 and "cannot be read" in err[0] and "does not exist" in err[1]

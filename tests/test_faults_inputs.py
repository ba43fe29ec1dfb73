"""Careless inputs refused up front (issue 28, second round): one line naming the option, the
value and what is allowed, exit code 2, before any work; plausibility warnings with the numbers."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

from bench.cli import main

ROOT = Path(__file__).resolve().parent.parent


def one_line_error(capsys, argv, *needles) -> str:
    """Run ``argv``; assert exit 2 and a one-line error holding every needle; return it."""
    code = main(argv)
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert len(err.splitlines()) == 1, err
    for needle in needles:
        assert needle in err, err
    return err


# --- meshes ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("mesh", ["1,1,1", "2,2,1:quarter", "4,4,1"])
def test_a_mesh_without_free_dofs_is_refused(capsys, mesh):
    """NZ = 1 puts every node on a plate (was: "cannot reshape array of size 0")."""
    one_line_error(capsys, ["forward", "--mesh", mesh], "--mesh", "NZ = 1", "NZ >= 2")


def test_a_mesh_whose_operators_exceed_half_the_memory_is_refused(capsys, monkeypatch):
    from bench.resources import mesh_operator_bytes

    monkeypatch.setenv("FEMUBENCH_MEMORY_BYTES", str(16e9))
    # 200 x 200 x 400 solved as the eighth: 24.4 M dofs, ~71 GB of operators
    assert mesh_operator_bytes("200,200,400") > 70e9
    assert mesh_operator_bytes("fine") < 1e8
    err = one_line_error(capsys, ["forward", "--mesh", "200,200,400"], "--mesh", "200,200,400")
    assert "71 GB" in err and "8 GB" in err


# --- option values ----------------------------------------------------------------------------


@pytest.mark.parametrize("delta", ["1e-300", "-0.01", "0", "0.9"])
def test_sensitivity_delta_outside_a_sane_relative_range_is_refused(capsys, delta, tmp_path):
    one_line_error(
        capsys,
        ["sensitivity", "linear-compression", "--delta", delta, "--out", str(tmp_path)],
        "--delta",
        "[1e-06, 0.5]",
    )


@pytest.mark.parametrize("hifi", ["1,1,2", "coarse", "6,6,10"])
def test_a_hifi_mesh_not_finer_than_the_inverse_mesh_is_refused(capsys, hifi, tmp_path):
    one_line_error(
        capsys,
        [
            "identify",
            "linear-compression",
            "--solver",
            "lm",
            "--correction",
            "one-point",
            "--hifi-mesh",
            hifi,
            "--json",
            str(tmp_path / "r.json"),
        ],  # fmt: skip
        "--hifi-mesh",
        "not finer",
    )
    assert not (tmp_path / "r.json").exists()


@pytest.mark.parametrize("command", [["identify", "analytic-linear", "--solver", "lm"],
                                     ["forward", "--mesh", "2,2,2"]])  # fmt: skip
def test_json_paths_are_checked_before_the_computation(capsys, tmp_path, command):
    err = one_line_error(
        capsys, [*command, "--json", str(tmp_path / "missing" / "r.json")], "--json", "missing"
    )
    assert "does not exist" in err
    one_line_error(capsys, [*command, "--json", str(tmp_path)], "--json", "is a directory")


def test_the_smoke_suite_has_the_number_of_runs_the_readme_says(capsys, tmp_path):
    assert main(["run", str(ROOT / "suites/smoke.toml"), "--dry-run", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "12 runs," in out
    readme = (ROOT / "README.md").read_text()
    assert "# 12 runs on analytic problems" in readme and "16 runs" not in readme


# --- suite files: validated before any work -------------------------------------------------------

SUITE = '[suite]\ncases = ["{case}"]\nmethods = ["lm"]\nbudgets = [10]\n'


def write_suite(tmp_path, text: str | bytes, name: str = "s.toml") -> Path:
    path = tmp_path / name
    (path.write_bytes if isinstance(text, bytes) else path.write_text)(text)
    return path


@pytest.mark.parametrize(
    "extra, case, needle",
    [
        ('mesh = "1,1,1"\n', "linear-compression", "NZ = 1"),
        ('mesh = "200,200,400"\n', "linear-compression", "of memory"),
        ('tracks = ["fe", "surrogate"]\n', "analytic-linear", "surrogate track is for the FE"),
        ('tracks = ["surrogate"]\n', "linear-compression", "no default surrogate of"),
    ],
)
@pytest.mark.parametrize("dry", [True, False])
def test_a_suite_that_cannot_run_is_refused_before_any_work(
    capsys, tmp_path, monkeypatch, extra, case, needle, dry
):
    monkeypatch.setenv("FEMUBENCH_SURROGATE_DIR", str(tmp_path / "no-surrogates"))
    monkeypatch.setenv("FEMUBENCH_MEMORY_BYTES", str(16e9))
    suite = write_suite(tmp_path, SUITE.format(case=case) + extra)
    out = tmp_path / "out"
    code = main(["run", str(suite), "--out", str(out), "--workers", "1", *(["--dry-run"] * dry)])
    err = capsys.readouterr().err
    assert code == 2 and needle in err and str(suite) in err, err
    assert not out.exists()


def test_every_bad_data_value_of_a_suite_is_reported_at_once(tmp_path):
    from bench.experiment.suite import load_suite

    text = SUITE.format(case="linear-compression") + (
        "[data]\nresolution_um = -1.0\nnoise_um = -2.0\nsnapshots = 0\nmargin_mm = 40.0\n"
        "displacement_mm = 1000.0\n"
    )
    with pytest.raises(ValueError) as exc:
        load_suite(write_suite(tmp_path, text))
    lines = [ln for ln in str(exc.value).splitlines() if ln.startswith("  - [data]")]
    assert len(lines) == 5, str(exc.value)
    for needle in ("resolution_um", "noise_um", "snapshots = 0", "margin_mm", "1000 mm"):
        assert needle in str(exc.value)


def test_a_suite_with_a_byte_order_mark_is_read(tmp_path):
    from bench.experiment.suite import load_suite

    path = write_suite(tmp_path, b"\xef\xbb\xbf" + SUITE.format(case="analytic-linear").encode())
    assert len(load_suite(path)) == 1


@pytest.mark.parametrize(
    "blob, needle",
    [
        (b"\x00\x01\x02PK binary", "binary file"),
        (b'[suite]\nname = "caf\xe9"\n', "not UTF-8 text (byte 0xe9 at offset 19)"),
        (b"[suite\ncases = 1\n", "not valid TOML"),
    ],
)
def test_a_binary_or_undecodable_suite_names_the_file(capsys, tmp_path, blob, needle):
    path = write_suite(tmp_path, blob)
    err = one_line_error(capsys, ["run", str(path), "--dry-run", "--out", str(tmp_path / "o")])
    assert str(path) in err and needle in err


# --- data files -----------------------------------------------------------------------------------


def shipped(case: str = "linear-compression"):
    from problems.inverse.data import load

    return load(ROOT / "problems/inverse/datasets/consistent" / f"{case}.json")


def edited(tmp_path, edit) -> Path:
    """The shipped data file with ``edit(doc)`` applied, re-hashed (a well-formed file)."""
    import json

    from problems.inverse.data import _digest

    doc = json.loads(
        (ROOT / "problems/inverse/datasets/consistent/linear-compression.json").read_text()
    )
    edit(doc)
    doc["hash"] = _digest(doc)
    path = tmp_path / "edited.json"
    path.write_text(json.dumps(doc))
    return path


def test_data_points_off_the_face_are_refused_with_a_count(tmp_path):
    from problems.inverse.data import load

    def edit(doc):
        doc["points"][0] = [80.0, 5.0]
        doc["points"][7] = [5.0, 160.0]

    with pytest.raises(ValueError, match=r"field points: 2 of 406 points lie off the front face"):
        load(edited(tmp_path, edit))


def test_all_infinite_sigma_is_refused_naming_the_field(tmp_path):
    from problems.inverse.data import load

    def edit(doc):
        doc["std_u_mm"] = [[[float("inf")] * len(r) for r in b] for b in doc["std_u_mm"]]

    with pytest.raises(ValueError, match=r"field std_u_mm: all 8120 standard deviations are infin"):
        load(edited(tmp_path, edit))


def test_a_displacement_beyond_the_specimen_is_refused(capsys):
    from problems.inverse.data import DataSettings

    one_line_error(capsys, ["forward", "--displacement", "1000"], "--displacement", "<= 10% ")
    with pytest.raises(ValueError, match=r"displacement_mm = 16 mm is beyond the specimen"):
        DataSettings(displacement_mm=16.0)
    assert DataSettings(displacement_mm=15.0).displacement_mm == 15.0


# --- plausibility warnings ------------------------------------------------------------------------


@pytest.mark.parametrize(
    "field, factor, needle",
    [
        ("reaction_kN", 1e3, "N instead of kN"),
        ("u_v", 1e3, "micrometres instead of mm"),
        ("points", 0.1, "cm instead of mm"),
    ],
)
def test_data_in_wrong_units_are_flagged(field, factor, needle):
    from dataclasses import replace

    from problems.inverse.plausibility import data_warnings

    ds = shipped()
    assert data_warnings(ds) == []
    bad = data_warnings(replace(ds, **{field: getattr(ds, field) * factor}))
    assert len(bad) == 1 and needle in bad[0]
    zero = replace(ds, u_h=ds.u_h * 0, u_v=ds.u_v * 0, reaction_kN=ds.reaction_kN * 0)
    assert "all zero" in data_warnings(zero)[0]


def test_a_cost_far_above_the_data_size_and_bounds_are_flagged():
    from types import SimpleNamespace

    from problems.inverse.plausibility import result_warnings

    def result(cost, x):
        return SimpleNamespace(cost=cost, x=x, parameter_names=["a", "b"])

    lo, hi = [0.0, 0.0], [1.0, 10.0]
    assert result_warnings(result(900.0, [0.5, 5.0]), 10, lo, hi) == []
    (msg,) = result_warnings(result(1000.0, [0.5, 5.0]), 10, lo, hi)
    assert "final cost 1000 is 100 x the 10 data" in msg
    (msg,) = result_warnings(result(1.0, [0.0, 10.0]), 10, lo, hi)
    assert "2 of 2 parameters on a bound: a = 0 (lower bound), b = 10 (upper bound)" in msg


@pytest.fixture(scope="module")
def small_data():
    """Consistent data of linear-compression on the 2,2,4 mesh."""
    from problems.inverse.data import make_data

    return make_data("linear-compression", tier="consistent", mesh="2,2,4")


@pytest.fixture(scope="module")
def force_in_newton(tmp_path_factory, small_data):
    """``small_data`` with the force in N (x 1000), and its file."""
    from dataclasses import replace

    from problems.inverse.data import save

    ds = small_data
    bad = replace(ds, reaction_kN=ds.reaction_kN * 1e3)
    return bad, save(bad, tmp_path_factory.mktemp("data") / "newton.json")


def test_identify_prints_and_writes_the_plausibility_warnings(capsys, tmp_path, force_in_newton):
    import json

    _, path = force_in_newton
    out = tmp_path / "r.json"
    argv = ["identify", "linear-compression", "--solver", "lm", "--mesh", "2,2,4", "--data",
            str(path), "--budget", "4", "--quiet", "--json", str(out)]  # fmt: skip
    assert main(argv) == 0
    text = capsys.readouterr().out
    found = json.loads(out.read_text())["warnings"]
    assert any("N instead of kN" in w for w in found)
    cost = [w for w in found if w.startswith("final cost")]
    assert cost and float(cost[0].split(" x the")[0].split(" is ")[1]) >= 100
    assert all(f"  warning: {w}" in text for w in found)


def test_a_suite_run_keeps_the_warnings_in_its_record_and_the_report_lists_them(force_in_newton):
    from bench.experiment.runner import run_one
    from bench.experiment.spec import DataSpec, RunSpec
    from bench.report.warnings import warnings_section

    ds, _ = force_in_newton
    config = RunSpec(
        "linear-compression", "lm", 0, "default", 0, 4, "2,2,4", data=DataSpec("consistent")
    )
    record = run_one(config, dataset=ds)
    plaus = [w for w in record["warnings"] if w.startswith("PlausibilityWarning: ")]
    assert any("N instead of kN" in w for w in plaus) and any("final cost" in w for w in plaus)
    md = "\n".join(warnings_section([record, {**record, "warnings": []}]))
    assert md.startswith("## Plausibility warnings") and "1 run(s) gave numbers" in md
    assert "N instead of kN" in md and "linear-compression/lm/s0/default0/b4" in md


# --- samples and walkers: memory estimated before any work ----------------------------------------


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["gsa", "analytic-linear", "--samples", "1e9", "--dry-run"], "--samples 1000000000"),
        (["gsa", "analytic-linear", "--method", "morris", "--samples", "1e9"], "--samples"),
        (["uncertainty", "analytic-linear", "--walkers", "1e9"], "--walkers 1000000000"),
        (["uncertainty", "analytic-linear", "--walkers", "100", "--budget", "1e10"], "--budget"),
    ],
)
def test_samples_and_walkers_beyond_the_memory_are_refused_up_front(
    capsys, tmp_path, monkeypatch, argv, needle
):
    monkeypatch.setenv("FEMUBENCH_MEMORY_BYTES", str(16e9))
    err = one_line_error(capsys, [*argv, "--out", str(tmp_path / "o")], needle, "8 GB")
    assert "of memory" in err and not (tmp_path / "o").exists()


def test_a_whole_number_in_float_notation_is_accepted():
    from bench.commands._args import ArgumentTypeError, positive_int

    assert positive_int("1e3") == 1000 and positive_int("2.0") == 2
    with pytest.raises(ArgumentTypeError, match="'1.5' is not a whole number"):
        positive_int("1.5")


# --- torn numba cache files -----------------------------------------------------------------------

KERNEL = "from numba import njit\n\n\n@njit(cache=True)\ndef twice(x):\n    return 2 * x\n"


@pytest.mark.parametrize("suffix", [".nbi", ".nbc"])
def test_a_torn_numba_cache_file_is_named_and_removed(tmp_path, monkeypatch, suffix):
    import importlib

    from problems.numba_cache import cache_files, heal

    name = f"i28b_kernel_{suffix[1:]}"
    (tmp_path / f"{name}.py").write_text(KERNEL)
    monkeypatch.syspath_prepend(str(tmp_path))
    importlib.invalidate_caches()
    module = importlib.import_module(name)
    monkeypatch.delitem(sys.modules, name)
    assert module.twice(2) == 4  # compiles and writes the cache
    files = cache_files(vars(module))
    assert sorted(Path(f).suffix for f in files) == [".nbc", ".nbi"]
    assert heal(vars(module)) == []  # whole files are kept
    (torn,) = [f for f in files if f.endswith(suffix)]
    Path(torn).write_bytes(Path(torn).read_bytes()[:20])
    with pytest.warns(RuntimeWarning, match=rf"numba cache file .*{name}.* was torn"):
        assert heal(vars(module)) == [torn]
    assert not Path(torn).exists()


def test_an_unwritable_output_folder_is_refused_before_the_computation(
    capsys, tmp_path, monkeypatch
):
    locked = tmp_path / "locked"
    locked.mkdir()
    real_access = os.access  # a read-only folder, also for root (who may write anywhere)
    monkeypatch.setattr(os, "access", lambda p, mode: Path(p) != locked and real_access(p, mode))
    one_line_error(
        capsys,
        ["identify", "analytic-linear", "--solver", "lm", "--json", str(locked / "r.json")],
        "--json",
        "not writable",
    )
    one_line_error(
        capsys,
        ["data", "linear-compression", "--mesh", "2,2,4", "--out", str(locked / "d.json")],
        "--out",
        "not writable",
    )
    assert list(locked.iterdir()) == []


def test_an_infinite_sigma_gives_its_value_no_weight(small_data):
    """Infinite standard deviation = not measured (a failed DIC subset): no weight (it used to
    stop every objective with "sigma must be positive and finite")."""
    from dataclasses import replace

    import numpy as np

    from problems.inverse.build import build_objective

    x = np.array([27000.0, 33.0, 0.9, 14.0, 21.0, 1400.0])  # off the reference: residuals != 0
    full = build_objective("linear-compression", mesh="2,2,4", data=small_data)
    ev_full = full.evaluate(x / full.reference)
    std = small_data.std_u_mm.copy()
    std[0, :, :3] = np.inf  # u_h of the first 3 points, every snapshot
    part = build_objective(
        "linear-compression", mesh="2,2,4", data=replace(small_data, std_u_mm=std)
    )
    ev_part = part.evaluate(x / part.reference)
    n, m = std.shape[1], std.shape[2]
    dropped = [k * m + j for k in range(n) for j in range(3)]  # u_h block first, snapshot-major
    assert ev_part.cost == pytest.approx(ev_full.cost - np.sum(ev_full.residual[dropped] ** 2))
    assert 0 < ev_part.cost < ev_full.cost
    std[:] = np.inf  # and the force's: nothing measured
    with pytest.raises(ValueError, match="sigma: .* all infinite"):
        build_objective(
            "linear-compression",
            mesh="2,2,4",
            data=replace(small_data, std_u_mm=std),
            sigma_force_kN=np.inf,
        )

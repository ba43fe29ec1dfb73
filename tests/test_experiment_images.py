"""The experiment file's images route: speckle images of a virtual test correlated by femubench's
DIC into the objective's Dataset (problems/inverse/experiment.py, ``[images]``)."""

from __future__ import annotations

import numpy as np
import pytest

from bench.cli import main
from problems.inverse.experiment import (
    ExperimentFileError,
    import_experiment,
    load_experiment,
    rigid_basis,
    rigid_fit,
    sha256,
)
from problems.inverse.virtual_experiment import (
    VirtualImages,
    VirtualTest,
    _data_response,
    write_virtual_images,
)
from tests.support import assert_shipped_calibration_is_of

#: a tiny virtual test: a 100 mm cube on a 2 x 2 x 4 data mesh, 216 x 216 px images (0.5 mm/px),
#: two load steps, a rigid drift of 0.2 / 0.1 px and 5e-4 rad (0.1 px at the face's corners)
TEST = VirtualTest(
    "linear-compression",
    (34000.0, 38.0, 0.9, 12.0, 24.0, 1500.0),
    levels_mm=(0.1, 0.3),
    data_mesh="2,2,4",
    drift_mm=(0.1, -0.05),
    drift_rad=5e-4,
)
CAMERA = VirtualImages(mm_per_px=0.5, speckle_mm=2.0, margin_px=8, noise_grey=2.0)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    return write_virtual_images(TEST, tmp_path_factory.mktemp("img"), "tiny", CAMERA)


def test_images_route_gives_the_fe_field(tiny):
    """Imported displacements against the FE field at the same points, rigid motion removed the
    same way: within 0.02 px rms (0.01 mm) and about the correlation's own sigma."""
    exp = load_experiment(tiny)
    assert exp.route == "images" and exp.correlation.subset == 21 and exp.correlation.step == 21
    ds = import_experiment(exp)
    # one reference for every image: a point's errors correlated by 1/2 between images
    assert exp.snapshot_rho == 0.5 and ds.snapshot_rho == 0.5 and ds.noise()["group_rho"] == 0.5
    meta = ds.meta
    c = meta["correlation"]
    assert c["subsets_correlated"] == 81 and c["not_converged_per_image"] == [0, 0]
    assert len(ds.points) == 81 and meta["dropped_not_in_every_image"] == 0
    assert all(abs(s - CAMERA.noise_grey) < 0.2 for s in c["grey_noise_per_image"])
    files = meta["files_sha256"]["images"]
    assert list(files) == ["images/reference.png", "images/image_01.png", "images/image_02.png"]
    assert files["images/image_02.png"] == sha256(tiny.parent / "images" / "image_02.png")
    assert meta["calibration"]["mm_per_unit"] == 0.5
    # the drift removed: 0.1 mm and -0.05 mm at the last image, rotation 5e-4 rad
    t_h, t_v, rot = meta["rigid_motion_removed"]["rows"][-1]
    assert rot == pytest.approx(5e-4, abs=3e-5)
    fh, fv = _data_response(TEST, "tiny").front_face(ds.points)
    sign = np.array(meta["fold_sign"])
    B = rigid_basis(sign * ds.points[:, 0], ds.points[:, 1], sign)
    px = CAMERA.mm_per_px
    for k in range(2):
        s = np.concatenate([ds.std_u_mm[0, k], ds.std_u_mm[1, k]])
        u = np.concatenate([fh[k], fv[k]])
        truth = u - B @ rigid_fit(B, u, 1.0 / s**2)
        err = np.concatenate([ds.u_h[k], ds.u_v[k]]) - truth
        assert np.sqrt(np.mean(err**2)) / px < 0.02, k  # px
        assert np.abs(err).max() / px < 0.08, k
        assert 0.003 < np.median(s) / px < 0.03  # the IC-GN sigma of 2-grey-level noise
        assert np.sqrt(np.mean((err / s) ** 2)) < 1.6, k  # sigma is honest


def test_image_problems_name_the_file_or_field(tiny, tmp_path):
    text = tiny.read_text().replace('"machine_log.csv"', f'"{tiny.parent / "machine_log.csv"}"')
    text = text.replace('"images/', f'"{tiny.parent}/images/')
    f = tmp_path / "roi.toml"
    f.write_text(text.replace("step = 21", "step = 21\nroi = [0, 0, 400, 100]"))
    with pytest.raises(ValueError, match=r"\[images\] roi = \[0, 0, 400, 100\].*outside the image"):
        import_experiment(load_experiment(f))
    from PIL import Image

    small = tmp_path / "small.png"
    Image.open(tiny.parent / "images" / "image_01.png").crop((0, 0, 100, 100)).save(small)
    files = f'files = ["{small}", "{tiny.parent}/images/image_02.png"]'
    f.write_text(text.replace(f'files = "{tiny.parent}/images/image_*.png"', files))
    with pytest.raises(ValueError, match="small.png: 100 x 100 px, but the reference"):
        import_experiment(load_experiment(f))


def test_bad_images_fields_one_line_each_exit_2(tiny, tmp_path, capsys):
    base = tiny.read_text().replace('"machine_log.csv"', f'"{tiny.parent / "machine_log.csv"}"')
    bad = base.replace('reference = "images/reference.png"', 'reference = "nope.png"')
    bad = bad.replace('files = "images/image_*.png"', 'files = "images/*.jpg"')
    bad = bad.replace(
        "subset = 21\nstep = 21", "subset = 20\nstep = 0\norder = 4\nzncc_min = 2\nroi = [1, 2]"
    )
    bad = bad.replace('units = "px"', 'units = "mm"\ny_axis = "up"')
    f = tmp_path / "bad.toml"
    f.write_text(bad)
    with pytest.raises(ExperimentFileError) as exc:
        load_experiment(f)
    text = "\n".join(exc.value.errors)
    for needle in (
        "[images] reference = 'nope.png': no such file",
        "[images] files = 'images/*.jpg': no file matches",
        "[images] subset = 20: the subset side must be odd",
        "[images] step = 0: a whole number >= 1",
        "[images] order = 4 is unknown; allowed: 3, 5",
        "[images] zncc_min = 2.0: must be in [-1, 1]",
        "[images] roi = [1, 2]: four whole numbers",
        "[camera] units = 'mm' is unknown; allowed: px",
        "[camera] y_axis = 'up': an image's y points down; allowed: down",
    ):
        assert needle in text, needle
    assert main(["calibrate", str(f)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 + len(exc.value.errors) and "9 errors" in err[0]
    both = tmp_path / "both.toml"
    both.write_text(base + '\n[dic]\nfiles = "dic/*.csv"\n')
    with pytest.raises(ExperimentFileError, match=r"\[dic\], \[images\]: give the measurement"):
        load_experiment(both)


def test_shipped_images_example_imports_and_starts_the_calibration():
    """suites/experiments/cube100-images: small (< 3 MB), every subset converges in every image,
    and the test's own start and box hold the truth (docs/calibrating.md)."""
    from pathlib import Path

    from problems.inverse.lab import curve_summary, lab_case

    folder = Path(__file__).resolve().parents[1] / "suites" / "experiments" / "cube100-images"
    assert sum(p.stat().st_size for p in folder.rglob("*") if p.is_file()) < 3e6
    ds = import_experiment(load_experiment(folder / "experiment.toml"))
    c = ds.meta["correlation"]
    assert len(ds.points) == c["subsets_correlated"] == 529
    assert c["not_converged_per_image"] == [0] * 6 and ds.u_h.shape == (6, 529)
    assert np.median(ds.std_u_mm) / 0.2 < 0.012  # px
    s = curve_summary(ds)
    assert s["E_MPa"] == pytest.approx(34000.0, rel=0.15)
    case = lab_case("linear-compression", ds, s)
    truth = np.array([34000.0, 38.0, 0.9, 12.0, 24.0, 1500.0])
    assert np.all(case.lower <= truth) and np.all(truth <= case.upper)
    # results/calibration/cube100-images-correlated is the calibration of the example as it imports
    # (cube100-images: the same calibration before the snapshot correlation, rho = 0)

    from bench import calibration as cal

    out = folder.parents[2] / "results" / "calibration" / "cube100-images-correlated"
    exp = load_experiment(folder / "experiment.toml")
    assert_shipped_calibration_is_of(out, ds, case, cal.CalibrationSettings(exp.mesh, exp.budget))


def test_calibration_report_of_the_images_route(tiny, tmp_path, monkeypatch):
    """`femubench calibrate` takes an images experiment: its report names the images and the
    correlation (a two-evaluation run on a one-element-thick mesh: the plumbing, not the fit)."""
    from bench.calibration import CalibrationSettings, calibrate

    settings = CalibrationSettings("2,2,2", 2, check_mesh="")
    out = tmp_path / "out"
    rep = calibrate(
        tiny,
        out,
        models=["linear-compression"],
        settings=settings,
        progress=lambda s: None,
        figures=False,
    )
    assert rep["import"]["correlation"]["subsets_correlated"] == 81
    assert len(rep["import"]["files_sha256"]["images"]) == 3
    md = (out / "report.md").read_text()
    assert "3 images, the reference included" in md and "not converged per image [0, 0]" in md
    assert "correlated between two images, rho = 0.5" in md and rep["import"]["snapshot_rho"] == 0.5
    # the residual maps say what they show: whitened residuals, not r / sigma
    import bench.plotting
    from bench.calibration import write_report

    titles = []

    def keep_titles(fig, path, **kw):
        titles.extend(ax.get_title() for ax in fig.axes)
        bench.plotting.pyplot().close(fig)

    monkeypatch.setattr(bench.plotting, "save", keep_titles)
    write_report(rep, import_experiment(load_experiment(tiny)), out, figures=True)
    assert "u_h whitened residual (rho 0.5), last image" in titles

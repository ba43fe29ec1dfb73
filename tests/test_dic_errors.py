"""Bad inputs give clear errors; failed points are flagged; image I/O; the CLI."""

from __future__ import annotations

import numpy as np
import pytest

from bench.cli import main as cli
from problems.dic import _kernels
from problems.dic.correlate import Correlator, DICConfig, grid_points
from problems.dic.imageio import read_image, write_image
from problems.dic.interpolate import BSplineImage, noise_gain
from problems.dic.speckle import acquire
from problems.dic.synthetic import fourier_shift, speckle_image


@pytest.fixture(scope="module")
def images():
    base = speckle_image(128, seed=5)
    ref = acquire(base, 8, 1.0, 1)
    de = acquire(fourier_shift(base, 0.4, -0.3), 8, 1.0, 2)
    return ref, de


# ------------------------------------------------------------------ bad inputs


def test_different_sizes(images):
    ref, de = images
    corr = Correlator(ref, grid_points(ref.shape, 21, 10), DICConfig())
    with pytest.raises(ValueError, match="image sizes differ"):
        corr.correlate(de[:100])


def test_blank_images(images):
    ref, _ = images
    with pytest.raises(ValueError, match="reference image is blank"):
        Correlator(np.full_like(ref, 100), grid_points(ref.shape, 21, 10))
    corr = Correlator(ref, grid_points(ref.shape, 21, 10))
    with pytest.raises(ValueError, match="deformed image is blank"):
        corr.correlate(np.zeros_like(ref))


@pytest.mark.parametrize(
    "roi, match",
    [
        ((0, 0, 200, 100), "outside the image"),
        ((-5, 0, 50, 50), "outside the image"),
        ((10, 10, 10, 50), "empty"),
        ((0, 0, 15, 100), "larger than the ROI"),
    ],
)
def test_bad_roi(roi, match):
    with pytest.raises(ValueError, match=match):
        grid_points((128, 128), 21, 10, roi)


def test_bad_subset_and_points(images):
    ref, _ = images
    with pytest.raises(ValueError, match="odd integer"):
        DICConfig(subset=20)
    with pytest.raises(ValueError, match="do not fit"):
        Correlator(ref, np.array([[5.0, 60.0]]), DICConfig())
    with pytest.raises(ValueError, match="larger than the image"):
        Correlator(ref[:15, :15], np.array([[7.0, 7.0]]), DICConfig(subset=21))
    with pytest.raises(ValueError, match="2-D"):
        Correlator(np.dstack([ref, ref]), np.array([[60.0, 60.0]]))


# ------------------------------------------------------------------ flags, never silently wrong


def test_points_on_a_destroyed_region_are_flagged(images):
    ref, de = images
    bad = de.copy()
    rng = np.random.default_rng(0)
    # noise only
    bad[:, :64] = np.clip(128 + 2 * rng.standard_normal((128, 64)), 0, 255).astype(np.uint8)
    pts = grid_points(ref.shape, 21, 10)
    r = Correlator(ref, pts, DICConfig()).correlate(bad)
    left = r.x + 10 < 64  # subsets entirely in the destroyed half
    right = r.x - 10 >= 64
    assert not r.converged[left].any()
    assert np.all(np.isnan(r.u[left])) and np.all(np.isnan(r.std_u[left]))
    assert r.converged[right].all()
    assert np.allclose(r.u[right], 0.4, atol=0.03) and np.allclose(r.v[right], -0.3, atol=0.03)


def test_textureless_reference_subset_is_flagged(images):
    ref, de = images
    ref2 = ref.copy()
    ref2[40:90, 40:90] = 120  # paint over: no texture
    de2 = de.copy()
    de2[40:90, 40:90] = 120
    pts = np.array([[65.0, 65.0], [20.0, 20.0], [105.0, 105.0]])
    corr = Correlator(ref2, pts, DICConfig())
    assert list(corr.valid) == [False, True, True]
    r = corr.correlate(de2)
    assert list(r.converged) == [False, True, True] and np.isnan(r.u[0])


def test_unrelated_image_gives_no_converged_points(images):
    ref, _ = images
    other = acquire(speckle_image(128, seed=99), 8, 1.0, 3)
    r = Correlator(ref, grid_points(ref.shape, 21, 10), DICConfig()).correlate(other)
    assert r.converged.mean() < 0.05
    assert np.all(np.isnan(r.u[~r.converged]))


def test_initial_guess_from_previous_snapshot(images):
    ref, de = images
    base = speckle_image(128, seed=5)
    de2 = acquire(fourier_shift(base, 1.1, -0.9), 8, 1.0, 4)
    corr = Correlator(ref, grid_points(ref.shape, 21, 10), DICConfig())
    r1 = corr.correlate(de)
    r2 = corr.correlate(de2, initial=r1)
    assert r2.meta["seeds"] == 0 and r2.meta["from_initial"] == len(r2.u)
    assert np.allclose(r2.u, 1.1, atol=0.03) and np.allclose(r2.v, -0.9, atol=0.03)


# ------------------------------------------------------------------ interpolation and back-ends


@pytest.mark.parametrize("order", [3, 5])
def test_spline_gradient_is_the_derivative_of_the_interpolant(order):
    img = speckle_image(40, seed=1) * 255
    s = BSplineImage(img, order)
    gx, gy = s.gradient_at_pixels()
    y, x = np.mgrid[0:40, 0:40].astype(float)
    e = 1e-5
    fdx = (s.values(x + e, y) - s.values(x - e, y)) / (2 * e)
    fdy = (s.values(x, y + e) - s.values(x, y - e)) / (2 * e)
    assert np.max(np.abs(fdx - gx)) < 1e-5 and np.max(np.abs(fdy - gy)) < 1e-5
    assert np.max(np.abs(s.values(x, y) - img)) < 1e-9


def test_noise_gain_of_interpolation():
    g = noise_gain(np.array([0.0, 0.5, 1.0, 0.25]), 3)
    assert g[0] == pytest.approx(1.0) and g[2] == pytest.approx(1.0)
    assert 0.7 < g[1] < 0.8 and g[1] < g[3] < 1.0


@pytest.mark.skipif("numba" not in _kernels.AVAILABLE, reason="numba not installed")
@pytest.mark.parametrize("order", [3, 5])
def test_scipy_and_numba_backends_agree(images, order):
    ref, de = images
    pts = grid_points(ref.shape, 21, 10)
    a = Correlator(ref, pts, DICConfig(order=order, backend="scipy")).correlate(de)
    b = Correlator(ref, pts, DICConfig(order=order, backend="numba")).correlate(de)
    assert np.array_equal(a.converged, b.converged)
    assert np.nanmax(np.abs(a.params - b.params)) < 1e-10


# ------------------------------------------------------------------ image I/O


@pytest.mark.parametrize(
    "name, dtype, compression",
    [
        ("a.tif", np.uint8, "packbits"),
        ("b.tiff", np.uint16, "packbits"),
        ("c.tif", np.uint16, "zlib"),
        ("d.png", np.uint8, None),
        ("e.png", np.uint16, None),
        ("f.bmp", np.uint8, None),
    ],
)
def test_image_round_trip(tmp_path, name, dtype, compression):
    rng = np.random.default_rng(0)
    a = rng.integers(0, np.iinfo(dtype).max + 1, (33, 47)).astype(dtype)
    write_image(tmp_path / name, a, compression)
    b = read_image(tmp_path / name)
    assert b.dtype == dtype and np.array_equal(a, b)


def test_image_io_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        read_image(tmp_path / "missing.png")
    (tmp_path / "x.jpg").write_bytes(b"not an image")
    with pytest.raises(ValueError, match="unsupported image format"):
        read_image(tmp_path / "x.jpg")
    (tmp_path / "y.png").write_bytes(b"not an image")
    with pytest.raises(ValueError, match="not a readable PNG"):
        read_image(tmp_path / "y.png")
    with pytest.raises(ValueError, match="8-bit grey levels only"):
        write_image(tmp_path / "z.bmp", np.zeros((4, 4), np.uint16))


def test_rgb_is_converted_to_grey(tmp_path):
    from PIL import Image

    rgb = np.zeros((10, 12, 3), np.uint8)
    rgb[..., 0], rgb[..., 1], rgb[..., 2] = 100, 150, 200
    Image.fromarray(rgb).save(tmp_path / "c.png")
    g = read_image(tmp_path / "c.png")
    assert g.shape == (10, 12) and g[0, 0] == round(0.299 * 100 + 0.587 * 150 + 0.114 * 200)


# ------------------------------------------------------------------ CLI


def test_cli_writes_csv(tmp_path, images, capsys):
    ref, de = images
    write_image(tmp_path / "ref.tif", ref, "packbits")
    write_image(tmp_path / "def.png", de)
    out = tmp_path / "out.csv"
    rc = cli(
        [
            "dic",
            str(tmp_path / "ref.tif"),
            str(tmp_path / "def.png"),
            "--subset",
            "21",
            "--step",
            "10",
            "--roi",
            "10,10,118,118",
            "--csv",
            str(out),
            "--no-progress",
        ]
    )
    assert rc == 0
    lines = out.read_text().splitlines()
    assert lines[0] == "x_px,y_px,u_px,v_px,std_u_px,std_v_px,zncc,converged"  # units in the header
    rows = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]])
    assert len(rows) == len(grid_points(ref.shape, 21, 10, (10, 10, 118, 118)))
    assert (
        rows[:, 7].all()
        and np.allclose(rows[:, 2], 0.4, atol=0.03)
        and np.allclose(rows[:, 3], -0.3, atol=0.03)
    )
    # the per-point standard deviations the correlator computes: positive, small against the 0.03 px
    # check
    assert np.all(rows[:, 4:6] > 0) and np.all(rows[:, 4:6] < 0.03)
    assert rows[:, 0].min() - 10 >= 10 and rows[:, 0].max() + 10 < 118


@pytest.mark.parametrize(
    "extra, match",
    [
        (["--roi", "0,0,500,50"], "outside the image"),
        (["--subset", "61", "--roi", "0,0,60,60"], "larger than the ROI"),
        (["--subset", "8"], "odd integer"),
    ],
)
def test_cli_bad_arguments_exit_2(tmp_path, images, capsys, extra, match):
    ref, de = images
    write_image(tmp_path / "ref.png", ref)
    write_image(tmp_path / "def.png", de)
    assert (
        cli(["dic", str(tmp_path / "ref.png"), str(tmp_path / "def.png"), "--no-progress", *extra])
        == 2
    )
    assert match in capsys.readouterr().err


def test_cli_size_mismatch_and_blank(tmp_path, images, capsys):
    ref, de = images
    write_image(tmp_path / "ref.png", ref)
    write_image(tmp_path / "small.png", de[:64])
    write_image(tmp_path / "blank.bmp", np.full_like(de, 77))
    assert cli(["dic", str(tmp_path / "ref.png"), str(tmp_path / "small.png")]) == 2
    assert "image sizes differ" in capsys.readouterr().err
    assert cli(["dic", str(tmp_path / "ref.png"), str(tmp_path / "blank.bmp")]) == 2
    assert "is blank" in capsys.readouterr().err

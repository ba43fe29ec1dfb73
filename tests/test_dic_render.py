"""Speckle rendering, inverse mapping, symmetry, and render-and-correlate of a known FE-like
field."""

from __future__ import annotations

import json

import numpy as np
import pytest

from problems.dic import _kernels
from problems.dic.correlate import DICConfig
from problems.dic.pipeline import measure_front_face, pixel_displacement
from problems.dic.speckle import (
    CameraConfig,
    SpeckleConfig,
    SpecklePattern,
    blob_field,
    face_pattern,
    render,
)
from problems.dic.warp import inverse_map, mirror_quarter_field


def _pattern(size=80, seed=0):
    return SpecklePattern.random((0, size, 0, size), 5.0, 0.32, 0.2, 2.0, rng=seed).blurred(0.67)


def test_rendering_a_constant_translation_equals_moving_the_pattern():
    pat = _pattern()
    a = render(pat, (80, 80), displacement=lambda X, Y: (2.3 + 0 * X, -1.7 + 0 * Y))
    moved = SpecklePattern(pat.centres + [2.3, -1.7], pat.sigma, pat.amplitude)
    b = render(moved, (80, 80))
    assert np.max(np.abs(a - b)) < 1e-6  # float32 blob arithmetic


def test_inverse_map_solves_x_equals_X_plus_u_of_X():
    def disp(X, Y):
        return 0.02 * X + 0.001 * Y**2 / 50, -0.01 * Y + 0.3 * np.sin(X / 20)

    ux, uy = inverse_map(disp, (60, 70))
    y, x = np.mgrid[0:60, 0:70].astype(float)
    X, Y = x - ux, y - uy
    fx, fy = disp(X, Y)
    assert np.max(np.abs(X + fx - x)) < 1e-6 and np.max(np.abs(Y + fy - y)) < 1e-6
    # coarse solve + cubic interpolation (map_step) stays accurate for smooth fields
    ux2, uy2 = inverse_map(disp, (60, 70), map_step=4)
    assert np.max(np.abs(ux2 - ux)) < 1e-3 and np.max(np.abs(uy2 - uy)) < 1e-3


def test_inverse_map_refuses_a_fold():
    with pytest.raises(ValueError, match="did not converge"):
        inverse_map(lambda X, Y: (-1.5 * X, 0 * Y), (20, 20))


def test_quarter_field_is_mirrored_odd_and_even():
    full = mirror_quarter_field(
        lambda y, z: (0.01 * y + 0.002 * z, -0.003 * z + 0.001 * y), 75.0, 150.0
    )
    y = np.array([10.0, -10.0, 80.0, -80.0])
    z = np.array([20.0, 20.0, 160.0, 160.0])
    uy, uz = full(y, z)
    assert uy[1] == pytest.approx(-uy[0]) and uz[1] == pytest.approx(uz[0])
    # outside the face: clamped onto it (y = +-75, z = 150)
    assert uy[2] == pytest.approx(0.01 * 75 + 0.002 * 150) and uz[3] == pytest.approx(
        -0.003 * 150 + 0.001 * 75
    )


def test_pixel_displacement_signs_and_camera_mapping():
    cam = CameraConfig(pixels=(100, 100), face_mm=(150.0, 150.0), margin_px=10)
    x, y = cam.mm_to_px(np.array([-75.0, 0.0]), np.array([150.0, 0.0]))
    assert x[0] == pytest.approx(9.5) and y[0] == pytest.approx(9.5)  # top-left face corner
    assert x[1] == pytest.approx(59.5) and y[1] == pytest.approx(109.5)  # bottom centre
    disp = pixel_displacement(lambda yy, zz: (0.3 + 0 * yy, -0.6 + 0 * zz), cam)
    ux, uy = disp(np.array([80.0, 20.0]), np.array([50.0, 50.0]))  # right half, left half
    assert ux[0] == pytest.approx(0.3 / 1.5) and ux[1] == pytest.approx(-0.3 / 1.5)  # u_y odd
    # down in the image
    assert uy[0] == pytest.approx(0.6 / 1.5) and uy[1] == pytest.approx(0.6 / 1.5)


def test_speckle_defaults_give_about_half_dark_pixels():
    cam = CameraConfig(pixels=(200, 200), face_mm=(30.0, 30.0), margin_px=0, noise_sigma=0.0)
    img = render(face_pattern(SpeckleConfig(), cam, 4), cam.shape)
    dark = np.mean(img < 0.5)
    assert 0.35 < dark < 0.65
    assert img.min() >= 0.2 - 1e-9 and img.max() <= 0.8 + 1e-9


@pytest.mark.skipif("numba" not in _kernels.AVAILABLE, reason="numba not installed")
def test_numpy_and_numba_splat_agree():
    pat = _pattern(60, seed=2)
    c = pat.centres
    a = blob_field(pat, (60, 60), 3, c, backend="numpy")
    b = blob_field(pat, (60, 60), 3, c, backend="numba")
    assert np.max(np.abs(a - b)) < 1e-5


def _bulge(delta, nu=0.2):
    """Compression-like field on the quarter face: u_z = -delta z / 150, bulging u_y."""

    def field(y, z):
        return nu * delta * y / 150 * (1 + 0.5 * np.sin(np.pi * z / 150)), -delta * z / 150 + 0 * y

    return field


def test_render_and_correlate_reproduces_known_field_within_stated_uncertainty(tmp_path):
    cam = CameraConfig(pixels=(300, 300), margin_px=16)  # 0.5 mm/px
    sp = SpeckleConfig(size_mm=2.5, blur_mm=0.33)  # 5 px speckles, as with the default camera
    ys, zs = np.arange(10.0, 71.0, 10.0), np.arange(10.0, 141.0, 10.0)
    Y, Z = np.meshgrid(ys, zs)
    grid = np.column_stack([Y.ravel(), Z.ravel()])
    fields = [_bulge(0.75), _bulge(1.5)]  # up to 3 px at the top
    m = measure_front_face(fields, grid, cam, sp, DICConfig(), seed=7, image_dir=tmp_path)
    assert m.u_h.shape == (2, len(grid)) and m.std_v.shape == (2, len(grid))
    assert m.converged.all()
    zs_all = []
    for k, f in enumerate(fields):
        uy, uz = f(grid[:, 0], grid[:, 1])
        zs_all += [(m.u_h[k] - uy) / m.std_h[k], (m.u_v[k] - uz) / m.std_v[k]]
        # the DIC std is 0.005-0.011 mm (0.01-0.022 px) here; the field is up to 1.5 mm
        assert np.all(m.std_h[k] < 0.02) and np.all(m.std_v[k] < 0.02)
    z = np.concatenate(zs_all)
    assert 0.7 < np.sqrt(np.mean(z**2)) < 1.4, np.sqrt(np.mean(z**2))
    assert np.max(np.abs(z)) < 4.5
    assert np.all(m.u_v[1] < 0)  # compression: the face moves down
    # images, setup and the subset figure's panels written (drawn on the bench side); setup
    # regenerates the same configuration
    assert (
        len(m.image_paths) == 3
        and m.subsets_path
        and (tmp_path / "dic_subsets.npz").stat().st_size > 0
    )
    from bench.dic_figures import render_subsets

    assert (
        render_subsets(tmp_path) == tmp_path / "dic_subsets.png"
        and (tmp_path / "dic_subsets.png").stat().st_size > 0
    )
    setup = json.loads((tmp_path / "dic_setup.json").read_text())
    assert (
        setup["seed"] == 7
        and CameraConfig(
            **{
                **setup["camera"],
                "pixels": tuple(setup["camera"]["pixels"]),
                "face_mm": tuple(setup["camera"]["face_mm"]),
            }
        )
        == cam
    )
    cov = m.covariance()
    assert cov.shape == (2, len(grid), 2, 2) and np.allclose(cov[..., 0, 0], m.std_h**2)


def test_grid_point_outside_quarter_is_rejected():
    with pytest.raises(ValueError, match="outside the quarter face"):
        measure_front_face([_bulge(0.1)], np.array([[-5.0, 10.0]]), CameraConfig(pixels=(100, 100)))


@pytest.mark.slow
def test_default_camera_and_measurement_grid():  # ~10 s: full 1000 x 1000 px images
    ys, zs = np.arange(5.0, 71.0, 5.0), np.arange(5.0, 146.0, 5.0)
    Y, Z = np.meshgrid(ys, zs)
    grid = np.column_stack([Y.ravel(), Z.ravel()])
    f = _bulge(0.45)
    m = measure_front_face([f], grid, seed=1)
    uy, uz = f(grid[:, 0], grid[:, 1])
    assert m.converged.all()
    z = np.concatenate([(m.u_h[0] - uy) / m.std_h[0], (m.u_v[0] - uz) / m.std_v[0]])
    assert 0.7 < np.sqrt(np.mean(z**2)) < 1.4
    assert np.median(m.std_v) < 0.003  # mm (0.15 mm/px, ~0.011 px)

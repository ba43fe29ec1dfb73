"""Figures are written as palette PNGs (bench.plotting.save / palette_png) and
``femubench figures compact`` converts an existing PNG with the very same function."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from bench.cli import main as cli
from bench.plotting import line_style, palette_png, pyplot, save

PNG_PALETTE = 3  # PNG colour type byte (IHDR) of a palette image


def _grey_figure():
    """A small line figure in greys only (<= 256 colours: converted without loss)."""
    fig, ax = pyplot().subplots(figsize=(2.0, 1.5))
    x = np.linspace(0.0, 1.0, 30)
    for i in range(3):
        ax.plot(x, x ** (i + 1), **line_style(i))
    ax.set_xlabel("x (mm)")
    return fig


def _colour_figure():
    """A small figure with a colour map image (> 256 colours: quantized)."""
    fig, ax = pyplot().subplots(figsize=(2.0, 1.5))
    ax.imshow(np.random.default_rng(0).random((40, 40)), cmap="viridis")
    ax.plot([0, 39], [0, 39], color="C3")
    return fig


def _pixels(data: bytes) -> np.ndarray:
    with Image.open(io.BytesIO(data)) as im:
        return np.asarray(im.convert("RGBA")).astype(int)


def _colours(data: bytes) -> int:
    rgb = _pixels(data)[..., :3].reshape(-1, 3)
    return len(np.unique(rgb, axis=0))


@pytest.mark.parametrize("draw", [_grey_figure, _colour_figure])
def test_a_render_equals_its_rgba_png_converted_and_is_deterministic(tmp_path, draw):
    direct = save(draw(), tmp_path / "direct.png").read_bytes()
    again = save(draw(), tmp_path / "again.png").read_bytes()
    rgba = save(draw(), tmp_path / "rgba.png", palette=False).read_bytes()
    assert rgba[25] == 6 and direct[25] == PNG_PALETTE  # matplotlib's RGBA -> palette
    assert again == direct  # same figure, same bytes
    assert palette_png(rgba) == direct  # converting the RGBA render == rendering directly
    assert palette_png(direct) == direct  # idempotent
    assert len(direct) < 0.6 * len(rgba)
    a, b = _pixels(rgba), _pixels(direct)
    assert (b[..., 3] == 255).all()
    white = (a[..., :3] == 255).all(-1)
    assert (b[white] == 255).all()  # the background stays white
    if draw is _grey_figure:
        assert _colours(rgba) <= 256
        assert np.array_equal(a, b)  # no loss at all
    else:
        assert _colours(rgba) > 256 >= _colours(direct)
        assert np.abs(a - b).max() <= 16  # per channel, of 255
    with Image.open(tmp_path / "direct.png") as im, Image.open(tmp_path / "rgba.png") as im0:
        assert im.info["dpi"] == im0.info["dpi"] == pytest.approx((150, 150), abs=0.05)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary left


def test_figures_compact_rewrites_a_folder_once_and_dry_run_writes_nothing(tmp_path, capsys):
    folder = tmp_path / "report"
    save(_grey_figure(), folder / "a.png", palette=False)
    save(_colour_figure(), folder / "sub" / "b.png", palette=False)
    old = {p: p.read_bytes() for p in folder.rglob("*.png")}
    assert cli(["figures", "compact", str(folder), "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert "would rewrite 2 of 2 figure(s)" in out and "diff text ~" in out
    assert {p: p.read_bytes() for p in folder.rglob("*.png")} == old
    assert cli(["figures", "compact", str(folder)]) == 0
    assert "rewrote 2 of 2 figure(s)" in capsys.readouterr().out
    for p, data in old.items():
        assert p.read_bytes() == palette_png(data) != data
    assert cli(["figures", "compact", str(folder / "a.png"), str(folder / "sub")]) == 0
    assert "rewrote 0 of 2 figure(s)" in capsys.readouterr().out  # idempotent


def test_figures_compact_rejects_a_png_that_is_not_ours_before_writing_anything(tmp_path, capsys):
    good = save(_grey_figure(), tmp_path / "a.png", palette=False)
    before = good.read_bytes()
    grey = tmp_path / "b_grey.png"
    Image.fromarray(np.zeros((4, 4), np.uint8)).save(grey)  # 8-bit greyscale: not matplotlib's
    clear = tmp_path / "c_clear.png"
    Image.fromarray(np.zeros((4, 4, 4), np.uint8)).save(clear)  # transparent
    torn = tmp_path / "d_torn.png"
    torn.write_bytes(before[: len(before) // 2])
    text = tmp_path / "e_text.png"
    text.write_text("not an image\n")
    for bad, message in [
        (grey, "PNG colour type 0 with 8 bits per sample"),
        (clear, "transparent pixels"),
        (torn, "corrupt PNG"),
        (text, "not a PNG file"),
    ]:
        assert cli(["figures", "compact", str(good), str(bad)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and str(bad) in err and message in err, err
        assert good.read_bytes() == before  # nothing written
    assert cli(["figures", "compact", str(tmp_path / "none.png")]) == 2
    assert "neither a file nor a folder" in capsys.readouterr().err


def test_figures_compact_dry_run_predicts_the_diff_text_of_its_commit(tmp_path, capsys):
    import re
    import subprocess

    folder = tmp_path / "results" / "default" / "report" / "figures"  # shipped path lengths
    for i in range(4):
        save(_colour_figure() if i % 2 else _grey_figure(), folder / f"f{i}.png", palette=False)

    def git(*a):
        cmd = ["git", "-c", "user.name=t", "-c", "user.email=t@t", "-C", str(tmp_path), *a]
        return subprocess.run(cmd, check=True, capture_output=True).stdout

    git("init", "-q")
    git("add", "-A")
    git("commit", "-qm", "rgba")
    assert cli(["figures", "compact", str(folder), "--dry-run"]) == 0
    predicted = int(re.search(r"diff text ~([0-9]+) bytes", capsys.readouterr().out).group(1))
    assert cli(["figures", "compact", str(folder)]) == 0
    git("add", "-A")
    git("commit", "-qm", "palette")
    actual = len(git("show", "--binary", "HEAD"))
    assert predicted == pytest.approx(actual, rel=0.1), (predicted, actual)

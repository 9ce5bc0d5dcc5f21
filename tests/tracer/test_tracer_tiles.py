# SPDX-License-Identifier: GPL-3.0-or-later
"""Tiled renders: a pixel's samples depend only on where the pixel lies in the whole image
and on the sample index, so an image rendered in tiles is the image rendered whole."""
import numpy as np
import pytest

from hairio import InputError
from tracer import Camera, RenderSettings
from tracer.__main__ import main, render_png, tiles
from tracer.reference import reference_render
from tracer.reference.samples import pixel_samples

from tracer_scenes import curls


def _camera(size):
    s = curls(n_strands=16, radius=0.02)
    return s, Camera.frame_bounds(*s.bounds(), size)


def _assemble(render, camera, xs, ys):
    """The image of `camera` put together from the windows [xs[i], xs[i+1]) x [ys[j], ys[j+1])."""
    W, H = camera.size
    out = np.full((H, W, 4), np.nan)
    for y0, y1 in zip(ys[:-1], ys[1:]):
        for x0, x1 in zip(xs[:-1], xs[1:]):
            out[y0:y1, x0:x1] = render(camera.window(x0, y0, x1 - x0, y1 - y0))
    return out


def test_a_window_keeps_the_rays_of_its_pixels():
    _, cam = _camera((40, 30))
    cam = Camera(cam.type, cam.position, cam.rotation, cam.size, cam.pixel_size, np.array([3.25, -1.5]))
    win = cam.window(12, 7, 9, 11)
    assert win.size == (9, 11) and tuple(win.pixel_origin) == (12, 7)
    x, y = np.meshgrid(np.arange(9) + 0.3, np.arange(11) + 0.7)
    np.testing.assert_allclose(win.rays(x, y)[1], cam.rays(x + 12, y + 7)[1], rtol=0, atol=1e-15)
    inner = win.window(2, 3, 4, 4)     # a window of a window is a window of the whole image
    assert tuple(inner.pixel_origin) == (14, 10)
    np.testing.assert_allclose(inner.rays(x[:4, :4], y[:4, :4])[1], cam.rays(x[:4, :4] + 14, y[:4, :4] + 10)[1],
                               rtol=0, atol=1e-15)
    with pytest.raises(InputError, match="window"):
        cam.window(35, 0, 6, 1)


@pytest.mark.parametrize("spp", [1, 4])
def test_reference_samples_follow_the_whole_image(spp):
    n = int(round(np.sqrt(spp)))
    _, cam = _camera((24, 18))
    whole = pixel_samples(cam, n).reshape(18, 24, spp, 2)
    win = pixel_samples(cam.window(10, 5, 7, 6), n).reshape(6, 7, spp, 2)
    np.testing.assert_array_equal(win + [10, 5], whole[5:11, 10:17])


def test_a_tiled_reference_render_is_the_whole_one():
    s, cam = _camera((20, 16))
    settings = RenderSettings(spp=4)
    whole = reference_render(s, cam, settings)
    assert (whole[..., 3] > 0.5).mean() > 0.05
    tiled = _assemble(lambda c: reference_render(s, c, settings), cam, [0, 9, 20], [0, 7, 16])
    np.testing.assert_allclose(tiled, whole, rtol=0, atol=1e-12)


@pytest.mark.parametrize("spp,kind", [(1, "persp"), (4, "persp"), (4, "ortho shifted")])
def test_a_2x2_tiled_render_is_the_whole_render(renderer, spp, kind):
    """Tiles of odd sizes at odd offsets; at spp 4 the jitter of each pixel must be the one
    it has in the whole image (tiles numbered their own pixels from 0 before)."""
    s, cam = _camera((96, 80))
    if kind == "ortho shifted":
        lo, hi = s.bounds()
        c = (lo + hi) / 2
        cam = Camera.look_at(c - [0, 3, 0], c, type="ORTHO", ortho_scale=1.2, size=(96, 80))
        cam = Camera(cam.type, cam.position, cam.rotation, cam.size, cam.pixel_size, np.array([7.3, -4.6]))
    settings = RenderSettings(spp=spp, min_pixel_width=kind != "persp")
    renderer.set_strands(s)
    whole = renderer.render(cam, settings)
    assert (whole[..., 3] > 0.5).mean() > 0.05 and (whole[..., 3] < 0.5).mean() > 0.05
    tiled = _assemble(lambda c: renderer.render(c, settings), cam, [0, 37, 96], [0, 45, 80])
    np.testing.assert_allclose(tiled, whole, rtol=0, atol=2e-7)


def test_render_png_tiles_at_4_spp_write_the_whole_image(renderer, tmp_path):
    from tracer.png import to_srgb8
    s, cam = _camera((70, 50))
    settings = RenderSettings(spp=4)
    renderer.set_strands(s)
    whole = to_srgb8(renderer.render(cam, settings))
    out = tmp_path / "tiled.png"
    assert sum(len(row) for _, _, row in tiles(cam.size, 900, 32)) == 6
    render_png(renderer, cam, settings, out, tile_pixels=900, tile_side=32)
    np.testing.assert_array_equal(_decode(out), whole)


def _decode(path):
    from tracer.png import read_png_rgba8
    return read_png_rgba8(path)


# ------------------------------------------------------------------ the command's stated limits

@pytest.mark.parametrize("size,want", [
    ("16385x2", "width and height must lie in 1..16384; the tracer places samples in float32 pixel coordinates, "
                "which 16385 pixels across round to 1/1024 of a pixel (1/2048 at 16384)"),
    ("40000x40000", "which 40000 pixels across round to 1/512 of a pixel"),
    ("0x8", "width and height must lie in 1..16384"),
])
def test_a_size_past_the_limit_is_refused_with_its_error_before_the_input_is_read(tmp_path, capsys, size, want):
    missing = tmp_path / "no-such-input.npz"
    assert main(["render", str(missing), "--out", str(tmp_path / "x.png"), "--size", size]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: --size '{size}': ") and want in err
    assert not list(tmp_path.iterdir())


def test_spp_past_the_limit_is_refused_with_its_error_before_the_input_is_read(tmp_path, capsys):
    missing = tmp_path / "no-such-input.npz"
    assert main(["render", str(missing), "--out", str(tmp_path / "x.png"), "--spp", str(1000 ** 2)]) == 2
    err = capsys.readouterr().err
    assert "spp: 1000000 samples per pixel, summed in float32, can be off by up to 5.96% of a pixel's value; " \
           "use at most 4096 (error 0.024%)" in err
    assert not list(tmp_path.iterdir())


def test_a_16k_image_is_refused_only_when_a_band_does_not_fit_in_memory(tmp_path, capsys, monkeypatch):
    import hairio.validate
    from tracer.__main__ import render_memory
    missing = tmp_path / "no-such-input.npz"
    argv = ["render", str(missing), "--out", str(tmp_path / "x.png"), "--size", "16384x16384"]
    need = render_memory((16384, 16384))
    assert need < 64 << 20          # a band of tiles, not the 4 GiB of the image in float32
    assert render_memory((16384, 16384)) == render_memory((16384, 300))
    monkeypatch.setattr(hairio.validate, "available_memory", lambda: need - 1)
    assert main(argv) == 2
    assert f"error: --size 16384x16384: needs about {need / 2**30:.2f} GiB of memory but" in capsys.readouterr().err
    monkeypatch.setattr(hairio.validate, "available_memory", lambda: need)
    assert main(argv) == 2           # past the size: refused only for the missing input
    err = capsys.readouterr().err
    assert str(missing) in err and "--size" not in err
    assert not list(tmp_path.iterdir())


def test_a_16k_wide_render_takes_no_more_than_its_estimate(renderer, tmp_path):
    """Two bands of eight 2048 x 128 tiles: the image (16384 x 256) is never held whole,
    in float32 or float64; what Python allocates stays within render_memory."""
    import tracemalloc
    from tracer.__main__ import render_memory
    s, cam = _camera((16384, 256))
    renderer.set_strands(s)
    out = tmp_path / "wide.png"
    tracemalloc.start()
    try:
        render_png(renderer, cam, RenderSettings(), out)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak <= render_memory(cam.size), (peak, render_memory(cam.size))
    assert peak < 16384 * 256 * 16       # less than the image in float32
    img = _decode(out)
    assert img.shape == (256, 16384, 4) and 0 < (img[..., 3] > 0).mean() < 0.05

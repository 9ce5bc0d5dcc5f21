# SPDX-License-Identifier: GPL-3.0-or-later
"""`python -m tracer render` with hostile options: what cannot work is refused before any
work (exit 2, a message naming the option, with the limit), what can is done in tiles,
and a write that fails after the work leaves nothing."""
import contextlib
import errno
import tracemalloc

import numpy as np
import pytest

from hairio import InputError, Strands
from tracer import Camera, RenderSettings
from tracer.__main__ import main, parse_size, render_png, tiles
from tracer.settings import MAX_SPP


@pytest.fixture
def tuft(tmp_path):
    s = Strands.from_arrays(np.array([[0, 0, 0], [0, 0, 1.0], [0.3, 0, 0], [0.3, 0.1, 0.8]]), [2, 2],
                            radius=np.full(4, 0.05))
    path = tmp_path / "tuft.npz"
    s.save_npz(path)
    return path


def _files(folder):
    return sorted(p.name for p in folder.iterdir())


@pytest.mark.parametrize("case", ["folder", "missing folder", "unwritable", "spp", "spp not square", "size"])
def test_refused_before_the_input_is_read(tmp_path, case, capsys):
    """The input does not exist: each refusal must come before the file is even opened."""
    missing = str(tmp_path / "no-such-input.npz")
    out = str(tmp_path / "x.png")
    argv = {"folder": ["--out", str(tmp_path)],
            "missing folder": ["--out", str(tmp_path / "nope" / "x.png")],
            "unwritable": ["--out", "/proc/keystrand-test.png"],
            "spp": ["--out", out, "--spp", str(1000 ** 2)],
            "spp not square": ["--out", out, "--spp", "5"],
            "size": ["--out", out, "--size", "16385x2"]}[case]
    before = _files(tmp_path)
    assert main(["render", missing] + argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and missing not in err
    want = {"folder": "is a folder", "missing folder": "does not exist", "unwritable": "cannot write in",
            "spp": f"use at most {MAX_SPP}", "spp not square": "square number", "size": "1..16384"}[case]
    assert want in err
    assert _files(tmp_path) == before


def test_the_largest_size_is_accepted():
    assert parse_size("16384x16384") == (16384, 16384)
    with pytest.raises(InputError):
        parse_size("0x10")


def test_a_full_disk_while_writing_is_exit_2_and_leaves_nothing(tuft, tmp_path, monkeypatch, capsys):
    import hairio.atomic
    import tracer.png
    real = hairio.atomic.atomic_write

    @contextlib.contextmanager
    def filling(path, mode="wb"):
        with real(path, mode) as f:
            class Full:
                def write(self, data):
                    raise OSError(errno.ENOSPC, "No space left on device")
            yield Full()

    monkeypatch.setattr(tracer.png, "atomic_write", filling)
    out = tmp_path / "out.png"
    assert main(["render", str(tuft), "--out", str(out), "--size", "32x32"]) == 2
    err = capsys.readouterr().err
    assert "No space left on device" in err and "nothing was written" in err
    assert _files(tmp_path) == ["tuft.npz"]


def test_tiles_cover_the_image_once():
    for size in ((1, 1), (300, 7), (5000, 3000), (16384, 16384)):
        seen = np.zeros(size[::-1], np.int8) if size[0] * size[1] < 1e8 else None
        covered = 0
        for y0, h, row in tiles(size):
            for x0, w in row:
                assert w * h <= max(1 << 18, w)
                covered += w * h
                if seen is not None:
                    seen[y0:y0 + h, x0:x0 + w] += 1
        assert covered == size[0] * size[1]
        assert seen is None or (seen == 1).all()


def _decode(path):
    from tracer.png import read_png_rgba8
    return read_png_rgba8(path)


def test_a_tiled_render_is_the_whole_render_pixel_for_pixel(shared_data, tmp_path):
    from hairio.formats import read_strands
    from tracer.png import to_srgb8
    from tracer.renderer import Renderer
    s = read_strands(shared_data / "straight.hair")
    r = Renderer()
    r.set_strands(s)
    lo, hi = s.bounds()
    cam = Camera.frame_bounds(lo, hi, (301, 203))
    whole = to_srgb8(r.render(cam, RenderSettings()))
    assert (whole[..., 3] > 0).mean() > 0.1
    out = tmp_path / "tiled.png"
    render_png(r, cam, RenderSettings(), out, tile_pixels=4000, tile_side=64)   # 5 x 4 bands of odd tiles
    np.testing.assert_array_equal(_decode(out), whole)


def test_a_large_image_takes_the_memory_of_a_band(tuft, tmp_path):
    """2048 x 2048 in float32 RGBA is 64 MiB, twice that in float64; tile by tile it is a
    fraction of that (a 16384² image takes the same: a band is at most 16384 x 128 pixels)."""
    out = tmp_path / "big.png"
    tracemalloc.start()
    try:
        assert main(["render", str(tuft), "--out", str(out), "--size", "2048x2048"]) == 0
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 32 << 20, peak
    img = _decode(out)
    assert img.shape == (2048, 2048, 4) and 0.005 < (img[..., 3] > 0).mean() < 0.5


# ------------------------------------------------------------------ python -m groom generate

@pytest.mark.parametrize("argv,match", [
    (["--count", str(2 ** 62)], "count 4,611,686,018,427,387,904: --out"),
    (["--count", str(10 ** 9)], "GiB of disk while it is written (96 points a strand at most, 32 bytes each) but"),
    (["--count", "0"], "must be at least 1"),
])
def test_generate_refuses_a_count_that_cannot_work(tmp_path, argv, match, capsys):
    """The command grows a block at a time into the file, so what cannot work is a file the
    disk cannot take (10^9 strands of wavy: up to 4 TB), refused with its size before any work."""
    from groom.__main__ import main as groom_main
    out = tmp_path / "x.npz"
    assert groom_main(["generate", "--preset", "wavy", "--out", str(out)] + argv) == 2
    assert match in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def test_generate_checks_its_memory_against_what_is_available(monkeypatch):
    import groom
    import hairio.validate
    scalp = groom.default_scalp()
    placement = groom.load_preset("wavy").place_keys(scalp)
    monkeypatch.setattr(hairio.validate, "available_memory", lambda: 1 << 30)
    params = placement.params.replace(count=200_000, points_per_strand=96)   # 1.2 GB estimated
    with pytest.raises(InputError, match=r"count 200,000: needs about 1.14 GiB of memory but 1.00 GiB"):
        groom.generate(scalp, placement.keys, params)
    assert groom.generate(scalp, placement.keys, params.replace(count=100)).strands.num_strands == 100


def test_generate_checks_out_before_the_work(tmp_path, capsys):
    from groom.__main__ import main as groom_main
    folder = tmp_path / "looks.npz"
    folder.mkdir()
    assert groom_main(["generate", "--preset", "wavy", "--out", str(folder)]) == 2
    assert "is a folder" in capsys.readouterr().err


# ------------------------------------------------------------------ the renderer's own limits

def _far_strand(offset, length):
    pts = np.array([[offset, 0, 0], [offset, 0, length], [offset + length, 0, length]])
    return Strands.from_arrays(pts, [3], radius=np.full(3, length / 20))


def test_a_strand_too_far_for_float32_squares_is_refused_not_drawn_empty(tmp_path, capsys):
    """At 1e20 the GPU image came out empty while the float64 reference showed hair."""
    from tracer.reference import reference_render
    from tracer.renderer import Renderer
    r = Renderer()
    near = _far_strand(5e16, 1e17)
    r.set_strands(near)
    cam = Camera.frame_bounds(*near.bounds(), (24, 24))
    gpu, ref = r.render(cam, RenderSettings()), reference_render(near, cam, RenderSettings())
    assert (gpu[..., 3] > 0).mean() > 0.02
    np.testing.assert_array_equal(gpu[..., 3] > 0.5, ref[..., 3] > 0.5)
    path = tmp_path / "far.npz"
    _far_strand(1e20, 1e20).save_npz(path)
    assert main(["render", str(path), "--out", str(tmp_path / "far.png")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {path}: points: coordinates reach 2.05e+20") and "1e+18" in err
    assert not (tmp_path / "far.png").exists()


def test_renderer_refuses_a_camera_too_far_and_an_image_too_large(monkeypatch):
    import hairio.validate
    from tracer.renderer import Renderer
    r = Renderer()
    r.set_strands(_far_strand(0, 1.0))
    with pytest.raises(InputError, match="camera: position 1e\\+20"):
        r.render(Camera.look_at([0, -1e20, 0], [0, 0, 0], size=(8, 8)), RenderSettings())
    side = min(r.ctx.info["GL_MAX_TEXTURE_SIZE"], *r.ctx.info["GL_MAX_VIEWPORT_DIMS"])
    with pytest.raises(InputError, match=f"draws at most {side} pixels a side"):
        r.render(Camera.look_at([0, -3, 0], [0, 0, 0], size=(side + 1, 8)), RenderSettings())
    monkeypatch.setattr(hairio.validate, "available_memory", lambda: 100 << 20)
    with pytest.raises(InputError, match=r"camera size 2048x2048: needs about 0.19 GiB of memory but 0.10 GiB"):
        r.render(Camera.look_at([0, -3, 0], [0, 0, 0], size=(2048, 2048)), RenderSettings())
    assert r.render(Camera.look_at([0, -3, 0.5], [0, 0, 0.5], size=(64, 64)), RenderSettings()).shape == (64, 64, 4)


def test_a_camera_too_far_names_the_option(tuft, tmp_path, capsys):
    camera = "0,-1e20,0:0,0,0:40"
    assert main(["render", str(tuft), "--out", str(tmp_path / "x.png"), "--camera", camera]) == 2
    assert capsys.readouterr().err.startswith(f"error: --camera {camera}: camera: position 1e+20")
    assert _files(tmp_path) == ["tuft.npz"]


def test_a_framebuffer_the_driver_refuses_is_an_input_error():
    """llvmpipe refuses float framebuffers past 2 GiB (12000² is INCOMPLETE_ATTACHMENT, below
    GL_MAX_TEXTURE_SIZE); whatever the driver does, no moderngl error reaches the caller."""
    from tracer.renderer import Renderer
    r = Renderer()
    r.set_strands(_far_strand(0, 1.0))
    try:
        img = r.render(Camera.look_at([0, -3, 0.5], [0, 0, 0.5], size=(12000, 12000)), RenderSettings())
    except InputError as e:
        assert "camera size 12000x12000" in str(e) and "tiles" in str(e)
    else:
        assert img.shape == (12000, 12000, 4)
    assert r.render(Camera.look_at([0, -3, 0.5], [0, 0, 0.5], size=(32, 32)), RenderSettings())[..., 3].max() > 0

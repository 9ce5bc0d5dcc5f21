# SPDX-License-Identifier: GPL-3.0-or-later
"""`python -m tracer render --min-pixel-width`: hair thinner than a pixel shows as strands
rather than dust, with the coverage it has; the option's default is RenderSettings'."""
from tracer import RenderSettings
from tracer.__main__ import build_parser, main

from tracer_scenes import curls


def _alpha(path):
    from tracer.png import read_png_rgba8
    return read_png_rgba8(path)[..., 3] / 255.0


def test_the_default_is_render_settings_default():
    parse = build_parser().parse_args
    assert parse(["render", "x.npz", "--out", "x.png"]).min_pixel_width is RenderSettings().min_pixel_width
    assert parse(["render", "x.npz", "--out", "x.png", "--min-pixel-width"]).min_pixel_width is True
    assert parse(["render", "x.npz", "--out", "x.png", "--no-min-pixel-width"]).min_pixel_width is False


def test_min_pixel_width_turns_dust_into_strands_with_the_same_coverage(tmp_path, capsys):
    """Hairs 1/12 of a pixel wide: alone they hit one pixel in a few along their length;
    widened to half a pixel and made fainter they cover their whole path, and the image
    keeps about the same total alpha."""
    src = tmp_path / "thin.npz"
    curls(n_strands=12, radius=0.002).save_npz(src)
    alpha = {}
    for flag in ("--no-min-pixel-width", "--min-pixel-width"):
        out = tmp_path / f"{flag}.png"
        assert main(["render", str(src), "--out", str(out), "--size", "64x64", flag]) == 0
        alpha[flag] = _alpha(out)
        assert ("minimum pixel width" in capsys.readouterr().out) == (flag == "--min-pixel-width")
    thin, wide = alpha["--no-min-pixel-width"], alpha["--min-pixel-width"]
    assert 0 < (thin > 0).mean() and (wide > 0).mean() > 2.5 * (thin > 0).mean()
    assert abs(wide.mean() / thin.mean() - 1) < 0.25

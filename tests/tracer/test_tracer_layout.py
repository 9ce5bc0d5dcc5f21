# SPDX-License-Identifier: GPL-3.0-or-later
"""Texture layout: list textures fit the driver's maximum texture size, scenes beyond it
get a clear error."""
import numpy as np
import pytest

from hairio import InputError
from tracer import Camera, RenderSettings

from tracer_scenes import curls


def test_texture_layout_widens_rows_up_to_the_driver_limit():
    from tracer.renderer import texture_layout
    assert texture_layout("tex_idx", 21_000_000, 16384) == (12, 5127)    # fits 4096-wide rows
    assert texture_layout("tex_idx", 1000, 16384) == (12, 1)            # small scenes keep 4096
    # 200,000 strands x 16 points: 4096-wide rows would need 20946 > 16384 rows.
    assert texture_layout("tex_idx", 85_795_000, 16384) == (13, 10474)   # the narrowest rows that fit
    with pytest.raises(InputError, match="tex_idx.*allows 16384 per side"):
        texture_layout("tex_idx", 16384 * 16384 + 1, 16384)


def test_small_forced_texture_limit_renders_like_the_reference():
    # A driver limit of 64 texels per side with 4-texel base rows: both list textures must
    # grow their rows to fit, and the shader must address them the same way.
    from tracer import Renderer, reference_render
    s = curls(n_strands=12, n_points=10)
    r = Renderer(max_texture_size=64, base_width=4)
    r.set_strands(s)
    assert r._shift["tex_cyl"] > 2 and r._shift["tex_idx"] > 2
    cam = Camera.look_at((0.3, -2, 0.5), (0, 0, 0.5), fov_deg=40, size=(24, 24))
    settings = RenderSettings(shading="phong")
    img = r.render(cam, settings)
    ref = reference_render(s, cam, settings)
    assert ref[..., 3].max() > 0
    assert np.mean(np.abs(img - ref).max(axis=-1) > 2e-3) <= 0.01
    with pytest.raises(InputError, match="scene too large"):
        Renderer(max_texture_size=8, base_width=4).set_strands(s)

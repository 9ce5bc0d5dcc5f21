# SPDX-License-Identifier: GPL-3.0-or-later
"""The render loop's shortcuts change no pixel: the sorted hit list kept by
compare-and-swap keeps the nearest layers, and a shadow ray that tries the previous
layer's occluder first darkens exactly where the full walk would."""
import numpy as np

from tracer import Camera, Light, RenderSettings

from test_tracer_vs_reference import assert_matches_reference
from tracer_scenes import make_strands


def _sheets():
    """Four sheets of parallel translucent strands one behind the other, lit from behind
    and above: deep layers are shadowed by strands of the nearer sheets, and neighbouring
    layers of one pixel often share their occluder."""
    lines = [[[x, y, -0.5], [x + 0.02, y + 0.01, 0.5]]
             for y in np.linspace(-0.3, 0.3, 4) for x in np.linspace(-0.4, 0.4, 9)]
    return make_strands(lines, radius=0.03, alpha=0.55)


def test_hard_shadows_through_an_alpha_stack_match_the_reference(renderer):
    s = _sheets()
    cam = Camera.look_at((0.2, -2.2, 0.3), (0, 0, 0), fov_deg=40, size=(48, 48))
    light = Light("directional", (0.1, -0.6, -0.8))
    settings = RenderSettings(layers=4, shadows=True, shadow_mode="hard", shading="kajiya-kay",
                              lights=(light,), count=True)
    img, ref = assert_matches_reference(renderer, s, cam, settings)
    assert renderer.stats.shadow_rays > renderer.stats.layers_traced // 2
    # The shadows are there: without them some covered pixels are much brighter.
    lit = renderer.render(cam, RenderSettings(layers=4, shadows=False, shading="kajiya-kay", lights=(light,)))
    covered = ref[..., 3] > 0.5
    assert np.mean((lit - img)[covered][:, :3].max(axis=-1) > 0.05) > 0.1


def test_nearest_layers_win_whatever_the_order_they_are_found_in(renderer):
    # A ray along a row of strands meets them in the reverse order of their ids; with two
    # layers only the two nearest may show, each with its own colour.
    lines, colours = [], []
    for k in range(6):
        lines.append([[0.0, 0.3 * k, -0.4], [0.0, 0.3 * k, 0.4]])
    s = make_strands(lines[::-1], radius=0.05, alpha=0.5)
    cam = Camera.look_at((0, -2.0, 0.0), (0, 0, 0), fov_deg=20, size=(24, 24))
    settings = RenderSettings(layers=2, shadows=False, shading="phong")
    img, _ = assert_matches_reference(renderer, s, cam, settings)
    centre = img[12, 12]
    assert abs(centre[3] - 0.75) < 1e-5      # two layers of alpha 0.5, not more, not fewer

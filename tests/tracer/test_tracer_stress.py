# SPDX-License-Identifier: GPL-3.0-or-later
"""SPEC §9: every stress case gives finite pixels (or a clear error)."""
import numpy as np
import pytest

from hairio import InputError, Strands
from tracer import Camera, RenderSettings, reference_render

from tracer_scenes import curls, make_strands

SETTINGS = RenderSettings(shadows=True, layers=3, shading="phong")


def _finite(img):
    assert img.dtype == np.float32 and np.all(np.isfinite(img))
    return img


def test_ray_parallel_to_the_axis_sees_the_end_cap(renderer):
    renderer.set_strands(make_strands([[[0, 0, 0], [0, 0, 0.5], [0, 0, 1]]], radius=0.1))
    img = _finite(renderer.render(Camera.look_at((0, 0, 3), (0, 0, 0), up=(0, 1, 0), size=(32, 32)), SETTINGS))
    assert img[16, 16, 3] == 1.0      # the strand's end, seen head on, is a disc


def test_rays_parallel_to_grid_axes(renderer):
    renderer.set_strands(curls(20, 8))
    for eye, up in (((0, -3, 0.5), (0, 0, 1)), ((3, 0, 0.5), (0, 0, 1)), ((0, 0, 4), (0, 1, 0))):
        cam = Camera.look_at(eye, (0, 0, 0.5), up=up, size=(32, 32), type="ORTHO", ortho_scale=1.5)
        assert _finite(renderer.render(cam, SETTINGS))[..., 3].max() > 0


def test_camera_inside_the_hair_volume(renderer):
    renderer.set_strands(curls(60, 10, radius=0.01))
    cam = Camera.look_at((0, 0, 0.5), (0.3, 0.2, 0.9), size=(32, 32), fov_deg=90)
    assert renderer.screen_bounds(cam) == (0, 0, 32, 32)   # box behind the eye: every pixel traces
    assert _finite(renderer.render(cam, SETTINGS))[..., 3].max() > 0


def test_grazing_rays(renderer):
    s = make_strands([[[-1, 0, 0], [1, 0, 0]]], radius=0.05)
    renderer.set_strands(s)
    # Camera in the plane z = 0.05 (tangent to the cylinder's top) looking along it: the
    # centre row's rays graze the strand, the rows above miss it, the rows below meet it
    # across the whole image (the strand is wider than the view).
    cam = Camera.look_at((0, -3, 0.05), (0, 0, 0.05), size=(33, 33), fov_deg=10)
    img = _finite(renderer.render(cam, SETTINGS))
    alpha = img[..., 3]
    assert np.all(alpha[:16] == 0)
    assert np.all(alpha[17:22] == 1.0)
    assert np.all(alpha[23:] == 0)
    # Off the grazing row the pixels are the float64 reference's.
    ref = reference_render(s, cam, SETTINGS)
    off = np.r_[0:16, 17:33]
    np.testing.assert_allclose(img[off], ref[off], atol=1e-5)


def test_a_cell_with_thousands_of_cylinders(renderer):
    rng = np.random.default_rng(1)
    lines = [np.array([[0, 0, 0], [0, 0, 0.01]]) + rng.normal(0, 1e-3, (2, 3)) for _ in range(3000)]
    renderer.set_strands(make_strands(lines, radius=2e-4, alpha=0.5))
    cam = Camera.look_at((0, -0.05, 0.005), (0, 0, 0.005), size=(24, 24))
    img = _finite(renderer.render(cam, RenderSettings(layers=8, count=True)))
    assert img[..., 3].max() > 0.5 and renderer.stats.cylinder_tests > 3000


def test_empty_scene_renders_the_background(renderer):
    renderer.set_strands(Strands.empty())
    bg = (0.2, 0.3, 0.4, 1.0)
    img = _finite(renderer.render(Camera.look_at((0, -3, 0), (0, 0, 0), size=(16, 16)), RenderSettings(background=bg)))
    np.testing.assert_allclose(img, np.broadcast_to(bg, img.shape))


@pytest.mark.parametrize("scale,offset", [(1e-6, 0.0), (1.0, 1e4), (1e-3, 0.0), (1e3, 0.0)])
def test_tiny_radius_offsets_and_scales(renderer, scale, offset):
    s = curls(8, 8, radius=1e-6 if scale == 1e-6 else 0.02)
    if scale != 1e-6:
        s = Strands.from_arrays(s.points * scale + offset, s.counts, radius=s.radius * scale, color=s.color)
    renderer.set_strands(s)
    lo, hi = s.bounds()
    cam = Camera.frame_bounds(lo, hi, (32, 32))
    img = _finite(renderer.render(cam, SETTINGS))
    if scale != 1e-6:
        assert img[..., 3].max() > 0   # still visible after the offset: no precision collapse


@pytest.mark.parametrize("offset", [1e4, -3e3])
def test_radius_below_float32_spacing_raises_naming_points(renderer, offset):
    # A 0.2 mm head (radius 1e-6) far from the origin: float32 points lie ~1e-3 apart there,
    # the cylinders collapse, and the image once came out empty without a word.
    head = curls(8, 8, radius=1e-6)
    near = Strands.from_arrays(head.points * 2e-4, head.counts, radius=head.radius, color=head.color)
    s = Strands.from_arrays(head.points * 2e-4 + offset, head.counts, radius=head.radius, color=head.color)
    with pytest.raises(InputError, match=r"points:.*float32.*Recentre the strands near the origin"):
        renderer.set_strands(s)
    cam = Camera.frame_bounds(*s.bounds(), (8, 8))
    with pytest.raises(InputError, match=r"points:.*thinnest strand.s radius 1e-06"):
        reference_render(s, cam, SETTINGS)
    # The same head near the origin renders.
    renderer.set_strands(near)
    assert _finite(renderer.render(Camera.frame_bounds(*near.bounds(), (16, 16)), SETTINGS))[..., 3].max() > 0


def test_refused_strands_leave_the_scene_as_it_was(renderer):
    # Strands the tracer cannot resolve (as above) are refused before anything changes,
    # whether they come as a whole new scene or as a changed strand of the current one.
    head = curls(8, 8, radius=1e-6)
    near = Strands.from_arrays(head.points * 2e-4, head.counts, radius=head.radius, color=head.color)
    cam = Camera.frame_bounds(*near.bounds(), (16, 16))
    renderer.set_strands(near)
    before = renderer.render(cam, SETTINGS)
    assert before[..., 3].max() > 0
    far = Strands.from_arrays(near.points + 1e4, near.counts, radius=near.radius, color=near.color)
    with pytest.raises(InputError, match=r"points:.*float32"):
        renderer.set_strands(far)
    np.testing.assert_array_equal(renderer.render(cam, SETTINGS), before)
    moved = near.points.copy()
    a, n = near.offsets[3], near.counts[3]
    moved[a:a + n] += 1e4
    one_far = Strands.from_arrays(moved, near.counts, radius=near.radius, color=near.color)
    with pytest.raises(InputError, match=r"points:.*float32"):
        renderer.update_strands([3], one_far)
    assert renderer.strands is near
    np.testing.assert_array_equal(renderer.render(cam, SETTINGS), before)


def test_nan_and_inf_input_rejected_naming_the_array():
    with pytest.raises(InputError, match="radius"):
        Strands.from_arrays(np.zeros((2, 3)) + [[0, 0, 0], [0, 0, 1]], [2], radius=[0.1, np.inf])

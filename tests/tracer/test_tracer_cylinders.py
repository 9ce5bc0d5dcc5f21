# SPDX-License-Identifier: GPL-3.0-or-later
import numpy as np
import pytest

from hairio import InputError, Strands
from tracer import strands_to_cylinders
from tracer.layout import SHARP_BEND_DEG

from tracer_scenes import curls, make_strands


def test_one_cylinder_per_segment_with_top_tip_and_own_axis_at_the_end():
    s = make_strands([[[0, 0, 0], [0, 0, 1], [1, 0, 2]], [[5, 5, 5], [6, 5, 5]]])
    c = strands_to_cylinders(s)
    assert len(c) == s.num_segments == 3
    np.testing.assert_allclose(c.top, [[0, 0, 0], [0, 0, 1], [5, 5, 5]])
    np.testing.assert_allclose(c.tip, [[0, 0, 1], [1, 0, 2], [6, 5, 5]])
    # plane 2 of cylinder 0 is the next axis; the last cylinder of each strand uses its own.
    np.testing.assert_allclose(c.n2, [[np.sqrt(.5), 0, np.sqrt(.5)], [np.sqrt(.5), 0, np.sqrt(.5)], [1, 0, 0]], atol=1e-6)
    assert list(c.strand) == [0, 0, 1]
    assert list(c.flags) == [1, 2, 3]   # bit 0: plane 1 is an end cap; bit 1: plane 2 is


def test_consecutive_cylinders_share_their_plane():
    c = strands_to_cylinders(curls(4, 12))
    same = c.strand[1:] == c.strand[:-1]
    axis_next = c.tip[1:] - c.top[1:]
    axis_next /= np.linalg.norm(axis_next, axis=1)[:, None]
    np.testing.assert_allclose(c.n2[:-1][same], axis_next[same], atol=1e-6)
    np.testing.assert_array_equal(c.tip[:-1][same], c.top[1:][same])


def test_repeated_points_are_dropped_not_turned_into_zero_length_cylinders():
    s = make_strands([[[0, 0, 0], [0, 0, 1], [0, 0, 1], [0, 1, 2]], [[2, 2, 2], [2, 2, 2]]])
    c = strands_to_cylinders(s)
    assert len(c) == 2        # the repeated point goes; the all-repeated strand makes nothing
    assert np.all(np.linalg.norm(c.tip - c.top, axis=1) > 0)
    np.testing.assert_allclose(c.n2[0], [0, np.sqrt(.5), np.sqrt(.5)], atol=1e-6)


def test_sharp_bend_ends_both_cylinders_square_and_bounded():
    hairpin = make_strands([[[0, 0, 0], [0, 0, 1], [0.01, 0, 0]]])
    c = strands_to_cylinders(hairpin)
    angle = np.degrees(np.arccos(np.clip(np.dot([0, 0, 1], (c.tip[1] - c.top[1]) / np.linalg.norm(c.tip[1] - c.top[1])), -1, 1)))
    assert angle > SHARP_BEND_DEG
    np.testing.assert_allclose(c.n2[0], [0, 0, 1], atol=1e-6)
    assert list(c.flags) == [3, 3]
    assert np.all(c.extension == 0)


def test_bend_under_the_limit_reaches_r_tan_angle_past_the_tip():
    a = np.radians(60)
    s = make_strands([[[0, 0, 0], [0, 0, 1], [np.sin(a), 0, 1 + np.cos(a)]]], radius=0.1)
    c = strands_to_cylinders(s)
    assert c.extension[0] == pytest.approx(0.1 * np.tan(a), rel=1e-5)


def test_nan_points_are_rejected_naming_the_array():
    with pytest.raises(InputError, match="points"):
        Strands.from_arrays([[0, 0, 0], [np.nan, 0, 1]], [2])


def test_a_cylinder_takes_the_mean_of_its_two_points_radii():
    # A tapered strand: each cylinder as wide as the middle of its step, not its wider end.
    s = make_strands([[[0, 0, 0], [0, 0, 1], [0, 0, 2], [0, 0, 3]]], radius=[0.04, 0.03, 0.01, 0.0])
    c = strands_to_cylinders(s)
    np.testing.assert_allclose(c.radius, [0.035, 0.02, 0.005], rtol=1e-6)


@pytest.mark.parametrize("build", ["numpy", "gpu"])
def test_a_tapered_strand_covers_the_cones_silhouette(build):
    # A straight strand tapered from r0 at the root to 0 at the tip, seen from the side: the
    # curve through its points (what Cycles renders) covers a triangle of area r0·L. With each
    # cylinder as wide as its top point (the SPEC's r_i), three steps cover 4/3 of that.
    from tracer import Camera, RenderSettings, Renderer
    from tracer.gpu_build import compute_available
    from tracer.gl_state import shared_context
    if build == "gpu" and not compute_available(shared_context()):
        pytest.skip("this driver has no compute shaders (OpenGL 4.3)")
    r0, length = 0.05, 1.0
    s = make_strands([[[0, 0, 0], [0, 0, 1 / 3], [0, 0, 2 / 3], [0, 0, 1]]], radius=[r0, 2 * r0 / 3, r0 / 3, 0.0])
    size, scale = (64, 256), 1.2
    cam = Camera.look_at((0, -5, 0.5), (0, 0, 0.5), type="ORTHO", size=size, ortho_scale=scale)
    r = Renderer(build=build)
    r.set_strands(s)
    img = r.render(cam, RenderSettings(spp=64, shadows=False))
    pixel = scale / max(size)
    covered = float(img[..., 3].sum()) * pixel * pixel
    assert covered == pytest.approx(r0 * length, rel=0.03)

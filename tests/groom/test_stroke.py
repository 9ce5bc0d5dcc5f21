# SPDX-License-Identifier: GPL-3.0-or-later
"""Drawing keys by stroke (groom.stroke): projection, Bézier fitting, mirror, comb."""
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as hs

from groom import HeadFrame, KeyStrand, default_head, default_scalp, fit_head_frame
from groom import stroke
from hairio import InputError


def _wavy_stroke(n=150, noise=0.0, seed=0):
    """A strand-like stroke from the origin: down and sideways with a wave, optional jitter."""
    s = np.linspace(0.0, 1.0, n)
    p = np.stack([0.1 * np.sin(3 * s), 0.02 * s * s, -0.2 * s + 0.03 * np.sin(8 * s)], 1)
    p[1:] += np.random.default_rng(seed).normal(0.0, noise, (n - 1, 3))
    return p


def leave(control):
    """The unit direction a key leaves its root in."""
    return (control[1] - control[0]) / np.linalg.norm(control[1] - control[0])


def _dense_length(control):
    """Arc length by a polyline 20 times finer than the module's own, computed here."""
    return float(np.linalg.norm(np.diff(stroke.sample_cubic(control, 10000), axis=0), axis=1).sum())


# --- projection ------------------------------------------------------------------------

def test_plane_projection_orthographic_slides_points_along_the_view():
    p = _wavy_stroke(40) + [0.0, 0.3, 0.0]
    root = np.array([0.01, -0.05, 0.02])
    view = np.array([0.0, 1.0, 0.0])
    out = stroke.project_to_plane(p, root, view)
    np.testing.assert_allclose((out - root) @ view, 0.0, atol=1e-15)
    np.testing.assert_allclose(out[:, [0, 2]], p[:, [0, 2]], atol=1e-15)


def test_plane_projection_perspective_keeps_each_point_on_its_ray_from_the_eye():
    p = _wavy_stroke(40) + [0.0, 0.2, 0.0]
    eye = np.array([0.05, -0.8, 0.1])
    view = np.array([0.1, 1.0, -0.1])
    root = np.array([0.0, -0.09, 0.02])
    out = stroke.project_to_plane(p, root, view, eye=eye)
    n = view / np.linalg.norm(view)
    np.testing.assert_allclose((out - root) @ n, 0.0, atol=1e-14)
    along = (p - eye) / np.linalg.norm(p - eye, axis=1, keepdims=True)
    moved = (out - eye) / np.linalg.norm(out - eye, axis=1, keepdims=True)
    np.testing.assert_allclose(moved, along, atol=1e-12)


def test_plane_projection_refuses_a_view_of_zero():
    with pytest.raises(InputError, match="view_direction"):
        stroke.project_to_plane(_wavy_stroke(5), np.zeros(3), (0.0, 0.0, 0.0))


def test_shell_projection_lands_offset_outside_the_scalp_and_keeps_the_misses():
    scalp = default_scalp()
    offset = 0.01
    # Seen from above: a line across the crown and out past the cap's outline.
    x = np.linspace(-0.2, 0.2, 41)
    points = np.stack([x, np.zeros_like(x), np.full_like(x, 0.3)], 1)
    out, on = stroke.project_to_shell(points, scalp, offset, (0.0, 0.0, -1.0))
    assert on[np.abs(x) < 0.06].all() and not on[np.abs(x) > 0.09].any()
    np.testing.assert_array_equal(out[~on], points[~on])
    np.testing.assert_allclose(out[on][:, :2], points[on][:, :2], atol=1e-12)  # along the view only
    _, _, nearest = scalp.closest_points(out[on])
    distance = np.linalg.norm(out[on] - nearest, axis=1)
    # The shell is the mesh moved along its vertex normals: off by its flat facets only.
    np.testing.assert_allclose(distance, offset, rtol=0.05)


def test_shell_projection_takes_the_crossing_nearest_the_viewer():
    head = default_head()  # closed: every ray through it crosses the shell twice
    eye = np.array([0.0, -1.0, 0.02])
    points = np.array([[0.0, -0.5, 0.02], [0.01, -0.5, 0.0]])
    out, on = stroke.project_to_shell(points, head, 0.005, (0.0, 1.0, 0.0), eye=eye)
    assert on.all()
    front = head.vertices[:, 1].min()
    assert (out[:, 1] < front + 0.02).all(), out  # the face, not the back of the head
    ortho, on = stroke.project_to_shell(points, head, 0.005, (0.0, 1.0, 0.0))
    assert on.all() and (ortho[:, 1] < front + 0.02).all()


# --- fitting ---------------------------------------------------------------------------

@pytest.mark.parametrize("tolerance", [5e-4, 1e-3, 3e-3])
@pytest.mark.parametrize("noise", [0.0, 1e-4])
def test_fit_stays_within_the_tolerance_of_the_stroke(tolerance, noise):
    p = _wavy_stroke(150, noise)
    c = stroke.fit_bezier(p, tolerance)
    assert c.shape[1] == 3 and (len(c) - 1) % 3 == 0
    assert stroke.curve_deviation(c, p).max() <= tolerance
    # And the other way: the curve keeps to the stroke.
    assert stroke.distance_to_polyline(stroke.sample_cubic(c, 256), p).max() <= tolerance
    np.testing.assert_array_equal(c[[0, -1]], p[[0, -1]])


def test_fit_uses_few_segments_and_fewer_for_a_looser_tolerance():
    p = _wavy_stroke(150)
    tight, loose = (stroke.fit_bezier(p, t) for t in (5e-4, 4e-3))
    assert (len(loose) - 1) // 3 < (len(tight) - 1) // 3 <= 8


def test_fit_of_a_straight_stroke_is_one_straight_segment():
    p = np.linspace([0.0, 0.0, 0.0], [0.0, 0.0, 0.2], 30)
    c = stroke.fit_bezier(p, 1e-4)
    assert len(c) == 4
    np.testing.assert_allclose(c[:, :2], 0.0, atol=1e-15)


def test_fit_of_points_on_a_cubic_recovers_one_segment():
    ctrl = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.05], [0.08, 0.0, 0.06], [0.1, 0.0, -0.05]])
    # Dense enough that the first and last chords give the end tangents to within the tolerance.
    p = KeyStrand(ctrl, kind="cubic").evaluate(np.linspace(0.0, 1.0, 400))
    c = stroke.fit_bezier(p, 1e-4)
    assert len(c) == 4
    assert stroke.curve_deviation(c, p).max() <= 1e-4


def test_fit_leaves_the_first_point_along_the_imposed_tangent():
    p = _wavy_stroke(150, 1e-4)
    normal = np.array([0.0, 0.6, 0.8])
    c = stroke.fit_bezier(p, 1e-3, first_tangent=normal * 3.0)
    np.testing.assert_allclose(leave(c), normal, atol=1e-12)
    assert stroke.curve_deviation(c, p).max() <= 1e-3


def test_fitted_segments_join_smoothly():
    c = stroke.fit_bezier(_wavy_stroke(150, 1e-4), 5e-4)
    assert len(c) > 4
    for j in range(3, len(c) - 1, 3):
        a, b = c[j] - c[j - 1], c[j + 1] - c[j]
        cos = a @ b / (np.linalg.norm(a) * np.linalg.norm(b))
        assert cos > 1 - 1e-12, (j, cos)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(hs.lists(hs.tuples(*[hs.floats(-1.0, 1.0)] * 3), min_size=2, max_size=12),
       hs.floats(1e-3, 0.05), hs.sampled_from([None, (0.0, 0.0, 1.0), (1.0, 0.0, 0.0)]))
def test_any_stroke_is_fitted_within_the_tolerance(control, tolerance, tangent):
    """Random polylines (turns, hairpins, repeats, a root tangent along, across or against
    the stroke) made into strokes: the fit holds both ways."""
    corners = np.array(control) * 0.1
    p = np.vstack([np.linspace(a, b, 8, endpoint=False) for a, b in zip(corners[:-1], corners[1:])]
                  + [corners[-1:]])
    if np.linalg.norm(p - p[0], axis=1).max() <= tolerance:
        with pytest.raises(InputError, match="drag away from the root"):
            stroke.fit_bezier(p, tolerance)
        return
    c = stroke.fit_bezier(p, tolerance, first_tangent=tangent)
    assert np.isfinite(c).all()
    assert stroke.curve_deviation(c, p).max() <= tolerance * (1 + 1e-9)
    assert stroke.distance_to_polyline(stroke.sample_cubic(c, 256), p).max() <= tolerance


def test_a_stroke_that_ends_where_it_began_is_fitted():
    """Out and back within two tolerances: the end's tangent has no far point to read."""
    p = np.linspace([0.0, 0.0, 0.0], [0.0, 0.0, 0.025], 8, endpoint=False)
    p = np.vstack([p, p[::-1][:-1], [[0.0, 0.0, 0.0]]])
    c = stroke.fit_bezier(p, 0.015625)
    assert np.isfinite(c).all() and stroke.curve_deviation(c, p).max() <= 0.015625


def test_a_root_tangent_against_the_stroke_keeps_the_overshoot_within_the_tolerance():
    p = np.linspace([0.0, -0.1, 0.1], [0.0, -0.1, -0.1], 40)
    c = stroke.fit_bezier(p, 1e-3, first_tangent=(0.0, 0.0, 1.0))
    np.testing.assert_allclose(leave(c), (0.0, 0.0, 1.0), atol=1e-12)
    assert stroke.distance_to_polyline(stroke.sample_cubic(c, 256), p).max() <= 1e-3


@pytest.mark.parametrize("tolerance", [0.0, -1.0, float("nan"), "fine"])
def test_fit_refuses_a_tolerance_that_is_not_a_positive_number(tolerance):
    with pytest.raises(InputError, match="tolerance"):
        stroke.fit_bezier(_wavy_stroke(10), tolerance)


def test_fit_refuses_a_stroke_that_never_leaves_the_root():
    with pytest.raises(InputError, match="drag away from the root"):
        stroke.fit_bezier(np.zeros((5, 3)), 1e-3)
    with pytest.raises(InputError, match="drag away from the root"):
        stroke.fit_bezier([[0.0, 0.0, 0.0], [0.0, 0.0005, 0.0], [0.0005, 0.0, 0.0]], 1e-3)


def test_fit_refuses_a_stroke_with_nan_and_one_of_one_point():
    p = _wavy_stroke(10)
    p[4, 1] = np.nan
    with pytest.raises(InputError, match="stroke.*NaN"):
        stroke.fit_bezier(p, 1e-3)
    with pytest.raises(InputError, match="stroke: expected shape"):
        stroke.fit_bezier(np.zeros((1, 3)), 1e-3)


def test_fit_refuses_a_tolerance_far_too_small_for_the_stroke():
    with pytest.raises(InputError, match="larger tolerance"):
        stroke.fit_bezier(_wavy_stroke(150, 1e-4), 1e-9)


# --- mirror ----------------------------------------------------------------------------

def test_mirror_on_the_bundled_head_negates_x():
    frame = fit_head_frame(default_scalp())
    p = _wavy_stroke(20) + [0.03, 0.0, 0.09]
    np.testing.assert_allclose(stroke.mirror_points(p, frame), p * [-1.0, 1.0, 1.0], atol=1e-9)


def test_mirror_of_a_turned_head_reflects_across_its_own_left_right_plane():
    up, front = np.array([0.0, 1.0, 0.2]), np.array([0.3, 0.0, 1.0])
    frame = HeadFrame((1.0, 2.0, 3.0), (0.08, 0.1, 0.1), up=up, front=front)
    p = np.random.default_rng(1).normal(size=(30, 3))
    m = stroke.mirror_points(p, frame, "X")
    side = lambda q: (q - frame.centre) @ frame.right  # noqa: E731
    np.testing.assert_allclose(side(m), -side(p), atol=1e-12)
    for axis in (frame.up, frame.front):  # the other two coordinates stay
        np.testing.assert_allclose((m - frame.centre) @ axis, (p - frame.centre) @ axis, atol=1e-12)
    np.testing.assert_allclose(stroke.mirror_points(m, frame, "X"), p, atol=1e-12)
    np.testing.assert_allclose((stroke.mirror_points(p, frame, "Z") - frame.centre) @ frame.up,
                               -(p - frame.centre) @ frame.up, atol=1e-12)


def test_a_mirrored_key_roots_on_the_scalp():
    scalp = default_scalp()
    # An off-centre frame: the reflected root lands off the surface and is carried back.
    frame = HeadFrame((0.004, 0.0, 0.0), (0.08, 0.1, 0.1))
    _, _, root = scalp.closest_points(np.array([[0.05, 0.02, 0.09]]))
    key = np.vstack([root, root + [0.0, 0.0, 0.02], root + [0.02, 0.0, 0.02], root + [0.03, 0.0, -0.05]])
    m = stroke.mirror_key(key, frame, "X", scalp)
    _, _, nearest = scalp.closest_points(m[:1])
    assert np.linalg.norm(nearest[0] - m[0]) < 1e-12
    np.testing.assert_allclose(np.diff(m, axis=0), np.diff(stroke.mirror_points(key, frame), axis=0), atol=1e-15)


def test_mirror_refuses_an_unknown_axis():
    with pytest.raises(InputError, match="mirror axis"):
        stroke.mirror_points(np.zeros((2, 3)), fit_head_frame(default_scalp()), "W")


# --- comb ------------------------------------------------------------------------------

def _key():
    return stroke.fit_bezier(_wavy_stroke(150), 1e-3, first_tangent=(0.0, 0.0, 1.0))


def test_comb_bends_the_key_toward_the_drag_and_keeps_its_length():
    key = _key()
    length = _dense_length(key)
    centre = KeyStrand(key, kind="cubic").evaluate([0.6])[0]
    delta = np.array([0.0, 0.0, 0.02])
    combed = stroke.comb(key, centre, delta, radius=0.03)
    assert abs(_dense_length(combed) - length) < 1e-6 * length
    np.testing.assert_array_equal(combed[:2], key[:2])  # root and the way it leaves
    # The key's point under the brush moved with the drag.
    before = KeyStrand(key, kind="cubic").evaluate([0.6])[0]
    after = stroke.distance_to_polyline(before[None] + delta, stroke.sample_cubic(combed))[0]
    assert after < 0.5 * np.linalg.norm(delta)


def test_comb_leaves_the_key_before_the_brush_as_it_was():
    key = _key()
    tip = key[-1]
    combed = stroke.comb(key, tip, np.array([0.01, 0.01, 0.0]), radius=0.01)
    moved = np.flatnonzero(np.abs(combed - key).max(axis=1) > 0)
    assert len(moved) and moved.min() > len(key) // 2
    np.testing.assert_array_equal(combed[:moved.min()], key[:moved.min()])


def test_comb_far_from_the_key_changes_nothing():
    key = _key()
    np.testing.assert_array_equal(stroke.comb(key, (1.0, 1.0, 1.0), (0.1, 0.0, 0.0), 0.05), key)


def test_a_long_comb_stroke_keeps_the_length_it_began_with():
    key = _key()
    length = _dense_length(key)
    mid = KeyStrand(key, kind="cubic").evaluate([0.5])[0]
    path = mid + np.linspace(0.0, 1.0, 40)[:, None] * np.array([0.0, 0.08, 0.04])
    combed = stroke.comb_stroke(key, path, radius=0.05, view_direction=(1.0, 0.0, 0.0))
    assert np.abs(combed - key).max() > 0.01
    assert abs(_dense_length(combed) - length) < 1e-6 * length
    np.testing.assert_array_equal(combed[0], key[0])
    np.testing.assert_allclose(leave(combed), leave(key), atol=1e-12)


def test_comb_measures_across_the_view_when_given_one():
    key = _key()
    mid = KeyStrand(key, kind="cubic").evaluate([0.5])[0]
    behind = mid + [0.0, 0.5, 0.0]  # far along the view, right over the key on screen
    assert np.array_equal(stroke.comb(key, behind, (0.0, 0.0, 0.01), 0.02), key)
    assert not np.array_equal(stroke.comb(key, behind, (0.0, 0.0, 0.01), 0.02, view_direction=(0, 1, 0)), key)


def test_comb_of_a_single_bezier_keeps_its_root_tangent_and_length():
    ctrl = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.05], [0.05, 0.0, 0.08], [0.1, 0.0, 0.0], [0.12, 0.0, -0.1]])
    length = KeyStrand(ctrl).arc_length_table(2, dense=400000)[1]
    combed = stroke.comb(ctrl, ctrl[3], (0.0, 0.03, 0.0), 0.05, kind="bezier")
    np.testing.assert_array_equal(combed[0], ctrl[0])
    np.testing.assert_allclose(leave(combed), leave(ctrl), atol=1e-12)
    assert combed[3, 1] > 0.01
    assert abs(KeyStrand(combed).arc_length_table(2, dense=400000)[1] - length) < 1e-6 * length


def test_comb_refuses_a_radius_of_zero_and_a_key_of_the_wrong_layout():
    with pytest.raises(InputError, match="brush radius"):
        stroke.comb(_key(), (0, 0, 0), (0, 0, 1), 0.0)
    with pytest.raises(InputError, match="3k\\+1"):
        stroke.comb(np.zeros((5, 3)), (0, 0, 0), (0, 0, 1), 0.1)

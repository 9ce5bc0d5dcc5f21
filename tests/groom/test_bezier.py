# SPDX-License-Identifier: GPL-3.0-or-later
"""Blender's points-with-handles layout <-> groom's piecewise cubic control points."""
import numpy as np
import pytest

from groom import KeyStrand
from groom.bezier import cubic_to_handles, handles_to_cubic, smooth_handles
from hairio import InputError


def _cubic(segments, seed=0):
    return np.random.default_rng(seed).normal(size=(3 * segments + 1, 3))


def test_each_point_s_right_handle_then_the_next_point_s_left_handle_lie_between_them():
    co = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0]], float)
    left = co + [[-9, -9, -9], [0, -0.5, 0], [0, -0.25, 0]]
    right = co + [[0.25, 0, 0], [0, 0.5, 0], [9, 9, 9]]
    np.testing.assert_array_equal(handles_to_cubic(co, left, right),
                                  [co[0], right[0], left[1], co[1], right[1], left[2], co[2]])


@pytest.mark.parametrize("segments", [1, 2, 7])
def test_cubic_to_handles_and_back_is_the_same_array(segments):
    control = _cubic(segments, segments)
    co, left, right = cubic_to_handles(control)
    assert co.shape == left.shape == right.shape == (segments + 1, 3)
    np.testing.assert_array_equal(handles_to_cubic(co, left, right), control)


def test_the_free_end_handles_continue_the_curve_straight_on():
    control = _cubic(3, 5)
    co, left, right = cubic_to_handles(control)
    # The first left handle mirrors the first right one through the root; likewise at the tip.
    np.testing.assert_allclose(left[0] - co[0], -(right[0] - co[0]), atol=1e-15)
    np.testing.assert_allclose(right[-1] - co[-1], -(left[-1] - co[-1]), atol=1e-15)


def test_smooth_handles_make_a_curve_through_every_point_with_one_tangent_at_each():
    t = np.linspace(0.0, 1.0, 6)
    points = np.stack([t, np.sin(3 * t), t * t], 1)
    left, right = smooth_handles(points)
    key = KeyStrand(handles_to_cubic(points, left, right), kind="cubic")
    np.testing.assert_allclose(key.evaluate(np.linspace(0.0, 1.0, 6)), points, atol=1e-12)
    # Left and right handles of an inner point lie on one line through it: no kink.
    a, b = points[1:-1] - left[1:-1], right[1:-1] - points[1:-1]
    np.testing.assert_allclose(np.cross(a, b), 0.0, atol=1e-15)
    np.testing.assert_allclose(a, b, atol=1e-15)


def test_smooth_handles_of_a_straight_line_stay_on_it():
    points = np.outer(np.linspace(0.0, 2.0, 5), (1.0, 2.0, -1.0))
    left, right = smooth_handles(points)
    for h in (left, right):
        np.testing.assert_allclose(np.cross(h, (1.0, 2.0, -1.0)), 0.0, atol=1e-12)


@pytest.mark.parametrize("call", [
    lambda: handles_to_cubic(np.zeros((1, 3)), np.zeros((1, 3)), np.zeros((1, 3))),
    lambda: handles_to_cubic(np.zeros((3, 3)), np.zeros((2, 3)), np.zeros((3, 3))),
    lambda: cubic_to_handles(np.zeros((5, 3))),
    lambda: cubic_to_handles(np.zeros((4, 2))),
    lambda: smooth_handles(np.zeros((1, 3))),
])
def test_arrays_of_the_wrong_shape_are_refused(call):
    with pytest.raises(InputError):
        call()

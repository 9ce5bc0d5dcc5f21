# SPDX-License-Identifier: GPL-3.0-or-later
"""Axis conversions are signed permutations (exact) with the documented handedness, and the
Unreal groom attributes have the shapes Unreal reads."""
import numpy as np
import pytest

from hairio import InputError
from hairio.formats import AXES, convert_points, convert_strands
from hairio.unreal import groom_attributes

from hairio_scenes import make_wavy

FRONT, UP, RIGHT = np.array([0, -1.0, 0]), np.array([0, 0, 1.0]), np.array([1.0, 0, 0])


@pytest.mark.parametrize("axis,up,front,handed", [
    ("none", [0, 0, 1], [0, -1, 0], 1), ("y-up", [0, 1, 0], [0, 0, 1], 1),
    ("unreal", [0, 0, 1], [0, 1, 0], -1), ("directx", [0, 1, 0], [0, 0, -1], -1)])
def test_axes_map_up_front_and_handedness(axis, up, front, handed):
    m = convert_points(np.stack([RIGHT, FRONT, UP]), axis)
    np.testing.assert_array_equal(m[2], up)
    np.testing.assert_array_equal(m[1], front)
    # determinant of the linear map: +1 keeps right-handedness, -1 mirrors
    basis = convert_points(np.eye(3), axis)
    assert round(np.linalg.det(basis)) == handed


def test_conversion_is_exact_and_scales_radius():
    s = make_wavy(10)
    c = convert_strands(s, "directx", 100.0)
    np.testing.assert_array_equal(c.points[:, 1], s.points[:, 2] * np.float32(100))
    np.testing.assert_array_equal(c.radius, s.radius * np.float32(100))
    assert convert_strands(s) is s
    with pytest.raises(InputError, match="axis"):
        convert_points(s.points, "x-up")
    with pytest.raises(InputError, match="scale"):
        convert_points(s.points, "none", 0)
    assert set(AXES) == {"none", "y-up", "unreal", "directx"}


def test_groom_attributes_shapes_and_domains():
    s = make_wavy(12)
    a = groom_attributes(s, root_uv=np.zeros((12, 2)), group_id=np.arange(12), guide=np.zeros(12),
                         closest_guides=np.zeros((12, 3)), guide_weights=np.full((12, 3), 1 / 3))
    assert a["groom_color"][0] == "POINT" and a["groom_color"][2].shape == (s.num_points, 3)
    for name in ("groom_root_uv", "groom_group_id", "groom_guide", "groom_closest_guides",
                 "groom_guide_weights", "groom_version_major", "groom_version_minor"):
        assert a[name][0] == "CURVE" and len(a[name][2]) == 12
    with pytest.raises(InputError, match="root_uv"):
        groom_attributes(s, root_uv=np.zeros((11, 2)))
    with pytest.raises(InputError, match="guide_weights"):
        groom_attributes(s, guide_weights=np.full((12, 3), np.nan))

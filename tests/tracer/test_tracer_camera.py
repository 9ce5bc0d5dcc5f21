# SPDX-License-Identifier: GPL-3.0-or-later
"""Camera.from_blender against projections worked out by hand from Blender's rules."""
import numpy as np
import pytest

from hairio import InputError
from tracer import Camera


def _matrix(position=(0, 0, 0)):
    m = np.eye(4)          # camera at `position` looking down -Z, +Y up (Blender's rest pose)
    m[:3, 3] = position
    return m


def test_horizontal_fit_50mm_on_a_36mm_sensor():
    cam = Camera.from_blender(_matrix(), (1920, 1080), lens=50, sensor_width=36, sensor_fit="AUTO")
    # 36 mm over 1920 px at 50 mm: a point at depth 10, 3.6 right, lands 3.6/10*50/36*1920 = 960 px right of centre.
    x, y, depth = cam.project(np.array([[3.6, 0.0, -10.0]]))
    assert x[0] == pytest.approx(960 + 960) and y[0] == pytest.approx(540) and depth[0] == pytest.approx(10)
    x, y, _ = cam.project(np.array([[0.0, 1.8, -10.0]]))
    assert y[0] == pytest.approx(540 - 480)   # +Y is up: 1.8 at depth 10 is 480 px above centre


def test_auto_fit_on_a_portrait_image_puts_the_width_sensor_on_the_height():
    cam = Camera.from_blender(_matrix(), (600, 1200), lens=36, sensor_width=36, sensor_height=10)
    _, y, _ = cam.project(np.array([[0.0, 0.5, -1.0]]))
    assert y[0] == pytest.approx(600 - 600)   # 36 mm / 36 mm lens spans 1 unit over 1200 px


def test_vertical_fit_uses_sensor_height():
    cam = Camera.from_blender(_matrix(), (1000, 500), lens=20, sensor_width=36, sensor_height=24,
                              sensor_fit="VERTICAL")
    x, _, _ = cam.project(np.array([[0.6, 0.0, -1.0]]))   # 24/20 = 1.2 units over 500 px
    assert x[0] == pytest.approx(500 + 250)


def test_shift_moves_the_view_by_the_fitted_dimension():
    cam = Camera.from_blender(_matrix(), (800, 400), lens=50, shift_x=0.25, shift_y=-0.1)
    x, y, _ = cam.project(np.array([[0.0, 0.0, -5.0]]))
    # Shifting the view right by 0.25 of the 800 px width moves a centred point 200 px left;
    # shift_y is also in units of the larger (fitted) dimension: -0.1 * 800 = 80 px.
    assert x[0] == pytest.approx(400 - 200) and y[0] == pytest.approx(200 - 80)


def test_orthographic_scale_spans_the_larger_dimension():
    m = _matrix((1, 2, 3))
    cam = Camera.from_blender(m, (400, 200), type="ORTHO", ortho_scale=4.0)
    x, y, _ = cam.project(np.array([[2.0, 2.5, -7.0]]))
    assert x[0] == pytest.approx(200 + 100) and y[0] == pytest.approx(100 - 50)


def test_rotation_and_scale_of_matrix_world():
    # Blender's default camera-like pose: rotated 90° about X so it looks along +Y; scaled 3x.
    m = np.array([[3, 0, 0, 0], [0, 0, -3, -10], [0, 3, 0, 0], [0, 0, 0, 1.0]])
    cam = Camera.from_blender(m, (100, 100), lens=50, sensor_width=36)
    np.testing.assert_allclose(cam.forward, [0, 1, 0], atol=1e-12)
    x, y, depth = cam.project(np.array([[0.0, 0.0, 1.0]]))
    assert depth[0] == pytest.approx(10)
    assert x[0] == pytest.approx(50) and y[0] < 50       # +Z world is up in the image


def test_rays_and_project_are_inverse():
    cam = Camera.from_blender(_matrix((0.3, -1, 2)), (64, 48), lens=35, shift_x=0.1)
    xs, ys = np.meshgrid(np.linspace(0, 64, 5), np.linspace(0, 48, 4))
    o, d = cam.rays(xs, ys)
    x, y, _ = cam.project((o + 3.7 * d).reshape(-1, 3))
    np.testing.assert_allclose(x, xs.ravel(), atol=1e-9)
    np.testing.assert_allclose(y, ys.ravel(), atol=1e-9)


def test_bad_camera_input_is_rejected():
    with pytest.raises(InputError, match="sensor_fit"):
        Camera.from_blender(_matrix(), (10, 10), sensor_fit="DIAGONAL")
    with pytest.raises(InputError, match="matrix_world"):
        Camera.from_blender(np.full((4, 4), np.nan), (10, 10))
    with pytest.raises(InputError, match="PANO"):
        Camera.from_blender(_matrix(), (10, 10), type="PANO")


def test_a_pass_moves_every_sample_by_its_offset_within_one_stratum():
    from tracer.camera import pass_offset
    cam = Camera.look_at((0.0, -2.0, 0.0), (0.0, 0.0, 0.0), size=(40, 30))
    assert cam.for_pass(0, 3) is cam
    offsets = np.array([pass_offset(k) for k in range(1, 65)])
    assert np.all(offsets >= -0.5) and np.all(offsets < 0.5)
    # The passes spread over the pixel: no two alike, every quarter of it visited.
    assert len({tuple(np.round(o, 9)) for o in offsets}) == 64
    assert len({(o[0] >= 0, o[1] >= 0) for o in offsets}) == 4
    # Pixel centres of pass 5 lie where the first pass's lie moved by its offset over n = 3
    # (x right, y down), for a perspective camera seen through its own rays.
    x, y = np.meshgrid(np.arange(40) + 0.5, np.arange(30) + 0.5)
    ox, oy = pass_offset(5)
    o1, d1 = cam.for_pass(5, 3).rays(x, y)
    o0, d0 = cam.rays(x + ox / 3, y + oy / 3)
    np.testing.assert_allclose(d1, d0, atol=1e-12)
    np.testing.assert_allclose(o1, o0, atol=1e-12)

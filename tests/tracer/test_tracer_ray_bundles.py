# SPDX-License-Identifier: GPL-3.0-or-later
"""The references' pairing of rays with cylinders (tracer.ray_bundles) keeps every pair that
hits: checked against testing every ray with every cylinder, for each kind of ray set it
treats differently (one origin, one direction, one target, anything else)."""
import numpy as np
import pytest

from tracer import Camera
from tracer.cylinders import strands_to_cylinders
from tracer.ray_bundles import candidate_pairs
from tracer.reference import CylinderSet as _Cyl, intersect, pixel_samples

from tracer_scenes import curls


@pytest.fixture(scope="module")
def cyl():
    return _Cyl(strands_to_cylinders(curls(40, 16, radius=0.012)))


def _all_hits(cyl, o, d, tmax=None):
    n = len(cyl)
    rr, cc = np.repeat(np.arange(len(o)), n), np.tile(np.arange(n), len(o))
    t, _, _ = intersect(cyl, cc, o[rr], d[rr])
    hit = np.isfinite(t) & (t > 0)
    if tmax is not None:
        hit &= t < tmax[rr]
    return set(zip(rr[hit].tolist(), cc[hit].tolist()))


def _assert_holds_every_hit(cyl, o, d, target=None, tmax=None):
    truth = _all_hits(cyl, o, d, tmax)
    assert len(truth) > 50, "the rays miss the hair: the test would prove nothing"
    r, c = candidate_pairs(o, d, cyl.top, cyl.far, cyl.radius, target)
    assert truth <= set(zip(r.tolist(), c.tolist()))
    assert np.all(np.diff(r) >= 0)          # ray-major
    assert len(r) < 0.2 * len(o) * len(cyl)  # and it does prune


CAMERAS = {
    "pinhole": Camera.look_at((1.2, -1.8, 1.2), (0, 0, 0.5), fov_deg=40, size=(40, 40)),
    "orthographic": Camera.look_at((0, -3, 0.5), (0, 0, 0.5), fov_deg=30, size=(40, 40), type="ORTHO",
                                   ortho_scale=1.3),
    "pinhole inside the hair, wide": Camera.look_at((0.1, 0.0, 0.45), (0, 0, 0.5), fov_deg=100, size=(40, 40)),
}


@pytest.mark.parametrize("name", sorted(CAMERAS))
def test_camera_rays_keep_every_hit(cyl, name):
    cam = CAMERAS[name]
    pos = pixel_samples(cam, 1)
    o, d = cam.rays(pos[:, 0], pos[:, 1])
    _assert_holds_every_hit(cyl, o, d)


def test_shadow_rays_toward_a_sun_or_a_point_light_keep_every_hit(cyl):
    rng = np.random.default_rng(3)
    p = cyl.top[rng.integers(0, len(cyl), 1500)] + rng.normal(0, 0.01, (1500, 3))
    sun = np.array([0.3, 1.0, -0.4]) / np.linalg.norm([0.3, 1.0, -0.4])
    _assert_holds_every_hit(cyl, p, np.broadcast_to(sun, p.shape).copy())
    light = np.array([1.5, -1.0, 2.0])
    v = light - p
    dist = np.linalg.norm(v, axis=1)
    _assert_holds_every_hit(cyl, p, v / dist[:, None], target=light, tmax=dist)


def test_rays_of_no_common_point_or_direction_keep_every_hit(cyl):
    rng = np.random.default_rng(4)
    o = rng.uniform(-1, 1, (1200, 3)) * [1.0, 1.0, 0.2] + [0, -2.0, 0.5]
    d = np.array([0, 1.0, 0]) + rng.normal(0, 0.15, (1200, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    _assert_holds_every_hit(cyl, o, d)

# SPDX-License-Identifier: GPL-3.0-or-later
"""Bent joints against both float64 references: the mirror of the shader's model
(tracer.reference) and the one written from the solids alone (tracer.reference_solid).

On the plane two cylinders share, the incoming cylinder's section is an ellipse of semi-axes
r and r/cos θ and the outgoing one's a circle of radius r: the crescents between them are hair
surface (SPEC §6). Bounds as in test_tracer_vs_reference (float32 against float64); the two
references, both float64, must agree to rounding."""
import numpy as np
import pytest

from tracer import Camera, RenderSettings, reference_render
from tracer.reference_solid import solid_render

from tracer_scenes import make_strands
from test_tracer_vs_reference import _boundary, assert_matches_reference

R = 0.04


def _bent(deg, radius=R, alpha=1.0):
    """A strand along +z that turns by `deg` toward +x at the origin; its plane-2 normal
    there is u2."""
    th = np.radians(deg)
    u2 = np.array([np.sin(th), 0.0, np.cos(th)])
    return make_strands([[[0, 0, -0.6], [0, 0, 0], 0.6 * u2]], radius=radius, alpha=alpha), u2


def assert_references_agree(strands, camera, settings):
    ref, sol = reference_render(strands, camera, settings), solid_render(strands, camera, settings)
    cov_r, cov_s = ref[..., 3] > 1e-6, sol[..., 3] > 1e-6
    assert cov_s.any(), "scene not in view: the test would prove nothing"
    differ = cov_r != cov_s
    assert np.all(_boundary(cov_s)[differ]) and differ.mean() <= 0.005
    same = ~differ
    assert np.abs(ref - sol)[same].max() < 1e-6
    return sol


def test_a_ray_into_a_crescent_hits_hair(renderer):
    # The case: 45°, r = 0.02; a ray along -u2 aimed at the middle of the outer
    # crescent enters the incoming cylinder through the shared plane, outside the outgoing
    # cylinder's circle, 0.5 from the image plane: solid hair, once rejected by every tracer.
    r, th = 0.02, np.radians(45)
    s, u2 = _bent(45, radius=r)
    e = np.array([np.cos(th), 0.0, -np.sin(th)])         # in the shared plane, in the bend plane
    target = -0.5 * (r + r / np.cos(th)) * e
    cam = Camera.look_at(target + 0.5 * u2, target, up=(0, 1, 0), size=(33, 33), type="ORTHO", ortho_scale=6 * r)
    settings = RenderSettings(shading="phong", shadows=False)
    renderer.set_strands(s)
    img = renderer.render(cam, settings)
    ref = reference_render(s, cam, settings)
    sol = solid_render(s, cam, settings)
    for name, image in (("GPU", img), ("reference", ref), ("solid reference", sol)):
        assert image[16, 16, 3] == pytest.approx(1.0), f"{name}: no hair where the ray enters the crescent"
    # Phong on the plane entered: its normal is u2, straight back along the ray.
    np.testing.assert_allclose(img[16, 16], sol[16, 16], atol=2e-3)
    assert_matches_reference(renderer, s, cam, settings)


VIEWS = {
    "along the next axis": lambda u2: u2 + np.array([-0.25, 0.15, 0.0]),
    "outside of the bend": lambda u2: np.array([-1.0, 0.2, 0.6]),
    "across the bend plane": lambda u2: np.array([0.05, 1.0, 0.1]),
    "inside of the bend": lambda u2: np.array([1.0, -0.3, -0.2]),
}


@pytest.mark.parametrize("deg", [10, 30, 45, 60, 75, 85, 100, 120])
@pytest.mark.parametrize("view", sorted(VIEWS))
def test_bend_matches_both_references(renderer, deg, view):
    s, u2 = _bent(deg)
    eye = VIEWS[view](u2)
    cam = Camera.look_at(2.0 * eye / np.linalg.norm(eye), (0, 0, 0), up=(0, 0, 1) if view.startswith("across") else (0, 1, 0),
                         fov_deg=9, size=(48, 48))
    settings = RenderSettings(shading="phong", shadows=False)
    assert_references_agree(s, cam, settings)
    assert_matches_reference(renderer, s, cam, settings)


@pytest.mark.parametrize("deg", [20, 45, 70])
def test_tapered_bend_matches_both_references(renderer, deg):
    # The next cylinder is thinner, so the crescents are wider than r(1/cos θ - 1).
    th = np.radians(deg)
    u2 = np.array([np.sin(th), 0.0, np.cos(th)])
    s = make_strands([[[0, 0, -0.6], [0, 0, 0], 0.6 * u2, 0.6 * u2 + [0.1, 0.0, 0.4]]], radius=np.array([R, 0.6 * R, 0.3 * R, 0.1 * R]))
    eye = u2 + np.array([-0.3, 0.2, 0.0])
    cam = Camera.look_at(2.0 * eye / np.linalg.norm(eye), (0, 0, 0), up=(0, 1, 0), fov_deg=9, size=(48, 48))
    settings = RenderSettings(shading="phong", shadows=False)
    assert_references_agree(s, cam, settings)
    assert_matches_reference(renderer, s, cam, settings)


@pytest.mark.parametrize("deg", [30, 60, 75])
def test_joints_add_no_layer_behind_transparent_hair(renderer, deg):
    # A ray through a joint crosses the shared plane inside the strand: no surface there, so
    # a half-transparent strand composites exactly the layers the solid reference counts
    # (one per entry into the tube).
    s, u2 = _bent(deg, alpha=0.5)
    eye = np.array([0.2, 1.0, 0.3])
    cam = Camera.look_at(2.0 * eye / np.linalg.norm(eye), (0, 0, 0), up=(0, 0, 1), fov_deg=10, size=(48, 48))
    settings = RenderSettings(shading="kajiya-kay", shadows=False, layers=6, background=(0.1, 0.2, 0.3, 1.0))
    sol = assert_references_agree(s, cam, settings)
    img, _ = assert_matches_reference(renderer, s, cam, settings)
    assert np.abs(img - sol).max(axis=-1).mean() < 1e-3

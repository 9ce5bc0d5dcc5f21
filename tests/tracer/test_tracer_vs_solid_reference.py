# SPDX-License-Identifier: GPL-3.0-or-later
"""The GPU tracer over whole images against the float64 reference written from the solids
(tracer.reference_solid), which shares no code with the shader's hit test: coverage IoU over
the union of both masks and RMSE over those hair pixels (benchmarks.metrics, the report's own
measure), with the bounds of test_tracer_vs_reference (float32 against float64)."""
import numpy as np
import pytest

from hairio import InputError
from tracer import Camera, Light, RenderSettings, reference_render
from tracer.reference_solid import cut_cylinders, solid_render, strand_entries

from benchmarks.metrics import image_error
from tracer_scenes import curls, make_strands


def _assert_whole_image_matches(img, sol):
    e = image_error(img, sol, coverage_alpha=1e-6)
    assert e["hair_pixels"] > 500, "too little hair in view: the test would prove nothing"
    assert e["nonfinite"] == 0
    assert e["iou"] >= 0.99, e
    assert e["rmse_hair"] < 2e-2 and e["bad_pixels"] <= 0.01 * e["hair_pixels"], e


SCENES = {
    "curls, hard shadows, Phong": (
        lambda: curls(30, 12, radius=0.02),
        Camera.look_at((1.2, -1.8, 1.2), (0, 0, 0.5), fov_deg=40, size=(80, 80)),
        RenderSettings(shading="phong", shadows=True, lights=(Light("point", (1.5, -1.0, 2.0)),))),
    "transparent curls, 4 layers, transmittance, two lights, 4 spp": (
        lambda: curls(14, 10, alpha=0.7),
        Camera.look_at((1.2, -1.8, 1.2), (0, 0, 0.5), fov_deg=40, size=(64, 64)),
        RenderSettings(shadows=True, shadow_mode="transmittance", layers=4, spp=4,
                       lights=(Light("directional", (0.2, 0.5, -1)), Light("point", (-1, -1, 2), intensity=0.5)))),
    "curls, Chiang, a point light falling off with distance": (
        lambda: curls(24, 12, radius=0.015),
        Camera.look_at((1.2, -1.8, 1.2), (0, 0, 0.5), fov_deg=40, size=(72, 72)),
        RenderSettings(shadows=True, lights=(Light("point", (0.8, -0.9, 1.3), intensity=2.0, falloff=True),))),
    "curls, Chiang, a spot light's edge and an area light that nothing shadows": (
        lambda: curls(24, 12, radius=0.015),
        Camera.look_at((1.2, -1.8, 1.2), (0, 0, 0.5), fov_deg=40, size=(72, 72)),
        RenderSettings(shadows=True, lights=(
            Light("spot", (0.6, -1.0, 1.6), intensity=3.0, axis=(-0.3, 0.9, -0.9), spot_size=0.5, spot_blend=0.5),
            Light("area", (-0.8, -0.6, 1.2), intensity=1.5, axis=(0.6, 0.5, -0.6), shadows=False)))),
    "curls, lights with an extent (a sun 3° wide, a sphere, a rectangle, an environment), 4 spp": (
        lambda: curls(24, 12, radius=0.015),
        Camera.look_at((1.2, -1.8, 1.2), (0, 0, 0.5), fov_deg=40, size=(64, 64)),
        RenderSettings(shadows=True, spp=4, lights=(
            Light("directional", (0.2, 0.5, -1.0), intensity=2.0, angle=np.radians(3.0)),
            Light("point", (0.8, -0.9, 1.3), intensity=1.0, falloff=True, radius=0.3),
            Light("area", (-0.8, -0.6, 1.4), intensity=1.5, axis=(0.6, 0.5, -0.7), tangent=(1.0, 0.0, 0.0),
                  size=(0.8, 0.5)),
            Light("environment", intensity=4 * np.pi * 0.1)))),
    "orthographic, Kajiya-Kay": (
        lambda: curls(20, 10, radius=0.01),
        Camera.look_at((0, -3, 0.5), (0, 0, 0.5), fov_deg=30, size=(72, 72), type="ORTHO", ortho_scale=1.1),
        RenderSettings(shadows=True)),
}


@pytest.mark.parametrize("name", sorted(SCENES))
def test_gpu_matches_the_solid_reference_over_the_whole_image(renderer, name):
    make, cam, settings = SCENES[name]
    s = make()
    renderer.set_strands(s)
    img = renderer.render(cam, settings).astype(np.float64)
    sol = solid_render(s, cam, settings)
    _assert_whole_image_matches(img, sol)
    # And the two references, both float64, agree to rounding.
    ref = reference_render(s, cam, settings)
    assert image_error(ref, sol, coverage_alpha=1e-6)["bad_pixels"] == 0


def test_a_ray_through_a_joint_enters_the_strand_once():
    s = make_strands([[[0, 0, -1], [0, 0, 0], [0.5, 0, 0.8]]], radius=0.05)
    cyl = cut_cylinders(s)
    o = np.array([[-2.0, 0.0, 0.01]])                     # across the joint, inside both sections
    ray, cid, t, surf = strand_entries(cyl, o, np.array([[1.0, 0.0, 0.0]]), np.zeros(1))
    assert len(ray) == 1 and surf[0] == 0 and t[0] == pytest.approx(2.0 - 0.05, abs=1e-3)


def test_the_solid_reference_refuses_widened_strands():
    with pytest.raises(InputError, match="min_pixel_width"):
        solid_render(curls(2, 4), Camera.look_at((0, -2, 0.5), (0, 0, 0.5), size=(8, 8)),
                     RenderSettings(min_pixel_width=True))

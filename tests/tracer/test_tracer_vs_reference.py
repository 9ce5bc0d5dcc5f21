# SPDX-License-Identifier: GPL-3.0-or-later
"""The GPU tracer (float32) against the float64 reference of the same model.

Bounds, and why: float32 carries 24 bits, so hit distances and points are off by about
1e-7 relative to the scene size; shading is smooth in them, giving colour errors near 1e-5
(what we measure). A pixel whose ray passes within that rounding of a silhouette, a cut
plane or a shadow edge may flip outright; such pixels lie on a boundary and are rare. So:
coverage may differ only on the reference mask's one-pixel boundary and on at most 1 % of
pixels; colour must agree within 2e-3 on at least 99 % of pixels, RMSE below 2e-3."""
import numpy as np
import pytest

from tracer import Camera, Light, Renderer, RenderSettings, reference_render

from tracer_scenes import curls, make_strands


def _boundary(mask):
    pad = np.pad(mask, 1, mode="edge")
    shifted = [pad[1 + dy:pad.shape[0] - 1 + dy, 1 + dx:pad.shape[1] - 1 + dx]
               for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
    return np.any(shifted, axis=0) & ~np.all(shifted, axis=0)


def assert_matches_reference(renderer, strands, camera, settings):
    renderer.set_strands(strands)
    img = renderer.render(camera, settings).astype(np.float64)
    ref = reference_render(strands, camera, settings)
    assert np.all(np.isfinite(img))
    cov_g, cov_r = img[..., 3] > 1e-6, ref[..., 3] > 1e-6
    assert cov_r.any(), "scene not in view: the test would prove nothing"
    differ = cov_g != cov_r
    assert differ.mean() <= 0.01
    assert np.all(_boundary(cov_r)[differ]), "coverage differs away from a silhouette"
    err = np.abs(img - ref).max(axis=-1)
    assert np.mean(err > 2e-3) <= 0.01, f"max err {err.max():.3g}"
    assert np.sqrt(np.mean((img - ref) ** 2)) < 2e-3
    return img, ref


DIRS = [(0, -1, 0), (1, -1, 0.3), (0.2, 0.1, 1), (0.02, 0.0, 1.0), (-1, 0.3, -0.5), (1, 1, 1), (0, 0.001, -1)]


@pytest.mark.parametrize("direction", DIRS)
def test_single_cylinder_from_many_angles(renderer, direction):
    s = make_strands([[[0, 0, -0.5], [0.05, 0, 0.5]]], radius=0.08)
    d = np.asarray(direction, float)
    cam = Camera.look_at(-2.5 * d / np.linalg.norm(d), (0, 0, 0), up=(0, 1, 0) if abs(d[2]) > 0.9 else (0, 0, 1),
                         fov_deg=40, size=(40, 40))
    assert_matches_reference(renderer, s, cam, RenderSettings(shading="phong", shadows=False))


def test_bends_and_hairpins_with_hard_shadows(renderer):
    lines = [
        [[0, 0, 0], [0, 0, 0.4], [0.3, 0, 0.6], [0.3, 0, 0.2]],            # 90° + hairpin-ish
        [[-0.4, 0.1, 0], [-0.4, 0.1, 0.5], [-0.38, 0.1, 0.0]],             # hairpin
        [[0.2, -0.2, -0.2], [0.1, 0.0, 0.1], [0.25, 0.1, 0.3], [0.0, 0.2, 0.5], [0.2, 0.2, 0.7]],
    ]
    s = make_strands(lines, radius=0.04)
    cam = Camera.look_at((0.5, -2, 0.8), (0, 0, 0.3), fov_deg=45, size=(48, 48))
    settings = RenderSettings(shading="phong", shadows=True, lights=(Light("point", (1.5, -1.0, 2.0)),))
    assert_matches_reference(renderer, s, cam, settings)


def test_tapered_tips_kajiya_kay(renderer):
    t = np.linspace(0, 1, 9)
    lines = [np.stack([0.1 * k + 0.05 * np.sin(7 * t), 0.03 * np.cos(5 * t), t], 1) for k in range(-3, 4)]
    radius = np.tile(0.03 * (1 - t) + 1e-4, 7)
    s = make_strands(lines, radius=radius)
    cam = Camera.look_at((0.3, -2, 0.5), (0, 0, 0.5), fov_deg=40, size=(48, 48))
    assert_matches_reference(renderer, s, cam, RenderSettings(shading="kajiya-kay", shadows=True))


def test_alpha_stack_with_transmittance_shadows(renderer):
    lines = [[[x, y, -0.5], [x + 0.05, y, 0.5]] for y in np.linspace(-0.5, 0.5, 6) for x in (-0.1, 0.1)]
    s = make_strands(lines, radius=0.06, alpha=0.45)
    cam = Camera.look_at((0.2, -2.5, 0.2), (0, 0, 0), fov_deg=35, size=(48, 48))
    settings = RenderSettings(layers=6, shadows=True, shadow_mode="transmittance",
                              lights=(Light("directional", (0.3, 1.0, -0.4)),), background=(0.1, 0.2, 0.3, 1.0))
    img, _ = assert_matches_reference(renderer, s, cam, settings)
    one = renderer.render(cam, RenderSettings(**{**settings.__dict__, "layers": 1}))
    assert np.abs(one - img).max() > 0.02, "layers behind the first changed nothing"


def test_supersampling_min_pixel_width_and_orthographic(renderer):
    s = curls(10, 8, radius=0.002)
    cam = Camera.look_at((0, -3, 0.5), (0, 0, 0.5), fov_deg=30, size=(40, 40), type="ORTHO", ortho_scale=1.3)
    settings = RenderSettings(spp=4, min_pixel_width=True, shadows=True, layers=3)
    assert_matches_reference(renderer, s, cam, settings)


def test_curls_perspective_with_two_lights(renderer):
    s = curls(14, 10, alpha=0.7)
    cam = Camera.look_at((1.2, -1.8, 1.2), (0, 0, 0.5), fov_deg=40, size=(48, 48))
    settings = RenderSettings(shadows=True, layers=4, spp=4,
                              lights=(Light("directional", (0.2, 0.5, -1)), Light("point", (-1, -1, 2), intensity=0.5)))
    assert_matches_reference(renderer, s, cam, settings)


def test_empty_blocks_between_tufts_are_skipped_without_losing_hits(grid_renderer):
    # Two tufts far apart: the grid between them is empty blocks the DDA jumps over.
    a, b = curls(12, 8, seed=1, radius=0.01), curls(12, 8, seed=2, radius=0.01)
    from hairio import Strands
    pts = np.concatenate([a.points, b.points + [2.0, 1.5, 0.7]])
    s = Strands.from_arrays(pts, np.concatenate([a.counts, b.counts]), radius=np.full(len(pts), 0.01))
    grid_renderer.set_strands(s)
    from tracer.scene_grid import block_occupancy
    assert block_occupancy(grid_renderer.grid).mean() < 0.5
    cam = Camera.look_at((-1.5, -2.0, -0.2), (1.0, 0.75, 0.85), fov_deg=60, size=(48, 48))
    settings = RenderSettings(shadows=True, lights=(Light("directional", (1.0, 0.8, 0.2)),))
    assert_matches_reference(grid_renderer, s, cam, settings)


@pytest.mark.parametrize("shadows", [False, True])
def test_many_samples_with_layers_and_shadows(renderer, shadows):
    # 64 samples x 8 layers x shadow rays in one pixel: once ran past llvmpipe's cap on loop
    # iterations per shader invocation, which silently dropped hits (alpha 0.09 vs 0.14).
    s = curls(n_strands=20, alpha=0.3, radius=0.03)
    cam = Camera.look_at((0.3, -2, 0.5), (0, 0, 0.5), fov_deg=40, size=(8, 8))
    settings = RenderSettings(spp=64, layers=8, shadows=shadows, shadow_mode="transmittance",
                              min_pixel_width=True)   # its wider grid lists more cylinders per cell
    img, ref = assert_matches_reference(Renderer(), s, cam, settings)
    assert abs(img[..., 3].mean() - ref[..., 3].mean()) < 1e-5

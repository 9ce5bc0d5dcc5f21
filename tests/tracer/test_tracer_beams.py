# SPDX-License-Identifier: GPL-3.0-or-later
"""Beams (Renderer(accel="beams"), tracer/beams.py): the camera's and the suns' binned lists
give the grid's image, every cylinder a ray of a bin can meet is in the bin's list no later
than its depth allows, the compute passes list what numpy lists, and where beams cannot serve
a family of rays (a camera among the hair, lists past their budget, a light among the hair) those
rays walk the grid and the image does not change. A camera move uploads nothing. Point, spot
and area lights get beams from their position (a frame of perspective bins), widened for the
rays' ends spread over the light."""
from dataclasses import replace

import numpy as np
import pytest

from tracer import Camera, Light, Renderer, RenderSettings, strands_to_cylinders
from tracer import layout
from tracer.beams import (BeamsUnfit, TooManyRefs, build_beams, camera_frame, capsule_far, fine_bits, frame_reach,
                          light_frame, project, sun_frame)
from tracer.gpu_build import compute_available
from tracer.gl_state import shared_context
from tracer.scene_beams import CAMERA_BUFFERS, SUN_BUFFERS, beam_scene_box, read_beams

from test_tracer_accel import CAM, CASES as ACCEL_CASES, _render_both
from test_tracer_grid import _surface_samples
from test_tracer_vs_reference import assert_matches_reference
from tracer_scenes import curls, dense_tuft, uv_sphere

pytestmark = pytest.mark.skipif(not compute_available(shared_context()),
                                reason="beams are built by compute shaders (OpenGL 4.3); the grid serves without")

# The BVH's cases (the same scenes, settings and camera), and a second sun, one with an angle.
CASES = dict(ACCEL_CASES, **{
    "two suns, one with an angle, chiang": (curls(30, 10, alpha=0.8), RenderSettings(
        spp=4, layers=2, lights=(Light(vector=(0.3, 0.2, -1.0)), Light(vector=(-0.5, 0.4, -0.6), angle=0.2,
                                                                          intensity=0.7))))})


@pytest.fixture(scope="module")
def pair():
    """(grid renderer, beams renderer), both built by the compute passes."""
    return Renderer(build="gpu", accel="grid"), Renderer(build="gpu", accel="beams")


@pytest.mark.parametrize("case", list(CASES))
def test_beams_give_the_grids_image(pair, case):
    strands, settings = CASES[case]
    grid, beams = _render_both(pair, strands, CAM, settings)
    assert (grid[..., 3] > 0).mean() > 0.05, "scene not in view: the test would prove nothing"
    # One independent sample a pixel: lists for the pixels' centres; more: whole bins.
    want = "pixel centres" if settings.spp == 1 and settings.sampler == "independent" else "1 px bins"
    assert pair[1].stats.camera_beams == want
    assert np.abs(grid - beams).max() <= 1e-6


def _fill(monkeypatch, how):
    """Makes the compute passes fill every family's lists `how` ("by fine slice": a dispatch
    each, "sorted": in id order, then sorted; tracer/beams.py, fill_plan) in their finest
    order; returns the list of the sorted fills' sub bits, one a sorted fill."""
    from tracer.gpu_beams import BeamBuilder
    if how == "sorted":
        monkeypatch.setattr(layout, "BEAM_SORT_REFS_PER_CYLINDER", 1e9)
        monkeypatch.setattr(layout, "BEAM_SORT_REFS_PER_MARKED", 1e9)
        monkeypatch.setattr(layout, "BEAM_SORT_SLICES_PER_ENTRY", 1e9)
    else:
        monkeypatch.setattr(layout, "BEAM_SORT_REFS_PER_CYLINDER", 0.0)
        monkeypatch.setattr(layout, "BEAM_SORT_REFS_PER_MARKED", 0.0)
        monkeypatch.setattr(layout, "BEAM_REFS_PER_FILL", 1)
    sorted_subs = []
    real = BeamBuilder._sorted_fill

    def spy(self, frame, n, tex_cyl, pad_factor, sub, *rest):
        sorted_subs.append(sub)
        return real(self, frame, n, tex_cyl, pad_factor, sub, *rest)
    monkeypatch.setattr(BeamBuilder, "_sorted_fill", spy)
    return sorted_subs


@pytest.mark.parametrize("how", ["by fine slice", "sorted"])
@pytest.mark.parametrize("case", ["alpha layers, transmittance", "two suns, one with an angle, chiang"])
def test_fine_slices_give_the_grids_image(pair, case, how, monkeypatch):
    """Lists in their finest order (a fill dispatch for every fine slice however few the
    references, or as many fine slices as a sort takes) stop their walks sooner and find the
    same."""
    sorted_subs = _fill(monkeypatch, how)
    strands, settings = CASES[case]
    grid, beams = _render_both(pair, strands, CAM, settings)
    state = pair[1].beam_state
    top = layout.beam_sub_bits(pair[1].num_cylinders)
    assert top == layout.BEAM_SUB_BITS_MAX
    finest = top if how == "by fine slice" else layout.BEAM_SORT_SUB_BITS_MAX
    suns = [s[1] for s in state.suns if s is not None and s[1] is not None]
    assert suns and all(b.sub == finest for b in suns + [state.camera])
    # Every family filled the way asked: the sorted fill takes the camera's whole bins and
    # the suns' lists (most cylinders listed), never the pixel centres' few.
    assert len(sorted_subs) == (0 if how == "by fine slice" else len(suns) + 1)
    assert (grid[..., 3] > 0).mean() > 0.05
    assert np.abs(grid - beams).max() <= 1e-6


@pytest.mark.parametrize("family", ["sun", "camera"])
def test_rays_test_fully_only_the_cylinders_whose_capsule_holds_their_point(pair, family, monkeypatch):
    """A shadow ray toward a sun, and an independent sample's camera ray in a bin of whole
    pixels, test a listed cylinder fully only where the ray's point lies within the
    cylinder's capsule in its bin, as the entry's mark codes it (scene_beams.SUN_BUFFERS,
    CAMERA_BUFFERS; shaders/accel_beams.glsl, beam_mark_holds): a share of the full tests
    they make when every mark lets its entry through, and the same image, the grid's."""
    from tracer import shader_source
    # The sun's at one sample (the camera's lists then for the pixels' centres: few tests),
    # the camera's at four with shadows off (and hair its beams serve at four samples), so
    # that the family's rays make most tests.
    if family == "sun":
        strands, cam, settings = dense_tuft(), DENSE_CAM, RenderSettings(layers=3, count=True)
    else:
        strands, cam = curls(200, 10, radius=0.003, alpha=0.8, seed=4), CAM
        settings = RenderSettings(layers=3, spp=4, count=True, shadows=False)
    _render_both(pair, strands, cam, settings)     # (a sun's beams may wait for a second render)
    grid, beams = (r.render(cam, settings) for r in pair)
    assert (grid[..., 3] > 0).mean() > 0.1
    state = pair[1].beam_state
    kept = state.suns[0][1] if family == "sun" else state.camera
    assert kept is not None and kept.reach is not None      # the family's rays walked its marked lists
    assert family == "camera" or pair[1].stats.shadow_rays > 500
    tests = pair[1].stats.cylinder_tests
    # The same walks with marks that hold every point (a new renderer compiles its programs).
    real = shader_source.load_shader
    head = "bool beam_mark_holds(vec2 l, uint m, float reach) {\n"

    def every_entry(name):
        text = real(name)
        if name == "accel_beams.glsl":
            assert text.count(head) == 1
            text = text.replace(head, head + "    if (true) return true;\n")
        return text
    monkeypatch.setattr(shader_source, "load_shader", every_entry)
    r = Renderer(build="gpu", accel="beams")
    r.set_strands(strands)
    every = [r.render(cam, settings) for _ in range(2)][1]
    assert tests < 0.5 * r.stats.cylinder_tests
    np.testing.assert_array_equal(every, beams)
    assert np.abs(grid - beams).max() <= 1e-6


# Lights whose shadow rays share neither a direction nor an end: beams from their position.
LIGHTS = {
    "point": Light("point", (1.0, -1.0, 2.0), intensity=0.5),
    "point with a radius": Light("point", (-1.2, 0.4, 2.2), intensity=3.0, falloff=True, radius=0.06),
    "spot with a radius": Light("spot", (0.9, 1.1, 2.4), intensity=4.0, axis=(-0.3, -0.4, -1.0),
                                spot_size=1.2, spot_blend=0.3, radius=0.04),
    "area": Light("area", (1.4, -0.6, 1.9), intensity=3.0, axis=(-0.6, 0.3, -0.7), size=(0.12, 0.06),
                  tangent=(0.0, 1.0, 0.0)),
    "environment": Light("environment", intensity=1.0),
}


@pytest.mark.parametrize("light", list(LIGHTS))
@pytest.mark.parametrize("spp", [1, 4])
def test_a_lights_beams_give_the_grids_image(pair, light, spp):
    """A point, spot or area light's shadow rays take beams from its position, soft shadows
    (points drawn over its extent) too; an environment's walk the grid."""
    strands = curls(30, 10, alpha=0.6)
    settings = RenderSettings(spp=spp, layers=3, shading="chiang", lights=(LIGHTS[light],))
    grid, beams = _render_both(pair, strands, CAM, settings)
    assert (grid[..., 3] > 0).mean() > 0.05
    lit = grid[..., :3][grid[..., 3] > 0]
    assert lit.max() > 2 * np.percentile(lit, 10), "no light and shadow to tell apart"
    assert (pair[1].scene.grid is None) == (light != "environment")
    assert np.abs(grid - beams).max() <= 1e-6


@pytest.mark.parametrize("lights, sampler, spp", [(4, "independent", 1), (5, "independent", 1), (4, "pixel", 4)])
def test_four_lights_take_beams_and_a_fifth_walks_the_grid(pair, lights, sampler, spp):
    """Three-point lighting and one more: a sun and a point, spot and area light each cast
    their shadow rays through beams of their own (four slots), with the grid's image and no
    grid built, for either sampler; a fifth light walks the grid."""
    from tracer.scene_beams import MAX_SUN_BEAMS
    strands = curls(30, 10, alpha=0.6)
    chosen = (Light(vector=(0.3, 0.2, -1.0), intensity=0.5), LIGHTS["point"], LIGHTS["spot with a radius"],
              LIGHTS["area"], Light("point", (-1.0, 1.2, 1.8), intensity=0.4))[:lights]
    settings = RenderSettings(spp=spp, sampler=sampler, layers=3, lights=chosen)
    if sampler == "pixel":          # with a mesh too: its points' shadow rays take the same beams
        for r in pair:
            r.set_meshes([(*uv_sphere((0.3, -0.4, 0.5), 0.25), (0.6, 0.5, 0.4))])
    try:
        grid, beams = _render_both(pair, strands, CAM, settings)
    finally:
        for r in pair:
            r.set_meshes(None)
    assert MAX_SUN_BEAMS == 4
    assert all(s is not None and s[1] is not None for s in pair[1].beam_state.suns)
    assert (pair[1].scene.grid is None) == (lights <= MAX_SUN_BEAMS)
    lit = grid[..., :3][grid[..., 3] > 0]
    assert lit.max() > 2 * np.percentile(lit, 10), "no light and shadow to tell apart"
    assert np.abs(grid - beams).max() <= 1e-6


def test_sun_slots_fit_the_drivers_texture_units(pair):
    """Each sun slot takes two texture units after every other buffer's: a driver of 32 (llvmpipe,
    desktop GPUs) holds all four, one of 16 none (their lights walk the grid, rather than
    bind a buffer past the driver's units); the renderer asks its own driver."""
    from tracer.draw import sun_slots_within
    from tracer.scene_beams import sun_slots
    assert sun_slots_within(32) == 4 and sun_slots_within(18) == 1 and sun_slots_within(16) == 0
    settings = RenderSettings(lights=(Light(), LIGHTS["point"], Light("environment"), LIGHTS["area"]))
    assert sun_slots(settings) == [0, 1, -1, 2]
    assert sun_slots(settings, usable=1) == [0, -1, -1, -1]
    assert sun_slots(RenderSettings(shadows=False, lights=settings.lights)) == [-1] * 4


def test_a_driver_of_fewer_texture_units_leaves_the_lights_past_them_to_the_grid(pair, monkeypatch):
    """The renderer reads its driver's units: told 18 (room for one sun slot), the second of
    two lights walks the grid, and the image is the grid's."""
    strands = curls(30, 10, alpha=0.6)
    settings = RenderSettings(spp=1, layers=3, lights=(Light(vector=(0.3, 0.2, -1.0)), LIGHTS["point"]))
    monkeypatch.setitem(pair[1].ctx.info, "GL_MAX_TEXTURE_IMAGE_UNITS", 18)
    grid, beams = _render_both(pair, strands, CAM, settings)
    assert pair[1].beam_state.suns[0][1] is not None and pair[1].beam_state.suns[1] is None
    assert pair[1].scene.grid is not None
    assert np.abs(grid - beams).max() <= 1e-6


@pytest.mark.parametrize("where", ["a light far away", "hair far from the origin under a sun"])
def test_a_far_light_or_far_hair_keeps_its_bins(pair, where):
    """A shadow ray looks its bin up from its offset to a point amid the hair, in float32,
    whose frame coordinates come from the host (tracer/beams.py, anchored): a light some
    40,000 times the hair's size away loses no bins (measured from the light's position, as
    before, some did), and hair thousands of units from the world's origin under a sun keeps
    the grid's image too."""
    strands = curls(30, 10, alpha=0.6)
    camera = CAM
    if where == "a light far away":
        light = Light("point", tuple(np.array([0.0, 0.0, 0.5]) + 5e4 * np.array([0.4, -0.5, 0.76])), intensity=1.0)
    else:
        shift = np.array([3000.0, -2000.0, 1500.0])
        strands = replace(strands, points=strands.points + shift.astype(strands.points.dtype))
        camera = Camera.look_at(tuple(np.array([1.8, -1.6, 0.9]) + shift), tuple(np.array([0, 0, 0.5]) + shift),
                                fov_deg=40, size=(64, 64))
        light = Light(vector=(0.3, 0.2, -1.0))
    settings = RenderSettings(spp=1, layers=3, lights=(light,))
    grid, beams = _render_both(pair, strands, camera, settings)
    assert (grid[..., 3] > 0).mean() > 0.05
    assert pair[1].scene.grid is None and pair[1].beam_state.suns[0][1] is not None
    assert np.abs(grid - beams).max() <= 1e-6


def test_shadow_walks_past_the_loop_steps_leave_the_longest_lists_to_the_grid():
    from types import SimpleNamespace
    from tracer.renderer import shadow_walks, within_walk_steps
    suns = [SimpleNamespace(longest=3000), SimpleNamespace(longest=9000)]
    steps = layout.BEAM_WALK_STEPS
    # Four walks of each (four layers): 4 · 12,000 · (1 + 1/32) steps, more than 48,000.
    assert within_walk_steps([0, 1, -1], suns, 4) == [0, -1, -1]
    assert within_walk_steps([0, 1], suns, 1) == [0, 1]
    assert within_walk_steps([1, 0], suns, steps // 3000) == [-1, -1]
    assert within_walk_steps([-1, -1], suns, 100) == [-1, -1]
    # A sample casts a shadow ray a layer, one more from a mesh behind; the pixel sampler one
    # for each strand it shades and one more.
    assert shadow_walks(RenderSettings(layers=4), 4) == 4
    assert shadow_walks(RenderSettings(layers=4), 4, meshes=True) == 5
    pixel = RenderSettings(spp=16, layers=4, sampler="pixel")
    assert shadow_walks(pixel, 4) == layout.PIXEL_SHADE + 1 and shadow_walks(pixel, 1) == 2


def test_a_lights_lists_longer_than_the_walks_may_take_walk_the_grid(pair, monkeypatch):
    """The same image where a light's lists would take a sample's walks past the steps llvmpipe
    allows an invocation (renderer.within_walk_steps): its shadow rays walk the grid."""
    strands = curls(30, 10, alpha=0.6)
    settings = RenderSettings(spp=1, layers=3, lights=(LIGHTS["point with a radius"],))
    grid, _ = _render_both(pair, strands, CAM, settings)
    beams = pair[1]
    assert beams.scene.grid is None
    longest = beams.beam_state.suns[0][1].longest
    assert longest > 0
    monkeypatch.setattr(layout, "BEAM_WALK_STEPS", 3 * longest)        # less than three walks and their runs
    beams.set_strands(strands)
    img = beams.render(CAM, settings)
    assert beams.scene.grid is not None and beams.beam_state.suns[0][1] is not None   # kept, not walked
    assert np.abs(grid - img).max() <= 1e-6


@pytest.mark.parametrize("where", ["among the hair", "wide beside it"])
def test_a_light_among_the_hair_or_wide_walks_the_grid(pair, where):
    """A light whose box of hair reaches its plane cannot be projected; one so wide beside the
    hair that its bins would be many times coarser than a point's (scene_beams,
    LIGHT_MAX_COARSENING) would make long lists: their shadow rays walk the grid."""
    strands = curls(30, 10, alpha=0.6)
    inside = (Light("point", (0.0, 0.0, 0.5), intensity=0.3) if where == "among the hair" else
              Light("point", (-1.2, 0.4, 2.2), intensity=3.0, falloff=True, radius=0.6))
    settings = RenderSettings(spp=1, layers=3, lights=(Light(), inside))
    grid, beams = _render_both(pair, strands, CAM, settings)
    assert pair[1].scene.grid is not None           # built for the point light's shadow rays
    assert pair[1].beam_state.suns[0][1] is not None and pair[1].beam_state.suns[1][1] is None
    assert np.abs(grid - beams).max() <= 1e-6
    strands, settings = CASES["opaque, hard shadows"]
    _render_both(pair, strands, CAM, settings)
    assert pair[1].scene.grid is None               # a sun alone: no ray walks the grid


@pytest.mark.parametrize("spp, lists", [(1, "pixel centres"), (4, "1 px bins")])
def test_orthographic_camera_from_below(pair, spp, lists):
    cam = Camera.look_at((0.1, 0.05, -2.0), (0, 0, 0.5), fov_deg=30, size=(48, 48), type="ORTHO", ortho_scale=1.4)
    grid, beams = _render_both(pair, curls(20, 8, alpha=0.7), cam, RenderSettings(layers=2, spp=spp))
    assert (grid[..., 3] > 0).mean() > 0.05 and pair[1].stats.camera_beams == lists
    assert np.abs(grid - beams).max() <= 1e-6


def test_beams_match_the_float64_reference():
    r = Renderer(build="gpu", accel="beams")
    assert_matches_reference(r, curls(25, 10, alpha=0.6), CAM, RenderSettings(layers=4, shadow_mode="transmittance"))


def test_a_window_of_the_image_is_the_whole_images_pixels(pair):
    r = pair[1]
    r.set_strands(curls(30, 10, alpha=0.6))
    settings = RenderSettings(layers=3, spp=4)
    whole = r.render(CAM, settings)
    part = r.render(CAM.window(10, 20, 40, 30), settings)
    np.testing.assert_array_equal(part, whole[20:50, 10:50])


def test_meshes_hide_hair_and_take_its_shadows(pair):
    strands = curls(30, 10, alpha=0.7)
    sphere = uv_sphere((0.3, -0.4, 0.5), 0.25)
    for r in pair:
        r.set_meshes([(*sphere, (0.6, 0.5, 0.4))])
    try:
        grid, beams = _render_both(pair, strands, CAM, RenderSettings(layers=3, spp=4))
        pix_grid, pix_beams = _render_both(pair, strands, CAM, RenderSettings(layers=3, spp=4, sampler="pixel"))
    finally:
        for r in pair:
            r.set_meshes(None)
    assert (grid[..., 3] == 1).mean() > 0.05
    assert np.abs(grid - beams).max() <= 1e-6
    assert abs(pix_grid[..., :3].mean() - pix_beams[..., :3].mean()) < 0.01 * pix_grid[..., :3].mean()


def test_a_camera_among_the_hair_walks_the_grid(pair):
    strands = curls(40, 10)
    inside = Camera.look_at((0.0, 0.0, 0.5), (0.5, -0.5, 0.5), fov_deg=70, size=(48, 48))
    grid, beams = _render_both(pair, strands, inside, RenderSettings())
    assert "camera's plane" in pair[1].stats.camera_beams
    assert (grid[..., 3] > 0).mean() > 0.05
    assert np.abs(grid - beams).max() <= 1e-6


def test_lists_past_their_budget_take_coarser_bins_then_the_grid(pair, monkeypatch):
    strands, one = CASES["alpha layers, transmittance"]
    settings = RenderSettings(layers=one.layers, shadow_mode=one.shadow_mode, spp=4)   # whole bins
    want = _render_both(pair, strands, CAM, settings)[0]
    one_px = pair[1].beam_state.camera.refs
    monkeypatch.setattr(layout, "BEAM_MAX_REFS", int(one_px * 0.8))
    r = Renderer(build="gpu", accel="beams")
    r.set_strands(strands)
    np.testing.assert_allclose(r.render(CAM, settings), want, atol=1e-6)
    assert r.stats.camera_beams in ("2 px bins", "4 px bins")
    monkeypatch.setattr(layout, "BEAM_MAX_REFS", 10)
    r = Renderer(build="gpu", accel="beams")
    r.set_strands(strands)
    np.testing.assert_allclose(r.render(CAM, settings), want, atol=1e-6)
    assert r.stats.camera_beams.startswith("none") and r.scene.grid is not None


def test_camera_moves_upload_nothing_and_a_kept_camera_builds_nothing(pair):
    r = pair[1]
    strands = curls(200, 10, seed=4)
    r.set_strands(strands)
    sent = r.stats.bytes_uploaded
    first = r.render(CAM)
    assert r.stats.beams_s > 0
    moved = Camera.look_at((-1.5, -1.9, 0.4), (0, 0, 0.4), fov_deg=50, size=(64, 64))
    r.render(moved, RenderSettings(shading="phong", spp=4))
    again = r.render(CAM)
    assert r.stats.bytes_uploaded == sent
    np.testing.assert_array_equal(again, first)
    r.render(CAM)
    assert r.stats.beams_s == 0.0          # the same camera and sun: the lists are kept


@pytest.mark.parametrize("sampler, spp", [("independent", 1), ("pixel", 16)])
def test_the_passes_of_a_progressive_render_keep_the_first_ones_beams(pair, sampler, spp):
    """A progressive render's passes move the camera by a fraction of a pixel (Camera.for_pass):
    an independent sample looks up the bin its ray crosses, the pixel sampler its pixel's bin,
    widened once for the passes' shift; one independent sample a pixel gets lists for the
    first pass's pixel centres, and the second pass, moved, lists of whole bins. After that no
    pass builds, and every image is the one a renderer that builds beams for that pass's camera
    gives (for the independent sampler, the grid's)."""
    strands = curls(60, 10, alpha=0.7)
    settings = RenderSettings(layers=3, spp=spp, sampler=sampler)
    for r in pair:
        r.set_strands(strands)
    built = []
    for k in range(4):
        cam = CAM.for_pass(k, settings.spp_n)
        fresh = Renderer(build="gpu", accel="beams") if sampler == "pixel" else pair[0]
        fresh.set_strands(strands)
        want, beams = fresh.render(cam, settings), pair[1].render(cam, settings)
        assert (want[..., 3] > 0).mean() > 0.05
        np.testing.assert_allclose(beams, want, atol=1e-6)
        built.append(pair[1].stats.beams_s > 0)
        if k == 0:
            assert pair[1].stats.camera_beams == ("pixel centres" if sampler == "independent" else "1 px bins")
    # The pixel sampler's lists widened once; the centres' made whole bins once.
    assert built[0] and built[1] and not any(built[2:])


def test_an_edit_rebuilds_the_beams(pair):
    r = pair[1]
    strands = curls(60, 10, seed=5)
    r.set_strands(strands)
    r.render(CAM)
    pts = strands.points.copy()
    first = strands.offsets[7]
    pts[first:first + strands.counts[7]] += np.array([0.05, 0.0, 0.02], np.float32)
    edited = type(strands).from_arrays(pts, strands.counts, radius=strands.radius, color=strands.color,
                                       alpha=strands.alpha)
    r.update_strands([7], edited)
    fresh = Renderer(build="gpu", accel="beams")
    fresh.set_strands(edited)
    np.testing.assert_array_equal(r.render(CAM), fresh.render(CAM))


def test_the_sample_that_sizes_the_bins_is_made_once_for_the_renders_of_the_same_strands(pair, monkeypatch):
    """The camera's and the suns' bins are sized from an even sample of the cylinders
    (scene_beams._segments_sample): made once for the renders of the same strands (camera
    moves, a sun's fine lists after its coarse ones), again for new strands, and the images
    are a fresh renderer's."""
    from tracer import scene_beams
    made = []
    real = scene_beams._segments_sample

    def spy(plan, *a):
        made.append(plan)
        return real(plan, *a)
    monkeypatch.setattr(scene_beams, "_segments_sample", spy)
    r = pair[1]
    moved = Camera.look_at((-1.5, -1.9, 0.4), (0, 0, 0.4), fov_deg=50, size=(64, 64))
    plans = []
    for seed in (6, 7):
        strands = curls(60, 10, seed=seed)
        r.set_strands(strands)
        plans.append(r.scene.plan)
        images = [r.render(cam, RenderSettings(spp=spp)) for cam, spp in ((CAM, 1), (moved, 1), (CAM, 16))]
        assert r.stats.camera_beams == "1 px bins"          # (whole bins: the third camera build)
        assert [p for p in made if p is plans[-1]] == [plans[-1]]
        fresh = Renderer(build="gpu", accel="beams")
        fresh.set_strands(strands)
        np.testing.assert_array_equal(images[1], fresh.render(moved, RenderSettings(spp=1)))
        np.testing.assert_array_equal(images[2], fresh.render(CAM, RenderSettings(spp=16)))
    assert plans[0] is not plans[1]


def test_split_cylinder_buffers_render_as_one(pair):
    """Past the driver's limit the cylinders continue in further buffers (tracer/scene_buffers.py):
    the beams' passes and walks find them there. (A beam list itself lives in one buffer.)"""
    strands, settings = curls(300, 10), RenderSettings(shadows=False)
    cam = Camera.look_at((1.8, -1.6, 0.9), (0, 0, 0.5), fov_deg=40, size=(16, 16))
    want = _render_both(pair, strands, cam, settings)[0]
    limit = 10_000
    assert pair[1].beam_state.camera.refs < limit < pair[1].num_cylinders * layout.TEXELS_PER_CYL
    small = Renderer(build="gpu", accel="beams", max_buffer_texels=limit)
    small.set_strands(strands)
    img = small.render(cam, settings)
    assert small.buffers.parts("tex_cyl") == 2 and small.stats.camera_beams == "pixel centres"
    assert (img[..., 3] > 0).mean() > 0.05
    np.testing.assert_array_equal(img, want)


@pytest.mark.parametrize("spp", [1, 4])
def test_the_counters_see_a_bin_and_the_entries_read_a_ray(pair, spp):
    """A ray of beams counts its bin and each list entry it reads as steps (cells_visited),
    its full tests apart: every full test reads its entry first, and no ray reads more than
    its bin's whole list (the camera's lists at one sample: one ray a pixel centre's bin;
    the sun's: at most the longest list a shadow ray)."""
    r = pair[1]
    r.set_strands(curls(30, 10))
    settings = RenderSettings(count=True, spp=spp)
    r.render(CAM, settings)
    st = r.stats
    box = st.screen_box
    rays = spp * (box[2] - box[0]) * (box[3] - box[1])
    read = st.cells_visited - rays - st.shadow_rays      # one bin a camera ray and one a shadow ray
    assert st.cylinder_tests > 0 and read >= st.cylinder_tests
    cam = r.beam_state.camera
    sun = r.beam_state.suns[0][1]
    _, cam_count, _, _ = read_beams(cam, r.buffers, CAMERA_BUFFERS)
    _, sun_count, _, _ = read_beams(sun, r.buffers, SUN_BUFFERS[0])
    most = (cam_count.sum() if spp == 1 else rays * cam_count.max()) + st.shadow_rays * sun_count.max()
    assert read <= most
    grid = pair[0]
    grid.set_strands(curls(30, 10))
    grid.render(CAM, settings)
    assert st.cylinder_tests < 0.5 * grid.stats.cylinder_tests


def test_the_numpy_build_walks_the_grid():
    r = Renderer(build="numpy", accel="beams")
    assert r.accel == "grid"


# The dense tuft (tracer_scenes.dense_tuft) fills its view: over a hundred list entries a pixel.
DENSE_CAM = Camera.look_at((0.0, -1.6, 0.0), (0.0, 0.0, 0.0), fov_deg=22, size=(32, 32))
# Strands of a tuft dense past scene_beams.CENTRE_REFS_PER_RAY at one sample (about 2,000
# entries of 1-pixel bins a camera ray; the default tuft about 400).
DENSER_TUFT = 40_000


def test_one_sample_of_dense_hair_leaves_the_camera_to_the_grid(pair):
    """Rebuilt at every camera move, the camera's beams are built for a render only when its
    camera rays are many enough for the lists they would take: one sample of the dense tuft
    gets lists for the pixels' centres (up to CENTRE_REFS_PER_RAY), sixteen lists of whole
    pixels (CAMERA_REFS_PER_RAY), and one sample of a tuft five times as dense walks the grid.
    The image is the grid's every time."""
    grid, beams = _render_both(pair, dense_tuft(), DENSE_CAM, RenderSettings())
    assert pair[1].stats.camera_beams == "pixel centres"
    assert np.abs(grid - beams).max() <= 1e-6
    grid, beams = (r.render(DENSE_CAM, RenderSettings(spp=16)) for r in pair)
    assert pair[1].stats.camera_beams == "1 px bins"
    assert np.abs(grid - beams).max() <= 1e-6
    grid, beams = _render_both(pair, dense_tuft(DENSER_TUFT), DENSE_CAM, RenderSettings())
    assert pair[1].stats.camera_beams.startswith("none: about") and pair[1].scene.grid is not None
    assert np.abs(grid - beams).max() <= 1e-6


def test_a_suns_beams_wait_for_a_second_render_when_the_grid_is_built_anyway(pair):
    """One sample of the denser tuft walks the grid with its camera rays, so the grid is built
    for that render; its few shadow rays would not pay for the sun's beams, which the second
    render of the same strands builds (kept across camera moves, they serve the renders to
    come). The images are the grid's."""
    strands = dense_tuft(DENSER_TUFT)
    grid, first = _render_both(pair, strands, DENSE_CAM, RenderSettings())
    assert pair[1].scene.grid is not None and pair[1].beam_state.suns[0] is None
    moved = Camera.look_at((0.3, -1.6, 0.1), (0.0, 0.0, 0.0), fov_deg=22, size=(32, 32))
    again = pair[1].render(moved, RenderSettings())
    assert pair[1].beam_state.suns[0][1] is not None and pair[1].stats.sun_beams_s > 0
    assert np.abs(grid - first).max() <= 1e-6
    assert np.abs(pair[0].render(moved, RenderSettings()) - again).max() <= 1e-6


def _samples_for_fine_lists(state, fine):
    """Samples a pixel (a square number) that bring the rays traced to the fine lists' share
    (scene_beams.SUN_FINE_RAYS_PER_BIN of `fine`'s bins), after one render of one sample
    that traced state.traced rays."""
    from tracer import scene_beams
    return int(np.ceil(np.sqrt(scene_beams.SUN_FINE_RAYS_PER_BIN * fine.num_bins / state.traced))) ** 2


def test_a_suns_lists_are_coarse_for_few_rays_and_fine_once_the_rays_pay_for_them(pair, monkeypatch):
    """A render of few rays gets a sun's coarse lists (SUN_MIN_REFS_PER_CYLINDER references a
    cylinder: half the build), kept with the fine frame; the render that brings the rays
    traced to SUN_FINE_RAYS_PER_BIN a fine bin builds the fine lists, which later renders
    keep. The images are the grid's every time. (The rule's figure set low, so that a few
    samples bring the rays there.)"""
    from tracer import scene_beams
    monkeypatch.setattr(scene_beams, "SUN_FINE_RAYS_PER_BIN", 1.5)
    strands = dense_tuft()
    grid, first = _render_both(pair, strands, DENSE_CAM, RenderSettings())
    assert np.abs(grid - first).max() <= 1e-6
    state = pair[1].beam_state
    _, coarse, fine = state.suns[0]
    assert coarse is not None and fine is not None
    assert coarse.refs <= 0.75 * scene_beams.SUN_REFS_PER_CYLINDER * pair[1].num_cylinders
    assert state.traced < scene_beams.SUN_FINE_RAYS_PER_BIN * fine.num_bins
    spp = _samples_for_fine_lists(state, fine)
    grid, again = (r.render(DENSE_CAM, RenderSettings(spp=spp)) for r in pair)
    assert np.abs(grid - again).max() <= 1e-6
    _, rebuilt, later = state.suns[0]
    assert later is None and pair[1].stats.sun_beams_s > 0
    assert rebuilt.frame.num_bins == fine.num_bins and rebuilt.refs > 1.5 * coarse.refs
    moved = Camera.look_at((0.3, -1.6, 0.1), (0.0, 0.0, 0.0), fov_deg=22, size=(32, 32))
    grid, kept = (r.render(moved, RenderSettings()) for r in pair)
    assert pair[1].stats.sun_beams_s == 0 and state.suns[0][1] is rebuilt
    assert np.abs(grid - kept).max() <= 1e-6


def test_fine_lists_that_do_not_fit_leave_the_coarse_ones(pair, monkeypatch):
    """Where the sun's fine lists are refused (more bins than a family may have), the render
    that would build them keeps the coarse ones, whose buffers the refusal left as they were,
    and later renders do not try again. The images are the grid's."""
    from tracer import scene_beams
    monkeypatch.setattr(scene_beams, "SUN_FINE_RAYS_PER_BIN", 1.5)
    strands = dense_tuft()
    _render_both(pair, strands, DENSE_CAM, RenderSettings())
    state = pair[1].beam_state
    _, coarse, fine = state.suns[0]
    assert fine is not None and fine.num_bins > coarse.frame.num_bins
    monkeypatch.setattr(layout, "BEAM_MAX_BINS", fine.num_bins - 1)
    spp = _samples_for_fine_lists(state, fine)
    grid, kept = (r.render(DENSE_CAM, RenderSettings(spp=spp)) for r in pair)
    assert state.suns[0][1] is coarse and state.suns[0][2] is None
    assert np.abs(grid - kept).max() <= 1e-6
    grid, again = (r.render(DENSE_CAM, RenderSettings(spp=spp)) for r in pair)
    assert pair[1].stats.sun_beams_s == 0 and np.abs(grid - again).max() <= 1e-6


def test_a_render_that_says_the_samples_to_come_gets_a_suns_fine_lists_at_once(pair):
    """A first image followed by refinement passes (the preview's) says so
    (RenderSettings.samples_to_come): the sun's fine lists are built for it at once, not
    coarse ones and the fine ones later. The image is the grid's; a negative count is refused."""
    from hairio import InputError
    strands = dense_tuft()
    settings = RenderSettings(samples_to_come=1024)
    grid, first = _render_both(pair, strands, DENSE_CAM, settings)
    assert np.abs(grid - first).max() <= 1e-6
    _, beams, later = pair[1].beam_state.suns[0]
    assert beams is not None and later is None
    assert pair[1].beam_state.traced == pair[1].stats.traversed_pixels   # only the rays traced count
    with pytest.raises(InputError, match="samples_to_come"):
        RenderSettings(samples_to_come=-1).check()


def test_a_sun_of_too_many_cylinders_for_fine_bins_walks_the_grid(pair, monkeypatch):
    """Where the budget leaves a sun under SUN_MIN_REFS_PER_CYLINDER references a cylinder its
    bins would hand a shadow ray more entries than the grid's cells: its rays walk the grid."""
    from tracer import scene_beams
    strands, settings = CASES["opaque, hard shadows"]
    want = _render_both(pair, strands, CAM, settings)[0]
    n = pair[1].num_cylinders
    monkeypatch.setattr(layout, "BEAM_MAX_REFS", int(2 * n * (scene_beams.SUN_MIN_REFS_PER_CYLINDER - 1)))
    r = Renderer(build="gpu", accel="beams")
    r.set_strands(strands)
    np.testing.assert_allclose(r.render(CAM, settings), want, atol=1e-6)
    assert r.beam_state.suns[0][1] is None and r.scene.grid is not None


def test_the_pixel_sampler_on_dense_see_through_hair_keeps_every_hit():
    """The dense tuft of test_tracer_pixel_sampler.py's loop-cap test: the pixel sampler walking
    the camera's beams (four walks of four samples a pixel) has the independent sampler's
    coverage."""
    r = Renderer(build="gpu", accel="beams")
    r.set_strands(dense_tuft())
    cam = DENSE_CAM
    # 16 samples: at fewer the camera rays of so dense a tuft are left to the grid (the beams'
    # lists would hold over a hundred entries a ray: scene_beams.CAMERA_REFS_PER_RAY).
    ind = r.render(cam, RenderSettings(spp=16))
    pix = r.render(cam, RenderSettings(sampler="pixel", spp=16))
    assert r.stats.camera_beams.endswith("px bins") and ind[..., 3].mean() > 0.1
    assert abs(ind[..., 3].mean() - pix[..., 3].mean()) < 0.005
    assert np.abs(ind[..., 3] - pix[..., 3]).mean() < 0.02


# --- The lists themselves ----------------------------------------------------------------------
def _scene(strands):
    """(cylinders, scene box lo, hi, largest radius) as the renderer frames them."""
    from tracer.cylinders import plan_cylinders
    from tracer.settings import GRID_WIDEN_CAP
    plan = plan_cylinders(strands)
    lo, hi = beam_scene_box(plan, None, GRID_WIDEN_CAP)
    return strands_to_cylinders(strands), lo, hi, float(plan.radius.max())


SUN_SPREAD = np.tan(0.1)
LIGHT_AT = np.array([0.9, -1.1, 2.3])
LIGHT_EXTENT = 0.2
# A spot light there whose cone takes in part of the curls (axis and half angle).
_SPOT_AXIS = np.array([0.25, 0.1, 0.45]) - LIGHT_AT
SPOT_CONE = (*(_SPOT_AXIS / np.linalg.norm(_SPOT_AXIS)), 0.1)


def _frames(lo, hi, rmax):
    persp = camera_frame(CAM, (0, 0, 64, 64), lo, hi, rmax, 1.0)
    ortho_cam = Camera.look_at((0.1, 0.05, -2.0), (0, 0, 0.5), size=(48, 40), type="ORTHO", ortho_scale=1.4)
    ortho = camera_frame(ortho_cam, (3, 2, 45, 38), lo, hi, rmax, 1.0, bin_px=2)
    towards = np.array([-0.3, 0.5, 0.8]) / np.linalg.norm([-0.3, 0.5, 0.8])
    sun = sun_frame(towards, 0.0, lo, hi, rmax, 1.0, 0.02)
    wide_sun = sun_frame(towards, SUN_SPREAD, lo, hi, rmax, 1.0, 0.02)
    centres = camera_frame(CAM, (0, 0, 64, 64), lo, hi, rmax, 1.0, centres=True)
    light = light_frame(LIGHT_AT, 0.0, lo, hi, rmax, 1.0, 0.01)
    wide_light = light_frame(LIGHT_AT, LIGHT_EXTENT, lo, hi, rmax, 1.0, 0.03)
    spot = light_frame(LIGHT_AT, LIGHT_EXTENT, lo, hi, rmax, 1.0, 0.03, cone=SPOT_CONE)
    return {"spot": (spot, None), "perspective": (persp, CAM), "orthographic": (ortho, ortho_cam), "sun": (sun, None),
            "sun with an angle": (wide_sun, None), "pixel centres": (centres, CAM), "light": (light, None),
            "light with an extent": (wide_light, None)}


@pytest.mark.parametrize("family", ["perspective", "orthographic", "sun", "sun with an angle", "light",
                                    "light with an extent", "spot"])
def test_every_surface_point_is_listed_where_its_rays_look_it_up(family):
    """A ray that meets a point of a cylinder's surface looks up a bin that lists the cylinder
    in a fine slice starting no farther than the walk goes: a camera ray the bin of the pixel it
    goes through, up to the point's distance; a shadow ray the bin of where it leaves (below
    the point, within the sun's angle of its direction), up to minus that origin's height; a
    shadow ray toward a light (from beyond the point, toward a point of the light within its
    extent) the bin of where it leaves, up to that origin's distance from the light (or the
    extent, if more); toward a spot light, the rays it casts: those its cone lights."""
    rng = np.random.default_rng(5)
    c, lo, hi, rmax = _scene(curls(30, 12, radius=0.01))
    frame, camera = _frames(lo, hi, rmax)[family]
    beams = build_beams(frame, c)
    assert beams.refs > len(c)
    nx, ny = frame.dims
    checked = 0
    for k in rng.choice(len(c), 80, replace=False):
        q = _surface_samples(c, k, rng)
        if frame.kind == "sun":
            # Origins below q, each along a direction within the sun's angle of its own.
            w = frame.axes[2]
            spread = SUN_SPREAD if frame.drift > 0 else 0.0
            tilt = rng.normal(0, 1, (len(q), 3))
            tilt -= (tilt @ w)[:, None] * w
            tilt *= (spread * rng.uniform(0, 1, len(q)) / np.linalg.norm(tilt, axis=1))[:, None]
            d = w + tilt
            p = q - rng.uniform(0, 0.8, len(q))[:, None] * d / np.linalg.norm(d, axis=1)[:, None]
            reach = -(p @ w)
        elif camera is None:
            # Origins beyond q from a point of the light, within its extent of the position.
            ends = rng.normal(0, 1, (len(q), 3))
            ends *= (frame.extent * rng.uniform(0, 1, len(q)) ** (1 / 3) / np.linalg.norm(ends, axis=1))[:, None]
            ends += frame.origin
            p = q + rng.uniform(0, 0.8, len(q))[:, None] * (q - ends)
            # An origin deeper than the hair looks up where its ray comes back to its depth.
            z = (p - frame.origin) @ frame.axes[2]
            deep = z > frame.far_depth
            toward = ends - p
            p[deep] += ((z - frame.far_depth) / -(toward @ frame.axes[2]))[deep, None] * toward[deep]
            reach = np.maximum(np.linalg.norm(p - frame.origin, axis=1), frame.extent)
            if frame.cone is not None:      # no shadow ray where the light gives nothing
                away = p - ends
                cos = (away @ np.asarray(frame.cone[:3])) / np.linalg.norm(away, axis=1)
                reach = np.where(cos > np.cos(frame.cone[3]), reach, -np.inf)
        else:
            p = q
            reach = np.linalg.norm(q - camera.position, axis=1) if frame.kind == "persp" else project(frame, q)[2]
        gx, gy, _ = project(frame, p)
        inside = (gx >= 0) & (gx < nx) & (gy >= 0) & (gy < ny)
        bins = np.floor(gx).astype(int) + nx * np.floor(gy).astype(int)
        inside &= reach > -np.inf
        for b, limit in zip(bins[inside], reach[inside]):
            run = beams.entries[beams.start[b]:beams.start[b] + beams.count[b]]
            ids = beams.ids(run)
            assert k in ids, f"cylinder {k} missing from bin {b}"
            assert beams.starts(run[ids == k])[0] <= limit      # its fine slice starts no farther
            checked += 1
    assert checked > 500


def test_a_spots_lists_leave_out_what_lies_outside_its_cone(pair):
    """A spot light's shadow rays leave only where its cone lights (trace_main.glsl casts no
    other), so its lists leave out the capsules wholly outside the cone widened by its extent:
    fewer entries than the same light's without a cone, none of them outside, and a render
    under it gives the grid's image."""
    from tracer.beams import outside_cone
    c, lo, hi, rmax = _scene(curls(30, 12, radius=0.01))
    frames = _frames(lo, hi, rmax)
    spot, light = build_beams(frames["spot"][0], c), build_beams(frames["light with an extent"][0], c)
    out = outside_cone(SPOT_CONE, LIGHT_AT, LIGHT_EXTENT, c.top, capsule_far(c), c.radius)
    assert 0.2 < out.mean() < 0.8
    assert 0 < spot.refs < 0.8 * light.refs
    assert not np.any(out[spot.ids(spot.entries)])
    strands = curls(30, 10, alpha=0.6)
    lit = Light("spot", tuple(LIGHT_AT), intensity=6.0, axis=tuple(SPOT_CONE[:3]), spot_size=2 * SPOT_CONE[3],
                radius=LIGHT_EXTENT / 4, falloff=True)
    settings = RenderSettings(spp=1, layers=3, lights=(lit,))
    grid, beams = _render_both(pair, strands, CAM, settings)
    assert pair[1].scene.grid is None
    narrow = pair[1].beam_state.suns[0][1].refs
    assert (grid[..., 3] > 0).mean() > 0.05
    shade = grid[..., :3][grid[..., 3] > 0]
    assert shade.max() > 2 * np.percentile(shade, 10), "no light and shadow to tell apart"
    assert np.abs(grid - beams).max() <= 1e-6
    _render_both(pair, strands, CAM, replace(settings, lights=(replace(lit, spot_size=np.pi),)))
    assert narrow < 0.8 * pair[1].beam_state.suns[0][1].refs


@pytest.mark.parametrize("family", ["perspective", "orthographic", "sun", "pixel centres", "light",
                                    "light with an extent", "spot"])
def test_the_compute_passes_list_what_numpy_lists(family):
    assert _compute_vs_numpy(family) == 0       # references too few to pay for a fine slice


@pytest.mark.parametrize("how", ["by fine slice", "sorted"])
@pytest.mark.parametrize("family", ["perspective", "sun"])
def test_the_compute_passes_list_in_fine_slices_what_numpy_lists(family, how, monkeypatch):
    sorted_subs = _fill(monkeypatch, how)
    finest = layout.BEAM_SUB_BITS_MAX if how == "by fine slice" else layout.BEAM_SORT_SUB_BITS_MAX
    assert _compute_vs_numpy(family) == finest
    assert sorted_subs == ([] if how == "by fine slice" else [finest])


def _small_storage_blocks(monkeypatch, most=1 << 13, probed=False):
    """Makes the compute passes take the driver's largest storage block as `most` bytes (at
    offsets aligned to 256), so that lists past it are filled a window of bins at a time
    (tracer/gpu_beams.py, _windows), as on a driver that does not bind past it (`probed`:
    the driver's own answer, probed again); returns the list of the windows each build took."""
    from tracer import gpu_beams
    from tracer.gl_state import beam_builder
    monkeypatch.setattr(gpu_beams, "storage_limits", lambda ctx: (most, 256))
    if probed:
        monkeypatch.setattr(beam_builder(), "_past_block", None)
    else:
        monkeypatch.setattr(gpu_beams.BeamBuilder, "_binds_past_block", lambda self, buf, most: False)
    taken = []
    real = gpu_beams.BeamBuilder._windows

    def spy(self, *args):
        windows = real(self, *args)
        taken.append(windows)
        return windows
    monkeypatch.setattr(gpu_beams.BeamBuilder, "_windows", spy)
    return taken


@pytest.mark.parametrize("family, how", [("perspective", "by fine slice"), ("perspective", "sorted"),
                                         ("sun", "by fine slice"), ("sun", "sorted"),
                                         ("pixel centres", "by fine slice")])      # (never sorted: few listed)
def test_lists_past_the_drivers_storage_block_are_filled_a_window_at_a_time(family, how, monkeypatch):
    """Lists bigger than the driver's largest storage block (128 MB on llvmpipe, past which a
    buffer bound whole may be cut short) are filled and sorted a window of bins at a time,
    each bound within the block, where the driver does not bind past it: the same entries,
    fine slices and marks as numpy's."""
    sorted_subs = _fill(monkeypatch, how)
    most = 1 << 11 if family == "pixel centres" else 1 << 13     # (its lists are few and plain)
    taken = _small_storage_blocks(monkeypatch, most)
    _compute_vs_numpy(family)
    assert len(sorted_subs) == (how == "sorted")
    (windows,) = taken
    entry = 4 if family == "pixel centres" else 8
    assert len(windows) >= 3
    assert all(count * entry <= most and base * entry % 256 == 0 for _, _, base, count, _ in windows)
    bins = np.concatenate([np.arange(b0, b1) for b0, b1, *_ in windows])
    assert np.all(np.diff(bins) > 0), "each bin in one window"


@pytest.mark.parametrize("family", ["perspective", "sun"])
def test_a_driver_that_binds_past_its_storage_block_fills_the_lists_at_once(family, monkeypatch):
    """The probe (BeamBuilder._binds_past_block: a word written through a whole binding past
    the block lands) decides: one window where the driver binds past its block, as llvmpipe
    does, windows where not; numpy's lists either way."""
    from tracer.gl_state import beam_builder
    taken = _small_storage_blocks(monkeypatch, probed=True)
    _compute_vs_numpy(family)
    past, windows = beam_builder()._past_block, len(taken[0])
    assert past is not None
    assert (windows == 1) if past else (windows >= 3)
    if "llvmpipe" in shared_context().info["GL_RENDERER"]:
        assert past, "llvmpipe writes through a whole binding past its block"


def test_a_driver_that_refuses_a_whole_binding_past_its_block_gets_windows(monkeypatch):
    """Where binding the whole buffer raises a GL error, the probe touches nothing (the
    binding it would write through is still an earlier buffer's) and says no: windows."""
    from tracer.gl_state import beam_builder
    builder = beam_builder()

    class Refusing:
        """The builder's context, whose error after the probe's bind is GL_INVALID_VALUE."""
        def __init__(self, ctx):
            self._ctx, self._reads = ctx, 0

        def __getattr__(self, name):
            return getattr(self._ctx, name)

        @property
        def error(self):
            self._reads += 1
            return "GL_NO_ERROR" if self._reads == 1 else "GL_INVALID_VALUE"
    taken = _small_storage_blocks(monkeypatch, probed=True)
    monkeypatch.setattr(builder, "ctx", Refusing(builder.ctx))
    _compute_vs_numpy("sun")
    assert builder._past_block is False and len(taken[0]) >= 3


@pytest.mark.parametrize("spp", [1, 16])
def test_a_render_of_lists_past_the_storage_block_is_the_grids(pair, spp, monkeypatch):
    """A render whose sun's lists, and at 16 samples its camera's, are filled a window at a
    time gives the grid's image (the pixel centres' few lists of one sample fit one here;
    test_lists_past_the_drivers_storage_block_are_filled_a_window_at_a_time windows them)."""
    taken = _small_storage_blocks(monkeypatch)
    strands, settings = CASES["alpha layers, transmittance"]
    settings = replace(settings, spp=spp)
    grid, beams = _render_both(pair, strands, CAM, settings)
    assert [len(w) >= 2 for w in taken] == [spp > 1, True]
    assert (grid[..., 3] > 0).mean() > 0.05
    assert np.abs(grid - beams).max() <= 1e-6


def test_a_chunk_of_bins_past_the_storage_block_is_too_many_references(monkeypatch):
    """Where one chunk of bins (the scan's) holds more entries than a storage block, the lists
    cannot be bound a window at a time, nor the passes' words of the cylinders past one:
    TooManyRefs, whose camera then takes coarser bins or the grid."""
    _small_storage_blocks(monkeypatch, most=1 << 11)
    with pytest.raises(TooManyRefs, match="references in 256 bins, more than one storage block"):
        _compute_vs_numpy("perspective")
    # Nor can the passes bind their word a cylinder past it (440 cylinders: 1,760 bytes).
    _small_storage_blocks(monkeypatch, most=1 << 10)
    with pytest.raises(TooManyRefs, match="440 cylinders, more words than one storage block"):
        _compute_vs_numpy("perspective")


def test_the_fill_sorts_where_most_cylinders_are_listed_in_few_references():
    """fill_plan: the sorted fill for lists of most cylinders in few references each, with no
    more fine slices than a bin's entries; the fill a fine slice a dispatch otherwise."""
    from tracer.beams import fill_plan
    top = 3
    sizes = np.zeros(layout.BEAM_SLICES << top, np.int64)
    sizes[::3] = 10                                   # 1,710 cylinders listed
    listed = int(sizes.sum())
    per = layout.BEAM_SORT_REFS_PER_CYLINDER
    # Of 2,000 cylinders, 3.7 references a listed one: sorted; bins of 128 entries on
    # average take 128 fine slices (one bit), of fewer 64, of 512 or more the most the sort
    # keeps.
    refs = 128 * 50
    assert fill_plan(sizes, refs, 2000, 50) == (True, 1)
    assert fill_plan(sizes, refs, 2000, 51) == (True, 0)
    assert fill_plan(sizes, refs, 2000, 1) == (True, min(top, layout.BEAM_SORT_SUB_BITS_MAX))
    # More references a cylinder, or few of the cylinders listed: a fine slice a dispatch.
    assert fill_plan(sizes, int(per * listed) + 1, 2000, 1) == (False, fine_bits(sizes, int(per * listed) + 1))
    assert fill_plan(sizes, refs, 2 * listed + 1, 1) == (False, fine_bits(sizes, refs))
    assert not fill_plan(np.zeros_like(sizes), 0, 2000, 1)[0]      # nothing listed
    # Entries with marks: by their own threshold (none sorted at the shipped one).
    assert fill_plan(sizes, refs, 2000, 50, marks=True) == (False, fine_bits(sizes, refs))


def _compute_vs_numpy(family):
    """The lists of `family` built by the compute passes against numpy's (the same entries in
    the same fine slices of the same bins); their fine slices' bits."""
    r = Renderer(build="gpu", accel="beams")
    strands = curls(40, 12, radius=0.01, seed=2)
    r.set_strands(strands)
    c, lo, hi, rmax = _scene(strands)
    frame, _ = _frames(lo, hi, rmax)[family]
    want = build_beams(frame, c)
    from tracer.gl_state import beam_builder
    names = SUN_BUFFERS[1] if family in ("sun", "spot") or family.startswith("light") else CAMERA_BUFFERS
    # (The pixel centres' walk takes no marks.)
    reach = None if family == "pixel centres" else frame_reach(frame, lo, hi, rmax, 1.0)
    built = beam_builder().build(frame, r.num_cylinders, r.buffers["tex_cyl"], 1.0, r.buffers, *names,
                                 layout.BEAM_MAX_REFS, reach)
    assert built.refs == want.refs and built.reach == reach
    start, count, entries, marks = read_beams(built, r.buffers, names)
    np.testing.assert_array_equal(count, want.count)
    np.testing.assert_array_equal(start, want.start)
    assert built.sub == want.sub
    fine = entries >> built.id_bits
    for b in np.flatnonzero(count):       # fine slice by fine slice, the same entries
        run = slice(start[b], start[b] + count[b])
        assert np.all(np.diff(fine[run].astype(np.int64)) >= 0)
        np.testing.assert_array_equal(np.sort(entries[run]), want.entries[run])
    assert (marks is None) == (reach is None)
    if marks is not None:
        bins = np.repeat(np.arange(len(count)), count)      # (a bin's entries follow the bin before's)
        _assert_marks_hold_the_capsules(frame, c, reach, entries & ((1 << built.id_bits) - 1), bins, marks)
    return built.sub


def _assert_marks_hold_the_capsules(frame, c, reach, ids, bins, marks):
    """Each entry's mark (shaders/beams_build.glsl, beam_mark) against its cylinder's capsule
    axis as numpy projects it, at points across the entry's bin: a point within `reach` of the
    axis is within reach + a step of the mark's (the walk's test keeps every cylinder it can
    meet), and the mark's axis is no nearer to any point than the axis less the step's
    rounding (a mark that let everything through would fail)."""
    g = np.stack(project(frame, c.top)[:2] + project(frame, capsule_far(c))[:2], axis=1)[ids]
    corner = np.stack([bins % frame.dims[0], bins // frame.dims[0]], axis=1).astype(np.float64)
    step = (1 + 2 * reach) / 255
    code = (marks[:, None] >> np.array([0, 8, 16, 24], np.uint32)) & 255
    decoded = code.astype(np.float64) * step - reach
    u = (np.arange(5) + 0.5) / 5
    points = np.stack(np.meshgrid(u, u), axis=-1).reshape(-1, 2)

    def distance(ends, p):          # (entries, points): from each point to each entry's segment
        a, d = ends[:, None, :2], (ends[:, 2:] - ends[:, :2])[:, None, :]
        s = np.clip(np.sum((p - a) * d, axis=2) / np.maximum(np.sum(d * d, axis=2), 1e-30), 0, 1)
        return np.linalg.norm(a + s[..., None] * d - p, axis=2)

    true = distance(g - np.tile(corner, 2), points[None])
    coded = distance(decoded, points[None])
    near = true <= reach
    assert near.sum() > len(ids)    # most entries' capsules cover some of the points
    assert np.all(coded[near] <= reach + step)
    assert np.all(coded >= np.minimum(true, reach + step) - step)


@pytest.mark.parametrize("radius", [0.01, 0.002])
def test_a_pixels_centre_ray_finds_every_cylinder_it_meets_in_its_list(radius):
    """One sample a pixel goes through the pixel's centre, so a bin lists only what that ray
    may meet (BeamFrame.centres): every cylinder the centre ray of a pixel meets (the float64
    reference's intersection) is in the pixel's list, in a slice starting no farther than the
    hit, and the lists hold far fewer entries than whole pixels' lists."""
    from tracer.reference.shapes import intersect
    c, lo, hi, rmax = _scene(curls(30, 12, radius=radius))
    frame, camera = _frames(lo, hi, rmax)["pixel centres"]
    beams = build_beams(frame, c)
    whole = build_beams(_frames(lo, hi, rmax)["perspective"][0], c)
    assert 0 < beams.refs < 0.5 * whole.refs
    nx, ny = frame.dims
    px, py = (a.ravel() for a in np.meshgrid(np.arange(nx), np.arange(ny)))
    o, d = camera.rays(px + 0.5, py + 0.5)
    hits = 0
    for k in range(len(c)):
        t = intersect(c, np.full(len(px), k), o, d)[0]
        for b in np.flatnonzero(np.isfinite(t) & (t > 0)):
            run = beams.entries[beams.start[b]:beams.start[b] + beams.count[b]]
            ids = beams.ids(run)
            assert k in ids, f"cylinder {k} missing from the list of pixel {b}"
            assert beams.starts(run[ids == k])[0] <= t[b]
            hits += 1
    assert hits > 100


def test_a_capsule_at_the_cameras_plane_is_refused():
    c, lo, hi, rmax = _scene(curls(20, 8))
    cam = Camera.look_at((0.0, 0.0, 0.5), (1.0, 0.0, 0.5), size=(32, 32))
    with pytest.raises(BeamsUnfit, match="camera's plane"):
        camera_frame(cam, (0, 0, 32, 32), lo, hi, rmax, 1.0)


def test_fine_slices_only_where_their_references_pay_for_their_fills():
    """fine_bits: the most bits whose filled fine slices number no more than one per
    BEAM_REFS_PER_FILL references."""
    per = layout.BEAM_REFS_PER_FILL
    every = np.ones(layout.BEAM_SLICES << 3, np.int64)       # 512, 256, 128, 64 filled at 3..0 bits
    assert fine_bits(every, 512 * per) == 3
    assert fine_bits(every, 512 * per - 1) == 2
    assert fine_bits(every, 128 * per) == 1
    assert fine_bits(every, 128 * per - 1) == 0
    whole = np.zeros(layout.BEAM_SLICES << 3, np.int64)
    whole[::8] = 7                                            # whole slices alone: finer costs nothing
    assert fine_bits(whole, 64 * per) == 3
    assert fine_bits(np.ones(layout.BEAM_SLICES, np.int64), 10 ** 9) == 0    # no bits to give

# SPDX-License-Identifier: GPL-3.0-or-later
"""Both acceleration structures (Renderer accel="grid" | "bvh") give the same image: they
find the same hits with the same hit test, so pixels agree to float32 rounding (a
transmittance shadow may multiply its factors in another order). The BVH also keeps the
renderer's upload rules: a camera move sends nothing, a strand edit refits the tree and
sends only the changed part of it."""
import numpy as np
import pytest

from hairio import InputError
from tracer import Camera, Light, Renderer, RenderSettings

from test_tracer_vs_reference import assert_matches_reference
from tracer_scenes import curls, dense_tuft, make_strands


@pytest.fixture(scope="module")
def pair(renderer):
    """(grid renderer, BVH renderer), both with the build of the session's `renderer`."""
    return Renderer(build=renderer.build, accel="grid"), Renderer(build=renderer.build, accel="bvh")


def _render_both(pair, strands, camera, settings):
    imgs = []
    for r in pair:
        r.set_strands(strands)
        imgs.append(r.render(camera, settings))
    return imgs


CAM = Camera.look_at((1.8, -1.6, 0.9), (0, 0, 0.5), fov_deg=40, size=(64, 64))
CASES = {
    "opaque, hard shadows": (curls(30, 10), RenderSettings(shadows=True)),
    "alpha layers, transmittance": (curls(30, 10, alpha=0.5), RenderSettings(layers=4, shadow_mode="transmittance")),
    "alpha, hard, 4 spp, two lights": (curls(30, 10, alpha=0.6), RenderSettings(
        spp=4, layers=3, lights=(Light(), Light("point", (1.0, -1.0, 2.0), intensity=0.5)))),
    "min pixel width, phong": (curls(30, 10, radius=0.002), RenderSettings(min_pixel_width=True, shading="phong")),
}


@pytest.mark.parametrize("case", list(CASES))
def test_bvh_and_grid_give_the_same_image(pair, case):
    strands, settings = CASES[case]
    grid, bvh = _render_both(pair, strands, CAM, settings)
    assert (grid[..., 3] > 0).mean() > 0.05, "scene not in view: the test would prove nothing"
    assert np.abs(grid - bvh).max() <= 1e-6


def test_bvh_and_grid_agree_with_an_orthographic_camera_from_below(pair):
    cam = Camera.look_at((0.1, 0.05, -2.0), (0, 0, 0.5), fov_deg=30, size=(48, 48), type="ORTHO", ortho_scale=1.4)
    grid, bvh = _render_both(pair, curls(20, 8, alpha=0.7), cam, RenderSettings(layers=2))
    assert (grid[..., 3] > 0).mean() > 0.05
    assert np.abs(grid - bvh).max() <= 1e-6


def test_bvh_matches_the_float64_reference(pair):
    settings = RenderSettings(layers=4, shadow_mode="transmittance", count=True)
    assert_matches_reference(pair[1], curls(25, 10, alpha=0.6), CAM, settings)
    st = pair[1].stats
    assert st.cells_visited > 0 and st.cylinder_tests > 0     # boxes and cylinders tested


def test_camera_moves_upload_nothing_and_edits_refit_only_what_changed(pair):
    r = pair[1]
    strands = curls(2000, 10, seed=4)
    r.set_strands(strands)
    r.render(CAM)
    before = r.stats.bytes_uploaded
    r.render(Camera.look_at((-1.5, -1.9, 0.4), (0, 0, 0.4), fov_deg=50, size=(64, 64)))
    assert r.stats.bytes_uploaded == before
    # Move three strands: the tree is refitted, and only the chunks of it that changed go up
    # (the nodes above the moved cylinders), with the moved cylinders' chunks.
    pts = strands.points.copy()
    ids = np.array([3, 770, 1500])
    moved_pts = np.isin(np.repeat(np.arange(strands.num_strands), strands.counts), ids)
    pts[moved_pts] += np.array([0.05, 0.02, -0.03])
    edited = type(strands).from_arrays(pts, strands.counts, radius=strands.radius, color=strands.color,
                                       alpha=strands.alpha)
    before = r.stats.bytes_uploaded
    r.update_strands(ids, edited)
    sent = r.stats.bytes_uploaded - before
    assert r.stats.bvh_refit and sent > 0
    img = r.render(CAM)
    fresh = Renderer(build=r.build, accel="bvh")
    fresh.set_strands(edited)
    assert np.abs(img - fresh.render(CAM)).max() <= 1e-6
    assert sent < 0.5 * fresh.stats.bytes_uploaded


def test_only_the_hair_box_is_traced_with_either_structure(pair):
    s = make_strands([[(0, 0, 0), (0.1, 0, 0.3)], [(0.05, 0.02, 0), (0.12, 0.0, 0.25)]], radius=0.01)
    cam = Camera.look_at((0, -3, 0.15), (0, 0, 0.15), fov_deg=40, size=(96, 96))
    _render_both(pair, s, cam, RenderSettings())
    grid_px, bvh_px = (r.stats.traversed_pixels for r in pair)
    assert 0 < bvh_px <= grid_px < 96 * 96 // 4


def test_unknown_accelerator_is_refused():
    with pytest.raises(InputError, match="accel"):
        Renderer(accel="octree")


def test_command_line_renders_the_same_png_with_either_structure(tmp_path, capsys):
    from tracer.__main__ import main
    src = tmp_path / "tuft.npz"
    curls(20, 8).save_npz(src)
    pngs = {}
    for accel in ("grid", "bvh"):
        out = tmp_path / f"{accel}.png"
        assert main(["render", str(src), "--out", str(out), "--size", "40x32", "--accel", accel]) == 0
        pngs[accel] = out.read_bytes()
    assert "BVH build" in capsys.readouterr().out
    assert pngs["grid"] == pngs["bvh"]


def test_a_short_stack_that_overflows_loses_no_hit(renderer, monkeypatch):
    """With one slot the near-first walk overflows on nearly every ray and falls back to the
    walk in tree order: the image is still the grid's."""
    from tracer import layout
    strands, settings = CASES["alpha layers, transmittance"]
    grid = Renderer(build=renderer.build, accel="grid")
    grid.set_strands(strands)
    want = grid.render(CAM, settings)
    monkeypatch.setattr(layout, "BVH_SHORT_STACK", 1)
    bvh = Renderer(build=renderer.build, accel="bvh")       # programs compiled with one slot
    bvh.set_strands(strands)
    assert np.abs(bvh.render(CAM, settings) - want).max() <= 1e-6
    opaque, _ = CASES["opaque, hard shadows"]
    grid.set_strands(opaque)
    bvh.set_strands(opaque)
    counted = RenderSettings(shadows=False, count=True)
    assert np.abs(bvh.render(CAM, counted) - grid.render(CAM, counted)).max() <= 1e-6
    boxes_one_slot = bvh.stats.cells_visited
    monkeypatch.undo()
    roomy = Renderer(build=renderer.build, accel="bvh")
    roomy.set_strands(opaque)
    roomy.render(CAM, counted)
    assert boxes_one_slot > roomy.stats.cells_visited      # the fallback walk ran


# The grid's rules scaled down to a tuft of 3,000 faint strands seen through 32² pixels, which
# stands for a dense scene: one sample aims at 3 references a cylinder, and (once the tests set
# RAYS_TUNED to 32²) a render of 16 samples counts as many rays.
TUFT_CAM = Camera.look_at((0.0, -1.6, 0.0), (0.0, 0.0, 0.0), fov_deg=22, size=(32, 32))


def _tuft(renderer, monkeypatch, accel, settings):
    """(strands, the image of `settings` on the rule's grid, that grid's references) with the
    scaled-down rules in place."""
    from tracer import grid as tg
    monkeypatch.setattr(tg, "MAX_REFS_PER_CYLINDER", 3.0)
    monkeypatch.setattr(tg, "MIN_REFS_PER_CYLINDER", 2.0)
    strands = dense_tuft(3000)
    kept = Renderer(build=renderer.build, accel=accel)
    kept.set_strands(strands)
    want = kept.render(TUFT_CAM, settings)      # 16 x 32² rays: fewer than RAYS_TUNED
    assert (want[..., 3] > 0).mean() > 0.3, "tuft not in view: the test would prove nothing"
    return strands, want, kept.stats.grid_refs


@pytest.mark.parametrize("accel", ["grid", "beams"])
def test_a_render_of_many_rays_refines_the_grid_and_finds_the_same_hits(renderer, monkeypatch, accel):
    """A render of 16 samples a pixel builds the grid again with more references per
    cylinder (tracer/grid.py, refs_per_cylinder) where its rays pay for them; it keeps that
    grid for the renders after it, and new strands start from the rule for one sample. With
    beams the grid serves the shadow rays toward an environment (they go every way)."""
    import dataclasses
    from tracer import grid as tg
    one = RenderSettings(layers=3, shadow_mode="transmittance", lights=(Light("environment", intensity=3.0),))
    many = dataclasses.replace(one, spp=16)
    strands, want, coarse = _tuft(renderer, monkeypatch, accel, many)
    monkeypatch.setattr(tg, "RAYS_TUNED", 32 * 32)
    r = Renderer(build=renderer.build, accel=accel)
    r.set_strands(strands)
    r.render(TUFT_CAM, one)
    assert r.stats.grid_refs == coarse
    rebuilds = r.stats.grid_rebuilds
    got = r.render(TUFT_CAM, many)
    assert r.stats.grid_rebuilds == rebuilds + 1
    assert r.stats.grid_refs > 2 * coarse
    assert np.abs(got - want).max() <= 1e-5
    finer = r.stats.grid_refs
    r.render(TUFT_CAM, one)                 # fewer rays keep the finer grid
    r.render(TUFT_CAM, many)
    assert r.stats.grid_rebuilds == rebuilds + 1 and r.stats.grid_refs == finer
    r.set_strands(strands)
    r.render(TUFT_CAM, one)
    assert r.stats.grid_refs == coarse


MANY = RenderSettings(spp=16, layers=3, shadow_mode="transmittance")


def test_finer_lists_that_outgrow_the_buffers_fall_back_to_the_rule_for_one_sample(renderer, monkeypatch):
    """The aim is kept within a share of what the lists' buffers hold by an estimate; where
    the lists still outgrow them, the render builds the one-sample grid and renders the same
    image instead of failing."""
    from tracer import grid as tg
    strands, want, coarse = _tuft(renderer, monkeypatch, "grid", MANY)
    monkeypatch.setattr(tg, "RAYS_TUNED", 32 * 32)
    monkeypatch.setattr(tg, "CAPACITY_SHARE", 100.0)        # an estimate far off
    r = Renderer(build=renderer.build, accel="grid")
    r.buffers.max_texels = 2 * coarse // 4                  # lists of four parts hold 2x the rule's
    r.set_strands(strands)
    got = r.render(TUFT_CAM, MANY)
    assert r.stats.grid_refs == coarse
    assert np.abs(got - want).max() <= 1e-5
    rebuilds = r.stats.grid_rebuilds
    r.render(TUFT_CAM, MANY)                # not tried again for these strands
    assert r.stats.grid_rebuilds == rebuilds


def test_an_estimate_that_lists_too_much_is_corrected_by_the_lists_it_counted(renderer, monkeypatch):
    """Where the estimate of the lists' length is off (here 0.7 of the true one, with no floor
    on the cell size) and the finer lists outgrow their buffers, the build tries once more at
    the aim the counted length says fits, and keeps that grid rather than falling back to the
    one-sample rule."""
    from tracer import grid as tg
    from tracer import layout
    monkeypatch.setattr(tg, "MAX_CELLS_PER_CYLINDER", 64.0)
    strands, want, coarse = _tuft(renderer, monkeypatch, "grid", MANY)
    estimate = tg.expected_refs
    monkeypatch.setattr(tg, "expected_refs", lambda box_size, h: 0.7 * estimate(box_size, h))
    monkeypatch.setattr(tg, "RAYS_TUNED", 32 * 32)
    monkeypatch.setattr(layout, "MAX_BUFFER_PARTS", 1)
    r = Renderer(build=renderer.build, accel="grid")
    r.buffers.max_texels = 4 * coarse               # one buffer of lists holds 4x the rule's
    r.set_strands(strands)
    one = r.stats.grid_refs
    got = r.render(TUFT_CAM, MANY)
    assert one < r.stats.grid_refs <= 4 * coarse
    assert r.scene.grid_aim_failed > r.scene.grid_aim > 0   # the first aim failed, the second held
    assert np.abs(got - want).max() <= 1e-5

# SPDX-License-Identifier: GPL-3.0-or-later
"""Scene data in buffer textures: a scene that just fits the driver's limit renders as
usual, one past it gets a clear error and leaves no half scene, cylinders and cell lists
past one buffer's limit are split over several and render as unsplit ones do, buffers kept
from a bigger scene hold a smaller one correctly, and partial uploads in chunks equal a
fresh upload."""
import numpy as np
import pytest

from hairio import InputError
from tracer import Camera, Renderer, RenderSettings
from tracer import strand_upload
from tracer.gpu_build import compute_available
from tracer.gl_state import shared_context
from tracer.layout import IDX_SLACK, MAX_BUFFER_PARTS, TEXELS_PER_CYL
from tracer.scene_buffers import SceneBuffers
from tracer.stats import RenderStats

from tracer_scenes import curls

BUILDS = ["gpu", "numpy"] if compute_available(shared_context()) else ["numpy"]
SETTINGS = RenderSettings(layers=4, shadows=True, count=True)
# 4 samples of 4 layers: within the pixel sampler's list on see-through hair (more would take
# the independent sampler: Renderer.sampler_for).
PIXEL = RenderSettings(layers=4, shadows=True, spp=4, sampler="pixel")
COUNTERS = ("cells_visited", "cylinder_tests", "shadow_rays", "layers_traced")
# The work of primary rays alone: a hard shadow ray stops at the first blocker it meets, so
# its work depends on the order of a cell's list, which the GPU build fills as its atomics
# land (the image does not: any blocker darkens). Primary rays order hits by (t, id).
PRIMARY = RenderSettings(layers=4, shadows=False, count=True)


def _work(r, cam):
    """The counters of a render of `r`'s scene by primary rays alone."""
    r.render(cam, PRIMARY)
    return {k: getattr(r.stats, k) for k in COUNTERS}


def _camera(s, size=(40, 40)):
    return Camera.frame_bounds(*s.bounds(), size)


def _needed_texels(r):
    """The smallest texel limit of one buffer texture that holds the renderer's current
    scene: the cylinders and the cell lists split over up to MAX_BUFFER_PARTS buffers (the
    cylinders in whole cylinders), the other buffers whole."""
    return max(-(-r.num_cylinders // MAX_BUFFER_PARTS) * TEXELS_PER_CYL,
               -(-(r.stats.grid_refs + IDX_SLACK) // MAX_BUFFER_PARTS), r.grid.num_cells, len(r.strands.points))


@pytest.mark.parametrize("build", BUILDS)
def test_a_scene_at_the_buffer_limit_renders_and_one_past_it_is_refused(build):
    s = curls(20, 12, seed=3, alpha=0.6)
    free = Renderer(build=build, accel="grid")
    free.set_strands(s)
    want = free.render(_camera(s), SETTINGS)
    limit = _needed_texels(free)
    exact = Renderer(max_buffer_texels=limit, build=build, accel="grid")
    exact.set_strands(s)
    np.testing.assert_array_equal(exact.render(_camera(s), SETTINGS), want)
    tight = Renderer(max_buffer_texels=limit - 1, build=build, accel="grid")
    with pytest.raises(InputError, match="scene too large for this GPU: tex_.* needs .* texels"):
        tight.set_strands(s)
    # No half-built scene is left to trace.
    assert tight.num_cylinders is None and tight.grid is None
    with pytest.raises(InputError, match="no strands"):
        tight.render(_camera(s), SETTINGS)


def _dense():
    """Many cylinders and cell references per cell: limits that split the cylinders and the
    lists still hold the cell table."""
    return curls(60, 40, seed=3, alpha=0.6, radius=0.04)


def _split_limit(r, idx_parts):
    """A texel limit that splits the cell lists of `r` over `idx_parts` buffers (and the
    cylinders over as many as they then need) while every other buffer fits."""
    return max(-(-(r.stats.grid_refs + IDX_SLACK) // idx_parts), -(-r.num_cylinders // 4) * TEXELS_PER_CYL,
               r.grid.num_cells, len(r.strands.points))


def _unsplit(build, settings):
    """The dense scene, its camera, a renderer holding it in one buffer each, and its image."""
    s = _dense()
    cam = _camera(s, (48, 44))
    whole = Renderer(build=build, accel="grid")
    whole.set_strands(s)
    return s, cam, whole, whole.render(cam, settings)


@pytest.mark.parametrize("build", BUILDS)
def test_a_scene_split_over_several_buffers_renders_as_the_unsplit_scene(build):
    s, cam, whole, want = _unsplit(build, SETTINGS)
    want_work = _work(whole, cam)
    assert whole.buffers.parts("tex_cyl") == 1 and whole.buffers.parts("tex_idx") == 1
    assert want[..., 3].max() > 0
    seen = set()
    for idx_parts in (4, 3, 2):
        split = Renderer(max_buffer_texels=_split_limit(whole, idx_parts), build=build, accel="grid")
        split.set_strands(s)
        seen.add((split.buffers.parts("tex_cyl"), split.buffers.parts("tex_idx")))
        # The same data, read back across the parts, and the same image and work.
        n = whole.num_cylinders * TEXELS_PER_CYL
        assert split.buffers["tex_cyl"].read(n) == whole.buffers["tex_cyl"].read(n)
        np.testing.assert_array_equal(np.sort(split.grid_indices()), np.sort(whole.grid_indices()))
        np.testing.assert_array_equal(split.render(cam, SETTINGS), want)
        assert _work(split, cam) == want_work
    # Three different splits were traced, one with the cylinders split too.
    assert {p[1] for p in seen} == {4, 3, 2} and max(p[0] for p in seen) >= 2, seen


@pytest.mark.parametrize("build", BUILDS)
def test_the_pixel_sampler_renders_a_split_scene_as_the_unsplit_scene(build):
    s, cam, whole, want = _unsplit(build, PIXEL)      # its grid padded for the pixel's reach
    assert want[..., 3].max() > 0
    split = Renderer(max_buffer_texels=_split_limit(whole, 3), build=build, accel="grid")
    split.set_strands(s)
    got = split.render(cam, PIXEL)
    assert split.buffers.parts("tex_idx") == 3
    assert split.sampler_for(PIXEL).sampler == "pixel" and split.stats.layers_max == 4
    np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("build", BUILDS)
def test_updates_of_a_split_scene_render_as_a_fresh_unsplit_upload(build, monkeypatch):
    monkeypatch.setattr(strand_upload, "UPLOAD_CHUNK", 16)
    s = _dense()
    cam = _camera(s, (40, 40))
    whole = Renderer(build=build, accel="grid")
    whole.set_strands(s)
    r = Renderer(max_buffer_texels=_split_limit(whole, 4), build=build, accel="grid")
    r.set_strands(s)
    assert r.buffers.parts("tex_cyl") == 2
    # Strands in the first part, across the boundary and in the last part.
    boundary = r.buffers.part_size("tex_cyl")
    first_cyl = np.concatenate([[0], np.cumsum(s.counts - 1)])
    across = int(np.searchsorted(first_cyl, boundary, side="right") - 1)
    rng = np.random.default_rng(5)
    for changed in ([1], [across], [across - 1, across, len(s.counts) - 1]):
        pts = s.points.copy()
        for i in changed:
            a = s.offsets[i]
            pts[a:a + s.counts[i]] += rng.normal(0, 0.01, 3).astype(np.float32)
        s = type(s).from_arrays(pts, s.counts, radius=s.radius, color=s.color, alpha=s.alpha)
        r.update_strands(changed, s)
        fresh = Renderer(build=build, accel="grid")
        fresh.set_strands(s)
        n = fresh.num_cylinders * TEXELS_PER_CYL
        assert r.buffers["tex_cyl"].read(n) == fresh.buffers["tex_cyl"].read(n)
        np.testing.assert_array_equal(r.render(cam, SETTINGS), fresh.render(cam, SETTINGS))


@pytest.mark.parametrize("build", BUILDS)
def test_a_scene_past_what_the_split_holds_is_refused_by_name(build):
    s = _dense()
    whole = Renderer(build=build, accel="grid")
    whole.set_strands(s)
    # The cell lists would need one part more than the split allows; the rest fits.
    limit = -(-(whole.stats.grid_refs + IDX_SLACK) // (MAX_BUFFER_PARTS + 1))
    assert limit >= max(-(-whole.num_cylinders // MAX_BUFFER_PARTS) * TEXELS_PER_CYL, len(s.points))
    tight = Renderer(max_buffer_texels=limit, build=build, accel="grid")
    with pytest.raises(InputError, match=f"tex_idx needs .* splits one buffer over at most {MAX_BUFFER_PARTS}"):
        tight.set_strands(s)
    assert tight.num_cylinders is None and tight.grid is None


def test_a_split_buffer_reads_and_writes_across_its_parts():
    buffers = SceneBuffers(shared_context(), 10, RenderStats())
    store = buffers.store("tex_idx", 35, 1, "i4")        # parts of 10, 10, 10 and 5 texels
    assert buffers.parts("tex_idx") == 4 and len(store.parts) == 4
    data = np.arange(35, dtype=np.int32) * 7 + 1
    store.write(data)
    assert np.array_equal(np.frombuffer(store.read(35), np.int32), data)
    store.write(np.array([-1, -2, -3, -4, -5], np.int32), first=8)      # straddles parts 0 and 1
    data[8:13] = [-1, -2, -3, -4, -5]
    assert np.array_equal(np.frombuffer(store.read(12, first=6), np.int32), data[6:18])
    assert np.array_equal(np.frombuffer(buffers["tex_idx"].parts[1].read(10), np.int32), data[10:20])
    # Cylinders never straddle: parts of the cylinder buffer hold whole cylinders.
    assert buffers.part_texels("tex_cyl") == 8
    # A smaller scene gives back the parts it does not need.
    buffers.store("tex_idx", 12, 1, "i4")
    assert buffers.parts("tex_idx") == 2
    with pytest.raises(InputError, match="tex_cyl needs 44 texels .* at most 4"):
        buffers.store("tex_cyl", 44, 4, "f4")


@pytest.mark.parametrize("build", BUILDS)
def test_buffers_kept_from_a_bigger_scene_render_a_smaller_one_like_fresh_ones(build):
    # Buffers are reused when they are big enough: whatever the bigger scene left past the
    # end of the smaller one's data must not be read.
    big, small = curls(60, 16, seed=1, alpha=0.5), curls(15, 9, seed=2, alpha=0.7)
    reused = Renderer(build=build, accel="grid")
    reused.set_strands(big)
    reused.render(_camera(big), SETTINGS)
    kept = {name: store.glo for name, store in reused.buffers.items()}
    reused.set_strands(small)
    assert {name: store.glo for name, store in reused.buffers.items()} == kept     # really reused
    a = reused.render(_camera(small), SETTINGS)
    fresh = Renderer(build=build, accel="grid")
    fresh.set_strands(small)
    b = fresh.render(_camera(small), SETTINGS)
    assert a[..., 3].max() > 0
    np.testing.assert_array_equal(a, b)
    assert _work(reused, _camera(small)) == _work(fresh, _camera(small))


@pytest.mark.parametrize("build", BUILDS)
def test_updates_across_upload_chunks_equal_a_fresh_upload(build, monkeypatch):
    # Chunks of 16 cylinders or points: the changed strands start and end inside chunks,
    # cross chunk boundaries with and without whole chunks between, and sit side by side.
    monkeypatch.setattr(strand_upload, "UPLOAD_CHUNK", 16)
    s = curls(40, 7)
    r = Renderer(build=build, accel="grid")
    r.set_strands(s)
    cam = _camera(s, (48, 40))
    rng = np.random.default_rng(4)
    for changed in ([2], [2, 3], [5, 6, 7, 8, 9], sorted(rng.choice(40, 9, replace=False))):
        pts = s.points.copy()
        for i in changed:
            a = s.offsets[i]
            pts[a:a + s.counts[i]] += rng.normal(0, 0.01, 3).astype(np.float32)
        s = type(s).from_arrays(pts, s.counts, radius=s.radius, color=s.color, alpha=s.alpha)
        before = r.stats.bytes_uploaded
        r.update_strands(changed, s)
        sent = r.stats.bytes_uploaded - before
        fresh = Renderer(build=build, accel="grid")
        fresh.set_strands(s)
        n = r.num_cylinders * TEXELS_PER_CYL
        np.testing.assert_array_equal(np.frombuffer(r.buffers["tex_cyl"].read(n), np.float32),
                                      np.frombuffer(fresh.buffers["tex_cyl"].read(n), np.float32))
        np.testing.assert_array_equal(r.render(cam), fresh.render(cam))
        assert sent < fresh.stats.bytes_uploaded      # only the changed chunks went up


def test_changed_strands_taken_out_keep_their_colour_a_strand():
    """select_strands (the strands an update re-uploads) of strands whose colour is held a
    strand at a time: their own rows of it, no colour a point made for the whole."""
    from hairio import Strands
    from tracer.strand_upload import select_strands
    rng = np.random.default_rng(5)
    counts = rng.integers(2, 9, 30).astype(np.int32)
    points = rng.normal(size=(int(counts.sum()), 3)).astype(np.float32)
    rgb = rng.uniform(0, 1, (30, 3)).astype(np.float32)
    held = Strands.from_arrays(points, counts, strand_color=rgb)
    ids = np.array([0, 4, 5, 29])
    sub = select_strands(held, ids)
    assert held.point_color is None and sub.point_color is None
    np.testing.assert_array_equal(sub.strand_color, rgb[ids])
    np.testing.assert_array_equal(sub.color, np.repeat(rgb[ids], counts[ids], axis=0))
    np.testing.assert_array_equal(sub.points, np.concatenate([held.strand_points(i) for i in ids]))

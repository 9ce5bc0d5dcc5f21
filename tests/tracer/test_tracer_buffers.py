# SPDX-License-Identifier: GPL-3.0-or-later
"""Scene data in buffer textures: a scene that just fits the driver's limit renders as
usual, one past it gets a clear error and leaves no half scene, buffers kept from a bigger
scene hold a smaller one correctly, and partial uploads in chunks equal a fresh upload."""
import numpy as np
import pytest

from hairio import InputError
from tracer import Camera, Renderer, RenderSettings
from tracer import strand_upload
from tracer.gpu_build import compute_available
from tracer.gl_state import shared_context
from tracer.layout import IDX_SLACK, TEXELS_PER_CYL

from tracer_scenes import curls

BUILDS = ["gpu", "numpy"] if compute_available(shared_context()) else ["numpy"]
SETTINGS = RenderSettings(layers=4, shadows=True, count=True)
COUNTERS = ("cells_visited", "cylinder_tests", "shadow_rays", "layers_traced")


def _camera(s, size=(40, 40)):
    return Camera.frame_bounds(*s.bounds(), size)


def _needed_texels(r):
    """The most texels any of the renderer's buffers needs for its current scene."""
    return max(r.num_cylinders * TEXELS_PER_CYL, r.stats.grid_refs + IDX_SLACK, r.grid.num_cells,
               len(r.strands.points))


@pytest.mark.parametrize("build", BUILDS)
def test_a_scene_at_the_buffer_limit_renders_and_one_past_it_is_refused(build):
    s = curls(20, 12, seed=3, alpha=0.6)
    free = Renderer(build=build)
    free.set_strands(s)
    want = free.render(_camera(s), SETTINGS)
    limit = _needed_texels(free)
    exact = Renderer(max_buffer_texels=limit, build=build)
    exact.set_strands(s)
    np.testing.assert_array_equal(exact.render(_camera(s), SETTINGS), want)
    tight = Renderer(max_buffer_texels=limit - 1, build=build)
    with pytest.raises(InputError, match="scene too large for this GPU: tex_.* needs .* texels"):
        tight.set_strands(s)
    # No half-built scene is left to trace.
    assert tight.num_cylinders is None and tight.grid is None
    with pytest.raises(InputError, match="no strands"):
        tight.render(_camera(s), SETTINGS)


@pytest.mark.parametrize("build", BUILDS)
def test_buffers_kept_from_a_bigger_scene_render_a_smaller_one_like_fresh_ones(build):
    # Buffers are reused when they are big enough: whatever the bigger scene left past the
    # end of the smaller one's data must not be read.
    big, small = curls(60, 16, seed=1, alpha=0.5), curls(15, 9, seed=2, alpha=0.7)
    reused = Renderer(build=build)
    reused.set_strands(big)
    reused.render(_camera(big), SETTINGS)
    kept = {name: store.glo for name, store in reused.buffers.items()}
    reused.set_strands(small)
    assert all(reused.buffers[name].glo == glo for name, glo in kept.items())     # really reused
    a = reused.render(_camera(small), SETTINGS)
    fresh = Renderer(build=build)
    fresh.set_strands(small)
    b = fresh.render(_camera(small), SETTINGS)
    assert a[..., 3].max() > 0
    np.testing.assert_array_equal(a, b)
    assert {k: getattr(reused.stats, k) for k in COUNTERS} == {k: getattr(fresh.stats, k) for k in COUNTERS}


@pytest.mark.parametrize("build", BUILDS)
def test_updates_across_upload_chunks_equal_a_fresh_upload(build, monkeypatch):
    # Chunks of 16 cylinders or points: the changed strands start and end inside chunks,
    # cross chunk boundaries with and without whole chunks between, and sit side by side.
    monkeypatch.setattr(strand_upload, "UPLOAD_CHUNK", 16)
    s = curls(40, 7)
    r = Renderer(build=build)
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
        fresh = Renderer(build=build)
        fresh.set_strands(s)
        n = r.num_cylinders * TEXELS_PER_CYL
        np.testing.assert_array_equal(np.frombuffer(r.buffers["tex_cyl"].read(n), np.float32),
                                      np.frombuffer(fresh.buffers["tex_cyl"].read(n), np.float32))
        np.testing.assert_array_equal(r.render(cam), fresh.render(cam))
        assert sent < fresh.stats.bytes_uploaded      # only the changed chunks went up

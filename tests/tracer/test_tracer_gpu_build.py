# SPDX-License-Identifier: GPL-3.0-or-later
"""The GPU build (compute shaders) against the numpy build it must agree with."""
import numpy as np
import pytest

from hairio import InputError
from tracer import Camera, Light, RenderSettings, Renderer, strands_to_cylinders
from tracer import renderer as rmod
from tracer.grid import _cells_touched
from tracer import layout
from tracer.gpu_build import compute_available
from tracer.gl_state import shared_context
from tracer.layout import TEXELS_PER_CYL, cylinder_texels

from test_tracer_grid import _cell_of, _surface_samples
from tracer_scenes import curls, make_strands

pytestmark = pytest.mark.skipif(not compute_available(shared_context()),
                                reason="this driver has no compute shaders (OpenGL 4.3)")


@pytest.fixture(scope="module")
def gpu():
    return Renderer(build="gpu", accel="grid")


def _gpu_cylinder_texels(r):
    raw = np.frombuffer(r.buffers["tex_cyl"].read(r.num_cylinders * TEXELS_PER_CYL), np.float32)
    return raw.reshape(-1, TEXELS_PER_CYL, 4)


def _numpy_cylinder_texels(c):
    return cylinder_texels(c).reshape(-1, TEXELS_PER_CYL, 4)


def _hairpin_and_repeats():
    """Sharp bends (caps), a strand with a repeated point, a strand that collapses to one
    point, a straight one."""
    hairpin = np.array([[0, 0, 0], [0, 0, 0.2], [0.02, 0, 0.25], [0.04, 0, 0.2], [0.04, 0, 0.0]])
    repeated = np.array([[0.2, 0, 0], [0.2, 0, 0.1], [0.2, 0, 0.1], [0.25, 0.02, 0.2], [0.3, 0, 0.3]])
    single = np.array([[0.5, 0.5, 0.5], [0.5, 0.5, 0.5]])
    straight = np.array([[-0.2, 0, 0], [-0.2, 0.1, 0.1], [-0.2, 0.2, 0.2]])
    lines = [hairpin, repeated, single, straight]
    return make_strands(lines, radius=np.linspace(0.004, 0.001, sum(len(p) for p in lines)),
                        alpha=np.linspace(1.0, 0.4, sum(len(p) for p in lines)))


@pytest.mark.parametrize("scene", ["curls", "hairpin_and_repeats"])
def test_gpu_cylinders_are_the_numpy_cylinders(gpu, scene):
    s = curls(25, 14) if scene == "curls" else _hairpin_and_repeats()
    gpu.set_strands(s)
    c = strands_to_cylinders(s)
    assert gpu.num_cylinders == len(c)
    got, want = _gpu_cylinder_texels(gpu), _numpy_cylinder_texels(c)
    # Copies of the input are exact; the plane-2 normal is computed in float32 on both sides
    # and may differ in the last bit; the cap flags must agree.
    for j in (0, 1, 3):
        np.testing.assert_array_equal(got[:, j], want[:, j])
    np.testing.assert_allclose(got[:, 2, :3], want[:, 2, :3], atol=1e-6)
    np.testing.assert_array_equal(got[:, 2, 3], want[:, 2, 3])
    if scene == "hairpin_and_repeats":
        assert (want[:, 2, 3].astype(int) & 2).sum() > 1     # the scene has caps to check


def test_every_surface_point_lies_in_a_cell_whose_gpu_list_has_its_cylinder(gpu):
    rng = np.random.default_rng(5)
    s = curls(30, 12, radius=0.01)
    gpu.set_strands(s)
    assert gpu.stats.grid_build == "gpu"
    g, idx, c = gpu.grid, gpu.grid_indices(), strands_to_cylinders(s)
    assert g.num_cells > 8 and len(idx) == g.cell_count.sum()
    for k in rng.choice(len(c), 60, replace=False):
        for cell in np.unique(_cell_of(g, _surface_samples(c, k, rng))):
            run = idx[g.cell_start[cell]:g.cell_start[cell] + g.cell_count[cell]]
            assert k in run, f"cylinder {k} missing from cell {cell}"


def test_gpu_lists_are_the_numpy_listing_in_the_same_grid(gpu):
    s = curls(40, 16, radius=0.006)
    gpu.set_strands(s)
    g = gpu.grid
    idx = gpu.grid_indices()
    got = set(zip(np.repeat(np.arange(g.num_cells), g.cell_count).tolist(), idx.tolist()))
    cyl, cell = _cells_touched(strands_to_cylinders(s), 1.0, g.lo, g.cell_size, g.dims)
    want = set(zip(cell.tolist(), cyl.tolist()))
    # Same slabs and pads on both sides; float32 rounding in the shader may move a boundary
    # by far less than the thousandth of a cell both add, so the listings agree but for
    # references within that margin.
    assert len(got ^ want) <= 1e-3 * len(want)
    assert len(got) == len(idx)         # no cylinder listed twice in a cell


def _scene_camera(s, size=(48, 40)):
    lo, hi = s.bounds()
    centre = 0.5 * (lo + hi)
    return Camera.look_at(centre + np.array([0.3, -1.6, 0.5]), centre, size=size, fov_deg=35)


@pytest.mark.parametrize("shadows", ["hard", "transmittance"])
def test_gpu_and_numpy_builds_render_the_same_image(gpu, shadows):
    s = curls(20, 12, radius=0.01, alpha=0.6)
    cam = _scene_camera(s)
    settings = RenderSettings(spp=1, layers=3, shadows=True, shadow_mode=shadows,
                              lights=(Light(vector=(0.3, 0.5, -1.0)),))
    gpu.set_strands(s)
    a = gpu.render(cam, settings)
    cpu = Renderer(build="numpy", accel="grid")
    cpu.set_strands(s)
    b = cpu.render(cam, settings)
    assert (a[..., 3] > 0).mean() > 0.05
    np.testing.assert_array_equal(a[..., 3] > 0, b[..., 3] > 0)
    # Different grids (the GPU build bounds the scene by its points): the same hits, found
    # in other cells; transmittance multiplies the same factors in another order.
    np.testing.assert_allclose(a, b, atol=1e-5)


def test_update_on_the_gpu_equals_a_fresh_upload(gpu):
    s = curls(30, 10)
    gpu.set_strands(s)
    pts = s.points.copy()
    changed = np.array([3, 4, 17])
    for i in changed:
        a = s.offsets[i]
        pts[a:a + s.counts[i]] += np.array([0.01, -0.02, 0.0], np.float32)
    s2 = type(s).from_arrays(pts, s.counts, radius=s.radius, color=s.color, alpha=s.alpha)
    before = gpu.stats.bytes_uploaded
    gpu.update_strands(changed, s2)
    sent = gpu.stats.bytes_uploaded - before
    texels = _gpu_cylinder_texels(gpu).copy()
    cam = _scene_camera(s2)
    img = gpu.render(cam)
    fresh = Renderer(build="gpu", accel="grid")
    fresh.set_strands(s2)
    before = fresh.stats.bytes_uploaded
    np.testing.assert_array_equal(texels, _gpu_cylinder_texels(fresh))
    np.testing.assert_array_equal(img, fresh.render(cam))
    assert sent < before            # only the changed strands' points went up


def test_cylinders_made_a_range_of_the_drivers_block_size_at_a_time_are_the_whole_ones(monkeypatch):
    """The cylinder pass binds the cylinder buffer as a storage buffer a range at a time, no
    longer than the driver's block size and from offsets it aligns: ranges of a few dozen
    cylinders (a block of 37 cylinders' bytes and some, offsets of 256 bytes: 4 cylinders)
    make the same buffer as one range, and so does an update that starts between two
    aligned offsets."""
    from tracer import gpu_build
    size = 16 * TEXELS_PER_CYL
    monkeypatch.setattr(gpu_build, "storage_limits", lambda ctx: (37 * size + 5, 256))
    ranges = []
    real = gpu_build.set_uniforms

    def spy(prog, **values):
        if "out_first" in values:
            ranges.append((values["out_first"], values["first_item"], values["n_items"]))
        return real(prog, **values)
    monkeypatch.setattr(gpu_build, "set_uniforms", spy)
    s = curls(30, 10)
    r = Renderer(build="gpu", accel="grid")
    r.set_strands(s)
    n = r.num_cylinders
    assert len(ranges) == -(-n // 36) > 5
    for start, first, count in ranges:
        assert start % 4 == 0 and start <= first and first + count - start <= 36
    np.testing.assert_array_equal(_gpu_cylinder_texels(r), _numpy_cylinder_texels(strands_to_cylinders(s)))
    pts = s.points.copy()
    changed = np.array([5, 6])
    for i in changed:
        pts[s.offsets[i]:s.offsets[i] + s.counts[i]] += np.array([0.0, 0.01, 0.02], np.float32)
    s2 = type(s).from_arrays(pts, s.counts, radius=s.radius, color=s.color, alpha=s.alpha)
    del ranges[:]
    r.update_strands(changed, s2)
    assert ranges and ranges[0][1] % 4 != 0        # the update starts between aligned offsets
    fresh = Renderer(build="gpu", accel="grid")
    fresh.set_strands(s2)
    np.testing.assert_array_equal(_gpu_cylinder_texels(r), _gpu_cylinder_texels(fresh))


def test_a_cylinder_too_big_for_one_invocation_falls_back_to_the_numpy_grid(monkeypatch):
    # The limit is compiled into the shaders; a small one makes an ordinary fat strand
    # too big without a scene of millions of cells.
    monkeypatch.setattr(layout, "MAX_VISITS", 200)
    rng = np.random.default_rng(2)
    tiny = [np.array([p, p + [0, 0, 0.002]]) for p in rng.uniform(0, 1, (3000, 3))]
    fat = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    s = make_strands(tiny + [fat], radius=np.concatenate([np.full(6000, 2e-4), [0.03, 0.03]]))
    gpu = Renderer(build="gpu", accel="grid")
    gpu.set_strands(s)
    g = gpu.grid
    span = np.prod(np.minimum(g.dims, np.ceil(1.0 / g.cell_size) + 1))
    assert span > layout.MAX_VISITS
    assert gpu.stats.grid_build == "numpy"
    cam = _scene_camera(s)
    cpu = Renderer(build="numpy", accel="grid")
    cpu.set_strands(s)
    img = gpu.render(cam)
    assert (img[..., 3] > 0).mean() > 0.01
    np.testing.assert_array_equal(img, cpu.render(cam))


def test_build_choice_is_checked(monkeypatch):
    with pytest.raises(InputError, match="build"):
        Renderer(build="cuda")
    monkeypatch.setattr(rmod, "compute_available", lambda ctx: False)
    with pytest.raises(InputError, match="compute shaders"):
        Renderer(build="gpu")
    assert Renderer(build="auto").build == "numpy"


def test_update_with_repeated_points_elsewhere_equals_a_fresh_upload(gpu):
    # Strand 0 repeats a point, so the plan holds compacted copies of the arrays; moving
    # other strands writes into those copies, and a move that makes a new repeat starts over.
    lines = [np.array([[0, 0, 0], [0, 0, 0.1], [0, 0, 0.1], [0.02, 0, 0.2]])]
    lines += [np.array([[0.05 * k, 0.1, 0], [0.05 * k, 0.12, 0.1], [0.05 * k + 0.01, 0.1, 0.2]]) for k in range(1, 9)]
    s = make_strands(lines, radius=0.004)
    gpu.set_strands(s)
    cam = _scene_camera(s)
    for moved, shift in (([3, 4], (0.0, 0.01, 0.0)), ([5], None)):
        pts = s.points.copy()
        for i in moved:
            a = s.offsets[i]
            if shift is None:       # the strand's second point onto its first: a new repeat
                pts[a + 1] = pts[a]
            else:
                pts[a:a + s.counts[i]] += np.asarray(shift, np.float32)
        s = type(s).from_arrays(pts, s.counts, radius=s.radius, color=s.color, alpha=s.alpha)
        gpu.update_strands(moved, s)
        fresh = Renderer(build="gpu", accel="grid")
        fresh.set_strands(s)
        assert gpu.num_cylinders == fresh.num_cylinders == len(strands_to_cylinders(s))
        np.testing.assert_array_equal(_gpu_cylinder_texels(gpu), _gpu_cylinder_texels(fresh))
        np.testing.assert_array_equal(gpu.render(cam), fresh.render(cam))

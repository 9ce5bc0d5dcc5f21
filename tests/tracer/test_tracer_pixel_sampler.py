# SPDX-License-Identifier: GPL-3.0-or-later
"""The pixel sampler (RenderSettings(sampler="pixel")): a pixel's samples share one walk and
each pixel's strands are found for all its samples at once (tracer/shaders/sampler_pixel.glsl).
Checked against the geometry (a strand thinner than a pixel covers the fraction of each pixel
it crosses), against the independent sampler at the same samples over whole images (both
builds, both accelerators, with meshes), on a scene dense enough that a silent loop cap would
drop hits, and its settings."""
import numpy as np
import pytest

from hairio import InputError
from tracer import Camera, Light, Renderer, RenderSettings

from tracer_scenes import curls, dense_tuft, make_strands, uv_sphere


def _hair_rmse(a, b):
    """RMSE of RGBA over the pixels where either image has hair."""
    mask = (a[..., 3] > 0) | (b[..., 3] > 0)
    return float(np.sqrt(np.mean((a.astype(np.float64) - b)[mask] ** 2)))


def _iou(a, b, level=0.05):
    ma, mb = a[..., 3] > level, b[..., 3] > level
    return (ma & mb).sum() / max((ma | mb).sum(), 1)


# --- A strand thinner than a pixel --------------------------------------------------------------
# An orthographic camera of 32 pixels over 1 unit looks down -Y at a straight strand along x,
# 0.25 pixel wide, its centre 0.3 of a pixel into row 15: it covers the fraction 0.25 of every
# pixel of row 15 it crosses (rows 14 and 16 nothing).
PX = 1.0 / 32


def _thin_strand_scene():
    z = 0.5 - (15 + 0.3) * PX          # row 15 spans z in [0.5 - 16 px, 0.5 - 15 px]
    strand = make_strands([np.array([[-0.3, 0.0, z], [0.0, 0.0, z + 1e-4], [0.3, 0.0, z]])],
                          radius=0.125 * PX)
    cam = Camera.look_at((0.0, -2.0, 0.0), (0.0, 0.0, 0.0), size=(32, 32), type="ORTHO", ortho_scale=1.0)
    return strand, cam


def test_thin_strand_alpha_is_its_coverage(renderer):
    strand, cam = _thin_strand_scene()
    renderer.set_strands(strand)
    img = renderer.render(cam, RenderSettings(sampler="pixel", spp=16))
    crossed = img[15, 8:24, 3]            # columns well inside the strand's length
    # 16 jittered samples, one per cell of a 4x4 grid: the band [0.175, 0.425] of the pixel
    # holds each column's sample of row 0 with probability 0.3, of row 1 with 0.7, so a
    # pixel counts 0 to 8 of its 16 samples, 4 on average (std 1.3 per pixel, 0.33 over 16).
    assert abs(crossed.mean() - 0.25) < 0.04, crossed
    assert crossed.min() >= 1 / 16 and crossed.max() <= 0.5
    assert img[14, 8:24, 3].max() == 0 and img[16, 8:24, 3].max() == 0
    # The same samples as the independent sampler, each found by the footprint test as by
    # its own ray (a sample on the strand's very edge may go either way).
    ind = renderer.render(cam, RenderSettings(spp=16))[15, 8:24, 3]
    assert np.abs(crossed - ind).max() <= 1 / 16 + 1e-6 and abs(crossed.mean() - ind.mean()) < 0.01
    # The default (one sample) breaks the same strand into dust: whole pixels or none.
    dust = renderer.render(cam, RenderSettings())[15, 8:24, 3]
    assert set(np.unique(dust).tolist()) <= {0.0, 1.0}


# --- The same image as the independent sampler --------------------------------------------------
def _tuft_camera(size=72):
    return Camera.look_at((0.0, -2.6, 0.5), (0.0, 0.0, 0.5), fov_deg=28, size=(size, size))


# Opaque hair takes one layer, each sample its own nearest hit; see-through hair the list of
# distinct cylinders, which holds enough for 9 samples of 2 layers in one walk.
# Lights that fall off with distance light each strand by its own distance; the point light is
# a sphere (soft shadows); a spot's edge crosses the tuft, and nothing shadows the spot.
NEAR_LIGHT = (Light("point", (0.6, -1.2, 1.2), intensity=2.0, falloff=True, radius=0.3),
              Light("spot", (-0.4, -1.0, 1.4), intensity=2.0, axis=(0.3, 1.0, -0.7), spot_size=0.5, spot_blend=0.3,
                    shadows=False))


@pytest.mark.parametrize("alpha, layers, spp, lights", [(1.0, 4, 16, None), (0.45, 2, 9, None),
                                                        (1.0, 4, 16, NEAR_LIGHT), (0.45, 2, 9, NEAR_LIGHT)],
                         ids=["opaque", "layers", "opaque, near point light", "layers, near point light"])
def test_pixel_sampler_matches_independent_at_same_samples(renderer, alpha, layers, spp, lights):
    renderer.set_strands(curls(60, 12, radius=0.004, alpha=alpha))
    cam = _tuft_camera()
    rs = dict(spp=spp, layers=layers) | ({"lights": lights} if lights else {})
    ind = renderer.render(cam, RenderSettings(**rs))
    pix = renderer.render(cam, RenderSettings(sampler="pixel", **rs))
    empty = np.zeros_like(ind)
    assert (ind[..., 3] > 0).sum() > 400, "the camera misses the hair: the test would prove nothing"
    assert renderer.stats.layers_max == (1 if alpha == 1.0 else layers)
    # Coverage: the same sample positions per pixel, tested by a linear footprint test
    # instead of each ray's own; a sample on a strand's edge may flip (one sample is 1/spp).
    da = np.abs(ind[..., 3] - pix[..., 3])
    assert da.mean() < 0.01 and abs(ind[..., 3].mean() - pix[..., 3].mean()) < 0.005
    assert np.quantile(da[(ind[..., 3] > 0) | (pix[..., 3] > 0)], 0.95) <= 2.0 / spp + 1e-6
    # Colour: each pixel shades its heaviest strands once each (tracer/layout.py PIXEL_SHADE,
    # PIXEL_SHADE_ONE) and gives them the others' weight, where the independent sampler
    # shades every sample; the strands of one pixel lie side by side in the same light, so
    # the difference is a small part of the hair's own contrast. An empty image is far off on
    # both counts.
    assert _iou(pix, ind) > 0.9 and _iou(empty, ind) == 0
    assert _hair_rmse(pix, ind) < 0.03
    assert _hair_rmse(pix, ind) < 0.2 * _hair_rmse(empty, ind)


def test_one_layer_path_agrees_with_the_list(renderer):
    """Opaque hair takes one layer, where each sample keeps its own nearest cylinder and six
    strands a pixel are shaded under the heaviest one's shadow rays; hair of alpha 0.9995
    takes two layers and the list, layout.PIXEL_SHADE strands shaded, each with its own shadow
    rays. The samples find the same strands (alpha the same but for the 0.9995), and the
    shared shadow rays keep the colour about as near the independent sampler's as the
    list's own rays do."""
    cam = _tuft_camera()
    images, layers = {}, {}
    for alpha in (1.0, 0.9995):
        renderer.set_strands(curls(60, 12, radius=0.004, alpha=alpha))
        pix = renderer.render(cam, RenderSettings(sampler="pixel", spp=9, layers=2))
        layers[alpha] = renderer.stats.layers_max
        images[alpha] = pix, renderer.render(cam, RenderSettings(spp=9, layers=2))
    assert layers == {1.0: 1, 0.9995: 2}
    (one, ind_one), (lst, ind_lst) = images[1.0], images[0.9995]
    assert (one[..., 3] > 0).sum() > 400
    assert np.abs(one[..., 3] * 0.9995 - lst[..., 3]).max() < 1e-5
    assert _hair_rmse(one, ind_one) < 1.25 * _hair_rmse(lst, ind_lst) < 0.02


@pytest.mark.parametrize("alpha", [1.0, 0.45])
def test_a_bvh_keeps_its_boxes_for_the_pixel_sampler(alpha):
    """A BVH's pixel walk grows each box by the samples' reach itself, so the pixel sampler
    leaves the tree's boxes unpadded (a default render after it is a fresh renderer's) and
    finds what it finds in boxes padded by minimum pixel width."""
    hair = curls(60, 12, radius=0.004, alpha=alpha)
    cam = _tuft_camera(48)
    rs = RenderSettings(sampler="pixel", spp=9, layers=2)
    r = Renderer(accel="bvh")
    r.set_strands(hair)
    pix = r.render(cam, rs)
    assert r.scene.grid_pad == 1.0
    padded = Renderer(accel="bvh")
    padded.set_strands(hair)
    padded.render(cam, RenderSettings(min_pixel_width=True))
    assert padded.scene.grid_pad > 1.0
    assert (pix[..., 3] > 0).sum() > 300
    np.testing.assert_allclose(pix, padded.render(cam, rs), atol=1e-6)
    fresh = Renderer(accel="bvh")
    fresh.set_strands(hair)
    np.testing.assert_array_equal(r.render(cam, RenderSettings()), fresh.render(cam, RenderSettings()))


@pytest.mark.parametrize("accel", ["grid", "bvh"])
def test_pixel_sampler_with_meshes_and_both_accelerators(accel):
    r = Renderer(accel=accel)
    r.set_strands(curls(40, 12, radius=0.004))
    r.set_meshes([(*uv_sphere((0.0, 0.0, 0.5), 0.15), (0.5, 0.5, 0.5))])
    cam = _tuft_camera(64)
    ind = r.render(cam, RenderSettings(spp=16))
    pix = r.render(cam, RenderSettings(sampler="pixel", spp=16))
    # The sphere in front hides the hair behind it and shows in both.
    centre = (slice(28, 36), slice(28, 36))
    assert np.all(pix[centre][..., 3] == 1.0) and np.all(ind[centre][..., 3] == 1.0)
    # The mesh is shaded once a pixel, with one shadow ray per light, at one of its samples:
    # the hair's shadow edges on it are as sharp as one sample makes them, so pixels differ
    # there, but not the mesh as a whole (an unlit or black sphere would).
    diff = np.abs(pix[centre] - ind[centre])[..., :3]
    assert diff.mean() < 0.25 * ind[centre][..., :3].mean()
    assert np.abs(ind[..., 3] - pix[..., 3]).mean() < 0.01
    assert _hair_rmse(pix, ind) < 0.03


# --- A scene dense enough for llvmpipe's loop cap -----------------------------------------------
def test_dense_scene_keeps_every_hit(grid_renderer):
    """8,000 faint strands (alpha 0.05, 4 layers) packed in front of the camera: a pixel's walk
    crosses the whole tuft, hundreds of candidates, before its samples have their layers. A
    loop cap reached silently would end walks early and drop hits, leaving the pixel sampler's
    alpha below the independent sampler's, whose invocations each walk one sample; and one
    invocation does one walk, not one per sample (the counters say so). On the grid, whose
    walks test the most candidates (the beams' walk of the same scene: test_tracer_beams.py)."""
    grid_renderer.set_strands(dense_tuft())
    cam = Camera.look_at((0.0, -1.6, 0.0), (0.0, 0.0, 0.0), fov_deg=22, size=(32, 32))
    ind = grid_renderer.render(cam, RenderSettings(spp=4, count=True))
    ind_tests = grid_renderer.stats.cylinder_tests
    pix = grid_renderer.render(cam, RenderSettings(sampler="pixel", spp=4, count=True))
    pix_tests = grid_renderer.stats.cylinder_tests
    assert grid_renderer.stats.layers_max == 4
    assert pix_tests / pix[..., 3].size > 300, "not dense enough to prove anything"
    assert pix_tests < 2 * ind_tests        # one walk a pixel (four would be ~4x a sample's)
    assert abs(ind[..., 3].mean() - pix[..., 3].mean()) < 0.005
    assert np.abs(ind[..., 3] - pix[..., 3]).mean() < 0.02


def test_see_through_hair_past_one_list_walks_each_pixel_in_groups(renderer):
    """16 samples of 4 layers can need 64 distinct cylinders a pixel, more than one walk's
    list holds (tracer/layout.py PIXEL_LIST): on dense see-through hair one walk lost far
    layers (mean alpha 0.75 against 0.90 on straight.hair). Such a pixel is walked in groups
    of samples whose layers fit (settings.pixel_group: four walks of 4 samples), one draw
    each: the coverage is the independent sampler's. Past even one sample's layers (more
    layers than the list) the renderer takes the independent sampler, pixel for pixel."""
    from tracer.settings import pixel_group
    renderer.set_strands(curls(300, 12, radius=0.004, alpha=0.3))
    cam = _tuft_camera(48)
    assert pixel_group(16, 4) == 4
    ind = renderer.render(cam, RenderSettings(spp=16))
    assert renderer.stats.layers_max == 4
    pix = renderer.render(cam, RenderSettings(sampler="pixel", spp=16))
    assert renderer.sampler_for(RenderSettings(sampler="pixel", spp=16)).sampler == "pixel"
    assert (ind[..., 3] > 0.5).sum() > 200, "not dense enough to prove anything"
    assert abs(ind[..., 3].mean() - pix[..., 3].mean()) < 0.003
    assert np.abs(ind[..., 3] - pix[..., 3]).mean() < 0.01
    assert _hair_rmse(pix, ind) < 0.02 < _hair_rmse(np.zeros_like(ind), ind)
    many = RenderSettings(sampler="pixel", spp=4, layers=25)
    assert pixel_group(4, 25) == 0 and renderer.sampler_for(many).sampler == "independent"
    assert np.array_equal(renderer.render(cam, many), renderer.render(cam, RenderSettings(spp=4, layers=25)))


def test_a_walk_keeps_every_layer_a_sample_needs_however_many_hidden_ones_come_first(renderer):
    """Row 15 of the thin-strand camera, each pixel's 4 samples in a 2 × 2 grid: 30 see-through
    strands stacked in depth cover the row's upper half (its upper two samples), 4 more behind
    them its lower half. A sample needs its 4 nearest layers: 8 distinct strands a walk, but 34
    hit a sample, all within one cell or slice of the walk (a strand far away stretches the
    scene's depth). The list kept the 24 nearest of one epoch, so the lower samples lost their
    layers to upper ones they could never see (mean alpha 0.38 against 0.76); it now holds
    every strand some sample may still see."""
    row_top = 0.5 - 15 * PX                     # row 15 spans z in [row_top - PX, row_top]
    upper, lower = row_top - 0.25 * PX, row_top - 0.75 * PX

    def along_x(y, z):
        return np.array([[-0.3, y, z], [0.0, y, z + 1e-6], [0.3, y, z]])
    lines = [along_x(-0.03 + 0.0005 * k, upper) for k in range(30)]
    lines += [along_x(0.0 + 0.0005 * k, lower) for k in range(4)]
    lines.append(along_x(40.0, 0.3))            # far away: one epoch holds the stack
    renderer.set_strands(make_strands(lines, radius=0.25 * PX, alpha=0.3))
    cam = Camera.look_at((0.0, -2.0, 0.0), (0.0, 0.0, 0.0), size=(32, 32), type="ORTHO", ortho_scale=1.0)
    ind = renderer.render(cam, RenderSettings(spp=4))[15, 8:24, 3]
    pix = renderer.render(cam, RenderSettings(sampler="pixel", spp=4))[15, 8:24, 3]
    layered = 1.0 - 0.7 ** 4
    assert abs(ind.mean() - layered) < 0.03, ind      # every sample sees its four layers
    assert np.abs(pix - ind).max() <= 0.25 + 1e-6 and abs(pix.mean() - ind.mean()) < 0.01, (pix, ind)


def test_see_through_layers_in_shadow_keep_their_darkness(renderer):
    """With layers, a walk shades its few heaviest strands, mostly the front ones; the
    layers behind lie in their shadow. One more strand, drawn in proportion to its weight,
    stands for all the unshaded ones, so the mean colour is the independent sampler's (the
    unshaded weight given to the shaded strands made such hair some 16 % too bright)."""
    from tracer import Light
    renderer.set_strands(curls(400, 12, radius=0.006, alpha=0.5))
    cam = _tuft_camera(48)
    sun = (Light(vector=(0.2, 0.9, -0.4), intensity=3.0),)
    rs = dict(spp=16, layers=4, shading="kajiya-kay", lights=sun)
    ind = renderer.render(cam, RenderSettings(**rs))
    pix = renderer.render(cam, RenderSettings(sampler="pixel", **rs))
    dark = renderer.render(cam, RenderSettings(shadows=False, **rs))
    assert renderer.stats.layers_max == 4
    lit, shaded = float(dark[..., :3].mean()), float(ind[..., :3].mean())
    assert shaded < 0.8 * lit, "the layers hardly shadow each other: the test would prove nothing"
    assert abs(float(pix[..., :3].mean()) - shaded) < 0.03 * shaded


@pytest.mark.parametrize("shadows", [False, True], ids=["unshadowed", "shadowed"])
def test_opaque_hair_thinner_than_a_sample_keeps_its_brightness(renderer, shadows):
    """Opaque strands far thinner than a pixel: a strand is shaded where a sample drawn among
    those that meet it does (the middle of their rays met it nearer its axis, the first by
    index nearer one edge, and Chiang shading darkened), and the shadow rays start on a strand
    drawn by its light (the heaviest strand's, lit more often than those behind it, made the
    hair up to 18 % too bright). So the mean colour is the independent sampler's at the same
    samples (the draws' noise in the mean: some 1 % at 48², half that here)."""
    from tracer import Light
    renderer.set_strands(curls(1500, 12, radius=0.0008))
    cam = _tuft_camera(96)
    sun = (Light(vector=(0.3, 0.9, -0.3), intensity=3.0),)
    rs = dict(spp=25, shading="chiang", lights=sun, shadows=shadows)
    ind = renderer.render(cam, RenderSettings(**rs))
    pix = renderer.render(cam, RenderSettings(sampler="pixel", **rs))
    assert renderer.stats.layers_max == 1
    want = float(ind[..., :3].mean())
    assert want > 0.01
    if shadows:
        lit = float(renderer.render(cam, RenderSettings(**(rs | dict(shadows=False))))[..., :3].mean())
        assert want < 0.85 * lit, "the strands hardly shadow each other: the test would prove nothing"
    assert abs(float(pix[..., :3].mean()) - want) < 0.02 * want


def test_more_samples_than_one_mask_take_several_walks(renderer):
    """A walk's samples are bits of a 32-bit mask (at most layout.PIXEL_MAX_SPP): 64 samples
    of opaque hair take four walks of 16, and give the independent sampler's coverage."""
    from tracer.settings import pixel_group
    renderer.set_strands(curls(60, 12, radius=0.004))
    cam = _tuft_camera(40)
    assert pixel_group(64, 1) == 16
    pix = renderer.render(cam, RenderSettings(sampler="pixel", spp=64))
    ind = renderer.render(cam, RenderSettings(spp=64))
    assert (ind[..., 3] > 0).sum() > 200
    assert abs(ind[..., 3].mean() - pix[..., 3].mean()) < 0.002
    assert _hair_rmse(pix, ind) < 0.02 < _hair_rmse(np.zeros_like(ind), ind)


# --- Settings -----------------------------------------------------------------------------------
@pytest.mark.parametrize("change, words", [
    (dict(sampler="stratified"), "sampler"),
    (dict(sampler="pixel", spp=16, min_pixel_width=True), "min_pixel_width"),
])
def test_sampler_settings_are_checked(change, words):
    with pytest.raises(InputError, match=words):
        RenderSettings(**change).check()


def test_sampler_settings_accepted():
    RenderSettings(sampler="pixel", spp=25).check()
    RenderSettings(sampler="pixel", spp=64).check()
    RenderSettings(sampler="independent", spp=64).check()


# --- Refinement passes ----------------------------------------------------------------------------
def test_refinement_takes_as_many_samples_as_one_walk_keeps():
    from dataclasses import replace
    from tracer import layout
    rs = RenderSettings()
    # Opaque hair (one layer): the most samples a pixel takes in one walk.
    assert rs.refinement(True) == replace(rs, sampler="pixel", spp=layout.PIXEL_MAX_SPP)
    # See-through hair: samples x layers within the pixel's list (4 layers: 2 x 2 samples).
    see = rs.refinement(False)
    assert (see.sampler, see.spp) == ("pixel", 4) and see.spp * rs.layers <= layout.PIXEL_LIST
    assert replace(rs, layers=2).refinement(False).spp == 9
    # Where the pixel sampler would take no more samples than the settings' own, or cannot
    # take the settings (minimum pixel width), a pass is the settings' own.
    eight_layers, many, widened = replace(rs, layers=8), replace(rs, spp=25), replace(rs, min_pixel_width=True)
    assert eight_layers.refinement(False) is eight_layers      # 24 // 8: one sample
    assert many.refinement(True) is many
    assert widened.refinement(True) is widened


@pytest.mark.parametrize("alpha", [1.0, 0.5])
def test_a_refinement_pass_keeps_the_pixel_sampler(renderer, alpha):
    """The refinement's samples never make the renderer fall back to the independent sampler
    (Renderer.sampler_for), opaque or see-through, and its image agrees with the independent
    sampler's at as many samples."""
    renderer.set_strands(curls(n_strands=40, alpha=alpha))
    cam = Camera.look_at((0.0, -2.5, 0.3), (0.0, 0.0, 0.3), size=(48, 48))
    rs = RenderSettings().refinement(renderer.all_opaque)
    assert rs.sampler == "pixel" and renderer.sampler_for(rs) == rs
    assert rs.spp == (25 if alpha == 1.0 else 4)
    img = renderer.render(cam, rs)
    ref = renderer.render(cam, RenderSettings(spp=rs.spp))
    assert img[..., 3].max() > 0.5 and _iou(img, ref) > 0.9


def _padded(build, hair, cam, max_buffer_texels=None):
    """A renderer of `hair` whose own grid is padded (minimum pixel width asked for it)."""
    from tracer.settings import GRID_WIDEN_CAP
    r = Renderer(build=build, max_buffer_texels=max_buffer_texels, accel="grid")
    r.set_strands(hair)
    r.render(cam, RenderSettings(min_pixel_width=True))
    assert r.scene.grid_pad == GRID_WIDEN_CAP and r.scene.wide_grid is None
    return r


def test_the_pixel_sampler_walks_a_wide_grid_beside_the_scenes_own(grid_renderer):
    """The pixel sampler walks a grid of its own, padded for its samples' reach, built on its
    first render of new strands; the scene's grid stays unpadded, so later default renders
    (and every shadow ray) are a fresh renderer's. The image is the one it gives on a scene
    grid padded by minimum pixel width, bit for bit; new strands drop the wide grid."""
    cam = Camera.look_at((0.0, -2.5, 0.3), (0.0, 0.0, 0.3), size=(40, 40))
    hair = curls(n_strands=30)
    grid_renderer.set_strands(hair)
    refs = grid_renderer.stats.grid_refs
    rebuilds = grid_renderer.stats.grid_rebuilds
    img = grid_renderer.render(cam, RenderSettings(sampler="pixel", spp=4))
    assert grid_renderer.scene.grid_pad == 1.0 and grid_renderer.scene.wide_grid is not None
    assert grid_renderer.stats.wide_grid_refs > refs == grid_renderer.stats.grid_refs
    assert grid_renderer.stats.grid_rebuilds == rebuilds + 1
    padded = _padded(grid_renderer.build, hair, cam)
    np.testing.assert_array_equal(img, padded.render(cam, RenderSettings(sampler="pixel", spp=4)))
    assert img[..., 3].max() > 0.5
    grid_renderer.render(cam, RenderSettings(sampler="pixel", spp=9))      # the same wide grid
    assert grid_renderer.stats.grid_rebuilds == rebuilds + 1
    fresh = Renderer(build=grid_renderer.build, accel="grid")
    fresh.set_strands(hair)
    np.testing.assert_array_equal(grid_renderer.render(cam, RenderSettings()), fresh.render(cam, RenderSettings()))
    grid_renderer.set_strands(hair)
    assert grid_renderer.scene.wide_grid is None and grid_renderer.scene.grid_pad == 1.0


def test_after_minimum_pixel_width_the_pixel_sampler_walks_the_scenes_padded_grid(grid_renderer):
    """Minimum pixel width pads the scene's grid, and new strands keep the padding: the
    pixel sampler then walks that grid and builds no wide one."""
    from tracer.settings import GRID_WIDEN_CAP
    cam = Camera.look_at((0.0, -2.5, 0.3), (0.0, 0.0, 0.3), size=(40, 40))
    hair = curls(n_strands=30)
    grid_renderer.set_strands(hair)
    grid_renderer.render(cam, RenderSettings(min_pixel_width=True))
    grid_renderer.set_strands(hair)
    assert grid_renderer.scene.grid_pad == GRID_WIDEN_CAP
    img = grid_renderer.render(cam, RenderSettings(sampler="pixel", spp=4))
    assert grid_renderer.scene.wide_grid is None and img[..., 3].max() > 0.5


def test_a_wide_grid_past_one_buffer_pads_the_scenes_grid_instead(grid_renderer):
    """The wide grid's lists live in one buffer texture; past it the scene's own grid is
    padded (its lists may be split over several), and the image is the same."""
    from tracer.settings import GRID_WIDEN_CAP
    cam = Camera.look_at((0.0, -2.5, 0.3), (0.0, 0.0, 0.3), size=(40, 40))
    hair = curls(n_strands=30)
    probe = Renderer(build=grid_renderer.build, accel="grid")
    probe.set_strands(hair)
    probe.render(cam, RenderSettings(sampler="pixel", spp=4))
    wide, own = probe.stats.wide_grid_refs, probe.stats.grid_refs
    limit = (own + wide) // 2           # the scene's lists fit, the wide ones do not
    assert own < limit < wide
    small = Renderer(build=grid_renderer.build, max_buffer_texels=limit, accel="grid")
    small.set_strands(hair)
    img = small.render(cam, RenderSettings(sampler="pixel", spp=4))
    assert small.scene.wide_grid is None and small.scene.grid_pad == GRID_WIDEN_CAP
    assert small.buffers.parts("tex_idx") > 1
    np.testing.assert_array_equal(img, probe.render(cam, RenderSettings(sampler="pixel", spp=4)))
    grid_renderer.set_strands(hair)
    assert grid_renderer.scene.grid_pad == 1.0
    fresh = Renderer(build=grid_renderer.build, accel="grid")
    fresh.set_strands(hair)
    np.testing.assert_array_equal(grid_renderer.render(cam, RenderSettings()), fresh.render(cam, RenderSettings()))
    grid_renderer.render(cam, RenderSettings(min_pixel_width=True))
    grid_renderer.set_strands(hair)
    assert grid_renderer.scene.grid_pad == GRID_WIDEN_CAP

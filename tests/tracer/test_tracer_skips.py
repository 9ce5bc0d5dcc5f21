# SPDX-License-Identifier: GPL-3.0-or-later
"""The work the scene does not need is really skipped (counted with count=True)."""
import numpy as np

from tracer import Camera, Light, RenderSettings

from tracer_scenes import curls

CAM = Camera.look_at((0.4, -2.2, 0.6), (0, 0, 0.5), fov_deg=40, size=(40, 40))


def test_no_shadow_rays_with_shadows_off(renderer):
    renderer.set_strands(curls(10, 8))
    renderer.render(CAM, RenderSettings(shadows=True, count=True))
    assert renderer.stats.shadow_rays > 0
    renderer.render(CAM, RenderSettings(shadows=False, count=True))
    assert renderer.stats.shadow_rays == 0


def test_no_shadow_rays_where_a_light_gives_nothing(renderer):
    """A spot light whose cone misses the hair, or an area light that faces away from it,
    lights none of it: no shadow ray is cast toward it, and the image is the one without
    shadows. Turned toward the hair, the same lights cast them."""
    strands = curls(10, 8)
    renderer.set_strands(strands)
    lo, hi = strands.bounds()
    centre = 0.5 * (np.asarray(lo) + np.asarray(hi))
    above = tuple(centre + (0.0, 0.0, 2.0))
    for kind, extra in (("spot", dict(spot_size=0.3, falloff=True)), ("area", dict(size=(0.2, 0.2)))):
        for axis, lit in (((0.0, 0.0, 1.0), False), ((0.0, 0.0, -1.0), True)):
            light = Light(kind=kind, vector=above, axis=axis, intensity=4.0, **extra)
            img = renderer.render(CAM, RenderSettings(lights=(light,), count=True))
            rays = renderer.stats.shadow_rays
            plain = renderer.render(CAM, RenderSettings(lights=(light,), shadows=False))
            assert img[..., 3].max() > 0
            if lit:
                assert rays > 0 and not np.array_equal(img, plain), kind
            else:
                assert rays == 0, kind
                np.testing.assert_array_equal(img, plain)


def test_a_meshs_faces_turned_from_the_light_cast_no_shadow_rays(renderer):
    """A sphere under a sun: only its lit half sends shadow rays (the dark half gains nothing
    from the light whatever they found), so fewer rays than the sphere has pixels."""
    from tracer_scenes import make_strands, uv_sphere
    sphere = uv_sphere((0.0, 0.0, 0.0), 0.5)
    renderer.set_strands(make_strands([[[5, 5, 5], [5, 5, 5.1]]], radius=0.01))
    renderer.set_meshes([(*sphere, (0.6, 0.6, 0.6))])
    try:
        side = Camera.look_at((-2.5, 0.0, 0.0), (0, 0, 0), size=(48, 48), fov_deg=30)
        sun = Light(vector=(0.0, 0.0, -1.0))     # from above: the camera sees the upper half lit
        img = renderer.render(side, RenderSettings(lights=(sun,), count=True))
        covered = int(np.count_nonzero(img[..., 3] > 0))
        assert covered > 500
        rays = renderer.stats.shadow_rays
        assert 0.3 * covered < rays < 0.7 * covered
    finally:
        renderer.set_meshes(None)


def test_one_layer_when_every_alpha_is_one(renderer):
    renderer.set_strands(curls(10, 8, alpha=1.0))
    img = renderer.render(CAM, RenderSettings(layers=8, shadows=False, count=True))
    assert renderer.stats.layers_max == 1
    assert renderer.stats.layers_traced == np.count_nonzero(img[..., 3] > 0)
    renderer.set_strands(curls(10, 8, alpha=0.5))
    img = renderer.render(CAM, RenderSettings(layers=8, shadows=False, count=True))
    assert renderer.stats.layers_traced > np.count_nonzero(img[..., 3] > 0)


def test_pixels_outside_the_projected_bounds_never_trace(renderer):
    renderer.set_strands(curls(10, 8))
    far = Camera.look_at((0, -8, 0.5), (0, 0, 0.5), fov_deg=40, size=(64, 64))
    img = renderer.render(far, RenderSettings(count=True))
    x0, y0, x1, y1 = renderer.stats.screen_box
    assert renderer.stats.traversed_pixels == (x1 - x0) * (y1 - y0) < 64 * 64 / 4
    outside = np.ones((64, 64), bool)
    outside[y0:y1, x0:x1] = False
    assert np.all(img[outside] == 0)
    # and every covered pixel lies inside the box
    assert not np.any(img[outside][..., 3] > 0)


def test_camera_and_light_changes_upload_nothing(renderer):
    renderer.set_strands(curls(10, 8))
    sent = renderer.stats.bytes_uploaded
    renderer.render(CAM, RenderSettings())
    renderer.render(CAM.moved(position=(1.0, -2.0, 0.7)), RenderSettings(shading="phong", spp=4))
    assert renderer.stats.bytes_uploaded == sent


def test_update_strands_uploads_only_the_changed_rows_and_matches_a_full_upload(renderer):
    from hairio import Strands
    from tracer.scenes import wavy_cap
    s = wavy_cap(3000, 8, radius=1e-3, seed=2)
    renderer.set_strands(s)
    full_bytes = renderer.stats.bytes_uploaded
    pts = s.points.copy()
    changed = np.array([5, 6, 2900])
    rows = np.concatenate([np.arange(o, o + 8) for o in s.offsets[changed]])
    pts[rows] += 0.01
    s2 = Strands.from_arrays(pts, s.counts, s.radius, s.color, s.alpha)
    cam = Camera.frame_bounds(*s.bounds(), (48, 48))
    renderer.update_strands(changed, s2)
    partial = renderer.stats.bytes_uploaded - full_bytes
    img_update = renderer.render(cam, RenderSettings())
    renderer.set_strands(s2)
    whole = renderer.stats.bytes_uploaded - full_bytes - partial
    np.testing.assert_array_equal(img_update, renderer.render(cam, RenderSettings()))
    assert partial < whole

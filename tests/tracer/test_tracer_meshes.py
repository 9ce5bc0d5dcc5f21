# SPDX-License-Identifier: GPL-3.0-or-later
"""Opaque meshes beside the strands, against the float64 reference: they hide hair from
the camera and from the lights, take the hair's shadows and cast their own; bad meshes are
refused where they enter. Bounds as in test_tracer_vs_reference (float32 against float64:
pixels may flip only on a silhouette or shadow edge, and rarely)."""
import dataclasses

import numpy as np
import pytest

from hairio import InputError
from tracer import Camera, Light, RenderSettings, Renderer, reference_render
from tracer import layout
from tracer.meshes import mesh_set

from tracer_scenes import curls, make_strands, plane, uv_sphere
from test_tracer_vs_reference import _boundary

SUN = Light(vector=(0.2, 0.3, -1.0))


@pytest.fixture
def meshed(renderer):
    """The session's renderer, its meshes taken away again after the test (they stay on a
    renderer until the next set_meshes)."""
    yield renderer
    renderer.set_meshes(None)
GREY = (0.6, 0.6, 0.6)


def _matches_reference(renderer, strands, meshes, camera, settings):
    renderer.set_strands(strands)
    renderer.set_meshes(meshes)
    img = renderer.render(camera, settings).astype(np.float64)
    ref = reference_render(strands, camera, settings, meshes=meshes)
    assert np.all(np.isfinite(img))
    cov_g, cov_r = img[..., 3] > 1e-6, ref[..., 3] > 1e-6
    differ = cov_g != cov_r
    assert differ.mean() <= 0.01
    assert np.all(_boundary(cov_r)[differ]), "coverage differs away from a silhouette"
    err = np.abs(img - ref).max(axis=-1)
    assert np.mean(err > 2e-3) <= 0.01, f"max err {err.max():.3g}"
    return img, ref


def test_a_sphere_in_front_of_a_strand_hides_it(meshed):
    strand = make_strands([[[-0.6, 0, 0], [0, 0, 0.02], [0.6, 0, 0]]], radius=0.03)
    sphere = uv_sphere((0, -0.4, 0), 0.15)
    cam = Camera.look_at((0, -2.5, 0), (0, 0, 0), size=(64, 32), fov_deg=30)
    # Kajiya-Kay without highlight: hair then shows its colour times a grey level, as the
    # mesh does (the physically based default adds a white surface reflection).
    settings = RenderSettings(shadows=True, lights=(SUN,), specular=0.0, shading="kajiya-kay")
    img, ref = _matches_reference(meshed, strand, [(*sphere, (0.2, 0.4, 0.9))], cam, settings)
    centre = img[15, 32]
    # The sphere's centre pixel shows the sphere's colour times its lighting, nothing of the hair.
    np.testing.assert_allclose(centre[:3] / centre[2], np.array([0.2, 0.4, 0.9]) / 0.9, rtol=1e-5)
    assert centre[3] == 1.0
    # Beside the sphere the strand shows.
    hair = np.array([0.8, 0.5, 0.2])
    side = img[15, 4, :3]
    np.testing.assert_allclose(side / side[0], hair / hair[0], rtol=1e-4)
    # Without the sphere the centre pixel is hair.
    meshed.set_meshes([])
    bare = meshed.render(cam, settings)[15, 32, :3]
    np.testing.assert_allclose(bare / bare[0], hair / hair[0], rtol=1e-4)


def test_a_strand_shadows_a_plane(meshed):
    strand = make_strands([[[-0.5, 0, 0.2], [0.5, 0, 0.2]]], radius=0.04)
    floor = plane(0.0, 1.0)
    cam = Camera.look_at((0, -0.01, 2.5), (0, 0, 0), up=(0, 1, 0), size=(48, 48), fov_deg=35)
    settings = RenderSettings(shadows=True, lights=(Light(vector=(0.0, 0.0, -1.0)),))
    img, _ = _matches_reference(meshed, strand, [(*floor, GREY)], cam, settings)
    col = img[..., :3]
    # Straight down: the floor gets the full sun but under the strand (which hides that from
    # above), where it gets ambient only. The default shading's lights are irradiance (as
    # Cycles' sun strength), so the floor, a Lambertian surface, sends base colour / pi of it.
    lit_level, shadow_level = GREY[0] * (settings.ambient + 1.0 / np.pi), GREY[0] * settings.ambient
    floor_px = np.isclose(col[..., 1], col[..., 0]) & (img[..., 3] == 1.0)
    assert np.isclose(col[..., 0][floor_px], lit_level, atol=1e-4).sum() > 500
    # From the side the shadow shows.
    cam2 = Camera.look_at((0, -2.0, 1.2), (0, 0.3, 0), size=(64, 48), fov_deg=40)
    img2, _ = _matches_reference(meshed, strand, [(*floor, GREY)], cam2, settings)
    grey = img2[..., :3]
    assert np.isclose(grey[..., 0], shadow_level, atol=1e-4).sum() > 10
    assert np.isclose(grey[..., 0], lit_level, atol=1e-4).sum() > 500


def _out_of_view():
    """One strand far from every camera here: the renderer needs strands; these scenes are meshes."""
    return make_strands([[[5, 5, 5], [5, 5, 5.1]]], radius=0.01)


def _floor_points(cam):
    """Per pixel of `cam`, (H, W, 3): where its centre ray meets the floor plane(0.0, 2.0),
    lifted to where the renderer shades it (MESH_SHADOW_OFFSET × the mesh's diagonal above it);
    and (H, W) whether the ray meets the floor in front of the camera, away from its edge."""
    w, h = cam.size
    x, y = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    o, d = cam.rays(x, y)
    t = -o[..., 2] / d[..., 2]
    hit = o + t[..., None] * d
    on_floor = (t > 0) & np.all(np.abs(hit)[..., :2] < 0.99, axis=-1)
    return hit + [0.0, 0.0, layout.MESH_SHADOW_OFFSET * np.hypot(4.0, 4.0)], on_floor


def _emitted(kind, to_light, dist):
    """What leaves a light of radiant intensity 1 toward points seeing it along to_light (unit,
    (..., 3)) at dist, written out from Blender's lights: a spot of 70° and blend 0.4 pointing
    down and a little forward, an area light facing the same way."""
    if kind == "point, no fall-off":
        return np.ones_like(dist)
    axis = np.array([0.0, 0.3, -1.0]) / np.linalg.norm([0.0, 0.3, -1.0])
    c = -(to_light @ axis)
    if kind == "spot":
        cos_half = np.cos(np.radians(35.0))
        u = np.clip((c - cos_half) / ((1 - cos_half) * 0.4), 0.0, 1.0)
        return u * u * (3 - 2 * u) / dist ** 2
    if kind == "area":
        return np.maximum(c, 0.0) / dist ** 2
    return 1.0 / dist ** 2


LIGHT_KINDS = {
    "point": dict(kind="point", falloff=True),
    "point, no fall-off": dict(kind="point"),
    "spot": dict(kind="spot", axis=(0.0, 0.3, -1.0), spot_size=np.radians(70.0), spot_blend=0.4),
    "area": dict(kind="area", axis=(0.0, 0.3, -1.0)),
}


@pytest.mark.parametrize("name", sorted(LIGHT_KINDS))
def test_lights_light_a_plane_by_the_radiometry_of_their_kind(meshed, name):
    """Every pixel of a Lambertian floor under a light of radiant intensity I at height h,
    against the radiometry written out here: base colour / pi × I × emitted × cos θ, θ the angle
    from the floor's normal and `emitted` the light's fall-off, cone or emitter cosine."""
    floor = plane(0.0, 2.0)
    light = (0.3, -0.2, 0.8)
    cam = Camera.look_at((0.2, -1.6, 1.4), (0, 0, 0), size=(64, 48), fov_deg=45)
    settings = RenderSettings(shadows=True, ambient=0.0, lights=(Light(vector=light, intensity=3.0,
                                                                       **LIGHT_KINDS[name]),))
    meshed.set_strands(_out_of_view())
    meshed.set_meshes([(*floor, GREY)])
    img = meshed.render(cam, settings).astype(np.float64)
    h, w = img.shape[:2]
    p, on_floor = _floor_points(cam)
    to_light = np.asarray(light) - p
    dist = np.linalg.norm(to_light, axis=-1)
    to_light /= dist[..., None]
    expected = GREY[0] / np.pi * 3.0 * to_light[..., 2] * _emitted(name, to_light, dist)
    assert on_floor.sum() > 0.5 * h * w
    if name == "spot":              # inside, on the edge and outside the cone
        inside = expected[on_floor] > 0
        assert 0.1 < inside.mean() < 0.9
    np.testing.assert_allclose(img[..., 0][on_floor], expected[on_floor], rtol=2e-4, atol=2e-5)
    assert np.all(img[..., 3][on_floor] == 1.0)


@pytest.mark.parametrize("shape", ["rectangle", "ellipse"])
def test_an_area_light_lights_a_plane_as_its_surface_does(meshed, shape):
    """A large area light (as wide as it is high above the floor) against its irradiance
    integrated over its surface here (a 120 × 120 midpoint rule): the mean over a patch of the
    floor at 64 samples a pixel, each sample lit from a point of the light's surface. From the
    light's centre alone the floor would be 20-30 % brighter."""
    h, size = 0.6, (0.6, 0.4)
    axis, tangent = np.array([0.0, 0.0, -1.0]), np.array([1.0, 0.0, 0.0])
    light = Light("area", (0.0, 0.0, h), intensity=2.0, axis=tuple(axis), tangent=tuple(tangent), size=size,
                  shape=shape)
    floor = plane(0.0, 2.0)
    cam = Camera.look_at((0.0, 0.0, 1.5), (0, 0, 0), up=(0, 1, 0), size=(24, 24), type="ORTHO", ortho_scale=0.4)
    settings = RenderSettings(shadows=True, ambient=0.0, spp=64, lights=(light,))
    meshed.set_strands(_out_of_view())
    meshed.set_meshes([(*floor, GREY)])
    img = meshed.render(cam, settings).astype(np.float64)[..., 0]
    p = _floor_points(cam)[0].reshape(-1, 3)
    # The light's surface: radiance L = I / area, irradiance = ∫ L cos θ_light cos θ_floor / d² dA.
    g = (np.arange(120) + 0.5) / 120 * 2 - 1
    gu, gv = np.meshgrid(g, g)
    inside = np.ones_like(gu, bool) if shape == "rectangle" else gu ** 2 + gv ** 2 <= 1
    q = np.stack([gu[inside] * size[0] / 2, gv[inside] * size[1] / 2, np.full(inside.sum(), h)], axis=1)
    area = size[0] * size[1] * (np.pi / 4 if shape == "ellipse" else 1.0)
    dA = area / inside.sum()
    v = q[None] - p[:, None]
    dist2 = np.sum(v * v, axis=-1)
    cos_floor = v[..., 2] / np.sqrt(dist2)
    E = (2.0 / area * cos_floor * cos_floor / dist2).sum(axis=1) * dA      # cos θ_light = cos θ_floor here
    expected = (GREY[0] / np.pi * E).reshape(24, 24)
    assert abs(img.mean() / expected.mean() - 1.0) < 0.01, (img.mean(), expected.mean())
    assert np.quantile(np.abs(img / expected - 1.0), 0.9) < 0.08        # 64 points of the light a pixel
    centre_only = GREY[0] / np.pi * 2.0 / h ** 2
    assert centre_only > 1.15 * expected.mean()


def test_an_environment_lights_an_open_floor_by_its_radiance_and_a_tile_shades_it(meshed):
    """An even world of radiance W: a floor nothing hides sends base colour × W (the mean of
    many pixels at 64 directions each), and under a tile floating low over it much less (the
    tile hides most of its sky); the image against both float64 references' same directions."""
    W = 0.3
    env = Light("environment", intensity=4 * np.pi * W)
    floor, tile = plane(0.0, 2.0), plane(0.05, 0.3)
    cam = Camera.look_at((0.0, -0.01, 3.0), (0, 0, 0), up=(0, 1, 0), size=(40, 40), type="ORTHO", ortho_scale=3.0)
    settings = RenderSettings(shadows=True, ambient=0.0, spp=64, lights=(env,))
    meshed.set_strands(_out_of_view())
    meshed.set_meshes([(*floor, GREY)])
    open_floor = meshed.render(cam, settings)[..., 0]
    inside = np.zeros((40, 40), bool)
    inside[8:32, 8:32] = True           # the floor's pixels away from its edge
    assert abs(open_floor[inside].mean() / (GREY[0] * W) - 1.0) < 0.02
    img, ref = _matches_reference(meshed, _out_of_view(),
                                  [(*floor, GREY), (*tile, (0.0, 0.0, 0.0))], cam, settings)
    tile_px = img[..., 0] < 1e-6        # the black tile from above (8 × 8 pixels)
    assert 40 < tile_px.sum() < 120
    near = np.zeros((40, 40), bool)     # the tile grown by one pixel each way
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            near |= np.roll(np.roll(tile_px, dy, axis=0), dx, axis=1)
    ring = near & ~tile_px              # the floor just beyond the tile's edge
    assert ring.sum() > 20 and img[..., 0][ring].mean() < 0.85 * GREY[0] * W


def test_a_sun_with_an_angle_casts_a_soft_shadow(meshed):
    strand = make_strands([[[-0.5, 0, 0.3], [0.5, 0, 0.3]]], radius=0.01)
    floor = plane(0.0, 1.0)
    cam = Camera.look_at((0, 0.0, 2.0), (0, 0, 0), up=(0, 1, 0), size=(32, 32), type="ORTHO", ortho_scale=0.4)
    sun = Light(vector=(0.0, 0.0, -1.0))
    levels = {}
    for angle in (0.0, np.radians(10.0)):
        settings = RenderSettings(shadows=True, spp=64, lights=(dataclasses.replace(sun, angle=angle),))
        img, _ = _matches_reference(meshed, strand, [(*floor, GREY)], cam, settings)
        floor_px = img[..., 3] == 1.0
        shadow, lit = GREY[0] * settings.ambient, GREY[0] * (settings.ambient + 1.0 / np.pi)
        col = img[..., 0][floor_px & (np.abs(img[..., 0] - img[..., 2]) < 1e-6)]
        levels[angle] = ((col > shadow + 0.02) & (col < lit - 0.02)).sum()
    # A 0.02-wide strand 0.3 above the floor under a sun 10° wide: a penumbra 0.05 wide each side
    # of an umbra nearly gone; under a point-like sun, only the strand's edge pixels mix.
    assert levels[np.radians(10.0)] > 3 * max(levels[0.0], 1), levels


def test_a_directional_light_cannot_fall_off():
    with pytest.raises(InputError, match="falloff"):
        RenderSettings(lights=(Light("directional", (0, 0, -1), falloff=True),)).check()


def test_a_light_that_casts_no_shadows_lights_the_plane_under_the_strand(meshed):
    strand = make_strands([[[-0.5, 0, 0.2], [0.5, 0, 0.2]]], radius=0.04)
    floor = plane(0.0, 1.0)
    cam = Camera.look_at((0, -2.0, 1.2), (0, 0.3, 0), size=(64, 48), fov_deg=40)
    sun = Light(vector=(0.0, 0.0, -1.0))
    casting = RenderSettings(shadows=True, lights=(sun,))
    free = RenderSettings(shadows=True, lights=(dataclasses.replace(sun, shadows=False),))
    img, _ = _matches_reference(meshed, strand, [(*floor, GREY)], cam, free)
    shadow_level, lit_level = GREY[0] * casting.ambient, GREY[0] * (casting.ambient + 1.0 / np.pi)
    # Where the strand's shadow lay the floor is lit: no floor pixel at the shadow's level.
    assert np.isclose(meshed.render(cam, casting)[..., 0], shadow_level, atol=1e-4).sum() > 10
    assert np.isclose(img[..., 0], shadow_level, atol=1e-4).sum() == 0
    assert np.isclose(img[..., 0], lit_level, atol=1e-4).sum() > 500


def test_a_plane_shadows_strands(meshed):
    tuft = curls(16, 8, radius=0.015)
    roof = plane(1.3, 0.3, centre=(-0.3, 0.0))      # over the left half of the tuft
    cam = Camera.look_at((0, -2.6, 0.5), (0, 0, 0.5), size=(64, 48), fov_deg=40)
    # Kajiya-Kay: lit hair is well above the ambient level and brown (the levels below).
    settings = RenderSettings(shadows=True, lights=(Light(vector=(0.0, 0.0, -1.0)),), shading="kajiya-kay")
    img, ref = _matches_reference(meshed, tuft, [(*roof, GREY)], cam, settings)
    hair = (img[..., 3] > 0.99) & (img[..., 0] > 1.5 * img[..., 2])       # the brown pixels (the roof is grey)
    ambient_only = np.isclose(img[..., 0], 0.7 * settings.ambient, atol=2e-3)
    left, right = hair & (np.arange(64) < 28)[None], hair & (np.arange(64) > 36)[None]
    assert left.sum() > 30 and right.sum() > 30
    assert (ambient_only & left).sum() > 0.8 * left.sum()         # under the roof: in its shadow
    assert (ambient_only & right).sum() < 0.2 * right.sum()
    meshed.set_meshes(None)
    assert np.isclose(meshed.render(cam, settings)[..., 0], 0.7 * settings.ambient, atol=2e-3)[left].mean() < 0.5


@pytest.mark.parametrize("mesh,match", [
    ((np.array([[0, 0, 0], [1, 0, np.nan], [0, 1, 0]]), [[0, 1, 2]], GREY), "head: vertex 1 has NaN"),
    ((np.eye(3), [[0, 1, 3]], GREY), "head: triangle 0 refers to vertex 3, but the mesh has 3 vertices"),
    ((np.eye(3), np.zeros((0, 3), int), GREY), "head: no faces"),
    ((np.eye(3), [[0, 1]], GREY), r"head: triangles have shape \(1, 2\)"),
    ((np.eye(3), [[0, 1, 2]], (1.0, np.inf, 0)), "head: colour"),
    ((np.eye(4), [[0, 1, 2]], GREY), r"head: vertices have shape \(4, 4\)"),
])
def test_bad_meshes_are_refused_naming_them(mesh, match):
    with pytest.raises(InputError, match=match):
        mesh_set([(*mesh, "head")])


def test_a_refused_mesh_changes_nothing(meshed):
    s = curls(6, 6)
    meshed.set_strands(s)
    sphere = uv_sphere((0, -0.5, 0.5), 0.1)
    meshed.set_meshes([(*sphere, GREY)])
    cam = Camera.look_at((0, -2.5, 0.5), (0, 0, 0.5), size=(32, 32))
    before = meshed.render(cam)
    with pytest.raises(InputError, match="mesh 1: no faces"):
        meshed.set_meshes([(*sphere, GREY), (np.eye(3), np.zeros((0, 3), int), GREY)])
    np.testing.assert_array_equal(meshed.render(cam), before)
    assert meshed.stats.num_triangles == len(sphere[1])


def test_meshes_without_strands(meshed):
    from hairio import Strands
    floor = plane(0.0, 1.0)
    cam = Camera.look_at((0, -2.0, 1.5), (0, 0, 0), size=(32, 24))
    settings = RenderSettings(lights=(Light(vector=(0.0, 0.0, -1.0)),))
    img, ref = _matches_reference(meshed, Strands.empty(), [(*floor, GREY)], cam, settings)
    assert (img[..., 3] == 1.0).mean() > 0.3
    np.testing.assert_allclose(img[img[..., 3] == 1.0][:, :3], GREY[0] * (settings.ambient + 1.0 / np.pi), atol=1e-5)

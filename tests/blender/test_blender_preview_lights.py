# SPDX-License-Identifier: GPL-3.0-or-later
"""The preview lights a scene as Cycles does under the physically based shading: a sun at its
Strength, a point light at its Power falling off with the square of the distance, a spot light
the same within its cone, an area light at its Power / pi times the cosine from its axis, all
times 2^Exposure where Blender has it; under the other shadings every light is the thesis's
constant light of intensity 1. Checked against Cycles itself: a diffuse floor under each
light, every pixel of the preview beside Cycles' render of it."""
import importlib
import math

import numpy as np
import pytest
import bpy

from hairio import Strands


CLAY = (0.7, 0.55, 0.4)


def ext_module(extension, name):
    return importlib.import_module(f"{extension.__name__}.addon.{name}")


def _light(kind, energy, location=(0.0, 0.0, 0.0), rotation=(0.0, 0.0, 0.0), scene=None):
    data = bpy.data.lights.new(kind.title(), kind)
    data.energy = energy
    if kind in ('POINT', 'SPOT'):
        data.shadow_soft_size = 0.0          # a point, as the preview's
    if kind == 'SPOT':
        data.spot_size, data.spot_blend = math.radians(80.0), 0.4
    if kind == 'AREA':
        data.size = 0.02                     # small against its distance: the preview's point
    if kind == 'SUN':
        data.angle = 0.0
    obj = bpy.data.objects.new(kind.title(), data)
    scene = scene or bpy.context.scene
    scene.collection.objects.link(obj)
    obj.location, obj.rotation_euler = location, rotation
    scene.view_layers[0].update()
    return obj


def test_lights_reach_the_preview_at_their_power_for_the_physical_shading_only(clean):
    from tracer import RenderSettings
    preview = ext_module(clean, "preview")
    scene = bpy.context.scene
    sun = _light('SUN', 4.0, rotation=(0.3, 0.0, 0.0))
    lamp = _light('POINT', 1000.0, location=(1.0, -2.0, 3.0))
    physical = {light.kind: light for light in preview.scene_lights(scene, physical=True)}
    assert physical["directional"].intensity == pytest.approx(4.0) and not physical["directional"].falloff
    point = physical["point"]
    assert point.falloff and point.intensity == pytest.approx(1000.0 / (4.0 * math.pi))
    assert point.vector == pytest.approx((1.0, -2.0, 3.0))
    plain = preview.scene_lights(scene, physical=False)
    assert sorted((light.kind, light.intensity, light.falloff) for light in plain) == [
        ("directional", 1.0, False), ("point", 1.0, False)]
    assert all(light.shadows for light in plain)
    lamp.data.use_shadow = False            # Cast Shadow off: nothing shadows it in the preview either
    for physical_or_not in (True, False):
        by_kind = {light.kind: light for light in preview.scene_lights(scene, physical=physical_or_not)}
        assert not by_kind["point"].shadows and by_kind["directional"].shadows
    sun.data.angle = math.pi                # Blender's widest sun: sampled as 179°
    widest = next(light for light in preview.scene_lights(scene, physical=True) if light.kind == "directional")
    widest_settings = RenderSettings(lights=(widest,))
    widest_settings.check()
    assert widest.angle == pytest.approx(math.radians(179.0))
    if hasattr(lamp.data, "exposure"):       # Blender 5.0: Power × 2^Exposure
        lamp.data.exposure, sun.data.exposure = 1.0, -1.0
        lights = {light.kind: light for light in preview.scene_lights(scene, physical=True)}
        assert lights["point"].intensity == pytest.approx(2000.0 / (4.0 * math.pi))
        assert lights["directional"].intensity == pytest.approx(2.0)


def _cycles_floor(scene, size, samples=64):
    """Cycles' render of the scene, direct light only: (H, W, 3) linear RGB, row 0 at the top."""
    import os
    import tempfile
    scene.render.engine = 'CYCLES'
    c = scene.cycles
    c.device, c.samples, c.max_bounces = 'CPU', samples, 0
    c.use_denoising, c.use_adaptive_sampling = False, False
    c.pixel_filter_type, c.filter_width = 'BOX', 1.0
    scene.render.resolution_x, scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = 'Standard'
    fmt = scene.render.image_settings
    fmt.file_format, fmt.color_depth = 'OPEN_EXR', '32'
    with tempfile.TemporaryDirectory() as tmp:
        scene.render.filepath = os.path.join(tmp, "floor.exr")
        bpy.ops.render.render(write_still=True, scene=scene.name)
        img = bpy.data.images.load(scene.render.filepath)
        w, h = img.size
        px = np.empty(w * h * 4, np.float32)
        img.pixels.foreach_get(px)
        bpy.data.images.remove(img)
    return px.reshape(h, w, 4)[::-1, :, :3].astype(np.float64)


@pytest.fixture
def black_world():
    """A scene of its own (the render settings Cycles needs stay out of the other tests'),
    under a black world; removed after the test with what it holds."""
    scene = bpy.data.scenes.new("Lights")
    world = bpy.data.worlds.new("Black")
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    next(n for n in world.node_tree.nodes if n.bl_idname == "ShaderNodeBackground").inputs["Strength"].default_value = 0
    scene.world = world
    yield scene
    objects = list(scene.objects)
    bpy.data.scenes.remove(scene)
    bpy.data.worlds.remove(world)
    bpy.data.batch_remove(objects)
    for mat in [m for m in bpy.data.materials if m.name.startswith("Clay")]:
        bpy.data.materials.remove(mat)


def _floor(scene):
    """A 2 m square floor of a Lambert material (a Diffuse BSDF in Cycles, its colour as the
    viewport colour the preview falls back to when a material has no Principled BSDF)."""
    mesh = bpy.data.meshes.new("Floor")
    mesh.from_pydata([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], [], [(0, 1, 2, 3)])
    floor = bpy.data.objects.new("Floor", mesh)
    scene.collection.objects.link(floor)
    mat = bpy.data.materials.new("Clay")
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    tree = mat.node_tree
    tree.nodes.clear()
    diffuse, out = tree.nodes.new("ShaderNodeBsdfDiffuse"), tree.nodes.new("ShaderNodeOutputMaterial")
    diffuse.inputs["Color"].default_value = (*CLAY, 1.0)
    diffuse.inputs["Roughness"].default_value = 0.0
    tree.links.new(diffuse.outputs[0], out.inputs["Surface"])
    mat.diffuse_color = (*CLAY, 1.0)
    mesh.materials.append(mat)
    return floor


def _top_camera(scene):
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(cam)
    cam.data.type, cam.data.ortho_scale = 'ORTHO', 1.6
    cam.location = (0.0, 0.0, 2.0)
    scene.camera = cam
    scene.view_layers[0].update()
    return cam


def _preview_of(clean, scene, cam, size, spp=64):
    """The preview's image of `scene`'s meshes under its lights (physically based shading, no
    ambient), (H, W, 3) linear RGB: the add-on's lights and colours, the tracer's render."""
    from tracer import Renderer, RenderSettings
    preview = ext_module(clean, "preview")
    scene_data = ext_module(clean, "scene_data")
    meshes = []
    for obj in scene.objects:
        if obj.type == 'MESH':
            m = np.array(obj.matrix_world, np.float64)
            v = np.array([vert.co[:] for vert in obj.data.vertices]) @ m[:3, :3].T + m[:3, 3]
            tris = np.array([[0, 1, 2], [0, 2, 3]])
            meshes.append((v, tris, scene_data.material_base_color(obj.data.materials[0] if obj.data.materials else None)))
    renderer = Renderer()
    renderer.set_strands(Strands.from_arrays(np.array([[5.0, 5.0, 5.0], [5.0, 5.0, 5.1]], np.float32), [2]))
    renderer.set_meshes(meshes)
    settings = RenderSettings(lights=preview.scene_lights(scene, physical=True), ambient=0.0, shadows=True, spp=spp)
    return renderer.render(preview.camera_for(scene, cam, size), settings)[..., :3].astype(np.float64)


@pytest.mark.parametrize("kind", ['POINT', 'SUN', 'SPOT', 'AREA'])
def test_the_preview_lights_a_floor_as_cycles_does(clean, black_world, kind):
    scene = black_world
    _floor(scene)
    if kind == 'SUN':
        _light('SUN', 3.0, rotation=(0.5, 0.2, 0.0), scene=scene)
    else:                        # near the floor: the fall-off spans a factor of ten across it
        _light(kind, 100.0, location=(0.3, -0.2, 0.6), rotation=(0.4, 0.0, 0.0), scene=scene)
    cam = _top_camera(scene)
    size = (48, 48)
    cycles = _cycles_floor(scene, size)
    img = _preview_of(clean, scene, cam, size)
    assert cycles.mean() > 0.02, "Cycles' floor is dark: the test would prove nothing"
    lit = cycles[..., 0] > 1e-3 * cycles[..., 0].max()
    if kind == 'SPOT':                  # the cone's edge crosses the floor
        assert 0.2 < lit.mean() < 0.8
        assert abs((img[..., 0] > 1e-3 * cycles[..., 0].max()).mean() - lit.mean()) < 0.02     # the same cone
    # Delta lights (and a tiny area light) on a diffuse floor, 64 samples over each pixel on both
    # sides: they differ little but on the spot's edge.
    bright = cycles[..., 0] > 0.05 * cycles[..., 0].max()
    rel = np.abs(img - cycles)[bright] / cycles[bright]
    assert np.median(rel) < 0.01 and np.quantile(rel, 0.98) < 0.03, (np.median(rel), rel.max())
    assert np.abs(img - cycles).max() < 0.01 * cycles.max()         # the dim edge of a spot too
    if kind != 'SUN':
        assert cycles[..., 0].max() > 5 * cycles[..., 0][lit].min()     # the fall-off is in the picture


def test_an_area_light_scaled_flat_keeps_its_facing(clean):
    """Scale stretches an area light's size (Cycles' too); one scaled to nothing along its X is
    a line of light, not a light the tracer refuses."""
    from tracer import RenderSettings
    preview = ext_module(clean, "preview")
    lamp = _light('AREA', 50.0, location=(0.0, 0.0, 1.0), rotation=(0.3, 0.0, 0.0))
    lamp.data.shape, lamp.data.size, lamp.data.size_y = 'RECTANGLE', 0.4, 0.2
    lamp.scale = (2.0, 1.0, 1.0)
    bpy.context.view_layer.update()
    light = preview.scene_lights(bpy.context.scene, physical=True)[0]
    np.testing.assert_allclose(light.size, (0.8, 0.2), rtol=1e-6)
    np.testing.assert_allclose(light.axis, (0.0, math.sin(0.3), -math.cos(0.3)), atol=1e-6)
    lamp.scale = (0.0, 1.0, 1.0)
    bpy.context.view_layer.update()
    flat = preview.scene_lights(bpy.context.scene, physical=True)[0]
    np.testing.assert_allclose(flat.size, (0.0, 0.2), atol=1e-9)
    np.testing.assert_allclose(flat.axis, light.axis, atol=1e-6)
    RenderSettings(lights=(flat,)).check()


def test_past_eight_lights_the_preview_says_which_it_takes(clean):
    from types import SimpleNamespace
    from tracer.settings import MAX_LIGHTS
    preview = ext_module(clean, "preview")
    scene = bpy.context.scene
    on, off = SimpleNamespace(preview_scene_lights=True), SimpleNamespace(preview_scene_lights=False)
    lamps = [_light('POINT', 10.0, location=(i, 0.0, 2.0)) for i in range(MAX_LIGHTS)]
    assert preview.lights_note(scene, on) is None
    lamps.append(_light('POINT', 10.0, location=(0.0, 3.0, 2.0)))
    note = preview.lights_note(scene, on)
    assert note is not None and f"{MAX_LIGHTS + 1} lights" in note and f"first {MAX_LIGHTS}" in note
    assert len(preview.scene_lights(scene, physical=True)) == MAX_LIGHTS
    assert preview.lights_note(scene, off) is None
    lamps[0].hide_render = True             # hidden from renders: eight again
    assert preview.lights_note(scene, on) is None


@pytest.mark.parametrize("kind", ['AREA', 'POINT', 'SUN'])
def test_lights_with_an_extent_cast_the_soft_shadows_cycles_does(clean, black_world, kind):
    """A tile floating over the floor under a 0.5 × 0.3 m area light, a point light of 0.2 m
    radius and a sun 25° wide: the preview (64 samples) against Cycles (64 samples), both
    sampling the light's extent, over the whole image, the penumbra included. (The point light's
    sphere is sampled as the disk facing the shading point, Cycles' as the sphere: 1.3 % apart
    in the mean at this distance.)"""
    scene = black_world
    floor = _floor(scene)
    mesh = bpy.data.meshes.new("Tile")
    mesh.from_pydata([(-0.2, -0.1, 0.3), (0.2, -0.1, 0.3), (0.2, 0.1, 0.3), (-0.2, 0.1, 0.3)], [], [(0, 1, 2, 3)])
    tile = bpy.data.objects.new("Tile", mesh)
    scene.collection.objects.link(tile)
    tile.data.materials.append(floor.data.materials[0])
    if kind == 'SUN':
        sun = _light('SUN', 3.0, rotation=(0.3, 0.1, 0.0), scene=scene)
        sun.data.angle = math.radians(25.0)
    else:
        lamp = _light(kind, 100.0, location=(0.1, -0.1, 0.8), rotation=(0.1, 0.0, 0.0), scene=scene)
        if kind == 'AREA':
            lamp.data.shape, lamp.data.size, lamp.data.size_y = 'RECTANGLE', 0.5, 0.3
        else:
            lamp.data.shadow_soft_size = 0.2
    cam = _top_camera(scene)
    size = (48, 48)
    cycles = _cycles_floor(scene, size)
    img = _preview_of(clean, scene, cam, size)
    peak = cycles.max()
    tile.hide_render = True             # the floor without the tile's shadow
    open_floor = _cycles_floor(scene, size)
    shadowed = cycles[..., 0] / np.maximum(open_floor[..., 0], 1e-9)
    penumbra = (shadowed > 0.1) & (shadowed < 0.9)
    assert penumbra.sum() > 30, "no soft shadow in Cycles' image: the test would prove nothing"
    assert abs(img.mean() / cycles.mean() - 1.0) < 0.02
    err = np.abs(img - cycles) / peak
    # Both sides' own noise (64 points of the light a pixel) is most of the mean; hard shadows
    # in place of soft would put a few percent of the pixels 20-50 % of the peak off.
    assert np.mean(err) < 0.015 and np.quantile(err, 0.99) < 0.06, (np.mean(err), np.quantile(err, 0.99))

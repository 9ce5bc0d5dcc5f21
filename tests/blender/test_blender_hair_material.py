# SPDX-License-Identifier: GPL-3.0-or-later
"""The preview's "chiang" shading reads the hair's Principled Hair BSDF and the suns'
strengths, so it shows what Cycles will."""
import importlib
import math

import numpy as np
import pytest
import bpy

from hairio import Strands


def _module(extension, name):
    return importlib.import_module(f"{extension.__name__}.addon.{name}")


def _drop_hair_materials():
    for mat in [m for m in bpy.data.materials if m.name.startswith("Key-Strand Hair")]:
        bpy.data.materials.remove(mat)


@pytest.fixture(autouse=True)
def _fresh_hair_material():
    """The tests change the add-on's hair material; later tests (the preview's image against
    the tracer's defaults) must not find it so."""
    yield
    _drop_hair_materials()


def _hair(extension):
    curves = _module(extension, "blender_curves")
    _drop_hair_materials()      # a fresh add-on material, not an earlier test's
    pts = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.5]], np.float32)
    hair = curves.strands_to_curves("Hair", Strands.from_arrays(pts, [2]), collection=bpy.context.scene.collection)
    curves.ensure_hair_material(hair)
    return hair


def _sun(energy=3.0):
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", 'SUN'))
    bpy.context.scene.collection.objects.link(sun)
    sun.data.energy = energy
    return sun


class _Settings:
    preview_samples, preview_shadows, preview_shadow_mode, preview_layers = 1, True, "hard", 4
    preview_min_pixel_width, preview_scene_lights = False, True

    def __init__(self, shading):
        self.preview_shading = shading


def test_the_add_on_material_is_direct_coloring_at_cycles_defaults(clean):
    material = _module(clean, "hair_material")
    got = material.principled_hair_settings(_hair(clean))
    assert got["hair_color"] == "strand" and "hair_melanin" not in got
    assert abs(got["hair_roughness"] - 0.3) < 1e-6 and abs(got["hair_radial_roughness"] - 0.3) < 1e-6
    assert abs(got["hair_ior"] - 1.55) < 1e-6 and abs(got["hair_cuticle_tilt"] - 2.0) < 1e-5


def test_melanin_sliders_reach_the_preview_settings_and_linked_ones_do_not(clean):
    preview = _module(clean, "preview")
    hair = _hair(clean)
    tree = hair.data.materials[0].node_tree
    node = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBsdfHairPrincipled")
    node.parametrization = 'MELANIN'
    node.inputs["Melanin"].default_value = 0.35
    node.inputs["Melanin Redness"].default_value = 0.6
    node.inputs["Coat"].default_value = 0.2
    node.inputs["Offset"].default_value = math.radians(-3.0)
    value = tree.nodes.new("ShaderNodeValue")
    tree.links.new(value.outputs[0], node.inputs["Roughness"])
    rs = preview.render_settings(bpy.context.scene, _Settings("chiang"), hair)
    rs.check()
    assert (rs.hair_color, round(rs.hair_melanin, 6), round(rs.hair_melanin_redness, 6), round(rs.hair_coat, 6)) == (
        "melanin", 0.35, 0.6, 0.2)
    assert abs(rs.hair_cuticle_tilt + 3.0) < 1e-5
    assert rs.hair_roughness == 0.3          # linked: the tracer's default, not the node's


def test_suns_shine_at_their_strength_for_chiang_only(clean):
    preview = _module(clean, "preview")
    hair = _hair(clean)
    _sun(4.5)
    chiang = preview.render_settings(bpy.context.scene, _Settings("chiang"), hair)
    kk = preview.render_settings(bpy.context.scene, _Settings("kajiya-kay"), hair)
    assert [light.intensity for light in chiang.lights] == [4.5]
    assert [light.intensity for light in kk.lights] == [1.0]
    assert kk.hair_color == "strand" and kk.hair_melanin == chiang.hair_melanin   # untouched


def _plain_world(name, rgb, strength):
    """A world of one colour: a Background node of `rgb` and `strength` feeding the output."""
    world = bpy.data.worlds.new(name)
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    nodes, links = world.node_tree.nodes, world.node_tree.links
    out = next((n for n in nodes if n.bl_idname == "ShaderNodeOutputWorld"), None) or nodes.new("ShaderNodeOutputWorld")
    bg = next((n for n in nodes if n.bl_idname == "ShaderNodeBackground"), None) or nodes.new("ShaderNodeBackground")
    links.new(bg.outputs["Background"], out.inputs["Surface"])
    bg.inputs["Color"].default_value = (*rgb, 1.0)
    bg.inputs["Strength"].default_value = strength
    return world


@pytest.fixture
def world_kept():
    """The scene's world as it was, back after the test."""
    scene = bpy.context.scene
    kept = scene.world
    yield scene
    scene.world = kept


def test_the_world_lights_the_chiang_preview_as_its_ambient_term(clean, world_kept):
    from tracer import RenderSettings
    preview = _module(clean, "preview")
    hair, scene = _hair(clean), world_kept
    rgb, strength = (0.2, 0.4, 0.1), 2.5
    scene.world = _plain_world("Grey", rgb, strength)
    # A scene without lights gets the tracer's default lighting, its ambient term too.
    assert preview.render_settings(scene, _Settings("chiang"), hair).ambient == RenderSettings().ambient
    sun = _sun()
    luminance = 0.2126 * 0.2 + 0.7152 * 0.4 + 0.0722 * 0.1
    assert preview.render_settings(scene, _Settings("chiang"), hair).ambient == pytest.approx(strength * luminance)
    # The world is a light of the physically based shading only, and only with the scene's lights.
    assert preview.render_settings(scene, _Settings("kajiya-kay"), hair).ambient == RenderSettings().ambient
    off = _Settings("chiang")
    off.preview_scene_lights = False
    assert preview.render_settings(scene, off, hair).ambient == RenderSettings().ambient
    # A black world, or none, gives Cycles no light: no ambient term.
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    assert preview.render_settings(scene, _Settings("chiang"), hair).ambient == 0.0
    scene.world = None
    assert preview.render_settings(scene, _Settings("chiang"), hair).ambient == 0.0
    assert preview.world_note(scene, _Settings("chiang")) is None
    sun.hide_render = True          # no light of the scene's left: the default lighting again
    assert preview.render_settings(scene, _Settings("chiang"), hair).ambient == RenderSettings().ambient


def test_a_world_lit_by_a_texture_keeps_the_default_ambient_and_says_so(clean, world_kept):
    from tracer import RenderSettings
    preview = _module(clean, "preview")
    hair, scene = _hair(clean), world_kept
    _sun()
    scene.world = world = _plain_world("Sky", (0.5, 0.5, 0.5), 1.0)
    noise = world.node_tree.nodes.new("ShaderNodeTexNoise")
    world.node_tree.links.new(noise.outputs["Color"], world.node_tree.nodes["Background"].inputs["Color"])
    assert preview.render_settings(scene, _Settings("chiang"), hair).ambient == RenderSettings().ambient
    note = preview.world_note(scene, _Settings("chiang"))
    assert note is not None and "'Sky'" in note and "ambient" in note
    assert preview.world_note(scene, _Settings("kajiya-kay")) is None


@pytest.mark.skipif(bpy.app.version >= (5, 0, 0), reason="from Blender 5.0 every world uses its nodes")
def test_a_world_without_nodes_lights_with_its_colour(clean, world_kept):
    preview = _module(clean, "preview")
    hair, scene = _hair(clean), world_kept
    scene.world = world = bpy.data.worlds.new("Plain")
    world.use_nodes = False
    world.color = (0.3, 0.3, 0.6)
    _sun()
    expected = 0.2126 * 0.3 + 0.7152 * 0.3 + 0.0722 * 0.6
    assert preview.render_settings(scene, _Settings("chiang"), hair).ambient == pytest.approx(expected)

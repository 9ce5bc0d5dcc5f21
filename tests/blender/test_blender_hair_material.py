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
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", 'SUN'))
    bpy.context.scene.collection.objects.link(sun)
    sun.data.energy = 4.5
    chiang = preview.render_settings(bpy.context.scene, _Settings("chiang"), hair)
    kk = preview.render_settings(bpy.context.scene, _Settings("kajiya-kay"), hair)
    assert [light.intensity for light in chiang.lights] == [4.5]
    assert [light.intensity for light in kk.lights] == [1.0]
    assert kk.hair_color == "strand" and kk.hair_melanin == chiang.hair_melanin   # untouched

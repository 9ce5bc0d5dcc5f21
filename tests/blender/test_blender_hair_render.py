# SPDX-License-Identifier: GPL-3.0-or-later
"""The hair material renders the strand colours in Cycles (a tiny CPU render, ~1 s).

Cycles resolves an Attribute node named like one of its standard attributes ("color" is
the volume colour) to that attribute, which hair lacks, and shades the hair black; these
tests catch the material or the stored attribute drifting back to such a name.
"""
import importlib
import os
import tempfile

import numpy as np
import bpy

from hairio import Strands

# The left strands red-orange, the right ones blue: a black, grey or single-coloured
# render fails the channel ratios on one side or the other.
LEFT_RGB, RIGHT_RGB = (0.8, 0.15, 0.04), (0.04, 0.15, 0.8)
SIZE = 48


def _curves_module(extension):
    return importlib.import_module(f"{extension.__name__}.addon.blender_curves")


def _strands(n=6, per=5):
    """n thick vertical strands side by side in the plane y = 0."""
    pts = np.zeros((n, per, 3), np.float32)
    pts[:, :, 0] = np.linspace(-0.3, 0.3, n)[:, None]
    pts[:, :, 2] = np.linspace(-0.4, 0.4, per)[None, :]
    m = n * per
    color = np.where((pts[:, :, 0] < 0)[..., None], np.float32(LEFT_RGB), np.float32(RIGHT_RGB))
    return Strands.from_arrays(pts.reshape(m, 3), np.full(n, per), radius=np.full(m, 0.04, np.float32),
                               color=color.reshape(m, 3), alpha=np.ones(m, np.float32))


_SETTINGS = (("render", "engine"), ("render", "resolution_x"), ("render", "resolution_y"),
             ("render", "resolution_percentage"), ("render", "film_transparent"), ("render", "filepath"),
             ("cycles", "device"), ("cycles", "samples"), ("cycles", "use_denoising"),
             ("view_settings", "view_transform"), ("view_settings", "look"))


def _render(scene):
    """The scene's camera view as a (SIZE, SIZE, 4) float RGBA array (rows bottom up, columns
    left to right), scene settings restored after."""
    saved = [(getattr(scene, a), b, getattr(getattr(scene, a), b)) for a, b in _SETTINGS]
    fd, path = tempfile.mkstemp(suffix=".png")
    os.close(fd)
    try:
        r = scene.render
        r.engine = 'CYCLES'
        r.resolution_x = r.resolution_y = SIZE
        r.resolution_percentage = 100
        r.film_transparent = True  # background alpha 0 tells hair pixels apart
        r.filepath = path
        scene.cycles.device = 'CPU'
        scene.cycles.samples = 2
        scene.cycles.use_denoising = False
        scene.view_settings.view_transform = 'Standard'
        scene.view_settings.look = 'None'
        bpy.ops.render.render(write_still=True)
        img = bpy.data.images.load(path)
        try:
            return np.array(img.pixels[:], np.float32).reshape(SIZE, SIZE, 4)
        finally:
            bpy.data.images.remove(img)
    finally:
        for owner, name, value in saved:
            setattr(owner, name, value)
        os.remove(path)


def _scene_with_hair(curves_module):
    scene = bpy.context.scene
    hair = curves_module.strands_to_curves("Hair", _strands(), collection=scene.collection)
    curves_module.ensure_hair_material(hair)
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(cam)
    cam.location, cam.rotation_euler = (0.0, -2.0, 0.0), (1.5708, 0.0, 0.0)
    scene.camera = cam
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", 'SUN'))
    scene.collection.objects.link(sun)
    sun.data.energy = 3.0
    sun.rotation_euler = (1.2, 0.0, 0.0)  # lights the strands' camera-facing side
    return hair


def _mean_hair_rgb(pixels):
    hair = pixels[pixels[..., 3] > 0.5, :3]
    assert len(hair) > 30, f"only {len(hair)} hair pixels: the strands are not in view"
    return hair.mean(axis=0)


def _assert_strand_coloured(pixels):
    # The camera looks along +y, so the strands at x < 0 fill the image's left half.
    left = _mean_hair_rgb(pixels[:, :SIZE // 2])
    right = _mean_hair_rgb(pixels[:, SIZE // 2:])
    assert left.max() > 0.1 and right.max() > 0.1, f"hair renders black: left {left}, right {right}"
    # The Principled Hair BSDF's white primary reflection pales a single layer of strands,
    # but each side's dominant channel and a clear excess over the opposite one survive
    # (an uncoloured render has equal channels).
    assert left[0] > 1.3 * left[2] and left[0] > left[1] > left[2], f"left strands not red-orange: {left}"
    assert right[2] > 1.3 * right[0] and right[2] > right[1] > right[0], f"right strands not blue: {right}"


def test_cycles_renders_the_strand_colour(clean):
    curves = _curves_module(clean)
    hair = _scene_with_hair(curves)
    names = [n.attribute_name for n in hair.data.materials[0].node_tree.nodes if n.type == 'ATTRIBUTE']
    assert names == [curves.COLOR_ATTRIBUTE] and curves.COLOR_ATTRIBUTE in hair.data.attributes
    _assert_strand_coloured(_render(bpy.context.scene))


def test_material_and_curves_from_the_old_colour_name_are_repaired(clean):
    """A file saved when the colour was stored as "color" renders coloured after a refill."""
    curves = _curves_module(clean)
    hair = _scene_with_hair(curves)
    c = hair.data
    # Turn the object into what the earlier version wrote.
    rgba = np.empty(len(c.points) * 4, np.float32)
    c.attributes[curves.COLOR_ATTRIBUTE].data.foreach_get("color", rgba)
    c.attributes.remove(c.attributes[curves.COLOR_ATTRIBUTE])
    c.attributes.new("color", 'FLOAT_COLOR', 'POINT').data.foreach_set("color", rgba)
    mat = c.materials[0]
    [node] = [n for n in mat.node_tree.nodes if n.type == 'ATTRIBUTE']
    node.attribute_name = "color"
    # The old layout is still read ...
    np.testing.assert_array_equal(curves.curves_to_strands(hair).color, _strands().color)
    # ... and refilling plus ensuring the material moves both to the new name.
    curves.strands_to_curves("Hair", _strands(), obj=hair)
    assert curves.ensure_hair_material(hair) is mat
    assert node.attribute_name == curves.COLOR_ATTRIBUTE
    assert "color" not in c.attributes and curves.COLOR_ATTRIBUTE in c.attributes
    _assert_strand_coloured(_render(bpy.context.scene))

# SPDX-License-Identifier: GPL-3.0-or-later
"""Cycles' side of the contact sheet (section contact_sheet): a groom and the head it grows
on, lit by one sun, rendered so that Cycles computes the light transport the preview
computes, plus the coverage masks the error is measured over.

The hair and the film are set up as in benchmarks/blender_hair_shading.py (section
hair_shading, where the preview's fibre model meets Cycles' to MAE <= 0.0043): Principled
Hair BSDF (Chiang), round curves, a delta sun (angle 0, irradiance = its strength), max
bounces 0 (direct light only), a black world of strength 0, a box pixel filter of width 1,
no denoiser, adaptive sampling, clamping or glossy filter, linear floats from an OpenEXR
file. The head is a flat-shaded mesh with a Diffuse BSDF (Lambert, roughness 0) of its base
colour: Cycles' diffuse surface, radiance = base colour / pi * irradiance * cos.

The masks come from a second, cheap render of the same scene: the hair an Emission of 1,
the head an Emission of 0, the film transparent, so each pixel's red is the fraction of it
the hair covers and its alpha the fraction hair or head cover (box filter: the mean over
the pixel's area, as the preview's stratified samples take it).

Only this module (and the one it borrows from) imports bpy, lazily.
"""

import numpy as np

from benchmarks.blender_anchors import _bpy, empty_node_material
from benchmarks.blender_hair_shading import _hair_object, _material, direct_light_scene, render_exr




def _head_object(vertices, triangles):
    bpy = _bpy()
    mesh = bpy.data.meshes.new("head")
    mesh.from_pydata(np.asarray(vertices, np.float64).tolist(), [], np.asarray(triangles, np.int64).tolist())
    mesh.update()
    obj = bpy.data.objects.new("head", mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _node_material(name, kind, rgb, strength=1.0):
    """A material of one shader node: "diffuse" (Lambert) or "emission"."""
    mat, nt = empty_node_material(name)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    if kind == "diffuse":
        node = nt.nodes.new("ShaderNodeBsdfDiffuse")
        node.inputs["Roughness"].default_value = 0.0
    else:
        node = nt.nodes.new("ShaderNodeEmission")
        node.inputs["Strength"].default_value = float(strength)
    node.inputs["Color"].default_value = (*(float(c) for c in rgb), 1.0)
    if kind == "emission" and hasattr(mat, "cycles"):
        mat.cycles.emission_sampling = 'NONE'      # a mask, not a light: nothing to sample
    nt.links.new(node.outputs[0], out.inputs["Surface"])
    return mat


class _PreviewSettings:
    """The scalp's preview settings render_settings reads, at their defaults (the physically
    based shading with the scene's lights)."""
    preview_samples, preview_shadows, preview_shadow_mode, preview_layers = 1, True, "hard", 4
    preview_shading, preview_min_pixel_width, preview_scene_lights = "chiang", False, True


def _studio_lights(sc, studio):
    """The scene's sun removed, the `studio` lights (render_contact) added in its place."""
    import mathutils
    bpy = _bpy()
    for obj in [o for o in sc.objects if o.type == 'LIGHT']:
        bpy.data.objects.remove(obj)
    for i, (kind, power, location, target, extent) in enumerate(studio):
        data = bpy.data.lights.new(f"{kind.title()} {i}", kind)
        data.energy = float(power)
        if kind == 'AREA':
            data.shape, data.size = 'SQUARE', float(extent)
        else:
            data.shadow_soft_size = float(extent)
        obj = bpy.data.objects.new(data.name, data)
        sc.collection.objects.link(obj)
        obj.location = tuple(float(x) for x in location)
        aim = mathutils.Vector(tuple(float(x) for x in target)) - obj.location
        obj.rotation_euler = aim.to_track_quat('-Z', 'Y').to_euler()
    bpy.context.view_layer.update()


def _render(sc, samples, seed, transparent):
    """(H, W, 4) float64 RGBA, row 0 at the top, and the render's wall time."""
    sc.cycles.samples = int(samples)
    sc.cycles.seed = int(seed)
    sc.render.film_transparent = bool(transparent)
    return render_exr(sc)


def render_contact(strands, head_vertices, head_triangles, head_rgb, camera_matrix, size, sun_direction,
                   sun_strength, hair, samples, mask_samples=64, seeds=(1,), mask_seeds=(1,), lens=50.0,
                   sensor_width=36.0, world=0.0, studio=None):
    """Cycles' images of the strands (the Principled Hair `hair`: a dict as
    blender_hair_shading._material takes) and the head (a diffuse mesh of `head_rgb`);
    `world`: the radiance of a grey world lighting them beside the sun (0: black, no light);
    `studio`: lights in place of the sun, (kind, power, location, target, extent) each: a
    Blender light of that type and power at `location` pointing at `target`, extent its Size
    (AREA) or Radius (POINT, SPOT). Then out["lights"] and out["ambient"] are what the add-on
    makes of the scene for the preview (addon/preview.py: render_settings, its lights and the
    world's).

    Returns a dict: rgb, a list of (H, W, 3) linear RGB renders, one per seed (on a black
    film); seconds, their render times; hair, (H, W) the fraction of each pixel the hair
    covers; cover, (H, W) the fraction hair or head cover; masks, (hair, cover) per mask
    seed (the first is hair, cover; none with no mask seeds); mask_seconds."""
    bpy = _bpy()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    hair_obj = _hair_object(strands)
    head_obj = _head_object(head_vertices, head_triangles)
    hair_mat, head_mat = _material(hair), _node_material("skin", "diffuse", head_rgb)
    hair_obj.data.materials.append(hair_mat)
    head_obj.data.materials.append(head_mat)

    direct_light_scene(sc, camera_matrix, size, sun_direction, sun_strength, lens, sensor_width)
    if world:
        bg = sc.world.node_tree.nodes["Background"]
        bg.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
        bg.inputs["Strength"].default_value = float(world)
    out = {"rgb": [], "seconds": []}
    if studio is not None:
        _studio_lights(sc, studio)
        from addon import preview
        settings = preview.render_settings(sc, _PreviewSettings())
        out["lights"], out["ambient"] = settings.lights, settings.ambient

    for seed in seeds:
        img, seconds = _render(sc, samples, seed, transparent=False)
        out["rgb"].append(img[..., :3])
        out["seconds"].append(seconds)
    # The masks: the same geometry, flat white hair on a black head.
    hair_obj.data.materials[0] = _node_material("hair mask", "emission", (1.0, 1.0, 1.0))
    head_obj.data.materials[0] = _node_material("head mask", "emission", (0.0, 0.0, 0.0))
    out["masks"] = []
    for seed in mask_seeds:
        img, out["mask_seconds"] = _render(sc, mask_samples, seed, transparent=True)
        out["masks"].append((img[..., 0], img[..., 3]))
    if out["masks"]:
        out["hair"], out["cover"] = out["masks"][0]
    return out

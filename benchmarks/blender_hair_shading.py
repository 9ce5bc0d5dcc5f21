# SPDX-License-Identifier: GPL-3.0-or-later
"""Cycles' Principled Hair BSDF (Chiang model) on given strands, direct light only: the
yardstick of the preview's hair shading (section hair_shading).

Set-up, chosen so Cycles computes exactly what the preview computes: round "3D curves"; one
sun of angle 0 (a delta light: hard shadows, irradiance = its strength in W/m^2 along its
direction); max bounces 0 (camera ray, then the sun sampled at the hit: direct light only);
the world black with strength 0; a box pixel filter of width 1 (the preview's stratified
pixel samples); no denoiser, no adaptive sampling, no clamping, no glossy filter; the result
read as linear Rec.709 floats from an OpenEXR file (view transform Standard, exposure 0, so
nothing between the film and the file). Opaque black film, so each pixel is the hair's
radiance times its coverage: the preview's premultiplied RGB over a transparent background.

Only this module imports bpy, lazily, so the section reports "not measured" where Blender is
missing.
"""
import os
import tempfile
import time

import numpy as np

from benchmarks.blender_anchors import _bpy, empty_node_material


def _matrix(m):
    import mathutils
    return mathutils.Matrix(np.asarray(m, np.float64).tolist())


def _hair_object(strands):
    bpy = _bpy()
    curves = bpy.data.hair_curves.new("hair")
    curves.add_curves(np.asarray(strands.counts, np.int64).tolist())
    curves.set_types(type='POLY')
    curves.position_data.foreach_set("vector", np.ascontiguousarray(strands.points, np.float32).ravel())
    attr = curves.attributes.get("radius") or curves.attributes.new("radius", 'FLOAT', 'POINT')
    attr.data.foreach_set("value", np.ascontiguousarray(strands.radius, np.float32))
    # Not named "color": Cycles does not hand that name to shader nodes on hair curves.
    rgba = np.ones((strands.num_points, 4), np.float32)
    rgba[:, :3] = strands.color
    col = curves.attributes.new("strand_rgba", 'FLOAT_COLOR', 'POINT')
    col.data.foreach_set("color", rgba.ravel())
    obj = bpy.data.objects.new("hair", curves)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _material(hair):
    """Principled Hair (Chiang). hair: dict with parametrization "melanin" (melanin,
    melanin_redness; the strand colour as Tint) or "color" (the strand colour, Direct
    Coloring), and roughness, radial_roughness, coat, ior, offset (radians)."""
    mat, nt = empty_node_material("hair")
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    bsdf = nt.nodes.new("ShaderNodeBsdfHairPrincipled")
    bsdf.model = 'CHIANG'
    attr = nt.nodes.new("ShaderNodeAttribute")
    attr.attribute_name = "strand_rgba"
    if hair["parametrization"] == "color":
        bsdf.parametrization = 'COLOR'
        nt.links.new(attr.outputs["Color"], bsdf.inputs["Color"])
    else:
        bsdf.parametrization = 'MELANIN'
        bsdf.inputs["Melanin"].default_value = hair["melanin"]
        bsdf.inputs["Melanin Redness"].default_value = hair["melanin_redness"]
        nt.links.new(attr.outputs["Color"], bsdf.inputs["Tint"])
    bsdf.inputs["Roughness"].default_value = hair["roughness"]
    bsdf.inputs["Radial Roughness"].default_value = hair["radial_roughness"]
    bsdf.inputs["Coat"].default_value = hair["coat"]
    bsdf.inputs["IOR"].default_value = hair["ior"]
    bsdf.inputs["Offset"].default_value = hair["offset"]
    for name in ("Random Roughness", "Random Color"):    # "Random Color" exists for melanin only
        if name in bsdf.inputs:
            bsdf.inputs[name].default_value = 0.0
    nt.links.new(bsdf.outputs[0], out.inputs["Surface"])
    return mat


def render_cycles(strands, camera_matrix, size, sun_direction, sun_strength, hair, samples,
                  lens=50.0, sensor_width=36.0, threads=None, seed=1):
    """(H, W, 3) float64 linear RGB, row 0 = top, and the render's wall time in seconds."""
    bpy = _bpy()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    obj = _hair_object(strands)
    obj.data.materials.append(_material(hair))

    direct_light_scene(sc, camera_matrix, size, sun_direction, sun_strength, lens, sensor_width, threads)
    sc.render.film_transparent = False
    sc.cycles.samples = int(samples)
    sc.cycles.seed = int(seed)
    img, seconds = render_exr(sc)
    return img[..., :3], seconds


def direct_light_scene(sc, camera_matrix, size, sun_direction, sun_strength, lens=50.0, sensor_width=36.0,
                       threads=None):
    """Set scene `sc` up for a like-for-like comparison with the preview: the camera
    (`camera_matrix`, 4x4 world), one delta sun along `sun_direction`, a black world giving
    no light, Cycles on the CPU with direct light only (no bounces, no clamping, no glossy
    blur, no denoiser, no adaptive sampling), a box pixel filter one pixel wide, thick
    curves, the Standard view transform, and a 32-bit float EXR with alpha."""
    bpy = _bpy()
    cam = bpy.data.cameras.new("camera")
    cam.lens, cam.sensor_width, cam.sensor_fit = float(lens), float(sensor_width), 'AUTO'
    cam.clip_start, cam.clip_end = 1e-3, 1e4
    cam_obj = bpy.data.objects.new("camera", cam)
    sc.collection.objects.link(cam_obj)
    cam_obj.matrix_world = _matrix(camera_matrix)
    sc.camera = cam_obj

    sun = bpy.data.lights.new("sun", 'SUN')
    sun.energy, sun.angle = float(sun_strength), 0.0
    sun_obj = bpy.data.objects.new("sun", sun)
    sc.collection.objects.link(sun_obj)
    d = np.asarray(sun_direction, np.float64)
    z = -d / np.linalg.norm(d)                      # a sun shines along its local -Z
    x = np.cross((0.0, 0.0, 1.0), z) if abs(z[2]) < 0.99 else np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2] = x, np.cross(z, x), z
    sun_obj.matrix_world = _matrix(m)

    world = bpy.data.worlds.new("black")
    sc.world = world
    if hasattr(world, "use_nodes") and not world.use_nodes:
        world.use_nodes = True
    bg = world.node_tree.nodes.get("Background")
    if bg is not None:
        bg.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        bg.inputs["Strength"].default_value = 0.0

    sc.render.engine = 'CYCLES'
    c = sc.cycles
    c.device = 'CPU'
    sc.render.threads_mode = 'FIXED'
    sc.render.threads = int(threads or os.cpu_count())
    sc.render.resolution_x, sc.render.resolution_y = int(size[0]), int(size[1])
    sc.render.resolution_percentage = 100
    c.use_denoising = False
    c.use_adaptive_sampling = False
    c.max_bounces = 0
    c.transparent_max_bounces = 0
    c.sample_clamp_direct = 0.0
    c.sample_clamp_indirect = 0.0
    c.blur_glossy = 0.0
    c.pixel_filter_type = 'BOX'
    c.filter_width = 1.0
    sc.cycles_curves.shape = 'THICK'
    sc.view_settings.view_transform = 'Standard'
    sc.view_settings.look = 'None'
    sc.view_settings.exposure = 0.0
    sc.view_settings.gamma = 1.0
    fmt = sc.render.image_settings
    fmt.file_format = 'OPEN_EXR'
    fmt.color_depth = '32'
    fmt.color_mode = 'RGBA'


def render_exr(sc):
    """Render scene `sc` to a float EXR (its image settings say so) and read it back:
    ((H, W, 4) float64 RGBA, row 0 at the top, the render's wall time)."""
    bpy = _bpy()
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "cycles.exr")
        sc.render.filepath = path
        t0 = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        seconds = time.perf_counter() - t0
        img = bpy.data.images.load(path)
        w, h = img.size
        px = np.empty(w * h * 4, np.float32)
        img.pixels.foreach_get(px)
        bpy.data.images.remove(img)
    # Blender's images start at the bottom row.
    return px.reshape(h, w, 4)[::-1].astype(np.float64), seconds

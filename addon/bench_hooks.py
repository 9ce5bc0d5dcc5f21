# SPDX-License-Identifier: GPL-3.0-or-later
"""Timings of the Blender side against the pure packages alone, for the benchmark report.

    from <extension package>.addon import bench_hooks      # or `from addon import bench_hooks`
    bench_hooks.generate_timings(scalp_obj, count=100_000)
    bench_hooks.preview_timings(scalp_obj)

Both return medians over `runs` after one warm-up; comparisons belong in one run on one
machine (SPEC §8). Never called by tests.
"""
import statistics
import time

import numpy as np
import bpy

from . import blender_curves, hair, preview, scene_data
from .properties import groom_params


def _median(fn, runs):
    fn()
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def _active(obj):
    bpy.context.view_layer.objects.active = obj


def generate_timings(scalp, count=100_000, runs=5):
    """Seconds: `operator` (Generate pressed: read scene, groom, write the Curves object),
    `groom` (groom.Generator(...).generate() alone on the same arrays and collider), `write`
    (strands -> Curves object alone) and `read` (scalp + keys -> arrays), plus the
    strand/point counts. The collider is built once beforehand (groom caches it), as a second
    press of Generate finds it."""
    from groom import Generator
    settings = scalp.keystrand_hair
    old = settings.count
    settings.count = count
    try:
        depsgraph = bpy.context.evaluated_depsgraph_get()
        scalp_data, keys = hair.read_inputs(scalp, depsgraph)
        collider = hair.read_collider(scalp, depsgraph, scalp_data)
        params = groom_params(settings)
        result = Generator(scalp_data, keys, params, collider=collider).generate()

        def operator():
            _active(scalp)
            if bpy.ops.hair.generate() != {'FINISHED'}:
                raise RuntimeError("Generate failed")

        out = {
            "strands": result.strands.num_strands,
            "points": result.strands.num_points,
            "operator_s": _median(operator, runs),
            "groom_s": _median(lambda: Generator(scalp_data, keys, params, collider=collider).generate(), runs),
            "write_s": _median(lambda: hair.write_hair(scalp, result.strands, result.root_uv), runs),
            "read_s": _median(lambda: hair.read_inputs(scalp, bpy.context.evaluated_depsgraph_get()), runs),
        }
    finally:
        settings.count = old
    out["overhead_s"] = out["operator_s"] - out["groom_s"]
    return out


def preview_timings(scalp, runs=5):
    """Seconds: `operator` (Render Preview pressed, strands already uploaded: camera, render,
    pixels into the image), `tracer` (renderer.render alone, same renderer and camera),
    `upload` (set_strands of the hair), `write_image` (pixels -> image alone)."""
    settings = scalp.keystrand_hair
    hair_obj = hair.existing_hair(scalp)
    scene = bpy.context.scene
    if hair_obj is None or scene.camera is None:
        raise RuntimeError("bench: generate the hair and set a scene camera first")

    def operator():
        _active(scalp)
        if bpy.ops.hair.render_preview() != {'FINISHED'}:
            raise RuntimeError("Render Preview failed")

    out = {"operator_s": _median(operator, runs)}
    renderer = preview.current_renderer()
    camera = preview.camera_for(scene, scene.camera, preview.preview_size(scene, settings))
    rs = preview.render_settings(scene, settings)
    out["tracer_s"] = _median(lambda: renderer.render(camera, rs), runs)
    strands = preview.world_strands(hair_obj)
    out["upload_s"] = _median(lambda: renderer.set_strands(strands), max(1, runs // 2))
    pixels = np.asarray(renderer.render(camera, rs), np.float32)
    out["write_image_s"] = _median(lambda: preview.write_image(pixels), runs)
    out["read_strands_s"] = _median(lambda: blender_curves.curves_to_strands(hair_obj), runs)
    out["size"] = tuple(pixels.shape[1::-1])
    out["in_process"] = preview.in_process_requested(settings)
    out["overhead_s"] = out["operator_s"] - out["tracer_s"]
    return out


def demo_scene(preset="wavy", count=100_000):
    """A scalp with a preset's keys and a camera, for scripted benchmarks: returns the scalp."""
    import bmesh
    mesh = bpy.data.meshes.new("Bench Scalp")
    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=48, v_segments=24, radius=0.1)
    bm.to_mesh(mesh)
    bm.free()
    scalp = bpy.data.objects.new("Bench Scalp", mesh)
    bpy.context.scene.collection.objects.link(scalp)
    _active(scalp)
    from .operators import preset_files
    path = preset_files().get(preset)
    if path is None or bpy.ops.hair.load_preset(filepath=str(path)) != {'FINISHED'}:
        raise RuntimeError(f"bench: preset {preset!r} not found")
    scalp.keystrand_hair.count = count
    cam = bpy.data.objects.new("Bench Camera", bpy.data.cameras.new("Bench Camera"))
    bpy.context.scene.collection.objects.link(cam)
    cam.location = (0.0, -0.75, 0.02)
    cam.rotation_euler = (1.5708, 0.0, 0.0)
    bpy.context.scene.camera = cam
    _active(scalp)
    return scalp


__all__ = ["generate_timings", "preview_timings", "demo_scene", "scene_data"]

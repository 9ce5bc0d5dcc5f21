# SPDX-License-Identifier: GPL-3.0-or-later
"""Timings of the Blender side against the pure packages alone, for the benchmark report.

    hooks = BlenderHooks("addon")                 # this checkout's add-on, or
    hooks = BlenderHooks(f"{package}.addon")      # the installed extension's
    scalp = hooks.demo_scene("wavy", count=100_000)
    hooks.generate_timings(scalp, count=100_000)
    hooks.preview_timings(scalp)

Both timings are medians over `runs` after one warm-up; comparisons belong in one run on one
machine (SPEC §8). They drive the add-on as a user does (its operators) and call its modules
by the package given, so the extension as installed from its zip is measured too. Benchmarks
only: the extension does not ship this file, and tests never call it.
"""
import importlib
import statistics
import time

import numpy as np
import bpy


def _medians_in_turn(fns, runs):
    """Median seconds of each of `fns`, after a warm-up each, called one after another in
    `runs` rounds, so that all see the same state of a shared machine (measured one after
    the other, a host whose speed drifts moves their ratio)."""
    for fn in fns:
        fn()
    times = [[] for _ in fns]
    for _ in range(runs):
        for fn, out in zip(fns, times):
            t = time.perf_counter()
            fn()
            out.append(time.perf_counter() - t)
    return [statistics.median(t) for t in times]


def _median(fn, runs):
    """Median seconds of `runs` calls of fn after a warm-up."""
    return _medians_in_turn([fn], runs)[0]


def _active(obj):
    bpy.context.view_layer.objects.active = obj


def _uv_sphere(segments, rings, radius):
    """(vertices, faces) of a UV sphere: the poles, `rings` - 1 rings of `segments`, quads
    between the rings and triangles at the poles, numbered here (bmesh's primitive numbers
    its vertices differently in 4.2 than in 5.x: the same scene would not be the same mesh)."""
    theta = np.pi * np.arange(1, rings) / rings
    phi = 2.0 * np.pi * np.arange(segments) / segments
    ring = np.stack([np.outer(np.sin(theta), np.cos(phi)), np.outer(np.sin(theta), np.sin(phi)),
                     np.repeat(np.cos(theta)[:, None], segments, axis=1)], axis=2).reshape(-1, 3)
    vertices = np.vstack([[0.0, 0.0, 1.0], ring, [0.0, 0.0, -1.0]]) * radius
    j = np.arange(segments)
    nxt = (j + 1) % segments
    bottom = len(vertices) - 1
    faces = [(0, 1 + a, 1 + b) for a, b in zip(j, nxt)]
    for i in range(rings - 2):
        a, b = 1 + i * segments + j, 1 + i * segments + nxt
        faces += list(zip(a, a + segments, b + segments, b))
    last = 1 + (rings - 2) * segments
    faces += [(bottom, last + b, last + a) for a, b in zip(j, nxt)]
    return vertices, [tuple(int(i) for i in f) for f in faces]


class BlenderHooks:
    """The timings and the demo scene, through the add-on package `addon` (a module path)."""

    def __init__(self, addon="addon"):
        for name in ("blender_curves", "hair", "operators", "preview", "properties"):
            setattr(self, name, importlib.import_module(f"{addon}.{name}"))

    def generate_timings(self, scalp, count=100_000, runs=5):
        """Seconds: `operator` (Generate pressed: read scene, groom, write the Curves object,
        and Blender's undo step after it), `operator_no_undo` (the same without the undo step),
        `groom` (groom.Generator(...).generate() alone on the same arrays and collider), `write`
        (strands -> Curves object alone) and `read` (scalp + keys -> arrays), plus the
        strand/point counts. The collider is built once beforehand (groom caches it), as a second
        press of Generate finds it."""
        from groom import Generator
        hair, groom_params = self.hair, self.properties.groom_params
        settings = scalp.keystrand_hair
        old = settings.count
        settings.count = count
        try:
            depsgraph = bpy.context.evaluated_depsgraph_get()
            scalp_data, keys = hair.read_inputs(scalp, depsgraph)
            collider = hair.read_collider(scalp, depsgraph, scalp_data)
            params = groom_params(settings)
            result = Generator(scalp_data, keys, params, collider=collider).generate()

            def operator(undo=True):
                _active(scalp)
                if bpy.ops.hair.generate('EXEC_DEFAULT', undo) != {'FINISHED'}:
                    raise RuntimeError("Generate failed")

            op, op_no_undo, model = _medians_in_turn(
                [operator, lambda: operator(False),
                 lambda: Generator(scalp_data, keys, params, collider=collider).generate()], runs)
            out = {
                "strands": result.strands.num_strands,
                "points": result.strands.num_points,
                "operator_s": op,
                # The operator called without Blender's undo step: what the step after it costs
                # (the undo system stores the new Curves datablock) is the difference.
                "operator_no_undo_s": op_no_undo,
                "groom_s": model,
                "write_s": _median(lambda: hair.write_hair(scalp, result.strands, result.root_uv), runs),
                "read_s": _median(lambda: hair.read_inputs(scalp, bpy.context.evaluated_depsgraph_get()), runs),
            }
        finally:
            settings.count = old
        out["overhead_s"] = out["operator_s"] - out["groom_s"]
        return out

    def preview_timings(self, scalp, runs=5):
        """Seconds: `operator` (Render Preview pressed, strands already uploaded: camera, render,
        pixels into the image), `tracer` (renderer.render alone, same renderer and camera),
        `upload` (set_strands of the hair), `write_image` (pixels -> image alone)."""
        hair, preview, blender_curves = self.hair, self.preview, self.blender_curves
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

    def demo_scene(self, preset="wavy", count=100_000):
        """A scalp with a preset's keys and a camera, for scripted benchmarks: returns the scalp.
        The same mesh in every Blender, so their images can be compared."""
        mesh = bpy.data.meshes.new("Bench Scalp")
        vertices, faces = _uv_sphere(48, 24, 0.1)
        mesh.from_pydata(vertices.tolist(), [], faces)
        mesh.update()
        scalp = bpy.data.objects.new("Bench Scalp", mesh)
        bpy.context.scene.collection.objects.link(scalp)
        _active(scalp)
        path = self.operators.preset_files().get(preset)
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

# SPDX-License-Identifier: GPL-3.0-or-later
"""Generate and Render Preview timed in whichever Blender this interpreter's `bpy` is, with
the extension installed from its zip by Blender's own installer, as a user gets it (groom,
tracer and moderngl come from the zip's wheels, not from a checkout).

    PYTHON probe.py --zip dist/keystrand_hair-0.1.0.zip --count 100000 --runs 5 --out result.json

Writes JSON: Blender and Python versions, the timings of blender_hooks.py (beside this file)
driving the installed extension, and the
error figures beside them: the largest difference between the Curves object Generate wrote
and groom's own strands, and the preview image (saved as .npy beside the JSON) against the
tracer alone on the same camera.
"""
import argparse
import importlib
import json
import os
import pathlib
import platform
import shutil
import sys
import tempfile
import time

REPO_MODULE, EXT_ID = "keystrand_bench", "keystrand_hair"


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--zip", required=True)
    ap.add_argument("--count", type=int, default=100_000)
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--out", required=True)
    args = ap.parse_args(argv)
    user = tempfile.mkdtemp(prefix="keystrand-bench-user-")
    os.environ["BLENDER_USER_RESOURCES"] = user
    os.environ.setdefault("KEYSTRAND_PREVIEW_IN_PROCESS", "1")
    try:
        result = _measure(args, user)
    finally:
        shutil.rmtree(user, ignore_errors=True)
    pathlib.Path(args.out).write_text(json.dumps(result, indent=1))
    return 0


def _measure(args, user):
    import numpy as np
    import bpy
    t0 = time.perf_counter()
    repos = bpy.context.preferences.extensions.repos
    repos.new(name="bench", module=REPO_MODULE, custom_directory=str(pathlib.Path(user) / "repo"), source='USER')
    done = bpy.ops.extensions.package_install_files(filepath=str(args.zip), repo=REPO_MODULE,
                                                    enable_on_install=True)
    if done != {'FINISHED'}:
        raise RuntimeError(f"Blender's installer refused the zip: {done}")
    install_s = time.perf_counter() - t0
    package = f"bl_ext.{REPO_MODULE}.{EXT_ID}"
    # Run as a script, this folder is first on sys.path: the hooks come from here, everything
    # they drive from the installed extension.
    from blender_hooks import BlenderHooks
    hooks = BlenderHooks(f"{package}.addon")
    curves_mod = importlib.import_module(f"{package}.addon.blender_curves")
    hair_mod = importlib.import_module(f"{package}.addon.hair")
    props = importlib.import_module(f"{package}.addon.properties")
    from groom import Generator

    scalp = hooks.demo_scene("wavy", args.count)
    gen = hooks.generate_timings(scalp, count=args.count, runs=args.runs)
    # Error beside the time: what Generate wrote against groom run directly on the same input.
    settings = scalp.keystrand_hair
    settings.count = args.count
    bpy.context.view_layer.objects.active = scalp
    bpy.ops.hair.generate()
    hair_obj = hair_mod.existing_hair(scalp)
    written = curves_mod.curves_to_strands(hair_obj)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    scalp_data, keys = hair_mod.read_inputs(scalp, depsgraph)
    collider = hair_mod.read_collider(scalp, depsgraph, scalp_data)
    direct = Generator(scalp_data, keys, props.groom_params(settings), collider=collider).generate().strands
    same_layout = np.array_equal(written.counts, direct.counts)
    gen["max_point_difference"] = (float(np.abs(written.points - direct.points.astype(np.float32)).max())
                                   if same_layout else None)
    pre = hooks.preview_timings(scalp, runs=args.runs)
    image = bpy.data.images.get("Hair Preview")
    w, h = image.size
    shown = np.empty(w * h * 4, np.float32)
    image.pixels.foreach_get(shown)
    shown = shown.reshape(h, w, 4)
    preview = importlib.import_module(f"{package}.addon.preview")
    scene = bpy.context.scene
    renderer = preview.current_renderer()
    camera = preview.camera_for(scene, scene.camera, preview.preview_size(scene, settings))
    alone = np.asarray(renderer.render(camera, preview.render_settings(scene, settings)), np.float32)
    if alone.shape != shown.shape:
        pre["image_rmse_vs_tracer"] = None
    else:
        # Blender images are stored bottom row first; compare either orientation's best.
        pre["image_rmse_vs_tracer"] = float(min(np.sqrt(np.mean((shown - alone) ** 2)),
                                                np.sqrt(np.mean((shown[::-1] - alone) ** 2))))
    pre["covered_pixels"] = int((alone[..., 3] > 0).sum())
    npy = pathlib.Path(args.out).with_suffix(".npy")
    np.save(npy, alone)
    draw = _draw_to_regrown(scalp, package, props, hair_mod, Generator, runs=max(3, args.runs // 2))
    import hashlib
    import moderngl
    scalp_mesh = scalp.data
    facts = {"scalp_vertices": len(scalp_mesh.vertices), "strands": int(written.num_strands),
             "points": int(written.num_points),
             "strands_sha1": hashlib.sha1(np.ascontiguousarray(written.points).tobytes()).hexdigest()[:12],
             "preview_size": [w, h]}
    return {"draw": draw, "scene": facts, "blender": bpy.app.version_string, "python": platform.python_version(),
            "numpy": np.__version__, "moderngl": moderngl.__version__,
            "moderngl_from": str(pathlib.Path(moderngl.__file__).parent.parent),
            "install_s": install_s, "generate": gen, "preview": pre, "image": str(npy)}


def _draw_to_regrown(scalp, package, props, hair_mod, Generator, runs):
    """Seconds from the release of a drawn key (Draw Key Strand's execute, its stroke given as
    points) to the hair regrown around it at the viewport count by live update, median of
    `runs` keys drawn around the head; beside it, the largest difference between the regrown
    viewport hair and a full regeneration at the viewport count with every key."""
    import statistics
    import numpy as np
    import bpy
    live = importlib.import_module(f"{package}.addon.live")
    curves_mod = importlib.import_module(f"{package}.addon.blender_curves")
    settings = scalp.keystrand_hair
    settings.symmetry = 'NONE'
    to_key, to_hair = [], []
    for i in range(runs):
        angle = 2 * np.pi * (i + 0.5) / runs
        radial = np.array([np.cos(angle), np.sin(angle), 0.0])
        s = np.linspace(0.0, 1.0, 80)[:, None]
        stroke = (0.1 * radial + radial * (0.05 * np.sin(np.pi * s) + 0.01 * s)
                  + np.array([0.0, 0.0, -0.18]) * s)
        bpy.context.view_layer.objects.active = scalp
        t0 = time.perf_counter()
        done = bpy.ops.hair.draw_key_strand(
            stroke=[{"name": "", "location": tuple(map(float, q)), "mouse": (0.0, 0.0)} for q in stroke],
            pixel_size=5e-4, tolerance=2.0)
        t1 = time.perf_counter()
        if done != {'FINISHED'}:
            raise RuntimeError(f"Draw Key Strand did not finish: {done}")
        bpy.context.view_layer.update()
        live.process(settle=False)
        t2 = time.perf_counter()
        to_key.append(t1 - t0)
        to_hair.append(t2 - t0)
    view_count = min(settings.viewport_count, settings.count)
    shown = curves_mod.curves_to_strands(hair_mod.existing_hair(scalp))
    depsgraph = bpy.context.evaluated_depsgraph_get()
    scalp_data, keys = hair_mod.read_inputs(scalp, depsgraph)
    collider = hair_mod.read_collider(scalp, depsgraph, scalp_data)
    full = Generator(scalp_data, keys, props.groom_params(settings, view_count), collider=collider).generate().strands
    same = np.array_equal(shown.counts, full.counts)
    return {"release_to_key_s": statistics.median(to_key), "release_to_regrown_s": statistics.median(to_hair),
            "viewport_count": int(view_count), "keys": len(keys),
            "max_difference_vs_full": float(np.abs(shown.points - full.points.astype(np.float32)).max())
            if same else None}


if __name__ == "__main__":
    sys.exit(main())

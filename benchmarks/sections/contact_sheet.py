# SPDX-License-Identifier: GPL-3.0-or-later
"""Contact sheet (issues 13 and 14): every preset grown on the bundled scalp, kept out of the
bundled head, rendered with Cycles as the extension's hair material makes it (Principled
Hair BSDF, the strand colours) with the head beside it, next to the tracer's preview of the
same strands with the same head, camera and sun: its first image (the add-on's default,
one sample per pixel) and the image its refinement reaches (REFINED_SPP samples, stratified;
the Blender preview refines to 64). The preview's head is what Render Preview
shows: opaque, diffuse, the head's base colour; Cycles renders the head with a Principled
BSDF of that colour. A reading aid, not a measure: the preview's default hair shading is
Cycles' fibre model (chiang; section hair_shading measures it against Cycles alone), but
Cycles here also adds indirect light and the preview an ambient term.

Run alone: `python -m benchmarks --only contact_sheet [--full]` (quick: a quarter of each
preset's strands at 320²; full: the presets' own counts at 512²).
"""
import numpy as np

from benchmarks.harness import NotMeasured, fmt_time, once
from benchmarks.scenes import groom_api, load_preset, tracer_api, tracer_camera, view_matrix
from benchmarks.sections import left

HEAD_RGB = (0.62, 0.45, 0.36)              # a skin tone, linear
VIEW = np.array([0.45, 1.0, -0.25])        # the way the camera looks: the face and one side
SUN = np.array([0.3, 0.6, -0.75])          # the way the light travels: from the front, above
CYCLES_SAMPLES = 32
REFINED_SPP = 64


def _cycles(strands, head, matrix, size):
    """Cycles' image (H, W, 4) float, row 0 at the top, and its render time."""
    import bpy
    import tempfile
    import os
    from addon.blender_curves import ensure_hair_material, strands_to_curves
    from benchmarks.blender_anchors import _link, _matrix, look_at_matrix, reset_scene
    sc = reset_scene()
    hair = strands_to_curves("hair", strands, collection=sc.collection)
    ensure_hair_material(hair)
    mesh = bpy.data.meshes.new("head")
    mesh.from_pydata(head.vertices.tolist(), [], head.triangles.tolist())
    mesh.update()
    skin = bpy.data.materials.new("skin")
    if bpy.app.version < (5, 0, 0):
        skin.use_nodes = True
    bsdf = next(n for n in skin.node_tree.nodes if n.type == 'BSDF_PRINCIPLED')
    bsdf.inputs["Base Color"].default_value = (*HEAD_RGB, 1.0)
    mesh.materials.append(skin)
    _link(bpy.data.objects.new("head", mesh))
    cam = bpy.data.cameras.new("camera")
    cam.lens, cam.sensor_width, cam.sensor_fit = 50.0, 36.0, 'AUTO'
    cam.clip_start = 1e-3
    sc.camera = _link(bpy.data.objects.new("camera", cam))
    sc.camera.matrix_world = _matrix(matrix)
    sun = bpy.data.lights.new("sun", 'SUN')
    sun.energy, sun.angle = 3.0, 0.0
    _link(bpy.data.objects.new("sun", sun)).matrix_world = _matrix(look_at_matrix(-SUN * 10, (0, 0, 0)))
    r = sc.render
    r.engine = 'CYCLES'
    sc.cycles.device, sc.cycles.samples, sc.cycles.use_denoising = 'CPU', CYCLES_SAMPLES, False
    r.resolution_x, r.resolution_y, r.resolution_percentage = size[0], size[1], 100
    r.film_transparent = True
    sc.view_settings.view_transform, sc.view_settings.look = 'Standard', 'None'
    fd, path = tempfile.mkstemp(suffix=".exr")
    os.close(fd)
    try:
        r.filepath = path
        r.image_settings.file_format = 'OPEN_EXR'
        t, _ = once(lambda: bpy.ops.render.render(write_still=True))
        img = bpy.data.images.load(path)
        try:
            px = np.array(img.pixels[:], np.float32).reshape(size[1], size[0], 4)[::-1]
        finally:
            bpy.data.images.remove(img)
    finally:
        os.remove(path)
    return px, t


def run(sec, cfg):
    try:
        import bpy  # noqa: F401
    except ImportError as e:
        raise NotMeasured(f"bpy is not importable ({e})") from e
    groom, tracer = groom_api(), tracer_api()
    from benchmarks.harness import to_srgb8
    full = cfg.mode == "full"
    size = (512, 512) if full else (320, 320)
    scalp, head = groom.default_scalp(), groom.default_head()
    sec.text(__doc__.strip())
    sec.settings(image=f"{size[0]}x{size[1]}", strands="each preset's count" if full else "a quarter of each preset's",
                 cycles_samples=CYCLES_SAMPLES, preview="the add-on's defaults (1 spp) with the head",
                 head_rgb=HEAD_RGB)
    rows, panels = [], []
    for name in groom.list_presets():
        if left(sec) < 0:
            rows.append([name, "not measured: the section's time ran out", "", ""])
            continue
        preset = load_preset(name)
        count = preset.params.count if full else max(1000, preset.params.count // 4)
        params = preset.params.replace(count=count)
        keys = preset.keys_on(scalp)
        t_groom, result = once(lambda: groom.generate(scalp, keys, params, collider=(head.vertices, head.triangles)))
        strands = result.strands
        lo = np.minimum(strands.bounds()[0], head.vertices.min(axis=0))
        hi = np.maximum(strands.bounds()[1], head.vertices.max(axis=0))
        matrix = view_matrix(lo, hi, size, direction=VIEW)
        renderer = tracer.Renderer()
        renderer.set_strands(strands)
        renderer.set_meshes([(head.vertices, head.triangles, HEAD_RGB, "head")])
        rs = tracer.RenderSettings(lights=(tracer.Light("directional", tuple(SUN), (1, 1, 1), 3.0),))
        camera = tracer_camera(matrix, size)
        t_preview, preview = once(lambda: renderer.render(camera, rs))
        refined_spp = REFINED_SPP if full else 16
        t_refined, refined = once(lambda: renderer.render(camera, tracer.RenderSettings(
            **{**rs.__dict__, "spp": refined_spp})))
        cycles, t_cycles = _cycles(strands, head, matrix, size)
        panels.append((name, to_srgb8(cycles), to_srgb8(preview), to_srgb8(refined)))
        rows.append([name, f"{strands.num_strands:,}", fmt_time(t_cycles), fmt_time(t_preview), fmt_time(t_refined)])
    sec.table(["preset", "strands", f"Cycles ({CYCLES_SAMPLES} samples, one run)", "preview, 1 spp (one run)",
               f"preview, {REFINED_SPP if full else 16} spp (one run)"], rows)
    if panels:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, axes = plt.subplots(len(panels), 3, figsize=(9, 3 * len(panels)), squeeze=False)
        spp = REFINED_SPP if full else 16
        for row, (name, cyc, pre, ref) in zip(axes, panels):
            for ax, img, title in zip(row, (cyc, pre, ref), ("Cycles", "preview, 1 spp", f"preview, {spp} spp")):
                ax.imshow(img)
                ax.set_title(f"{name}: {title}", fontsize=8)
                ax.axis("off")
        fig.tight_layout()
        sec.figure(fig, "contact_sheet.png", "Each preset with the bundled head: Cycles (left), the tracer's "
                                             "preview at one sample per pixel (middle) and refined (right); "
                                             "same strands, camera and sun")
    sec.summary.append(f"contact sheet: {len(panels)} presets, Cycles beside the preview with the head")

# SPDX-License-Identifier: GPL-3.0-or-later
"""4. Anchors: the tracer against Blender Cycles on the CPU, same strands, same camera.

The Blender camera (matrix_world, 50 mm lens, 36 mm sensor, AUTO fit) is given to both:
to Cycles as a camera object, to the tracer through `tracer.Camera.from_blender`. Cycles'
time is the wall time of `bpy.ops.render.render` (scene sync + BVH build + sampling; persistent
data off, so every render pays all three). The tracer's "first render" is `set_strands`
(cylinders, upload, grid) + `render` on a warm GL context; "re-render" is a render after a
camera move, which uploads nothing.
"""
import os
import tempfile

import numpy as np

from benchmarks.blender_anchors import CyclesAnchor
from benchmarks.harness import TooSlow, fmt_num, fmt_time, measure, once, ratio, to_srgb8
from benchmarks.metrics import image_error
from benchmarks.scenes import (SUN_DIRECTION, crop_camera, groom_scene, orbit, pick_window, real_strands,
                               settings, tracer_api, tracer_camera, view_matrix)
from benchmarks.sections import left

REF_PAIRS = 6e7      # rays × cylinders the float64 window may cost


def _scenes(cfg):
    for count in cfg.anc_counts:
        yield f"groom wavy {count // 1000}k", lambda count=count: groom_scene("wavy", count, resolution="adaptive")[3].strands
    if cfg.anc_real:
        yield "straight.hair (real)", lambda: real_strands("straight.hair")


def run(sec, cfg):
    tracer = tracer_api()
    size = (cfg.anc_size, cfg.anc_size)
    layers = 4
    sec.text(__doc__.split("\n", 2)[2].strip())
    sec.text("Cycles set-up: " + CyclesAnchor.MATERIAL + f"; CPU device, {os.cpu_count()} threads, "
             "no denoiser, no adaptive sampling. Tracer: Kajiya-Kay, one directional light (the same "
             f"direction), hard shadows, {layers} alpha layers.")
    sec.settings(image=f"{size[0]}x{size[1]}", spp=list(cfg.anc_spp), runs=cfg.runs, layers=layers)
    rows, pics, targets = [], [], []
    scenes = list(_scenes(cfg))
    for i, (name, make) in enumerate(scenes):
        # Each scene gets an equal share of what is left; inside it the tracer may use 55 %,
        # the float64 window 15 %, Cycles the rest.
        share = left(sec) / (len(scenes) - i)
        scene_start = sec.elapsed()

        def until(fraction):
            return scene_start + fraction * share - sec.elapsed()

        strands = make()
        lo, hi = strands.bounds()
        matrix = view_matrix(lo, hi, size)
        cam = tracer_camera(matrix, size)
        moved = tracer_camera(orbit(matrix, np.radians(12), 0.5 * (lo + hi)), size)
        renderer = tracer.Renderer()
        cold, _ = once(lambda: (renderer.set_strands(strands), renderer.render(cam, settings(spp=1, layers=layers))))
        per_spp = {}
        m = len(cfg.anc_spp)
        for j, spp in enumerate(cfg.anc_spp):
            rs = settings(spp=spp, layers=layers)
            try:
                first, img = measure(lambda: (renderer.set_strands(strands), renderer.render(cam, rs))[1],
                                     runs=cfg.runs, budget=until(0.55 * (j + 0.6) / m))
                state = {"flip": False}

                def rerender():
                    state["flip"] = not state["flip"]
                    return renderer.render(moved if state["flip"] else cam, rs)

                uploaded = renderer.stats["bytes_uploaded"]
                again, _ = measure(rerender, runs=cfg.runs, budget=until(0.55 * (j + 1) / m))
                no_upload = renderer.stats["bytes_uploaded"] == uploaded
                img = renderer.render(cam, rs)
                per_spp[spp] = (first, again, no_upload, img)
            except TooSlow as exc:
                per_spp[spp] = str(exc)
        if not isinstance(per_spp.get(cfg.anc_spp[0]), tuple):
            sec.not_measured(name, f"the tracer at {cfg.anc_spp[0]} spp: {per_spp.get(cfg.anc_spp[0])}")
            continue
        # Error beside the time: float64 reference on a window of the 1-spp image.
        e = None
        ncyl = max(1, strands.num_segments)
        side = int(np.clip(np.sqrt(REF_PAIRS / ncyl), 4, 24))
        if until(0.7) > 0:
            rs1 = settings(spp=1, layers=layers)
            x0, y0 = pick_window(per_spp[cfg.anc_spp[0]][3], side, side)
            win = crop_camera(cam, x0, y0, side, side)
            e = image_error(renderer.render(win, rs1), tracer.reference_render(strands, win, rs1))
        del renderer
        cyc = CyclesAnchor(strands, matrix, size=size, sun_direction=SUN_DIRECTION, layers=layers)
        cyc_t, cyc_img = {}, None
        for j, spp in enumerate(cfg.anc_spp):
            try:
                cyc_t[spp], _ = measure(lambda: cyc.render(spp), runs=cfg.runs, budget=until(0.7 + 0.27 * (j + 1) / m))
            except TooSlow as exc:
                cyc_t[spp] = str(exc)
        if not hasattr(cyc_t[cfg.anc_spp[0]], "median"):
            sec.not_measured(f"{name}: Cycles", cyc_t[cfg.anc_spp[0]])
            continue
        shown = max(s_ for s_ in cfg.anc_spp if isinstance(per_spp[s_], tuple) and hasattr(cyc_t[s_], "median"))
        cyc.render(shown)   # the image shown beside ours, at the same samples
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "cycles.png")
            cyc.save_last(path)
            import matplotlib.image as mpimg
            cyc_img = mpimg.imread(path)
        del cyc
        c1 = cyc_t[cfg.anc_spp[0]].median
        for spp in cfg.anc_spp:
            if not isinstance(per_spp[spp], tuple) or not hasattr(cyc_t[spp], "median"):
                why = per_spp[spp] if not isinstance(per_spp[spp], tuple) else cyc_t[spp]
                rows.append([name, f"{strands.num_strands:,} / {strands.num_segments:,}", str(spp),
                             f"not measured: {why}"] + [""] * 7)
                continue
            first, again, no_upload, _ = per_spp[spp]
            err = f"{fmt_num(e['rmse'])} / {fmt_num(e['max_abs'])} / {100 * e['coverage_agree']:.1f} % ({side}² window)" \
                if (e and spp == cfg.anc_spp[0]) else ("see 1-spp row" if e else "not measured: time budget")
            rows.append([name, f"{strands.num_strands:,} / {strands.num_segments:,}", str(spp), str(cyc_t[spp]),
                         str(first), f"{ratio(first.median, cyc_t[spp].median):.2f}",
                         f"{ratio(first.median, c1):.2f}", str(again), f"{ratio(again.median, c1):.2f}",
                         "yes" if no_upload else "NO", err])
        f1, a1 = per_spp[cfg.anc_spp[0]][0].median, per_spp[cfg.anc_spp[0]][1].median
        targets.append((name, ratio(f1, c1), ratio(a1, c1)))
        sec.summary.append(f"{name}: first {fmt_time(f1)} = {ratio(f1, c1):.2f}× Cycles 1 spp ({fmt_time(c1)}); "
                           f"re-render {fmt_time(a1)} = {ratio(a1, c1):.2f}×; cold first {fmt_time(cold)}")
        pics.append((name, per_spp[shown][3], cyc_img, shown))
        sec.data.setdefault("rows", []).append({"scene": name, "cycles_1spp": c1, "first": f1, "rerender": a1})
    sec.table(["scene", "strands / cylinders", "spp", "Cycles (median)", "tracer first render (median)",
               "first / Cycles same spp", "first / Cycles 1 spp", "tracer re-render after camera move",
               "re-render / Cycles 1 spp", "re-render uploads nothing", "tracer error vs float64: RMSE / max / coverage"],
              rows, caption=f"The tracer against Cycles at {size[0]}×{size[1]} (medians, same run).")
    for name, first_r, again_r in targets:
        sec.text(f"**{name}: first render {first_r:.2f}× Cycles 1 spp (target ≤ 0.5: "
                 f"{'met' if first_r <= 0.5 else 'NOT met'}); re-render {again_r:.2f}× (target ≤ 0.25: "
                 f"{'met' if again_r <= 0.25 else 'NOT met'}).**")
    if pics:
        _side_by_side(sec, pics)


def _side_by_side(sec, pics):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(len(pics), 2, figsize=(8, 4 * len(pics)), squeeze=False)
    for row, (name, ours, cyc, spp) in zip(axes, pics):
        row[0].imshow(to_srgb8(ours))
        row[0].set_title(f"tracer, {spp} spp — {name}", fontsize=9)
        rgb = cyc[..., :3] * cyc[..., 3:4] + (1 - cyc[..., 3:4]) if cyc.shape[-1] == 4 else cyc
        row[1].imshow(np.clip(rgb, 0, 1))
        row[1].set_title(f"Cycles, {spp} spp — {name}", fontsize=9)
        for ax in row:
            ax.axis("off")
    fig.tight_layout()
    sec.figure(fig, "anchors_side_by_side.png", "The same strands and camera: tracer (left) and Cycles (right).")

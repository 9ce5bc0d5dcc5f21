# SPDX-License-Identifier: GPL-3.0-or-later
"""Acceleration structures: the BVH over cylinders (tracer/bvh.py) against the uniform grid
(tracer/grid.py), same scenes, camera, sun and settings, one renderer each, numpy builds.

Per scene: the structure's build time and size, the render time at 1 and 16 samples per
pixel (16 spp against 16 times 1 spp says how much of a pixel's work its samples share), and
the work per ray from the tracer's own counters: boxes (BVH) or cells (grid) visited and
cylinders tested per primary ray (a render without shadows) and per shadow ray (the rest of
a render with the sun, over the shadow rays it cast). Both images are compared pixel by
pixel: the structures must find the same hits. Times are wall-clock medians on a shared
machine; the ratio of the two structures, measured side by side, is the figure to read.

Run alone: `python -m benchmarks --quick --only accel` (or `--full`).
"""
import numpy as np

from hairio import InputError

from benchmarks.harness import TooSlow, fmt_num, fmt_time, measure, once
from benchmarks.scenes import groom_scene, real_strands, settings, tracer_api, tracer_camera, view_matrix
from benchmarks.sections import left, over_budget

QUICK_SCENES = (("straight.hair", None), ("wavy", 1000), ("wavy", 10000))
# 1,000,000 wavy strands make ~61 M cylinders, past the 33 M one buffer texture holds
# (set_strands refuses them; the scaling section shows where the limit lies).
FULL_SCENES = QUICK_SCENES + (("wavy", 100000),)
ACCELS = ("grid", "bvh")


def _work(renderer, camera, kw):
    """Per primary ray and per shadow ray: (structure steps, cylinder tests)."""
    renderer.render(camera, settings(**kw, shadows=False, count=True))
    p = renderer.stats.as_dict()
    renderer.render(camera, settings(**kw, count=True))
    q = renderer.stats.as_dict()
    rays = max(1, p["traversed_pixels"] * kw.get("spp", 1))
    shadow = max(1, q["shadow_rays"])
    return (p["cells_visited"] / rays, p["cylinder_tests"] / rays,
            (q["cells_visited"] - p["cells_visited"]) / shadow, (q["cylinder_tests"] - p["cylinder_tests"]) / shadow)


def _scene(name, count):
    if count is None:
        return name, real_strands(name)
    return f"{name} {count:,}", groom_scene(name, count, resolution="adaptive")[3].strands


def run(sec, cfg):
    tracer = tracer_api()
    size = (256, 256) if cfg.mode == "quick" else (512, 512)
    kw = dict(layers=4)
    scenes = QUICK_SCENES if cfg.mode == "quick" else FULL_SCENES
    runs = 3 if cfg.mode == "quick" else cfg.runs
    sec.text(__doc__.split("\n", 2)[2].strip())
    sec.settings(image=f"{size[0]}x{size[1]}", layers=4, shadows="hard, one sun", build="numpy",
                 runs=runs, spp="1 and 16")
    rows, work_rows = [], []
    for name, count in scenes:
        label = name if count is None else f"{name} {count:,}"
        if over_budget(sec, 0.8):
            rows.append([label, "not measured: time budget"] + [""] * 8)
            continue
        label, strands = _scene(name, count)
        cam = tracer_camera(view_matrix(*strands.bounds(), size), size)
        images, times = {}, {}
        for accel in ACCELS:
            r = tracer.Renderer(build="numpy", accel=accel)
            try:
                t_set, _ = once(lambda: r.set_strands(strands))
            except InputError as e:
                rows.append([label, accel, f"refused: {e}"] + [""] * 7)
                continue
            st = r.stats.as_dict()
            try:
                t1, img = measure(lambda: r.render(cam, settings(spp=1, **kw)), runs=runs,
                                  budget=left(sec, 0.8) / 4)
                t16, _ = measure(lambda: r.render(cam, settings(spp=16, **kw)), runs=1, warmup=0,
                                 budget=left(sec, 0.8) / 3)
            except TooSlow as e:
                rows.append([label, accel, fmt_time(st["accel_s"]), f"{st['accel_bytes'] / 2**20:.1f}",
                             f"not measured: {e}"] + [""] * 5)
                continue
            images[accel] = img
            times[accel] = t1.median
            pw, pt, sw, stt = _work(r, cam, kw)
            rows.append([label, accel, f"{strands.num_segments:,}", fmt_time(st["accel_s"]),
                         f"{st['accel_bytes'] / 2**20:.1f}", str(t1), fmt_time(t16.median),
                         f"{t16.median / (16 * t1.median):.2f}", fmt_num(pw), fmt_num(pt)])
            work_rows.append([label, accel, fmt_num(pw), fmt_num(pt), fmt_num(sw), fmt_num(stt)])
            sec.data.setdefault(label, {})[accel] = {
                "build_s": st["accel_s"], "bytes": st["accel_bytes"], "render_1spp_s": t1.median,
                "render_16spp_s": t16.median, "primary_steps": pw, "primary_tests": pt,
                "shadow_steps": sw, "shadow_tests": stt}
        if len(images) == 2:
            diff = float(np.abs(images["grid"] - images["bvh"]).max())
            speed = times["grid"] / times["bvh"]
            rows[-1].append(f"max |Δ| {diff:.1e}")
            sec.summary.append(f"{label}: BVH {fmt_time(times['bvh'])} vs grid {fmt_time(times['grid'])} "
                               f"at 1 spp ({speed:.2f}× the grid's speed), images equal to {diff:.1e}")
    sec.table(["scene", "structure", "cylinders", "build", "MB", "1 spp", "16 spp", "16 spp ÷ 16×(1 spp)",
               "steps / primary ray", "tests / primary ray", "images"], [r + [""] * (11 - len(r)) for r in rows],
              caption="Build, size and render time (median; 16 spp one run). Steps are BVH boxes or grid cells.")
    sec.table(["scene", "structure", "steps / primary ray", "tests / primary ray", "steps / shadow ray",
               "tests / shadow ray"], work_rows, caption="Work per ray (tracer counters, 1 spp).")

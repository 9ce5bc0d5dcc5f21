# SPDX-License-Identifier: GPL-3.0-or-later
"""Acceleration structures: the BVH over cylinder pieces (tracer/bvh.py) against the uniform
grid (tracer/grid.py), same scenes, camera, sun and settings, one renderer each, numpy builds.

Per scene: the structure's build time and size, the render time at 1 and 16 samples per
pixel (16 spp against 16 times 1 spp says how much of a pixel's work its samples share), and
the work per ray from the tracer's own counters: boxes (BVH) or cells (grid) visited and
cylinders tested per primary ray (a render without shadows) and per shadow ray (the rest of
a render with the sun, over the shadow rays it cast). Both images are compared pixel by
pixel: the structures must find the same hits.

The two structures render in turn (grid, BVH, grid, ...) so that both see the same load on
a shared machine; each time is the median of its runs, as wall-clock time and as the
process's CPU time (the driver's threads included), which another process's load disturbs
less. The ratio BVH ÷ grid is the figure to read.

1,000,000 `wavy` strands (~61 M cylinders, more than one buffer texture of the driver holds:
the cylinders and the cell lists are split over two each) are measured with the grid alone,
built by the compute passes (the default build; the numpy build's host copy of the cylinders
and its lists need several times the memory), once at 1 spp. The BVH is not built there: its
numpy build took 30 s and 280 MB at 100,000 strands and grows with the cylinders, past the
section's time and this machine's memory at ten times as many.

Run alone: `python -m benchmarks --quick --only accel` (or `--full`).
"""
import statistics
import time

import numpy as np

from hairio import InputError

from benchmarks.harness import fmt_num, fmt_time, once
from benchmarks.scenes import groom_scene, real_strands, settings, tracer_api, tracer_camera, view_matrix
from benchmarks.sections import left, over_budget

QUICK_SCENES = (("straight.hair", None), ("wavy", 1000), ("wavy", 10000))
FULL_SCENES = QUICK_SCENES + (("wavy", 100000), ("wavy", 1000000))
ACCELS = ("grid", "bvh")
# Scenes of more strands than this: the grid alone, GPU build, one run (see the module text).
HUGE_STRANDS = 500_000


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


def _alternate(renderers, camera, rs, runs):
    """Median (wall, CPU) seconds per renderer, renders taken in turn; the last images."""
    wall = {a: [] for a in renderers}
    cpu = {a: [] for a in renderers}
    images = {}
    for _ in range(runs):
        for a, r in renderers.items():
            t0, c0 = time.perf_counter(), time.process_time()
            images[a] = r.render(camera, rs)
            wall[a].append(time.perf_counter() - t0)
            cpu[a].append(time.process_time() - c0)
    return ({a: statistics.median(v) for a, v in wall.items()}, {a: statistics.median(v) for a, v in cpu.items()},
            images)


def run(sec, cfg):
    tracer = tracer_api()
    size = (256, 256) if cfg.mode == "quick" else (512, 512)
    kw = dict(layers=4)
    scenes = QUICK_SCENES if cfg.mode == "quick" else FULL_SCENES
    runs = 3
    sec.text(__doc__.split("\n", 2)[2].strip())
    sec.settings(image=f"{size[0]}x{size[1]}", layers=4, shadows="hard, one sun", build="numpy",
                 runs=f"{runs} at 1 spp, 1 at 16 spp")
    rows, work_rows = [], []
    for name, count in scenes:
        label = name if count is None else f"{name} {count:,}"
        if over_budget(sec, 0.6):
            rows.append([label, "not measured: time budget"])
            continue
        huge = count is not None and count > HUGE_STRANDS
        label, strands = _scene(name, count)
        cam = tracer_camera(view_matrix(*strands.bounds(), size), size)
        if huge:
            _huge_scene(sec, tracer, label, strands, cam, kw, rows, work_rows)
            continue
        renderers, builds = {}, {}
        for accel in ACCELS:
            r = tracer.Renderer(build="numpy", accel=accel)
            try:
                once(lambda: r.set_strands(strands))
            except InputError as e:
                rows.append([label, accel, f"refused: {e}"])
                continue
            renderers[accel], builds[accel] = r, r.stats.as_dict()
        if len(renderers) < 2:
            continue
        rs1, rs16 = settings(spp=1, **kw), settings(spp=16, **kw)
        for r in renderers.values():
            r.render(cam, rs1)          # compiles the programs
        wall1, cpu1, images = _alternate(renderers, cam, rs1, runs)
        wall16 = cpu16 = None
        if 16 * sum(wall1.values()) < left(sec, 0.8) / 2:
            wall16, cpu16, _ = _alternate(renderers, cam, rs16, 1)
        diff = float(np.abs(images["grid"] - images["bvh"]).max())
        for accel, r in renderers.items():
            st = builds[accel]
            pw, pt, sw, stt = _work(r, cam, kw)
            ratio16 = "" if cpu16 is None else f"{cpu16[accel] / (16 * cpu1[accel]):.2f}"
            rows.append([label, accel, f"{strands.num_segments:,}", fmt_time(st["accel_s"]),
                         f"{st['accel_bytes'] / 2**20:.1f}", fmt_time(wall1[accel]), fmt_time(cpu1[accel]),
                         "not measured: time budget" if cpu16 is None else fmt_time(cpu16[accel]), ratio16,
                         f"{diff:.1e}" if accel == "bvh" else ""])
            work_rows.append([label, accel, fmt_num(pw), fmt_num(pt), fmt_num(sw), fmt_num(stt)])
            sec.data.setdefault(label, {})[accel] = {
                "build_s": st["accel_s"], "bytes": st["accel_bytes"], "wall_1spp_s": wall1[accel],
                "cpu_1spp_s": cpu1[accel], "cpu_16spp_s": None if cpu16 is None else cpu16[accel],
                "primary_steps": pw, "primary_tests": pt, "shadow_steps": sw, "shadow_tests": stt}
        for r in renderers.values():     # GL buffers are not freed with their renderer
            r.buffers.release()
        ratio = cpu1["bvh"] / cpu1["grid"]
        sec.summary.append(f"{label}: BVH ÷ grid CPU time {ratio:.2f} at 1 spp (wall {fmt_time(wall1['bvh'])} vs "
                           f"{fmt_time(wall1['grid'])}); build {fmt_time(builds['bvh']['accel_s'])} vs "
                           f"{fmt_time(builds['grid']['accel_s'])}; images differ by at most {diff:.1e}")
    sec.table(["scene", "structure", "cylinders", "build", "MB", "1 spp wall", "1 spp CPU", "16 spp CPU",
               "16 spp ÷ 16×(1 spp)", "max abs diff BVH vs grid"], [r + [""] * (10 - len(r)) for r in rows],
              caption="Build (numpy; the 1,000,000-strand grid: compute passes), size and render time (medians; "
                      "grid and BVH rendered in turn). MB: the structure's buffers (grid: lists and cell table; "
                      "BVH: nodes, leaves and pieces).")
    sec.table(["scene", "structure", "steps / primary ray", "tests / primary ray", "steps / shadow ray",
               "tests / shadow ray"], work_rows,
              caption="Work per ray (tracer counters, 1 spp). Steps are BVH boxes tested or grid cells visited; "
                      "tests are cylinder (BVH: piece) intersection tests.")


def _huge_scene(sec, tracer, label, strands, cam, kw, rows, work_rows):
    """The grid alone, built by the compute passes, one render at 1 spp (see the module text)."""
    bvh_row = [label, "bvh", f"{strands.num_segments:,}", "not measured: the numpy BVH build at this size needs "
               "more time than the section has and more memory than this machine has (see the text)"]
    r = tracer.Renderer(build="auto", accel="grid")
    try:
        once(lambda: r.set_strands(strands))
    except InputError as e:
        rows.extend([[label, "grid", f"refused: {e}"], bvh_row])
        return
    st = r.stats.as_dict()
    parts = (r.buffers.parts("tex_cyl"), r.buffers.parts("tex_idx"))
    rs1 = settings(spp=1, **kw)
    try:
        r.render(cam, rs1)          # compiles the programs of the split buffers
        t0, c0 = time.perf_counter(), time.process_time()
        r.render(cam, rs1)
        wall1, cpu1 = time.perf_counter() - t0, time.process_time() - c0
        pw, pt, sw, stt = _work(r, cam, kw) if left(sec) > 3 * wall1 else (None,) * 4
    finally:
        r.buffers.release()
    build = f"{fmt_time(st['accel_s'])} ({st['grid_build']} build)"
    rows.append([label, "grid", f"{strands.num_segments:,}", build, f"{st['accel_bytes'] / 2**20:.1f}",
                 fmt_time(wall1), fmt_time(cpu1), "not measured: 16 one-spp renders of this size exceed the budget",
                 "", f"cylinders in {parts[0]} buffer textures, cell lists in {parts[1]}"])
    rows.append(bvh_row)
    if pw is None:
        work_rows.append([label, "grid", "not measured: time budget", "", "", ""])
    else:
        work_rows.append([label, "grid", fmt_num(pw), fmt_num(pt), fmt_num(sw), fmt_num(stt)])
    sec.data.setdefault(label, {})["grid"] = {
        "build_s": st["accel_s"], "build": st["grid_build"], "bytes": st["accel_bytes"], "wall_1spp_s": wall1,
        "cpu_1spp_s": cpu1, "cpu_16spp_s": None, "primary_steps": pw, "primary_tests": pt, "shadow_steps": sw,
        "shadow_tests": stt, "buffer_parts": parts, "grid_refs": st["grid_refs"], "grid_dims": st["grid_dims"]}
    sec.summary.append(f"{label}: grid only ({st['grid_build']} build {fmt_time(st['accel_s'])}, "
                       f"{st['accel_bytes'] / 2**20:.0f} MB, {st['grid_refs']:,} references), 1 spp {fmt_time(wall1)}")

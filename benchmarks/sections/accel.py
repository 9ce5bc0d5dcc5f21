# SPDX-License-Identifier: GPL-3.0-or-later
"""Acceleration structures: beams (tracer/beams.py, the default: camera rays and shadow rays
toward the sun look up a bin of lists made for their family), the uniform grid (tracer/grid.py,
the thesis's) and the BVH over cylinder pieces (tracer/bvh.py); same scenes, camera, sun and
settings, one renderer each.

Per scene: the structure's build time and size, the render time at 1 and 16 samples per
pixel (16 spp against 16 times 1 spp says how much of a pixel's work its samples share), and
the work per ray from the tracer's own counters: boxes (BVH), cells (grid) or the bin and
the list entries read (beams) and cylinders tested per primary ray (a render without
shadows) and per shadow ray (the rest of a render with the sun, over the shadow rays it
cast). A test is a full intersection test: the beams' walks first test each entry's mark,
the listed cylinder's capsule in the bin (a 2-D distance, docs/DECISIONS.md "Rays of a beam
test a cylinder's capsule first"), which the counters count as an entry read, a step. The
images are compared pixel by pixel: the structures must find the same hits.

Builds: the grid and the beams by the compute passes (the renderer's default build), the BVH
in numpy (its only build). The grid and the BVH are built by set_strands; the beams by the
first render that needs them (the camera's again at every camera move, the sun's once), and
the grid beside them only when some ray needs it: their build time is that render's. A
16-spp render builds the grid again, finer, where its rays pay for that (tracer/grid.py,
refs_per_cylinder: at 100,000 strands), and its time includes that build; the work per ray
is measured on the structures of the 1-spp renders. With
beams, 1-spp renders of dense hair leave the camera's rays to the grid, which a camera move
does not make again (tracer/scene_beams.py, CAMERA_REFS_PER_RAY): the column "camera rays"
says what they walked.

The structures render in turn (grid, beams, BVH, grid, ...) so that all see the same load on
a shared machine; each time is the median of its runs, as wall-clock time and as the
process's CPU time (the driver's threads included), which another process's load disturbs
less. The ratios to the grid are the figures to read.

1,000,000 `wavy` strands (~61 M cylinders, more than one buffer texture of the driver holds:
the cylinders and the cell lists are split over two each) are measured with the grid and the
beams, once at 1 spp, and with the grid a render of 16 samples builds there (finer cells:
tracer/grid.py, refs_per_cylinder), once at 16 spp, its build included, and its work per ray.
The BVH is not built there: its numpy build took 30 s and 280 MB at
100,000 strands and grows with the cylinders, past the section's time and this machine's
memory at ten times as many.

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
ACCELS = ("grid", "beams", "bvh")
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
            r = tracer.Renderer(accel=accel)
            try:
                once(lambda: r.set_strands(strands))
            except InputError as e:
                rows.append([label, accel, f"refused: {e}"])
                continue
            renderers[accel], builds[accel] = r, r.stats.as_dict()
        if len(renderers) < 2:
            continue
        rs1, rs16 = settings(spp=1, **kw), settings(spp=16, **kw)
        # The first render says the renders to come (the timed ones, the counters' and the
        # 16-spp one: RenderSettings.samples_to_come), so the beams are built once for them, as
        # the other structures are (a sun's lists are otherwise coarse until rays pay for fine ones).
        first = settings(spp=1, samples_to_come=runs + 2 + 16, **kw)
        for accel, r in renderers.items():
            r.render(cam, first)        # compiles the programs (and builds the beams)
            if accel == "beams":
                builds[accel] = _beams_build(r)
        wall1, cpu1, images = _alternate(renderers, cam, rs1, runs)
        camera1 = renderers["beams"].stats.camera_beams if "beams" in renderers else ""
        # The work per ray on the structures of the 1-spp renders, before a 16-spp render
        # builds the grid finer where its rays pay for that (tracer/grid.py, refs_per_cylinder).
        work = {accel: _work(r, cam, kw) for accel, r in renderers.items()}
        wall16 = cpu16 = None
        camera16 = ""
        if 16 * sum(wall1.values()) < left(sec, 0.8) / 2:
            wall16, cpu16, _ = _alternate(renderers, cam, rs16, 1)
            camera16 = renderers["beams"].stats.camera_beams if "beams" in renderers else ""
        diffs = {a: float(np.abs(images["grid"] - img).max()) for a, img in images.items() if a != "grid"}
        for accel, r in renderers.items():
            st = builds[accel]
            pw, pt, sw, stt = work[accel]
            ratio16 = "" if cpu16 is None else f"{cpu16[accel] / (16 * cpu1[accel]):.2f}"
            walked = {"grid": "grid", "bvh": "BVH"}.get(accel) or f"1 spp: {_said(camera1)}" + (
                f"; 16 spp: {_said(camera16)}" if camera16 else "")
            rows.append([label, accel, f"{strands.num_segments:,}", _build_cell(accel, st),
                         f"{st['accel_bytes'] / 2**20:.1f}", fmt_time(wall1[accel]), fmt_time(cpu1[accel]),
                         "not measured: time budget" if cpu16 is None else fmt_time(cpu16[accel]), ratio16,
                         f"{diffs[accel]:.1e}" if accel in diffs else "", walked])
            work_rows.append([label, accel, fmt_num(pw), fmt_num(pt), fmt_num(sw), fmt_num(stt)])
            sec.data.setdefault(label, {})[accel] = {
                "build_s": st["accel_s"], "bytes": st["accel_bytes"], "wall_1spp_s": wall1[accel],
                "cpu_1spp_s": cpu1[accel], "cpu_16spp_s": None if cpu16 is None else cpu16[accel],
                "wall_16spp_s": None if wall16 is None else wall16[accel],
                "primary_steps": pw, "primary_tests": pt, "shadow_steps": sw, "shadow_tests": stt}
        for r in renderers.values():     # GL buffers are not freed with their renderer
            r.buffers.release()
        parts = [f"{a} ÷ grid CPU time {cpu1[a] / cpu1['grid']:.2f} at 1 spp" for a in renderers if a != "grid"]
        if cpu16 is not None:
            parts += [f"{a} ÷ grid {cpu16[a] / cpu16['grid']:.2f} at 16 spp" for a in renderers if a != "grid"]
        sec.summary.append(f"{label}: " + ", ".join(parts) + "; builds " + ", ".join(
            f"{a} {fmt_time(builds[a]['accel_s'])}" for a in renderers) + "; images differ from the grid's by at "
            "most " + ", ".join(f"{d:.1e} ({a})" for a, d in diffs.items()))
    sec.table(["scene", "structure", "cylinders", "build", "MB", "1 spp wall", "1 spp CPU", "16 spp CPU",
               "16 spp ÷ 16×(1 spp)", "max abs diff vs grid", "camera rays walked"],
              [r + [""] * (11 - len(r)) for r in rows],
              caption="Build (grid, beams: compute passes; BVH: numpy), size and render time (medians; the "
                      "structures rendered in turn). MB: the structure's buffers (grid: lists and cell table; "
                      "beams: the camera's and the sun's lists and bin tables, with the grid's where it was built; "
                      "BVH: nodes, leaves and pieces).")
    sec.table(["scene", "structure", "steps / primary ray", "tests / primary ray", "steps / shadow ray",
               "tests / shadow ray"], work_rows,
              caption="Work per ray (tracer counters, 1 spp). Steps are BVH boxes tested, grid cells visited or "
                      "a beam ray's bin and the list entries it read, their marks tested (with beams a 1-spp camera "
                      "ray of dense hair walks the grid); tests are cylinder (BVH: piece) intersection tests.")
    if not over_budget(sec, 0.9):
        _point_light(sec, tracer, scenes, size, kw, runs)


# A point light where the sun stood, this many times the scene box's diagonal away, without a
# radius and with one of these shares of the diagonal (soft shadows, as Blender's default point
# light of 0.1 m casts: 0.004 of its distance, about 0.013 of a head's diagonal at 7 m).
POINT_DISTANCE = 3.0
POINT_RADII = (0.0, 0.01)


def _point_light(sec, tracer, scenes, size, kw, runs):
    """Shadow rays toward a point light: its beams (from its position, tracer/beams.py
    light_frame) against the grid, first render and re-render after a camera move."""
    from benchmarks.scenes import SUN_DIRECTION, orbit
    rows = []
    for name, count in scenes:
        if (count or 0) > HUGE_STRANDS or over_budget(sec, 0.95):
            continue
        label, strands = _scene(name, count)
        lo, hi = strands.bounds()
        diagonal = float(np.linalg.norm(hi - lo))
        toward = -SUN_DIRECTION / np.linalg.norm(SUN_DIRECTION)
        matrix = view_matrix(lo, hi, size)
        cams = [tracer_camera(orbit(matrix, np.radians(a), 0.5 * (lo + hi)), size) for a in (0.0, 12.0)]
        for radius in POINT_RADII:
            light = tracer.Light("point", tuple(0.5 * (lo + hi) + toward * POINT_DISTANCE * diagonal), intensity=3.0,
                                 radius=radius * diagonal)
            rows += _point_light_rows(sec, tracer, f"{label}, radius {radius:g}", strands, cams,
                                      settings(spp=1, lights=(light,), **kw), runs)
    sec.table(["scene, light's radius (of the diagonal)", "structure", "first render (median)",
               "re-render after a camera move (median)", "max abs diff vs grid", "shadow rays walked"], rows,
              caption=f"A point light where the sun stood ({POINT_DISTANCE:g} times the scene box's diagonal from "
                      f"its centre), without a radius and with one (soft shadows), 1 spp, 4 layers, "
                      f"{size[0]}×{size[1]}; first render = set_strands + render; the renderers take turns, "
                      f"{runs} rounds after one that compiles the programs. Its shadow rays take beams from the "
                      "light's position (tracer/beams.py, light_frame), or the grid where the light's lists would "
                      "be long (tracer/scene_beams.py, LIGHT_MAX_COARSENING).")


def _point_light_rows(sec, tracer, label, strands, cams, rs, runs):
    """_point_light's rows for one scene and light."""
    rows = []
    renderers = {a: tracer.Renderer(accel=a) for a in ("grid", "beams")}
    first = {a: [] for a in renderers}
    again = {a: [] for a in renderers}
    images = {}
    for _ in range(runs + 1):       # the first round compiles the programs: not counted
        for a, r in renderers.items():
            t0 = time.perf_counter()
            r.set_strands(strands)
            images[a] = r.render(cams[0], rs)
            t1 = time.perf_counter()
            r.render(cams[1], rs)
            first[a].append(t1 - t0)
            again[a].append(time.perf_counter() - t1)
    shadow = "beams" if renderers["beams"].scene.grid is None else "grid"
    diff = float(np.abs(images["grid"] - images["beams"]).max())
    for a in renderers:
        rows.append([label, a, fmt_time(statistics.median(first[a][1:])), fmt_time(statistics.median(again[a][1:])),
                     f"{diff:.1e}" if a == "beams" else "", shadow if a == "beams" else "grid"])
    sec.summary.append(f"{label}, a point light: beams first render {fmt_time(statistics.median(first['beams'][1:]))}"
                       f", re-render {fmt_time(statistics.median(again['beams'][1:]))} against the grid's "
                       f"{fmt_time(statistics.median(first['grid'][1:]))} and "
                       f"{fmt_time(statistics.median(again['grid'][1:]))}; images differ by {diff:.1e}")
    for r in renderers.values():
        r.buffers.release()
    return rows


FINE = "grid, 16-spp aim"


def _huge_grid_for_many_rays(sec, tracer, label, strands, cam, kw, rows, work_rows):
    """The grid a render of 16 samples builds on the huge scene (tracer/grid.py,
    refs_per_cylinder): one such render, which builds it (its time includes the build), then
    the work per ray on it at 1 spp, which keeps it."""
    r = tracer.Renderer(build="auto", accel="grid")
    try:
        once(lambda: r.set_strands(strands))
        t0, c0 = time.perf_counter(), time.process_time()
        r.render(cam, settings(spp=16, **kw))
        wall16, cpu16 = time.perf_counter() - t0, time.process_time() - c0
        st = r.stats.as_dict()
        parts = (r.buffers.parts("tex_cyl"), r.buffers.parts("tex_idx"))
        pw, pt, sw, stt = _work(r, cam, kw) if left(sec) > 0.25 * wall16 else (None,) * 4
    except InputError as e:
        rows.append([label, FINE, f"refused: {e}"])
        return
    finally:
        r.buffers.release()
    build = _build_cell("grid", st) + f", {st['grid_refs']:,} references"
    rows.append([label, FINE, f"{strands.num_segments:,}", build,
                 f"{st['accel_bytes'] / 2**20:.1f}", "", "",
                 f"{fmt_time(cpu16)} (wall {fmt_time(wall16)}, the build included)", "",
                 f"cylinders in {parts[0]} buffer textures, cell lists in {parts[1]}", "grid"])
    work_rows.append([label, FINE] + (["not measured: time budget", "", "", ""] if pw is None
                                      else [fmt_num(pw), fmt_num(pt), fmt_num(sw), fmt_num(stt)]))
    sec.data.setdefault(label, {})[FINE] = {
        "build_s": st["accel_s"], "bytes": st["accel_bytes"], "wall_16spp_s": wall16, "cpu_16spp_s": cpu16,
        "primary_steps": pw, "primary_tests": pt, "shadow_steps": sw, "shadow_tests": stt,
        "grid_refs": st["grid_refs"], "grid_dims": st["grid_dims"]}
    sec.summary.append(f"{label}: the grid of a 16-spp render (build {_build_cell('grid', st)}, "
                       f"{st['accel_bytes'] / 2**20:.0f} MB), 16 spp {fmt_time(wall16)} with the build"
                       + ("" if pt is None else f"; {pt:.0f} tests a camera ray, {stt:.0f} a shadow ray"))


def _said(camera_beams):
    """What the beams renderer's camera rays walked, from RenderStats.camera_beams."""
    return "grid" if camera_beams.startswith("none") else f"beams, {camera_beams}"


def _beams_build(r):
    """The stats of a beams renderer's first render, with its build as accel_s (the beams, and the
    grid where some ray needed it) and accel_bytes (their buffers: a family's entries 8 bytes
    each where they come with marks, else 4, and 8 a bin)."""
    st = r.stats.as_dict()
    grid_s = st["grid_s"] or 0.0
    families = [b for b in [r.beam_state.camera] + [s[1] for s in r.beam_state.suns if s] if b is not None]
    beam_bytes = sum((8 if b.reach is not None else 4) * b.refs + 8 * b.frame.num_bins for b in families)
    grid_bytes = 4 * st["grid_refs"] + 8 * int(np.prod(st["grid_dims"])) if st["grid_refs"] else 0
    st["accel_s"] = st["beams_s"] + grid_s
    st["accel_bytes"] = beam_bytes + grid_bytes
    st["grid_built"] = bool(st["grid_refs"])
    return st


def _build_cell(accel, st):
    if accel == "beams":
        return (f"{fmt_time(st['accel_s'])} (camera {fmt_time(st['camera_beams_s'])}, sun "
                f"{fmt_time(st['sun_beams_s'])}" + (", with the grid" if st["grid_built"] else "") + ")")
    return fmt_time(st["accel_s"]) + (f" ({st['grid_build']} build)" if accel == "grid" else " (numpy)")


def _huge_scene(sec, tracer, label, strands, cam, kw, rows, work_rows):
    """The grid and the beams, built by the compute passes, one render at 1 spp each (see the
    module text)."""
    rs1 = settings(spp=1, **kw)
    for accel in ("grid", "beams"):
        r = tracer.Renderer(build="auto", accel=accel)
        try:
            once(lambda: r.set_strands(strands))
        except InputError as e:
            rows.append([label, accel, f"refused: {e}"])
            continue
        try:
            r.render(cam, rs1)          # compiles the programs of the split buffers (and builds the beams)
            st = _beams_build(r) if accel == "beams" else r.stats.as_dict()
            parts = (r.buffers.parts("tex_cyl"), r.buffers.parts("tex_idx"))
            t0, c0 = time.perf_counter(), time.process_time()
            r.render(cam, rs1)
            wall1, cpu1 = time.perf_counter() - t0, time.process_time() - c0
            walked = "grid" if accel == "grid" else f"1 spp: {_said(r.stats.camera_beams)}"
            pw, pt, sw, stt = _work(r, cam, kw) if left(sec) > 3 * wall1 else (None,) * 4
        finally:
            r.buffers.release()
        rows.append([label, accel, f"{strands.num_segments:,}", _build_cell(accel, st),
                     f"{st['accel_bytes'] / 2**20:.1f}", fmt_time(wall1), fmt_time(cpu1),
                     "not measured: 16 one-spp renders of this size exceed the budget", "",
                     f"cylinders in {parts[0]} buffer textures, cell lists in {parts[1]}", walked])
        if pw is None:
            work_rows.append([label, accel, "not measured: time budget", "", "", ""])
        else:
            work_rows.append([label, accel, fmt_num(pw), fmt_num(pt), fmt_num(sw), fmt_num(stt)])
        sec.data.setdefault(label, {})[accel] = {
            "build_s": st["accel_s"], "build": st["grid_build"], "bytes": st["accel_bytes"], "wall_1spp_s": wall1,
            "cpu_1spp_s": cpu1, "cpu_16spp_s": None, "primary_steps": pw, "primary_tests": pt, "shadow_steps": sw,
            "shadow_tests": stt, "buffer_parts": parts, "grid_refs": st["grid_refs"], "grid_dims": st["grid_dims"]}
        sec.summary.append(f"{label}: {accel} (build {_build_cell(accel, st)}, {st['accel_bytes'] / 2**20:.0f} MB), "
                           f"1 spp {fmt_time(wall1)}")
    _huge_grid_for_many_rays(sec, tracer, label, strands, cam, kw, rows, work_rows)
    rows.append([label, "bvh", f"{strands.num_segments:,}", "not measured: the numpy BVH build at this size needs "
                 "more time than the section has and more memory than this machine has (see the text)"])

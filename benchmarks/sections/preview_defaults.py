# SPDX-License-Identifier: GPL-3.0-or-later
"""Preview defaults (issue 14, "no dust at the defaults"): the default render settings against
a 64-sample stratified reference, beside the 16-sample figure they must reach and the
candidate ways there, each with its time and its ratio to the default's time (the goal: the
16-sample error in at most twice the default's time). "The default" is the issue's: one
sample a pixel on the uniform grid, the tracer's default accelerator when the issue was
written; the candidates render on today's, beams (tracer/beams.py), so their ratios say what
the preview costs now against what it cost then. Among them the progressive preview's first
refined image: the first image at one sample and one refinement pass
(`RenderSettings.refinement`: the pixel sampler's 25 samples on opaque hair) at the next
pass's sub-pixel offset (`Camera.for_pass`), as the Blender preview shows them.

Scenes: the `wavy` preset at its own strand count on the bundled scalp, and the real
`Ratboy_mohawk.tfx` (Y up, turned Z up), each framed by the benchmark camera at 512² and
1920×1080. Error: RMSE of linear premultiplied RGBA over the pixels where either image has
any hair (alpha > 0), so dust (hair broken into dots) and haze both count. At 1920×1080 the
default's time is given for the whole frame; errors and the times they are compared with
come from the frame's middle 480×270 (Camera.window: the same pixels, samples and all).
Times: the median of the harness's runs for the one-sample settings; the many-sample
renders, a single run. On a machine shared with other work a time measured minutes after
another is no fair ratio, so each candidate timed with runs is timed interleaved with the
default (default, candidate, default, candidate, ...; both compiled and warm first), the
default on a renderer of its own whose grid no candidate pads (minimum pixel width widens
the grid's lists, which would slow the default down; the pixel sampler walks a wide grid of
its own beside the scene's); its ratio is the
candidate's median over that default's median, beside the same ratio of CPU time (the
process's, the driver's threads included), which other work on the machine moves less.

The pixel sampler (RenderSettings(sampler="pixel")) takes all of a pixel's samples in one walk
and shades each of the few strands that cover most of the pixel once, with one set of shadow
rays per pixel when the hair is opaque, as it is in both scenes (docs/DECISIONS.md, "Samples of
one pixel share the walk"); its rows beside the 16-spp row give the cost of 16 samples shared
against 16 separate ones. The default changes only for settings that meet both goals on every
scene measured.

Run alone: `python -m benchmarks --full --only preview_defaults` (15-30 minutes on 2 cores,
most of it the 64-sample references of `wavy`; the quick run's time limit stops it before
`wavy`).
"""
import os
import statistics
import time

import numpy as np

from benchmarks.harness import MIN_RUNS, NotMeasured, Timing, fmt_num, fmt_time, measure, once
from benchmarks.metrics import hair_rmse
from benchmarks.scenes import DATA, groom_scene, tracer_api, tracer_camera, view_matrix
from benchmarks.sections import left

REF_SPP = 64
TARGET_SPP = 16
# The samples a pixel the preview refines to (addon/progressive.py, TARGET_SAMPLES): its first
# image says so (RenderSettings.samples_to_come), and what it builds for the scene is sized
# for the passes to come.
PREVIEW_SAMPLES = 64
WINDOW = (480, 270)             # the middle of a 1920x1080 frame whose errors are measured
WINDOW_PIXELS = 512 * 512       # images larger than this are measured on WINDOW
MOHAWK_VIEW = np.array([0.0, 1.0, -0.2])       # from the front, a little above (the mohawk faces -Y once Z up)
# (label, RenderSettings fields over the defaults)
CANDIDATES = (
    ("min pixel width (cap 4, the default cap)", {"min_pixel_width": True}),
    ("min pixel width, cap 8", {"min_pixel_width": True, "min_pixel_width_cap": 8.0}),
    ("4 spp (stratified)", {"spp": 4}),
    # The pixel sampler: all of a pixel's samples in one walk, each strand shaded once.
    ("pixel sampler, 5² samples", {"sampler": "pixel", "spp": 25}),
    ("pixel sampler, 4² samples", {"sampler": "pixel", "spp": 16}),
    ("pixel sampler, 3² samples", {"sampler": "pixel", "spp": 9}),
    ("pixel sampler, 2² samples", {"sampler": "pixel", "spp": 4}),
)
# The progressive preview's first refined image (see the module text).
PROGRESSIVE = "the first image and one refinement pass (the preview's progressive image)"


def paired(default, job, runs):
    """(Timing of `default`, Timing of `job`, job's last result, the job's median CPU time over
    the default's): one warm-up each, then the two alternately, so both see the same load.
    The CPU time (of the process, the driver's threads included) moves less than the wall
    clock when other work takes the cores."""
    default()
    result = job()
    a, b, ca, cb = [], [], [], []
    for _ in range(max(int(runs), MIN_RUNS)):
        t0, c0 = time.perf_counter(), time.process_time()
        default()
        a.append(time.perf_counter() - t0)
        ca.append(time.process_time() - c0)
        t0, c0 = time.perf_counter(), time.process_time()
        result = job()
        b.append(time.perf_counter() - t0)
        cb.append(time.process_time() - c0)
    return Timing(a), Timing(b), result, statistics.median(cb) / statistics.median(ca)


def _progressive(tracer, renderer, camera):
    """The Blender preview's first refined image as a job: its first image (the default
    settings, one sample) and one refinement pass at the next pass's offset, the mean of their
    samples (addon/progressive.py), the first image saying how far the refinement goes."""
    first = tracer.RenderSettings(samples_to_come=PREVIEW_SAMPLES - 1)

    def job():
        a = renderer.render(camera, first).astype(np.float64)
        rs = first.refinement(renderer.all_opaque)
        b = renderer.render(camera.for_pass(1, rs.spp_n), rs).astype(np.float64)
        return ((a * first.spp + b * rs.spp) / (first.spp + rs.spp)).astype(np.float32)
    return job


def _scenes(cfg):
    path = os.path.join(DATA, "Ratboy_mohawk.tfx")
    if not os.path.exists(path):
        raise NotMeasured(f"{path} is missing (put ../shared/data beside the checkout or set HAIR_DATA)")

    def mohawk():
        from hairio.formats import read_strands
        from hairio.formats.up_axis import strands_to_z_up
        return strands_to_z_up(read_strands(path), path)
    yield "Ratboy_mohawk.tfx", mohawk, MOHAWK_VIEW
    yield "wavy", lambda: groom_scene("wavy", _preset_count())[3].strands, np.array([0.55, -1.0, -0.4])


def _preset_count():
    from benchmarks.scenes import load_preset
    return load_preset("wavy").params.count


def run(sec, cfg):
    tracer = tracer_api()
    sec.text(__doc__.strip())
    sizes = [(512, 512), (1920, 1080)]
    rows, summary = [], []
    for name, make, direction in _scenes(cfg):
        strands = make()
        renderer = tracer.Renderer()         # today's default accelerator, beams
        renderer.set_strands(strands)
        plain = tracer.Renderer(accel="grid")   # the default, its grid never padded
        plain.set_strands(strands)
        for size in sizes:
            where = f"{size[0]}×{size[1]}"
            if left(sec) < 0:
                rows.append([name, where, "not measured: the section's time ran out", "", "", "", ""])
                continue
            full_frame = tracer_camera(view_matrix(*strands.bounds(), size, direction=direction), size)
            camera = full_frame
            if size[0] * size[1] > WINDOW_PIXELS:
                # The default's time of the whole frame is the figure asked for; the errors and
                # the candidates' times come from its middle (the same pixels and samples as in
                # the whole image: Camera.window), where the 64-sample reference stays affordable.
                full, _ = measure(lambda: plain.render(full_frame, tracer.RenderSettings()), runs=cfg.runs)
                rows.append([name, where, "the issue's default (1 spp, grid), whole frame", str(full), "", "", ""])
                now, _ = measure(lambda: renderer.render(full_frame, tracer.RenderSettings()), runs=cfg.runs)
                rows.append([name, where, "1 spp with beams, whole frame", str(now), f"{now.median / full.median:.2f}",
                             "", ""])
                w, h = WINDOW
                camera = full_frame.window((size[0] - w) // 2, (size[1] - h) // 2, w, h)
                where = f"{where}, middle {w}×{h}"
            # The reference and the 16-sample figure are the same images on either accelerator.
            t_ref, ref = once(lambda: renderer.render(camera, tracer.RenderSettings(spp=REF_SPP)))
            base, img = measure(lambda: plain.render(camera, tracer.RenderSettings()), runs=cfg.runs)
            e_base = hair_rmse(img, ref)
            t16, img16 = once(lambda: plain.render(camera, tracer.RenderSettings(spp=TARGET_SPP)))
            e16 = hair_rmse(img16, ref)
            rows.append([name, where, "the issue's default (1 spp, grid)", str(base), "1.00", "1.00", fmt_num(e_base)])
            rows.append([name, where, f"{TARGET_SPP} spp (the error to reach), grid", fmt_time(t16) + " (1 run)",
                         f"{t16 / base.median:.2f}", "", fmt_num(e16)])
            met, shared = [], None
            today = (("1 spp (today's default settings, beams)", {}),)
            for label, change in today + CANDIDATES + ((PROGRESSIVE, None),):
                job = _progressive(tracer, renderer, camera) if change is None else (
                    lambda rs=tracer.RenderSettings(**change): renderer.render(camera, rs))
                dflt, timing, im, c = paired(lambda: plain.render(camera, tracer.RenderSettings()), job, cfg.runs)
                t, cell, ratio, cpu = timing.median, str(timing), timing.median / dflt.median, f"{c:.2f}"
                e = hair_rmse(im, ref)
                if change and change.get("sampler") == "pixel" and change.get("spp") == TARGET_SPP:
                    shared = t
                ok = e <= e16 and ratio <= 2.0
                met.append(ok)
                rows.append([name, where, label + (" ✓" if ok else ""), cell, f"{ratio:.2f}", cpu, fmt_num(e)])
            sec.data[f"{name} {where}"] = {"default_s": base.median, "default_rmse": e_base, "rmse_16": e16,
                                           "ref_s": t_ref, "t16_s": t16, "pixel16_s": shared,
                                           "ratios": {r[2].rstrip(" ✓"): float(r[4]) for r in rows[-len(met):]},
                                           "cpu_ratios": {r[2].rstrip(" ✓"): r[5] for r in rows[-len(met):]},
                                           "rmse": {r[2].rstrip(" ✓"): float(r[6]) for r in rows[-len(met):]}}
            summary.append(f"{name} {where}: the issue's default {fmt_num(e_base)} RMSE in {base}, 16 spp "
                           f"{fmt_num(e16)}; {sum(met)} of {len(met)} candidates meet both goals: "
                           + (", ".join(r[2].rstrip(" ✓") + f" ({r[4]}×, {r[6]})" for r in rows[-len(met):]
                                        if r[2].endswith("✓")) or "none"))
    sec.table(["scene", "image", "settings", "time (median)", "× default time", "× default CPU time",
               f"RMSE vs {REF_SPP} spp"], rows,
              caption="Default preview settings and the candidates (✓: the 16-sample error in at most twice "
                      "the default's time)")
    sec.summary.extend(summary)

# SPDX-License-Identifier: GPL-3.0-or-later
"""4. Anchors: the tracer against Blender Cycles on the CPU, same strands, same camera.

The Blender camera (matrix_world, 50 mm lens, 36 mm sensor, AUTO fit) is given to both:
to Cycles as a camera object, to the tracer through `tracer.Camera.from_blender`. Cycles'
time is the wall time of `bpy.ops.render.render` (scene sync + BVH build + sampling; persistent
data off, so every render pays all three). The tracer's "first render" is `set_strands`
(cylinders, upload) + `render` on a warm GL context, with its default accelerator, beams
(tracer/beams.py): the render builds the camera's beams and the sun's, and the grid where
some ray is left to it (a 1-spp render of dense hair leaves the camera's rays to the grid);
"re-render" is a render after a camera move, which uploads nothing and builds the camera's
beams again (the sun's are kept). The same Renderer serves every run of a scene, as in an
interactive session, so runs after the first reuse its GPU allocations; the cold first
render (new context allocations and shader compiles) is reported beside each scene, and the
stages of each first render (what its camera rays walked, what it built) below the table.

At each sample count of the independent samples the two take turns: after a warm-up of
each, every round (5, or up to 15 where they are short) times one first render, one
re-render and one Cycles render, so that both see the same state of a shared machine (timed
one block after the other, the ratios moved between runs more than the code did:
straight.hair's first render at 1 spp came out at 0.47-1.02 of Cycles over ten runs, and
Cycles' own time there ran from 248 to 520 ms over seventeen). The table gives the medians'
ratio and, in brackets, the spread of the rounds' own ratios. The pixel sampler's rows are
timed after (their Cycles figure is the independent row's), and so are the huge scenes
below.

The groom scenes fade alpha from 1 at 70 % of each strand's length to 0.4 at the tip, so both
renderers composite alpha layers, as the figure asks; the real file has alpha 0.64 throughout.

Beside each scene's time, the tracer's error against both float64 references (the shader's
model and the solids', section 3) over the whole image: coverage IoU over the union of both
hair masks and RMSE over those pixels, on every pixel or, where that would not fit the
scene's share of the time, a random subset of the image's pixel centres (its size is shown).

Scenes of more than 20 M cylinders (1,000,000 `wavy` strands: ~61 M, split over two buffer
textures of the driver) are timed once after one warm-up (the tracer) or once (Cycles, whose
every render pays sync and BVH build anyway), without the float64 references (numpy over
61 M cylinders needs more memory than the machine has); the tracer's GPU buffers are given
back before Cycles renders, so the two never hold the scene at once.

Beside each scene's independent samples (one walk per sample, as Cycles takes them), the
pixel sampler at the highest sample count (`RenderSettings(sampler="pixel")`: a pixel's samples
share one walk and each distinct strand is shaded once, docs/DECISIONS.md "Samples of one pixel
share the walk"; on see-through hair in groups whose layers fit a walk's list: 16 samples of 4
layers take four walks of 4), compared with Cycles at the same samples, with its error against
the tracer's own independent image at those samples (RMSE over the pixels either has hair in).
"""
import os
import tempfile

import numpy as np

from benchmarks.blender_anchors import CyclesAnchor, reset_scene
from benchmarks.harness import MIN_RUNS, Timing, TooSlow, fmt_num, fmt_time, measure, once, ratio, to_srgb8
from benchmarks.metrics import hair_rmse, image_error
from benchmarks.scenes import (SUN_DIRECTION, crop_camera, groom_scene, orbit, pick_window, real_strands,
                               settings, tracer_api, tracer_camera, view_matrix)
from benchmarks.sections import left
from benchmarks.sections.rendering import reference_error

REF_PAIRS = 6e7      # rays × cylinders the old method's float64 window may cost
REF_SHARE = 0.06     # of the section's budget, per scene, for the two whole-image references
LAYERS = 4
ALPHA_START, ALPHA_TIP = 0.7, 0.4   # the groom scenes' alpha fade (see the module text)
# Scenes past this many cylinders are timed once (see the module text): one first render of
# 1,000,000 wavy strands takes about a minute on the 2-core machine, one Cycles render more.
HUGE = 20_000_000
# _rounds_job: rounds shorter than ROUND_SECONDS / cfg.runs get more of them, up to
# MAX_ROUNDS, within ROUND_SECONDS a job.
ROUND_SECONDS = 20.0
MAX_ROUNDS = 15


def _huge(sc):
    return sc.strands.num_segments > HUGE


def _runs(sc, cfg):
    return 1 if _huge(sc) else cfg.runs


def _measure(job, runs, warmup=1, budget=None):
    """measure(), or for fewer than its MIN_RUNS runs the same thing done by hand: `warmup`
    untimed calls, TooSlow when `runs` more would not fit `budget`, then `runs` timed ones."""
    if runs >= MIN_RUNS:
        return measure(job, runs=runs, warmup=warmup, budget=budget)
    import time
    warm = []
    for _ in range(warmup):
        t0 = time.perf_counter()
        job()
        warm.append(time.perf_counter() - t0)
        if budget is not None and warm[-1] * runs > budget:
            raise TooSlow(f"one run takes {fmt_time(warm[-1])}, so {runs} run(s) would exceed the "
                          f"{fmt_time(max(budget, 0))} left in this section's budget")
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        result = job()
        times.append(time.perf_counter() - t0)
    return Timing(times, warm), result


def _scene_makers(cfg):
    for count in cfg.anc_counts:
        yield f"groom wavy {count // 1000}k", lambda count=count: groom_scene(
            "wavy", count, resolution="adaptive", alpha_start=ALPHA_START, alpha_tip=ALPHA_TIP)[3].strands
    if cfg.anc_real:
        yield "straight.hair (real)", lambda: real_strands("straight.hair")


class _Scene:
    def __init__(self, tracer, name, strands, size):
        self.name, self.strands = name, strands
        lo, hi = strands.bounds()
        self.matrix = view_matrix(lo, hi, size)
        self.cam = tracer_camera(self.matrix, size)
        self.moved = tracer_camera(orbit(self.matrix, np.radians(12), 0.5 * (lo + hi)), size)
        self.renderer = tracer.Renderer()
        self.cold = None
        self.parts = {}         # per job key: the stages of its last first render (_stages)
        self.parts_split = None  # buffer textures of the cylinders and of the cell lists (huge scenes)
        self.error_note = None
        self.ours, self.cycles, self.images, self.error = {}, {}, {}, None
        self.rounds = {}        # per sample count: [(first, re-render) / Cycles] of each round (_rounds_job)


def run(sec, cfg):
    tracer = tracer_api()
    size = (cfg.anc_size, cfg.anc_size)
    sec.text(__doc__.split("\n", 2)[2].strip())
    sec.text("Cycles set-up: " + CyclesAnchor.MATERIAL + f"; CPU device, {os.cpu_count()} threads, "
             "no denoiser, no adaptive sampling. Tracer: Kajiya-Kay, one directional light (the same "
             f"direction), hard shadows, {LAYERS} alpha layers.")
    sec.settings(image=f"{size[0]}x{size[1]}", spp=list(cfg.anc_spp), runs=cfg.runs, layers=LAYERS)
    scenes = []
    for name, make in _scene_makers(cfg):
        try:
            scenes.append(_Scene(tracer, name, make(), size))
        except Exception as e:  # noqa: BLE001 — e.g. the real file is missing: say so, go on
            sec.not_measured(name, f"{type(e).__name__}: {e}")
    # Every scene at the lowest sample count first (the targets), then the higher
    # counts, each taking what is left; a job whose runs cannot fit is reported, not half-run.
    # Huge scenes' lowest-spp jobs come first (their runs take about ten minutes of the budget,
    # which must not go to the smaller scenes' higher counts) and their other jobs last.
    low = min(cfg.anc_spp)
    by_cost = sorted(scenes, key=lambda s: s.strands.num_segments)     # cheapest first
    huge = [sc for sc in by_cost if _huge(sc)]
    # The pixel sampler's rows (its Cycles figure is the independent row's) come after each
    # scene's independent ones.
    top, ind = max(cfg.anc_spp), "independent"
    jobs = ([(low, ind, sc) for sc in huge]
            + [(spp, ind, sc) for spp in sorted(cfg.anc_spp) for sc in by_cost if not _huge(sc)]
            + [(top, PIXEL, sc) for sc in by_cost if not _huge(sc) and top > 1]
            + [(spp, ind, sc) for spp in sorted(cfg.anc_spp) if spp != low for sc in huge]
            + [(top, PIXEL, sc) for sc in huge if top > 1])
    for spp, sampler, sc in jobs:
        key = _key(spp, sampler)
        try:
            if sampler == ind and not _huge(sc):
                _rounds_job(sec, cfg, tracer, sc, spp, size)
                continue
            _tracer_job(sec, cfg, tracer, sc, spp, sampler)
            if sampler == ind:
                _cycles_job(sec, cfg, sc, spp, size)
        except Exception as e:  # noqa: BLE001 — one scene failing must not lose the others
            sc.ours.setdefault(key, f"failed: {type(e).__name__}: {e}")
            if isinstance(sc.ours.get(key), tuple) and sampler == ind:
                sc.cycles[spp] = f"failed: {type(e).__name__}: {e}"
    _report(sec, cfg, scenes, size)


# The samplers of the table's rows: independent samples at every count of cfg.anc_spp, the
# pixel sampler at the highest (see the module text).
PIXEL = "pixel"


def _key(spp, sampler):
    """The key of a job's results in _Scene.ours / images: the sample count, or (count, sampler)."""
    return spp if sampler == "independent" else (spp, sampler)


def _predicted(sc, spp, cfg, sampler="independent"):
    """Seconds one run of the tracer at `spp` should take, from the lowest-spp figures (render
    time grows with samples, upload does not); None before those exist."""
    low = min(cfg.anc_spp)
    base = sc.ours.get(low)
    if not isinstance(base, tuple) or spp == low:
        return None
    first, again, _ = base
    if sampler == PIXEL:
        # One walk for up to 25 opaque samples: 2-4x one sample's time; see-through hair in
        # groups: about 0.8 of as many independent samples (docs/DECISIONS.md).
        layers = sc.renderer.effective_layers(settings(spp=spp, layers=LAYERS, sampler=sampler))
        return first.median + again.median * (4 if layers == 1 else 0.8 * spp / low)
    return first.median + again.median * (spp / low - 1)


def _too_slow(sec, cfg, sc, spp, runs, sampler="independent"):
    """Why the tracer's `runs` first renders and re-renders at `spp` (each after one
    warm-up), predicted from the lowest-spp runs, would not fit what is left of the section;
    None where they would or there is no prediction yet."""
    guess = _predicted(sc, spp, cfg, sampler)
    if guess is None or 2 * guess * (runs + 1) <= left(sec):
        return None
    return (f"tracer: one run should take about {fmt_time(guess)} (from the {min(cfg.anc_spp)}-spp runs), "
            f"more than the {fmt_time(max(0, left(sec)))} left allows for {runs} run(s)")


def _tracer_job(sec, cfg, tracer, sc, spp, sampler="independent"):
    r = sc.renderer
    rs = settings(spp=spp, layers=LAYERS, shading="kajiya-kay", sampler=sampler)
    key = _key(spp, sampler)
    taken = r.sampler_for(rs).sampler
    if taken != sampler:
        # More layers than one walk's list holds (Renderer.sampler_for): the row above.
        sc.ours[key] = (f"the renderer takes the {taken} sampler for {spp} samples × {LAYERS} layers "
                        "(Renderer.sampler_for): the independent row's figures")
        return
    runs = _runs(sc, cfg)
    too_slow = _too_slow(sec, cfg, sc, spp, runs, sampler)
    if too_slow:
        sc.ours[key] = too_slow
        return
    try:
        first, _ = _measure(lambda: (r.set_strands(sc.strands), r.render(sc.cam, rs)), runs,
                            budget=left(sec))
        if sc.cold is None:
            sc.cold = first.warmups[0]
        sc.parts[key] = _stages(r.stats)
        flip = {"on": False}

        def rerender():
            flip["on"] = not flip["on"]
            return r.render(sc.moved if flip["on"] else sc.cam, rs)

        uploaded = r.stats.bytes_uploaded
        again, img = _measure(rerender, runs, budget=left(sec))
        no_upload = r.stats.bytes_uploaded == uploaded
        if flip["on"]:      # the last run saw the moved camera
            img = r.render(sc.cam, rs)
        sc.ours[key] = (first, again, no_upload)
        sc.images[("ours", key)] = img
        if _huge(sc):
            sc.parts_split = (r.buffers.parts("tex_cyl"), r.buffers.parts("tex_idx"))
    except TooSlow as e:
        sc.ours[key] = f"tracer: {e}"
        return
    finally:
        if _huge(sc):       # several GB the Cycles render needs more
            r.buffers.release()
    if _huge(sc):
        sc.error_note = ("not measured: the float64 references (numpy) over "
                         f"{sc.strands.num_segments / 1e6:.0f} M cylinders need more memory than this machine has")
        return
    _error_job(sec, cfg, tracer, sc, key, rs, img)


def _error_job(sec, cfg, tracer, sc, key, rs, img):
    """The tracer's error beside its time, once a scene (at the lowest sample count): `img`,
    its image of the scene's camera with settings `rs`, against the float64 references."""
    r = sc.renderer
    if sc.error is None and key == min(cfg.anc_spp) and left(sec) > 0:
        # Error beside the time: both float64 references over the whole image (a random
        # subset of its pixel centres where every pixel would not fit the scene's share of
        # the budget), and the old method's window once for comparison.
        share = min(REF_SHARE * sec.budget, max(0.0, left(sec))) / 2
        model, _, _ = reference_error(tracer, "model", sc.strands, sc.cam, rs, img, budget=share)
        solid, _, _ = reference_error(tracer, "solid", sc.strands, sc.cam, rs, img, budget=share)
        side = int(np.clip(np.sqrt(REF_PAIRS / max(1, sc.strands.num_segments)), 4, 24))
        x0, y0 = pick_window(img, side, side)
        win = crop_camera(sc.cam, x0, y0, side, side)
        old = image_error(r.render(win, rs), tracer.reference_render(sc.strands, win, rs))
        sc.error = (model, solid, side, old)


def _cycles_job(sec, cfg, sc, spp, size):
    """Cycles at `spp` on a huge scene (the others take turns with the tracer: _rounds_job):
    one render, no warm-up (every render pays sync and BVH build anyway), after the tracer's
    job, whose GPU buffers were given back; Blender's copy of the scene is given back after."""
    if not isinstance(sc.ours.get(spp), tuple):
        return      # nothing to compare with
    low = sc.cycles.get(min(cfg.anc_spp))
    if spp != min(cfg.anc_spp) and hasattr(low, "median") and low.median > left(sec):
        # A render at more samples takes at least as long as the lowest-spp one.
        sc.cycles[spp] = (f"Cycles: one render at {min(cfg.anc_spp)} spp took {fmt_time(low.median)}, more than the "
                          f"{fmt_time(max(0, left(sec)))} left")
        return
    cyc = CyclesAnchor(sc.strands, sc.matrix, size=size, sun_direction=SUN_DIRECTION, layers=LAYERS)
    try:
        sc.cycles[spp], _ = _measure(lambda: cyc.render(spp), _runs(sc, cfg), warmup=0, budget=left(sec))
    except TooSlow as e:
        sc.cycles[spp] = f"Cycles: {e}"
        return
    _keep_cycles_image(sc, cyc, spp)
    del cyc     # give Blender's copy of the scene back before the next job
    reset_scene()


def _keep_cycles_image(sc, cyc, spp):
    """Cycles' last image of scene `sc` at `spp`, for the side-by-side figure."""
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "cycles.png")
        cyc.save_last(path)
        import matplotlib.image as mpimg
        sc.images[("cycles", spp)] = mpimg.imread(path)


def _rounds_job(sec, cfg, tracer, sc, spp, size):
    """The tracer's independent samples at `spp` and Cycles at the same samples, side by side:
    after a warm-up of each, `runs` rounds of one first render, one re-render after a camera
    move and one Cycles render, in turn, so that the three see the same state of a shared
    machine (see the module text). Keeps the rounds' own ratios (sc.rounds) beside the medians."""
    r = sc.renderer
    rs = settings(spp=spp, layers=LAYERS, shading="kajiya-kay")
    runs = max(_runs(sc, cfg), MIN_RUNS)
    too_slow = _too_slow(sec, cfg, sc, spp, runs)
    if too_slow:
        sc.ours[spp] = too_slow
        return
    cyc = CyclesAnchor(sc.strands, sc.matrix, size=size, sun_direction=SUN_DIRECTION, layers=LAYERS)

    def first():
        r.set_strands(sc.strands)
        return r.render(sc.cam, rs)
    # Warm-ups: the first render (cold when it is the scene's first), a re-render, Cycles.
    warm_first, _ = once(first)
    if sc.cold is None:
        sc.cold = warm_first
    warm_again, _ = once(lambda: r.render(sc.moved, rs))
    warm_cycles, _ = once(lambda: cyc.render(spp))
    one = warm_first + warm_again + warm_cycles
    # Short rounds are noisier (straight.hair at 1 spp: one round's ratio 0.39, the next
    # 0.91): more of them, within ROUND_SECONDS.
    runs = max(runs, min(MAX_ROUNDS, int(ROUND_SECONDS / max(one, 1e-9))))
    if one * runs > left(sec):
        why = (f"one round takes {fmt_time(one)}, so {runs} rounds would exceed the "
               f"{fmt_time(max(0, left(sec)))} left in this section's budget")
        sc.ours[spp], sc.cycles[spp] = f"tracer: {why}", f"Cycles: {why}"
        return
    f, a, c = [], [], []
    no_upload = True
    for _ in range(runs):
        t, img = once(first)    # the last round's image is the one kept (renders are deterministic)
        f.append(t)
        sc.parts[spp] = _stages(r.stats)
        uploaded = r.stats.bytes_uploaded
        a.append(once(lambda: r.render(sc.moved, rs))[0])
        no_upload &= r.stats.bytes_uploaded == uploaded
        c.append(once(lambda: cyc.render(spp))[0])
    sc.ours[spp] = (Timing(f, [warm_first]), Timing(a, [warm_again]), no_upload)
    sc.cycles[spp] = Timing(c, [warm_cycles])
    sc.rounds[spp] = [(x / z, y / z) for x, y, z in zip(f, a, c)]
    sc.images[("ours", spp)] = img
    _keep_cycles_image(sc, cyc, spp)
    _error_job(sec, cfg, tracer, sc, spp, rs, img)


def _round_range(sc, key, which):
    """' (rounds a-b)': the spread of the rounds' own ratios (0: first render, 1: re-render,
    each to Cycles at the same samples), or '' where the job had no rounds."""
    got = sc.rounds.get(key)
    if not got:
        return ""
    values = [x[which] for x in got]
    return f" (rounds {min(values):.2f}-{max(values):.2f})"


def _report(sec, cfg, scenes, size):
    rows, pics = [], []
    for sc in scenes:
        c1 = sc.cycles.get(min(cfg.anc_spp))
        c1 = c1.median if hasattr(c1, "median") else None
        label = f"{sc.strands.num_strands:,} / {sc.strands.num_segments:,}"
        top = max(cfg.anc_spp)
        for key in list(cfg.anc_spp) + ([_key(top, PIXEL)] if top > 1 else []):
            spp = key[0] if isinstance(key, tuple) else key
            shown = f"{spp}, pixel sampler" if isinstance(key, tuple) else str(spp)
            ours, theirs = sc.ours.get(key), sc.cycles.get(spp)
            if not isinstance(ours, tuple) or not hasattr(theirs, "median"):
                why = ours if isinstance(ours, str) else theirs if isinstance(theirs, str) else "time budget"
                if isinstance(ours, tuple):     # ours measured, Cycles not: still show ours
                    why = f"{why}; tracer first render {ours[0]}, re-render {ours[1]}"
                rows.append([sc.name, label, shown, f"not measured: {why}"] + [""] * 7)
                continue
            first, again, no_upload = ours
            if isinstance(key, tuple):
                err = _pixel_error(sc, key, spp)
            elif sc.error and spp == min(cfg.anc_spp):
                model, solid, side, old = sc.error
                err = " · ".join(f"{100 * e['iou']:.3f} % / {fmt_num(e['rmse_hair'])} / {fmt_num(e['max_abs'])} "
                                 f"({e['hair_pixels']:,} hair px of {e['rays']:,})" for e in (model, solid))
                err += f" · old method: {fmt_num(old['rmse'])} / {100 * old['coverage_agree']:.1f} % ({side}² window)"
            else:
                err = ("see the lowest-spp row" if sc.error else sc.error_note if sc.error_note
                       else "not measured: time budget")
            # The re-render's rounds were against Cycles at 1 spp only in the lowest-spp job.
            again_rounds = _round_range(sc, key, 1) if spp == min(cfg.anc_spp) else ""
            rows.append([sc.name, label, shown, str(theirs), str(first),
                         f"{ratio(first.median, theirs.median):.2f}{_round_range(sc, key, 0)}",
                         f"{ratio(first.median, c1):.2f}" if c1 else "n/a", str(again),
                         f"{ratio(again.median, c1):.2f}{again_rounds}" if c1 else "n/a",
                         "yes" if no_upload else "NO", err])
            sec.data.setdefault("rows", []).append({"scene": sc.name, "spp": spp, "cycles": theirs.median,
                                                    "sampler": key[1] if isinstance(key, tuple) else "independent",
                                                    "first": first.median, "rerender": again.median,
                                                    "round_ratios": sc.rounds.get(key, [])})
            if spp == top and top > min(cfg.anc_spp):
                sec.summary.append(_top_line(sc.name, spp, isinstance(key, tuple), first.median, again.median,
                                             theirs.median, _round_range(sc, key, 0), _round_range(sc, key, 1))
                                   + ("; " + err if isinstance(key, tuple) else ""))
        lowest = sc.ours.get(min(cfg.anc_spp))
        if isinstance(lowest, tuple) and c1:
            f1, a1 = lowest[0].median, lowest[1].median
            sec.text(f"**{sc.name}: first render {ratio(f1, c1):.2f}× Cycles {min(cfg.anc_spp)} spp (target ≤ 0.5: "
                     f"{'met' if ratio(f1, c1) <= 0.5 else 'NOT met'}); re-render after a camera move "
                     f"{ratio(a1, c1):.2f}× (target ≤ 0.25: {'met' if ratio(a1, c1) <= 0.25 else 'NOT met'}).** "
                     + (f"Cold first render (shader compile included): {fmt_time(sc.cold)}." if sc.cold else "")
                     + "".join(f" The last first render at {_shown(key)}: {stages}."
                               for key, stages in sc.parts.items())
                     + (" Cylinders in {} buffer textures, cell lists in {}; one run after one warm-up (no warm-up "
                        "for Cycles).".format(*sc.parts_split) if sc.parts_split else ""))
            low = min(cfg.anc_spp)
            sec.summary.append(f"{sc.name}: first {fmt_time(f1)} = {ratio(f1, c1):.2f}× Cycles 1 spp ({fmt_time(c1)})"
                               f"{_round_range(sc, low, 0)}; re-render {fmt_time(a1)} = {ratio(a1, c1):.2f}×"
                               f"{_round_range(sc, low, 1)}")
        both = [s for s in cfg.anc_spp if ("ours", s) in sc.images and ("cycles", s) in sc.images]
        if both:
            pics.append((sc.name, sc.images[("ours", both[-1])], sc.images[("cycles", both[-1])], both[-1]))
    sec.table(["scene", "strands / cylinders", "spp", "Cycles (median)", "tracer first render (median)",
               "first / Cycles same spp", "first / Cycles 1 spp", "tracer re-render after camera move",
               "re-render / Cycles 1 spp", "re-render uploads nothing",
               "tracer vs float64, whole image, IoU / RMSE (hair) / max: model reference · solid reference · "
               "old method (window RMSE / coverage agreement)"],
              rows, caption=f"The tracer against Cycles at {size[0]}×{size[1]} (medians, same run; in brackets the "
                            "spread of the rounds' own ratios, where the two took turns).")
    if pics:
        _side_by_side(sec, pics)


def _top_line(name, spp, pixel, first, again, cycles, first_rounds="", again_rounds=""):
    """The summary's line for a scene's highest sample count, with either sampler (the
    rounds' spreads, _round_range, where it had rounds)."""
    how = "with the pixel sampler" if pixel else "independent samples"
    return (f"{name}: {spp} spp, {how}: first {fmt_time(first)} = {ratio(first, cycles):.2f}× Cycles {spp} spp "
            f"({fmt_time(cycles)}){first_rounds}; re-render {ratio(again, cycles):.2f}×{again_rounds}")


def _stages(st):
    """The stages of a first render (set_strands + render) from the renderer's stats: what its
    camera rays walked and what it built."""
    parts = [f"cylinders {fmt_time(st.cylinders_s)}", f"upload {fmt_time(st.upload_s)}"]
    if st.accel == "beams" and st.beams_s is not None:
        parts.append(f"beams {fmt_time(st.beams_s)} (camera: {st.camera_beams}, {fmt_time(st.camera_beams_s)}; "
                     f"sun {fmt_time(st.sun_beams_s)})")
    if st.grid_refs is not None and st.grid_s:
        parts.append(f"grid ({st.grid_build or 'numpy'} build) {fmt_time(st.grid_s)}")
    # render_s holds the render's whole time, the beams' and a grid built for it included.
    parts.append(f"render {fmt_time(st.render_s)} in all")
    return ", ".join(parts)


def _shown(key):
    return f"{key[0]} spp, pixel sampler" if isinstance(key, tuple) else f"{key} spp"


def _pixel_error(sc, key, spp):
    """The pixel sampler's image against the tracer's independent one at the same samples."""
    pix, ind = sc.images.get(("ours", key)), sc.images.get(("ours", spp))
    if pix is None or ind is None:
        return f"error not measured: no independent {spp}-spp image to compare with"
    rmse = hair_rmse(pix, ind)
    if not np.isfinite(rmse):
        return "error not measured: neither image has hair"
    return f"vs the independent {spp}-spp image: RMSE (hair) {fmt_num(rmse)}"


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

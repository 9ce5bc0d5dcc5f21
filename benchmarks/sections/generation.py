# SPDX-License-Identifier: GPL-3.0-or-later
"""1. Generation: groom against Blender's Interpolate Curves node on the same job.

The job an artist gets: the shipped `wavy` preset on the bundled scalp as it is (its keys, its
adaptive resolution, clump, and collision with the bundled head), against Blender's
Interpolate Curves node growing the same number of strands at the same roots from the same
keys resampled by arc length to groom's average point count, 3 influences per strand, root
normals as "up" vectors. groom's time includes everything it does (root sampling, frames,
wisps, resolution, interpolation, clump, collision, radius, colour; the collider is built
once per process, as Blender's Generate reuses it); Blender's is the node tree's evaluation
alone (its result is not even copied out), so the comparison leans towards Blender. Both use
every core: Blender's node through its task scheduler, groom through one worker process per
CPU beside its own (groom.processes, Linux; elsewhere threads), each growing blocks of strands
of its own from 2 × 2,048 strands on (below that, each stage's whole-array numpy work split over
the threads). Beside the wall-clock times, the CPU time of the same runs (all threads, and
groom's worker processes): on a shared machine other work stretches wall time far more than
the CPU time a job needs.
"""
import json
import os
import time

import numpy as np

from benchmarks.harness import MIN_RUNS, Timing, TooSlow, fmt_time, measure, once, ratio, run_child
from benchmarks.scenes import groom_api, load_preset
from benchmarks.sections import left, over_budget

MEMORY_LIMIT_MB = 2048.0
# From this many strands on, one timed run a side (see run).
SINGLE_RUN_COUNT = 1_000_000
PRESET = "wavy"

_MEMORY_CHILD = """
import json, sys, time
sys.path.insert(0, '.')
from benchmarks.harness import PeakMemory, hwm_mb
from benchmarks.scenes import groom_api, load_preset
groom = groom_api()
scalp = groom.default_scalp()
collider = groom.default_collider()
placement = load_preset({preset!r}).place_keys(scalp)
params = placement.params.replace(count={count})
base = hwm_mb()
with PeakMemory(0.02) as mem:
    t0 = time.perf_counter()
    r = groom.generate(scalp, placement.keys, params, collider=collider)
    t = time.perf_counter() - t0
from groom import processes
own, workers = hwm_mb(), processes.workers_peak_mb()
print(json.dumps({{"base_mb": base, "peak_rss_mb": mem.peak if mem.peak is not None else own + workers,
                  "parts": mem.parts, "hwm_sum_mb": own + workers, "points": int(r.strands.num_points),
                  "result_mb": sum(0 if a is None else a.base.nbytes if a.strides == (0,) else a.nbytes
                                   for a in (r.strands.points, r.strands.radius, r.strands.point_color,
                                             r.strands.strand_color, r.strands.alpha)) / 2 ** 20, "time": t}}))
"""

_BLENDER_MEMORY_CHILD = """
import json, sys
sys.path.insert(0, '.')
from benchmarks.harness import hwm_mb
from benchmarks.sections.generation import blender_inputs
from benchmarks.scenes import groom_api, load_preset
from benchmarks.blender_anchors import InterpolateAnchor
groom = groom_api()
scalp = groom.default_scalp()
placement = load_preset({preset!r}).place_keys(scalp)
r = groom.generate(scalp, placement.keys, placement.params.replace(count={count}, collision=False))
args = blender_inputs(scalp, placement.keys, placement.params, r, {points})
del r
base = hwm_mb()
a = InterpolateAnchor(*args)
a.evaluate()
print(json.dumps({{"base_mb": base, "peak_rss_mb": hwm_mb()}}))
"""

# The command line grows the strands a block at a time straight into its .npz.
_STREAM_MEMORY_CHILD = """
import json, os, sys, tempfile, time
sys.path.insert(0, '.')
from benchmarks.harness import hwm_mb
from groom.__main__ import main
base = hwm_mb()
with tempfile.TemporaryDirectory() as folder:
    t0 = time.perf_counter()
    assert main(["generate", "--preset", {preset!r}, "--count", "{count}", "--out", os.path.join(folder, "h.npz")]) == 0
    t = time.perf_counter() - t0
print(json.dumps({{"base_mb": base, "peak_rss_mb": hwm_mb(), "time": t}}))
"""


def blender_inputs(scalp, keys, params, result, points):
    """(roots, root normals, keys resampled to `points` points, key root normals)."""
    root_up = scalp.normals_at(result.root_tri, result.root_bary, params.normal_mode)
    key_pts = np.stack([k.resample(points) for k in keys])
    tri, bary, _ = scalp.closest_points(np.array([k.root for k in keys]))
    key_up = scalp.normals_at(tri, bary, params.normal_mode)
    return result.roots, root_up, key_pts, key_up


def cpu_seconds():
    """CPU seconds of this process and of groom's worker processes so far."""
    from groom import processes
    return time.process_time() + processes.workers_cpu_seconds()


class _Cpu:
    """`job` that also keeps the process CPU seconds (every thread) of each call."""

    def __init__(self, job):
        self.job, self.seconds = job, []

    def __call__(self):
        c0 = cpu_seconds()
        out = self.job()
        self.seconds.append(cpu_seconds() - c0)
        return out

    def median(self):
        """Median over the timed calls (measure's first call is its warm-up)."""
        return float(np.median(self.seconds[1:] or self.seconds))


def _single_run(job, data, count, budget, side="ours"):
    """(Timing of one call of job, its result), for the counts where the runs of `measure`
    would not fit: TooSlow when the largest row measured so far, scaled linearly to
    `count`, says one call would not fit `budget` either."""
    if data:
        d = data[-1]
        guess = d[side] * count / d["count"]
        if guess > budget:
            raise TooSlow(f"one run should take about {fmt_time(guess)} ({fmt_time(d[side])} at {d['count']:,} strands), "
                          f"more than the {fmt_time(max(budget, 0))} left in this section's budget")
    t0 = time.perf_counter()
    out = job()
    return Timing([time.perf_counter() - t0]), out


def _side_by_side(ours, warm_ours, theirs, invalidate, runs, budget):
    """(Timing of `ours`, Timing of `theirs`): after one warm-up each (ours already had
    its, `warm_ours` seconds), `runs` rounds of one call of each in turn, so that both see
    the same state of a shared machine (measured one after the other, the two sides'
    ratio swung from 1.0 to 2.2 between runs of the same code). TooSlow when the rounds
    would not fit `budget`."""
    invalidate()
    warm_theirs, _ = once(theirs)
    if (warm_ours + warm_theirs) * runs > budget:
        raise TooSlow(f"one round takes {fmt_time(warm_ours + warm_theirs)}, so {runs} rounds would exceed the "
                      f"{fmt_time(max(budget, 0))} left in this section's budget")
    a, b = [], []
    for _ in range(max(int(runs), MIN_RUNS)):
        t, out = once(ours)
        a.append(t)
        del out
        invalidate()
        b.append(once(theirs)[0])
    return Timing(a, [warm_ours]), Timing(b, [warm_theirs])


def counts_for(cfg):
    """The strand counts of the main table: the mode's, and 1M in the full report."""
    counts = tuple(cfg.gen_counts)
    if cfg.mode == "full" and 1_000_000 not in counts:
        counts += (1_000_000,)
    return counts


def run(sec, cfg):
    groom = groom_api()
    from benchmarks.blender_anchors import InterpolateAnchor
    scalp = groom.default_scalp()
    collider = groom.default_collider()
    placement = load_preset(PRESET).place_keys(scalp)
    keys, base = placement.keys, placement.params
    sec.text(__doc__.split("\n", 2)[2].strip())
    sec.settings(preset=PRESET, keys=len(keys), resolution_mode=base.resolution_mode, tolerance=base.tolerance,
                 max_points_per_strand=base.points_per_strand, clump=base.clump, frizz=base.frizz, curl=base.curl,
                 collider="the bundled head", collision_margin=base.collision_margin,
                 neighbour_mode=base.neighbour_mode, blender_max_neighbors=3, runs=cfg.runs)

    rows, data = [], []
    for count in counts_for(cfg):
        single = count >= SINGLE_RUN_COUNT
        if data and over_budget(sec, 0.6 if single else 0.45):
            sec.not_measured(f"{count:,} strands", "skipped to stay inside the section's time budget")
            continue
        params = base.replace(count=int(count))
        costs = []

        def job():
            out = groom.generate(scalp, keys, params, collider=collider)
            costs.append(out.collision.last.seconds)
            return out
        try:
            our_cpu = _Cpu(job)
            if single:
                ours, result = _single_run(our_cpu, data, count, left(sec, 0.6))
            else:
                warm_ours, result = once(our_cpu)
            points = int(round(result.strands.num_points / result.strands.num_strands))
            inputs = blender_inputs(scalp, keys, params, result, points)
            # Only these of the result are needed from here: at 1M strands it holds 2 GB.
            roots, num_points, moved = result.roots, result.strands.num_points, result.collision.strands_moved
            del result
            anchor = InterpolateAnchor(*inputs)
            del inputs
            their_cpu = _Cpu(anchor.evaluate)
            if single:
                anchor.invalidate()
                theirs, _ = _single_run(their_cpu, data, count, left(sec, 0.6), side="blender")
            else:
                ours, theirs = _side_by_side(our_cpu, warm_ours, their_cpu, anchor.invalidate, cfg.runs,
                                             left(sec, 0.45))
        except TooSlow as e:
            sec.not_measured(f"{count:,} strands", str(e))
            continue
        blender_pos = anchor.positions()
        root_err = float(np.abs(blender_pos[:, 0] - roots).max())
        blender_shape = blender_pos.shape
        del blender_pos
        collision = float(np.median(costs[1:] or costs))
        r = ratio(ours.median, theirs.median)
        # The ratio of each round (one call of each side in turn): how far the machine's
        # state moved the figure within the run.
        rounds = [] if single else [ratio(a, b) for a, b in zip(ours.runs, theirs.runs)]
        cpu = (our_cpu.median(), their_cpu.median())
        rows.append([f"{count:,}" + (" (1 run)" if single else ""), f"{num_points / count:.1f}", str(ours),
                     fmt_time(collision), f"{moved / count:.1%}", str(theirs),
                     f"{blender_shape[0]:,}×{blender_shape[1]}", f"{root_err:.1e}", f"{r:.2f}",
                     fmt_time(cpu[0]), fmt_time(cpu[1]), f"{ratio(*cpu):.2f}", f"{os.getloadavg()[0]:.1f}"])
        data.append({"count": count, "ours": ours.median, "blender": theirs.median, "ratio": r,
                     "collision": collision, "points_per_strand": num_points / count, "runs": len(ours.runs),
                     "ours_cpu": cpu[0], "blender_cpu": cpu[1], "cpu_ratio": ratio(*cpu),
                     "round_ratios": rounds})
        spread = f"; rounds {min(rounds):.2f}-{max(rounds):.2f}" if rounds else ""
        sec.summary.append(f"{count:,} strands ({PRESET}, collision on): groom {ours} vs Interpolate Curves {theirs} "
                           f"→ ratio {r:.2f} (collision {fmt_time(collision)}{spread})")
        del anchor
    sec.table(["strands", "points per strand (mean)", "groom (median)", "of which collision", "strands moved",
               "Interpolate Curves (median)", "Blender output", "Blender root error (m)", "ratio groom/Blender",
               "groom CPU (median)", "Interpolate Curves CPU (median)", "CPU ratio", "load average"], rows,
              caption="Generation time with the shipped preset (median of runs after a warm-up; both in this "
                      "process, one call of each in turn, so that both see the same state of the machine). "
                      f"From {SINGLE_RUN_COUNT:,} strands on (*1 run*), one timed run each side and no "
                      "warm-up (the smaller rows have warmed both up): five would not fit the section's budget. "
                      "*of which collision*: the collision's own time in the same runs (median; where the blocks of "
                      "strands grow side by side, the threads' time summed, which can exceed its share of the "
                      "wall time). *CPU*: "
                      "process CPU seconds of the same runs, all threads. *load average*: the machine's 1-minute "
                      "load average after the row (above its core count, other work competed for the cores).")
    sec.text("*Blender output*: strands × points, the same count and the average of groom's adaptive counts. "
             "*Blender root error*: largest distance between Blender's strand roots and the given roots (it grew "
             "strands where asked).")
    target = [d for d in data if d["count"] == 100000]
    if target:
        d = target[0]
        sec.text(f"**Target (100,000 strands of the shipped `{PRESET}`, collision on, against Interpolate Curves with "
                 f"{d['points_per_strand']:.0f} points per strand): ratio {d['ratio']:.2f} (target ≤ 1.0: "
                 f"{'met' if d['ratio'] <= 1.0 else 'NOT met'}; moonshot 0.5); in CPU time "
                 f"{d['cpu_ratio']:.2f}.**" + (
                     f" The {len(d['round_ratios'])} rounds' own ratios ran from {min(d['round_ratios']):.2f} to "
                     f"{max(d['round_ratios']):.2f} (one call of each side in turn; the median ratio is the "
                     "ratio of the two medians)." if d.get("round_ratios") else ""))
    sec.data["timings"] = data
    _plot(sec, data)
    _one_cpu(sec, cfg, groom, scalp, keys, base, collider, data)
    _presets(sec, cfg, groom, scalp, collider)
    _memory(sec, cfg)
    _incremental(sec, cfg, groom, scalp, collider, placement)


def _one_cpu(sec, cfg, groom, scalp, keys, base, collider, data):
    """groom at 100,000 strands on one CPU against all of them, in turn: how much of the
    ratio is work and how much the threads' scaling. One CPU: the calling thread's affinity
    set to one CPU, so groom.parallel sees one and runs every job on that thread."""
    row = [d for d in data if d["count"] == 100000]
    if not row or not hasattr(os, "sched_setaffinity"):
        sec.not_measured("groom on one CPU", "needs the 100,000-strand row and a platform that sets thread affinity")
        return
    if over_budget(sec, 0.5):
        sec.not_measured("groom on one CPU", "skipped to stay inside the section's time budget")
        return
    params = base.replace(count=100000)
    cpus = os.sched_getaffinity(0)
    sides = {"all": [], "one": []}
    try:
        for _ in range(max(int(cfg.runs), MIN_RUNS)):
            for side in sides:
                os.sched_setaffinity(0, cpus if side == "all" else {min(cpus)})
                c0, t0 = cpu_seconds(), time.perf_counter()
                groom.generate(scalp, keys, params, collider=collider)
                sides[side].append((time.perf_counter() - t0, cpu_seconds() - c0))
    finally:
        os.sched_setaffinity(0, cpus)
    med = {side: (float(np.median([r[0] for r in v])), float(np.median([r[1] for r in v]))) for side, v in sides.items()}
    blender_cpu = row[0]["blender_cpu"]
    sec.table(["groom on", "time (median)", "CPU (median)", "time ÷ one CPU's", "CPU ÷ Interpolate Curves CPU"],
              [[f"all {len(cpus)} CPUs", fmt_time(med["all"][0]), fmt_time(med["all"][1]),
                f"{med['all'][0] / med['one'][0]:.2f}", f"{med['all'][1] / blender_cpu:.2f}"],
               ["one CPU", fmt_time(med["one"][0]), fmt_time(med["one"][1]), "1.00",
                f"{med['one'][1] / blender_cpu:.2f}"]],
              caption="groom at 100,000 strands of the same job on every CPU and on one (runs in turn), against "
                      "Interpolate Curves' CPU time in the table above: the work each side does, and what the "
                      "threads make of it.")
    sec.data["one_cpu"] = {"all": med["all"], "one": med["one"], "cpus": len(cpus), "blender_cpu": blender_cpu}
    sec.summary.append(f"100,000 strands: groom on one CPU {fmt_time(med['one'][0])} "
                       f"({med['one'][1] / blender_cpu:.2f}× Interpolate Curves' CPU time), on {len(cpus)} "
                       f"{fmt_time(med['all'][0])}")


def _plot(sec, data):
    if len(data) < 2:
        return
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    c = [d["count"] for d in data]
    ax.loglog(c, [d["ours"] for d in data], "o-", label=f"groom.generate ({PRESET}, collision on)")
    ax.loglog(c, [d["collision"] for d in data], "^:", label="of which collision")
    ax.loglog(c, [d["blender"] for d in data], "s-", label="Interpolate Curves (bpy)")
    ax.set_xlabel("strands")
    ax.set_ylabel("seconds (median)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    sec.figure(fig, "generation_time.png", "Generation time against strand count, groom and Blender.")


def inside_shares(collider, strands):
    """(share of strands, share of points) deeper inside the collider than their radius,
    roots left out (they are where the scalp puts them). Exact distances for the points the
    sampled distance puts near the head; the others are farther than its band."""
    pts = strands.points.astype(np.float64)
    root = np.zeros(len(pts), bool)
    root[strands.offsets] = True
    near = np.flatnonzero(~root & (collider.value(pts) < 0.99 * collider.band))
    inside = np.zeros(len(pts), bool)
    inside[near] = collider.signed_distance(pts[near]) < -strands.radius[near]
    strand = np.repeat(np.arange(strands.num_strands), strands.counts)
    return float(np.unique(strand[inside]).size / strands.num_strands), float(inside.sum() / (~root).sum())


def _presets(sec, cfg, groom, scalp, collider):
    """Per preset: hair inside the bundled head without and with collision, and its cost."""
    count = 40000 if cfg.mode == "full" else 4000
    rows = []
    # The timed preset first: if the budget runs out, the others go.
    for name in sorted(groom.list_presets(), key=lambda n: n != PRESET):
        if over_budget(sec, 0.75):
            sec.not_measured(f"preset {name} inside the head", "skipped to stay inside the section's time budget")
            continue
        placement = groom.load_preset(name).place_keys(scalp)
        params = placement.params.replace(count=count)
        t0 = time.perf_counter()
        plain = groom.generate(scalp, placement.keys, params.replace(collision=False))
        t_plain = time.perf_counter() - t0
        t0 = time.perf_counter()
        held = groom.generate(scalp, placement.keys, params, collider=collider)
        t_held = time.perf_counter() - t0
        before, after = inside_shares(collider, plain.strands), inside_shares(collider, held.strands)
        rows.append([name, f"{before[0]:.1%}", f"{before[1]:.2%}", f"{after[0]:.1%}", f"{after[1]:.2%}",
                     f"{held.collision.strands_moved / count:.1%}", fmt_time(held.collision.last.seconds),
                     f"{held.collision.last.seconds / max(t_held, 1e-9):.0%}", fmt_time(t_plain)])
        sec.summary.append(f"{name}: strands inside the head {before[0]:.1%} → {after[0]:.1%}, points "
                           f"{before[1]:.2%} → {after[1]:.2%}")
    if rows:
        sec.table(["preset", "strands inside, no collision", "points inside, no collision", "strands inside",
                   "points inside", "strands moved", "collision time", "share of generate", "generate without"],
                  rows, caption=f"Each preset on the bundled scalp, {count:,} strands, against the bundled head: "
                                "a strand is inside when any of its points (root aside) is deeper than its radius, "
                                "by the exact signed distance. One run each (cold caches aside: the collider is "
                                "built once).")


def _result_bytes(ours):
    """The in-process result's size in words, from the memory child's figures."""
    if not ours or "result_mb" not in ours:
        return "16 bytes a point"
    return (f"{ours['result_mb'] * 2 ** 20 / ours['points']:.0f} bytes a point "
            f"({ours['result_mb'] * 2 ** 20 / 1e9:.2f} GB here)")


def _memory(sec, cfg):
    count = 1_000_000 if cfg.mode == "full" else max(cfg.gen_counts)
    if over_budget(sec, 0.85):
        sec.not_measured("peak memory", "skipped to stay inside the section's time budget")
        _stream_runs(sec)
        return
    rows, streamed, ours = [], None, None
    # The command first: its figure is the target's (it grows and writes a block at a time).
    try:
        streamed = run_child(_STREAM_MEMORY_CHILD.format(preset=PRESET, count=count), timeout=600)
        rows.append([f"python -m groom generate --count {count} (written as it grows)",
                     f"{streamed['peak_rss_mb']:.0f}", f"{streamed['base_mb']:.0f}", fmt_time(streamed["time"])])
    except Exception as e:
        rows.append(["python -m groom generate (written as it grows)", f"not measured: {e}", "", ""])
    if not over_budget(sec, 0.85):
        try:
            ours = run_child(_MEMORY_CHILD.format(preset=PRESET, count=count), timeout=600)
            parts = ours.get("parts")
            split = (f" ({parts['own']:.0f} this process + {parts['children']:.0f} its worker processes + "
                     f"{parts['shared']:.0f} their memory files, at the peak; the sum of the processes' own "
                     f"peaks, VmHWM, would say {ours['hwm_sum_mb']:.0f})" if parts else "")
            rows.append(["groom.generate in process (collision on)", f"{ours['peak_rss_mb']:.0f}{split}",
                         f"{ours['base_mb']:.0f}", fmt_time(ours["time"])])
        except Exception as e:
            rows.append(["groom.generate in process (collision on)", f"not measured: {e}", "", ""])
    else:
        rows.append(["groom.generate in process (collision on)", "not measured: section time budget", "", ""])
    if ours is not None and not over_budget(sec, 0.9):
        points = int(round(ours["points"] / count))
        try:
            bl = run_child(_BLENDER_MEMORY_CHILD.format(preset=PRESET, count=count, points=points), timeout=600)
            rows.append(["Interpolate Curves (bpy process)", f"{bl['peak_rss_mb']:.0f}", f"{bl['base_mb']:.0f}", ""])
        except Exception as e:
            rows.append(["Interpolate Curves (bpy process)", f"not measured: {e}", "", ""])
    sec.table(["job", "peak memory (MiB)", "RSS before the job (MiB)", "time"], rows,
              caption=f"Peak memory at {count:,} strands of {PRESET}, each job in a fresh process (RSS = whole "
                      "process including the interpreter, numpy and the collider). groom.generate in process: "
                      "sampled every 20 ms, its own pages, its worker processes' (groom.processes) and the memory "
                      "files the result grows in, each page once (benchmarks.harness.PeakMemory). The command "
                      "grows and writes a block of 65,536 strands at a time; in process the result itself takes "
                      f"{_result_bytes(ours)} (an opaque groom's alpha takes none, groom.cylinders.ones, and a "
                      "colour that does not change along the strands is held once a strand, "
                      "hairio.Strands.strand_color; before, 28 bytes a point, 1.75 GB here).")
    best = streamed or ours
    if best is not None:
        ok = best["peak_rss_mb"] < MEMORY_LIMIT_MB
        inproc = "" if ours is None else (f"; in process {ours['peak_rss_mb']:.0f} MiB — "
                                          f"{'met' if ours['peak_rss_mb'] < MEMORY_LIMIT_MB else 'NOT met'}")
        sec.text(f"**Peak memory target at {count:,} strands (≤ 2 GB): {best['peak_rss_mb']:.0f} MiB"
                 f"{' (python -m groom generate)' if streamed else ''} — {'met' if ok else 'NOT met'}{inproc}.**")
        sec.summary.append(f"peak RSS at {count:,} strands: {best['peak_rss_mb']:.0f} MiB"
                           + (" (command line)" if streamed else "") + inproc)
    sec.text("Before the strands grew in blocks (commit 483dfc1, one run each at 1,000,000 strands, measured by "
             "hand): python -m groom generate 4687 MiB (the whole result, then numpy.savez), groom.generate in "
             "process 4007 MiB.")
    sec.text("In process, measured by hand at commit f320517 and after (1,000,000 strands of wavy, one run each, "
             "this machine, the sampled measure above): 2,994 MiB with every page of the result made when its "
             "arrays were (the sum of the processes' VmHWM said 2,266 MiB: a worker that unmaps its block's rows "
             "counts one block at most); alpha of ones in no memory (an opaque groom) 2,717 MiB; each block's "
             "pages made when it grows 2,647 MiB; each part of the collision walk writing its points when done, "
             "in parts of 8,192 strands, 2,326 MiB. What is left beside the result: this process's per-strand "
             "arrays (roots, frames, guides, weights: some 250 bytes a strand) and a worker process with its "
             "own interpreter and collider.")
    _stream_runs(sec)


def _stream_runs(sec):
    """The command's runs past the section's budget (benchmarks/stream_run.py), as stored."""
    from benchmarks.stream_run import result_path
    rows = []
    for count in (10_000_000,):
        try:
            with open(result_path(count)) as f:
                r = json.load(f)
        except (OSError, ValueError):
            sec.not_measured(f"{count:,} strands written as they grow",
                             f"run `python -m benchmarks.stream_run {count}`")
            continue
        m = r["measured"]
        rows.append([f"{count:,}", f"{r['peak_rss_mb']:.0f}", fmt_time(r["time"]),
                     f"{r['cpu_user'] + r['cpu_system']:.0f} s", f"{r['file_bytes'] / 1e9:.1f} GB",
                     f"{m['commit']}, {m['date_utc']}, load {m['load_average']}"])
        sec.summary.append(f"{count:,} strands (command line): {r['peak_rss_mb']:.0f} MiB peak RSS, "
                           f"{fmt_time(r['time'])}")
    if rows:
        sec.table(["strands", "peak RSS of the process (MiB)", "time", "CPU", ".npz", "measured"], rows,
                  caption=f"python -m groom generate --preset {PRESET} --count N, the strands grown and written a "
                          "block at a time, one run in a fresh process by `python -m benchmarks.stream_run N` (too "
                          "long for the section's budget; kept in benchmarks/results/stream_N.json).")


def _incremental(sec, cfg, groom, scalp, collider, placement):
    if over_budget(sec, 0.9):
        sec.not_measured("incremental regeneration", "skipped to stay inside the section's time budget")
        return
    count = 20000 if cfg.mode != "full" else 100000
    keys = list(placement.keys)
    params = placement.params.replace(count=count)
    gen = groom.Generator(scalp, keys, params, collider=collider)
    gen.generate()
    moved_index = 3 % len(keys)
    k = keys[moved_index]
    shift = 0.15 * (k.points[-1] - k.points[0])
    shift[2] = 0.0
    moved = groom.KeyStrand(np.vstack([k.points[:1], k.points[1:] + shift]), kind=k.kind, color=k.color,
                            root_radius=k.root_radius, group=k.group)
    state = {"moved": False}

    def toggle():
        # Alternate moved/original so every timed call really changes one key.
        state["moved"] = not state["moved"]
        return gen.update_keys({moved_index: moved if state["moved"] else k})

    inc, _ = measure(toggle, runs=cfg.runs + (cfg.runs % 2 == 0))
    full, _ = measure(lambda: groom.generate(scalp, keys, params, collider=collider), runs=cfg.runs)
    final = gen.update_keys({moved_index: moved})
    keys_moved = list(keys)
    keys_moved[moved_index] = moved
    reference = groom.generate(scalp, keys_moved, params, collider=collider).strands
    same = all(np.array_equal(getattr(final.strands, n), getattr(reference, n))
               for n in ("points", "counts", "radius", "color", "alpha", "wisp"))
    frac = ratio(inc.median, full.median)
    sec.table(["job", "time (median)", "fraction of full", "strands recomputed", "identical to full run"],
              [["full generate", str(full), "1.00", f"{count:,}", "—"],
               [f"update_keys (1 of {len(keys)} keys moved)", str(inc), f"{frac:.2f}", f"{gen.last_recomputed:,}",
                "yes (bit-identical)" if same else "NO"]],
              caption=f"Incremental regeneration at {count:,} strands of {PRESET}, collision on.")
    sec.summary.append(f"incremental (1 of {len(keys)} keys): {fmt_time(inc.median)} = {frac:.2f} of full; "
                       f"identical={same}")
    sec.data["incremental_fraction"] = frac

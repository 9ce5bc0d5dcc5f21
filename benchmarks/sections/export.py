# SPDX-License-Identifier: GPL-3.0-or-later
"""Export of a groom with guides, format by format (issue 17).

The wavy preset at `int_strands` strands (100,000 in the full report) × 32 points, carrying its
key strands, every strand's three guides and weights and its root UVs, as `groom generate`
writes it, is written in every format of the format registry through the command line's
own path (hairio.cli.export_strands): write time (median of runs after a warm-up) and the
size of everything written (the .npz sidecar, the TressFX guide file and its JSON). Formats
whose library is not installed are named, not measured. TressFX twice: the strands alone,
and with guides taken from the wisps for TressFX's follow hairs (4 per guide). Then how
equal the TressFX chords are per preset and vertex count (the writer asks for 1 %).

Regenerate alone: `python -m benchmarks --full --only export`.
"""
import os
import tempfile

import numpy as np

from benchmarks.harness import TooSlow, fmt_time, measure
from benchmarks.scenes import groom_scene
from benchmarks.sections import left

FOLLOW_HAIRS = 4


def run(sec, cfg):
    sec.text(__doc__.split("\n", 2)[2].strip())
    from groom.generate import strands_with_guides
    from hairio.cli import export_strands
    from hairio.formats import FORMATS
    count = cfg.int_strands
    _, keys, params, result = groom_scene("wavy", count, resolution="fixed", points=32)
    groom = strands_with_guides(result, keys, params)
    # Times on a shared machine depend on what else runs: say how loaded it was.
    sec.settings(strands=f"{groom.num_strands:,}", points=f"{groom.num_points:,}",
                 keys=groom.guides.keys.num_strands, runs=cfg.runs,
                 load_average=f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    jobs = [(f, {}, f.label) for f in FORMATS]
    tfx = next(f for f in FORMATS if f.name == "tfx")
    jobs.insert(FORMATS.index(tfx) + 1, (tfx, {"follow_hairs": FOLLOW_HAIRS},
                                         f"{tfx.label} + guides from the wisps ({FOLLOW_HAIRS} follow hairs each)"))
    rows, summary = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for i, (fmt, opts, label) in enumerate(jobs):
            if not fmt.available():
                rows.append([label, "not measured: " + f"{fmt.library} is not installed", "", ""])
                continue
            path = os.path.join(tmp, f"groom{i}{fmt.extension}")
            written = []
            try:
                t, _ = measure(lambda: written.__setitem__(slice(None), export_strands(groom, path, fmt.name, **opts)),
                               runs=cfg.runs, budget=left(sec, 0.7))
            except TooSlow as e:
                rows.append([label, f"not measured: {e}", "", ""])
                continue
            size = sum(os.path.getsize(p) for p in written)
            names = ", ".join(os.path.basename(p).replace(f"groom{i}", "NAME") for p in written)
            rows.append([label, str(t), f"{size / 2**20:.1f} MiB", names])
            summary.append(f"{fmt.name}{'+guides' if opts else ''} {fmt_time(t.median)} / {size / 2**20:.1f} MiB")
    sec.table(["format", "write time (median)", "size (all files)", "files"], rows,
              caption=f"Export of {groom.num_strands:,} strands × 32 points with "
                      f"{groom.guides.keys.num_strands} key strands as guides.")
    sec.summary.append(f"export {groom.num_strands:,} strands with guides: " + ", ".join(summary))
    _chords(sec, cfg)


def _chords(sec, cfg):
    from hairio.formats import resample_strands
    rows = []
    worst = 0.0
    for preset in ("wavy", "curly"):
        _, _, _, result = groom_scene(preset, min(cfg.int_strands, 20000), resolution="fixed", points=32)
        s = result.strands
        for n in cfg.tfx_vertices:
            if left(sec, 0.95) <= 0:
                rows.append([preset, str(n), "not measured: time budget", "", ""])
                continue
            pts = resample_strands(s, n).points.reshape(-1, n, 3).astype(np.float64)
            chord = np.linalg.norm(np.diff(pts, axis=1), axis=2)
            apart = np.abs(chord / chord.mean(axis=1, keepdims=True) - 1).max(axis=1)
            worst = max(worst, float(apart.max()))
            rows.append([preset, str(n), f"{100 * np.median(apart):.3f} %", f"{100 * apart.max():.2f} %",
                         f"{100 * (apart > 0.01).mean():.2f} %"])
    sec.table(["preset", "vertices", "median deviation", "largest", "strands over 1 %"], rows,
              caption="TressFX chords within a strand: the largest deviation of a chord from the strand's "
                      "mean chord (equal arc steps gave up to 94 %).")
    sec.summary.append(f"TressFX chord deviation at most {100 * worst:.1f} %")

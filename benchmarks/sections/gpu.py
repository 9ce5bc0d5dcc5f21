# SPDX-License-Identifier: GPL-3.0-or-later
"""8. GPU: frames per second at 1920×1080 for 10,000 and 100,000 strands (issue 3; the thesis
managed 10,000 strands at 15–25 fps on a 2006 GPU)."""
import numpy as np

from benchmarks.harness import TooSlow, gl_renderer, measure
from benchmarks.scenes import groom_scene, orbit, settings, tracer_api, tracer_camera, view_matrix
from benchmarks.sections import left

SOFTWARE = ("llvmpipe", "softpipe", "swrast", "software", "lavapipe")


def run(sec, cfg):
    renderer_name = gl_renderer()
    software = any(s in renderer_name.lower() for s in SOFTWARE) or renderer_name.startswith("unavailable")
    sec.text(f"GL renderer of this run: `{renderer_name}`.")
    if software and cfg.mode != "gpu":
        sec.text("**No GPU machine was available for this run**: the renderer above rasterises on the "
                 "CPU, so every tracer time in this report is a CPU time. On a machine with a GPU, run "
                 "`python -m benchmarks --gpu-only` (sizes: 1920×1080, 10,000 and 100,000 strands, "
                 "1 spp, one shadowing light, 4 alpha layers); it fills this section with frames per "
                 "second (re-render after a camera move, nothing uploaded) and the first-render time.")
        sec.summary.append("no GPU available: frames per second not measured (hook: --gpu-only)")
        return
    tracer = tracer_api()
    size = cfg.gpu_size
    rows = []
    r = tracer.Renderer()
    for count in cfg.gpu_counts:
        strands = groom_scene("wavy", count, resolution="adaptive")[3].strands
        lo, hi = strands.bounds()
        matrix = view_matrix(lo, hi, size)
        cams = [tracer_camera(orbit(matrix, np.radians(a), 0.5 * (lo + hi)), size) for a in (0, 10)]
        rs = settings(spp=1, layers=4)
        try:
            first, _ = measure(lambda: (r.set_strands(strands), r.render(cams[0], rs)), runs=cfg.runs,
                               budget=left(sec, 0.45))
            state = {"i": 0}

            def frame():
                state["i"] ^= 1
                return r.render(cams[state["i"]], rs)

            again, _ = measure(frame, runs=max(cfg.runs, 10), budget=left(sec, 0.9))
        except TooSlow as e:
            rows.append([f"{count:,}", f"not measured: {e}", "", ""])
            continue
        fps = 1.0 / again.median
        rows.append([f"{count:,}", str(first), str(again), f"{fps:.1f}"])
        sec.summary.append(f"{count:,} strands at {size[0]}x{size[1]}: {fps:.1f} fps")
    sec.table(["strands", "first render (upload + grid + render)", "frame after a camera move (median)",
               "frames per second"], rows, caption=f"{size[0]}×{size[1]}, 1 spp, shadows, 4 layers.")

# SPDX-License-Identifier: GPL-3.0-or-later
"""9. GPU: frames per second at 1920×1080 for 10,000, 100,000 and 1,000,000 strands (issue 15;
the thesis managed 10,000 strands at 15–25 fps on a 2006 GPU), and the time of a 16-sample
frame beside it."""
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
                 "`python -m benchmarks --gpu-only` (1920×1080; "
                 + ", ".join(f"{c:,}" for c in cfg.gpu_counts) + " strands; one shadowing light, 4 alpha "
                 "layers); it fills this section with frames per second at 1 spp (re-render after a "
                 "camera move, nothing uploaded), the first-render time and a 16-spp frame's time.")
        sec.summary.append("no GPU available: frames per second not measured (hook: --gpu-only)")
        return
    tracer = tracer_api()
    size = cfg.gpu_size
    rows = []
    r = tracer.Renderer()
    # Each count's share of the budget ends where its weight (the square root of its strands:
    # the largest scene takes the most) says.
    weights = np.sqrt(np.asarray(cfg.gpu_counts, np.float64))
    ends = np.cumsum(weights) / weights.sum()
    for count, end in zip(cfg.gpu_counts, ends):
        strands = groom_scene("wavy", count, resolution="adaptive")[3].strands
        lo, hi = strands.bounds()
        matrix = view_matrix(lo, hi, size)
        cams = [tracer_camera(orbit(matrix, np.radians(a), 0.5 * (lo + hi)), size) for a in (0, 10)]
        one, many = settings(spp=1, layers=4), settings(spp=16, layers=4)
        state = {"i": 0}

        def frame(rs):
            state["i"] ^= 1
            return r.render(cams[state["i"]], rs)
        try:
            first, _ = measure(lambda: (r.set_strands(strands), r.render(cams[0], one)), runs=cfg.runs,
                               budget=left(sec, end * 0.4))
            again, _ = measure(lambda: frame(one), runs=max(cfg.runs, 10), budget=left(sec, end * 0.8))
            sixteen, _ = measure(lambda: frame(many), runs=cfg.runs, budget=left(sec, end))
        except TooSlow as e:
            rows.append([f"{count:,}", f"not measured: {e}", "", "", ""])
            continue
        finally:
            del strands
        fps = 1.0 / again.median
        rows.append([f"{count:,}", str(first), str(again), f"{fps:.1f}", str(sixteen)])
        sec.summary.append(f"{count:,} strands at {size[0]}x{size[1]}: {fps:.1f} fps")
    sec.table(["strands", "first render (upload + beams or grid + render)", "frame after a camera move (median)",
               "frames per second", "16-spp frame after a camera move (median)"], rows,
              caption=f"{size[0]}×{size[1]}, shadows, 4 layers; 1 spp unless named.")

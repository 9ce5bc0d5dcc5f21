# SPDX-License-Identifier: GPL-3.0-or-later
"""Meshes in the preview: what the opaque head and body cost.

The shipped `wavy` preset on the bundled scalp, rendered with no mesh, with the bundled head
(groom.default_head, the head the scalp lies on), and with the head and a body (a torso and
shoulders below it: a flattened ellipsoid of 32 x 64 quads, as a scene's body mesh would
stand there), each with one shadow-casting sun. First render: set_meshes and a render (the
strands are already uploaded, as in the add-on, where the meshes change less often than the
view); re-render: the camera turned by 10 degrees, nothing uploaded. Beside each time its
error: a window of the image against the float64 reference tracer with the same meshes
(IoU over the union of both hair-or-mesh masks, RMSE over those pixels).
"""
import numpy as np

from benchmarks.harness import fmt_num, fmt_time, measure, ratio
from benchmarks.metrics import image_error
from benchmarks.scenes import (crop_camera, groom_api, groom_scene, orbit, pick_window, settings, tracer_api,
                               tracer_camera, view_matrix)

HEAD_RGB = (0.62, 0.45, 0.36)
BODY_RGB = (0.25, 0.3, 0.45)


def body_mesh(rings=32, segments=64):
    """A torso below the bundled head: an ellipsoid 0.36 m wide, 0.2 m deep and 0.5 m tall
    whose top (the shoulders) lies 0.14 m under the head's centre."""
    theta = np.linspace(0.0, np.pi, rings + 1)
    phi = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    v = np.stack([0.18 * np.sin(t) * np.cos(p), 0.1 * np.sin(t) * np.sin(p), 0.25 * np.cos(t) - 0.39], axis=-1)
    v = v.reshape(-1, 3)
    i, j = np.meshgrid(np.arange(rings), np.arange(segments), indexing="ij")
    a = i * segments + j
    b = i * segments + (j + 1) % segments
    c, d = a + segments, b + segments
    tri = np.concatenate([np.stack([a, c, b], -1).reshape(-1, 3), np.stack([b, c, d], -1).reshape(-1, 3)])
    return v, tri


def run(sec, cfg):
    tracer = tracer_api()
    groom = groom_api()
    size = (cfg.skip_size, cfg.skip_size)
    scalp, keys, params, result = groom_scene("wavy", cfg.skip_strands, resolution="adaptive")
    strands = result.strands
    head = groom.default_head()
    body_v, body_t = body_mesh()
    scenes = [
        ("none", []),
        ("head", [(head.vertices, head.triangles, HEAD_RGB, "head")]),
        ("head + body", [(head.vertices, head.triangles, HEAD_RGB, "head"), (body_v, body_t, BODY_RGB, "body")]),
    ]
    lo, hi = strands.bounds()
    lo, hi = np.minimum(lo, body_v.min(0)), np.maximum(hi, body_v.max(0))
    matrix = view_matrix(lo, hi, size)
    cam = tracer_camera(matrix, size)
    moved = tracer_camera(orbit(matrix, np.radians(10.0), 0.5 * (lo + hi)), size)
    rs = settings(spp=1)
    r = tracer.Renderer()
    r.set_strands(strands)
    sec.text(__doc__.split("\n", 2)[2].strip())
    sec.settings(preset="wavy", strands=strands.num_strands, cylinders=strands.num_segments,
                 image=f"{size[0]}x{size[1]}", spp=1, shading=rs.shading, runs=cfg.runs,
                 head_triangles=len(head.triangles), body_triangles=len(body_t))
    rows, base = [], {}
    for name, meshes in scenes:
        def first():
            r.set_meshes(meshes)
            return r.render(cam, rs)
        t_first, img = measure(first, runs=cfg.runs)
        t_again, _ = measure(lambda: r.render(moved, rs), runs=cfg.runs)
        x0, y0 = pick_window(img, 24, 24)
        win = crop_camera(cam, x0, y0, 24, 24)
        e = image_error(r.render(win, rs), tracer.reference_render(strands, win, rs, meshes=meshes))
        base.setdefault("first", t_first.median)
        base.setdefault("again", t_again.median)
        rows.append([name, f"{sum(len(m[1]) for m in meshes):,}", str(t_first),
                     f"{ratio(t_first.median, base['first']):.2f}×", str(t_again),
                     f"{ratio(t_again.median, base['again']):.2f}×",
                     f"{100 * e['iou']:.1f} % / {fmt_num(e['rmse_hair'])}"])
        sec.summary.append(f"meshes {name}: first render {fmt_time(t_first.median)} "
                           f"({ratio(t_first.median, base['first']):.2f}× none), re-render "
                           f"{fmt_time(t_again.median)} ({ratio(t_again.median, base['again']):.2f}×); "
                           f"window vs float64 IoU {100 * e['iou']:.1f} %, RMSE {fmt_num(e['rmse_hair'])}")
    sec.table(["meshes", "triangles", "first render (median)", "÷ none", "re-render after a camera move (median)",
               "÷ none", "24² window vs float64: IoU / RMSE"], rows)

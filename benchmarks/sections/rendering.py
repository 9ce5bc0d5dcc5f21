# SPDX-License-Identifier: GPL-3.0-or-later
"""3. Rendering: samples per pixel, minimum pixel width, grid resolution and alpha layers
against image error and time; the float32 GPU tracer against the float64 reference.

The float64 reference costs rays × cylinders, so it renders a window of the real image
(the same camera narrowed to a block of pixels whose hair coverage is near one half: edges
and interior) — pixel for pixel the same rays as the GPU's window. Anti-aliasing errors are
measured over the whole image against a 64-sample stratified GPU render, which is itself
checked against the float64 reference at 64 samples on a window.
"""
import numpy as np

from benchmarks.harness import TooSlow, fmt_num, fmt_time, measure, once
from benchmarks.knobs import grid_scale
from benchmarks.metrics import image_error, pareto_front
from benchmarks.scenes import (crop_camera, groom_scene, pick_window, settings, tracer_api,
                               tracer_camera, view_matrix)
from benchmarks.sections import left, over_budget

WINDOW = 24          # reference window, pixels per side (at most)
REF_PAIRS = 1.5e8    # rays × cylinders one float64 window may cost
AA_WINDOW = 8        # float64 64-sample window


def _err_cells(e):
    return [fmt_num(e["rmse"]), fmt_num(e["max_abs"]), f"{100 * e['coverage_agree']:.2f} %"]


def run(sec, cfg):
    tracer = tracer_api()
    size = (cfg.ren_size, cfg.ren_size)
    # Alpha below 1 towards the tips so layers matter (SPEC §6 alpha profile).
    _, _, params, result = groom_scene("wavy", cfg.ren_strands, resolution="adaptive",
                                       alpha_start=0.5, alpha_tip=0.2)
    strands = result.strands
    camera = tracer_camera(view_matrix(*strands.bounds(), size), size)
    renderer = tracer.Renderer()
    renderer.set_strands(strands)
    base = dict(spp=1, shadows=True, layers=4)
    sec.text(__doc__.split("\n", 3)[3].strip())
    sec.settings(preset="wavy", strands=strands.num_strands, cylinders=strands.num_segments,
                 image=f"{size[0]}x{size[1]}", alpha_start=0.5, alpha_tip=0.2, shading="kajiya-kay",
                 light="one sun, hard shadows", window=f"up to {WINDOW}x{WINDOW}", runs=cfg.runs)
    img = renderer.render(camera, settings(**base))
    x0, y0 = pick_window(img, WINDOW, WINDOW)
    side = int(np.clip(np.sqrt(REF_PAIRS / max(1, strands.num_segments)), 4, WINDOW))
    win = crop_camera(camera, x0, y0, side, side)
    sec.data["window"] = [x0, y0]
    _gpu_vs_reference(sec, cfg, tracer, renderer, strands, camera, win, (x0, y0), base)
    _antialiasing(sec, cfg, tracer, renderer, strands, camera, base)
    _layers(sec, cfg, tracer, renderer, strands, camera, base)
    _grid(sec, cfg, tracer, strands, camera, win, base)


def _gpu_vs_reference(sec, cfg, tracer, renderer, strands, camera, win, xy, base):
    variants = [
        ("Kajiya-Kay, hard shadows, 4 layers", {}),
        ("Phong", {"shading": "phong"}),
        ("transmittance shadows", {"shadow_mode": "transmittance"}),
        ("shadows off", {"shadows": False}),
        ("minimum pixel width", {"min_pixel_width": True}),
        ("9 spp", {"spp": 9}),
    ]
    rows = []
    x0, y0 = xy
    for label, kw in variants:
        if over_budget(sec, 0.25):
            rows.append([label, "not measured: time budget", "", "", "", "", ""])
            continue
        rs = settings(**{**base, **kw})
        t_full, full = measure(lambda: renderer.render(camera, rs), runs=cfg.runs)
        # Fewer pixels when more samples: the float64 cost is rays × cylinders.
        side = int(np.clip(np.sqrt(REF_PAIRS / (max(1, strands.num_segments) * rs.spp)), 4, WINDOW))
        win = crop_camera(camera, x0, y0, side, side)
        gpu_win = renderer.render(win, rs)
        t_ref, ref = once(lambda: tracer.reference_render(strands, win, rs))
        e = image_error(gpu_win, ref)
        same = float(np.abs(full[y0:y0 + side, x0:x0 + side] - gpu_win).max())
        rows.append([label, str(t_full), f"{fmt_time(t_ref)} ({side}²)"] + _err_cells(e) + [fmt_num(same)])
        sec.data.setdefault("f32_vs_f64", []).append({"label": label, **e})
        if not kw:
            sec.summary.append(f"GPU float32 vs float64 reference (window): RMSE {e['rmse']:.2e}, "
                               f"max {e['max_abs']:.2e}, coverage {100 * e['coverage_agree']:.2f} %")
    sec.table(["settings", f"GPU full image {camera.size[0]}² (median)",
               "float64 reference on a window (1 run)", "RMSE", "max abs", "coverage agreement",
               "GPU window vs GPU full-image crop (max abs)"], rows,
              caption="The float32 GPU tracer against the float64 reference tracer of the same model "
                      "(same rays, same settings). Last column: the window camera reproduces the "
                      "full image's pixels (exactly at 1 spp; above 1 spp each image jitters its samples "
                      "by a hash of the pixel's own row and column, so a window draws other samples — "
                      "the reference does the same, so its comparison stays exact).")


def _antialiasing(sec, cfg, tracer, renderer, strands, camera, base):
    ref_spp = cfg.ren_aa_ref_spp
    t_ref, aa_ref = once(lambda: renderer.render(camera, settings(**{**base, "spp": ref_spp})))
    rows, pts = [], []
    for spp in cfg.ren_spp:
        for mpw in (False, True):
            rs = settings(**{**base, "spp": spp, "min_pixel_width": mpw})
            try:
                t, img = measure(lambda: renderer.render(camera, rs), runs=cfg.runs, budget=left(sec, 0.6))
            except TooSlow as e:
                rows.append([str(spp), "on" if mpw else "off", f"not measured: {e}", "", "", ""])
                continue
            e = image_error(img, aa_ref)
            rows.append([str(spp), "on" if mpw else "off", str(t)] + _err_cells(e))
            pts.append((mpw, spp, t.median, e["rmse"], e["max_abs"]))
    # The AA reference itself against float64 at the same samples, on a window small enough
    # for the float64 cost (rays × samples × cylinders).
    side = int(np.clip(np.sqrt(REF_PAIRS / (max(1, strands.num_segments) * ref_spp)), 2, AA_WINDOW))
    x0, y0 = pick_window(aa_ref, side, side)
    w = crop_camera(camera, x0, y0, side, side)
    rs64 = settings(**{**base, "spp": ref_spp})
    check = None
    if not over_budget(sec, 0.65):
        _, ref64 = once(lambda: tracer.reference_render(strands, w, rs64))
        check = image_error(renderer.render(w, rs64), ref64)
    sec.table(["spp", "min pixel width", f"GPU {camera.size[0]}² (median)", "RMSE", "max abs", "coverage agreement"],
              rows, caption=f"Anti-aliasing against a {ref_spp}-sample stratified reference "
                            f"(GPU, {fmt_time(t_ref)} for one render).")
    if check:
        sec.summary.append(f"{ref_spp}-spp GPU reference vs float64 at {ref_spp} spp ({side}² window): RMSE "
                           f"{check['rmse']:.2e}, coverage {100 * check['coverage_agree']:.1f} %")
        sec.text(f"Check of that reference: GPU {ref_spp} spp against the float64 reference at {ref_spp} spp on "
                 f"a {side}×{side} window: RMSE {fmt_num(check['rmse'])}, max abs "
                 f"{fmt_num(check['max_abs'])}, coverage agreement {100 * check['coverage_agree']:.2f} %.")
    else:
        sec.not_measured("float64 check of the 64-sample reference", "time budget")
    if pts:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(5.8, 3.8))
        for mpw, marker in ((False, "o"), (True, "^")):
            sel = [p for p in pts if p[0] == mpw]
            ax.plot([p[2] * 1e3 for p in sel], [p[3] for p in sel], marker=marker, ls="-",
                    label=f"min pixel width {'on' if mpw else 'off'}")
            for p in sel:
                ax.annotate(f"{p[1]} spp", (p[2] * 1e3, p[3]), fontsize=7, xytext=(3, 3), textcoords="offset points")
        xs = np.array([p[2] for p in pts])
        ys = np.array([p[3] for p in pts])
        front = pareto_front(xs, ys)
        ax.plot(xs[front] * 1e3, ys[front], "k--", lw=0.8, label="Pareto front")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("GPU render time (ms, median)")
        ax.set_ylabel(f"RMSE against {ref_spp}-spp reference")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
        sec.figure(fig, "rendering_pareto_aa.png", "Anti-aliasing: time against RMSE (lower left is better).")
        best = min(pts, key=lambda p: p[3])
        sec.summary.append(f"AA: best RMSE {best[3]:.2e} at {best[1]} spp, mpw {'on' if best[0] else 'off'}, "
                           f"{best[2] * 1e3:.0f} ms")
    return aa_ref


def _layers(sec, cfg, tracer, renderer, strands, camera, base):
    if over_budget(sec, 0.8):
        sec.not_measured("alpha layers", "time budget")
        return
    ref = renderer.render(camera, settings(**{**base, "layers": 64}))
    rows, pts = [], []
    for k in cfg.ren_layers:
        rs = settings(**{**base, "layers": k})
        t, img = measure(lambda: renderer.render(camera, rs), runs=cfg.runs)
        e = image_error(img, ref)
        rows.append([str(k), str(t)] + _err_cells(e))
        pts.append((k, t.median, e["rmse"]))
    sec.table(["layers K", f"GPU {camera.size[0]}² (median)", "RMSE", "max abs", "coverage agreement"], rows,
              caption="Alpha layers against the same render with 64 layers (alpha 1 → 0.2 along each strand).")
    _simple_plot(sec, pts, "layers K", "rendering_pareto_layers.png", "Alpha layers: time against RMSE.")


def _grid(sec, cfg, tracer, strands, camera, win, base):
    if over_budget(sec, 0.85):
        sec.not_measured("grid resolution", "time budget")
        return
    rs = settings(**base)
    ref = None
    rows, pts, default_img, default_cells = [], [], None, None
    for scale in sorted(cfg.ren_grid_scale, key=lambda s: s != 1.0):
        try:
            with grid_scale(scale):
                r = tracer.Renderer()
                t_build, _ = measure(lambda: r.set_strands(strands), runs=cfg.runs, budget=left(sec, 1.0))
            stats = dict(r.stats)
            t, img = measure(lambda: r.render(camera, rs), runs=cfg.runs, budget=left(sec, 1.0))
        except TooSlow as e:
            rows.append([f"{scale:g}×", f"not measured: {e}", "", "", "", "", "", ""])
            continue
        if scale == 1.0:
            default_img = img
            ref = tracer.reference_render(strands, win, rs) if not over_budget(sec, 0.9) else None
        e = image_error(r.render(win, rs), ref) if ref is not None else None
        diff = float(np.abs(img - default_img).max()) if default_img is not None else float("nan")
        dims = "×".join(str(d) for d in stats.get("grid_dims", ()))
        cells = float(np.prod(stats.get("grid_dims", (1,))))
        default_cells = default_cells or cells
        actual = (cells / default_cells) ** (1 / 3)
        label = f"{scale:g}×" + (f" (capped at {actual:.2f}×)" if abs(actual - scale) > 0.05 * scale else "")
        rows.append([label, dims, fmt_num(stats.get("cylinders_per_full_cell")), str(t_build), str(t)]
                    + ([fmt_num(e["rmse"]), fmt_num(e["max_abs"])] if e else ["n/a", "n/a"]) + [fmt_num(diff)])
        pts.append((f"{scale:g}×", t.median, t_build.median))
    sec.table(["grid cells per axis", "dims", "cylinders per non-empty cell", "set_strands (upload + grid, median)",
               "render (median)", "RMSE vs float64 (window)", "max abs vs float64", "max abs vs default grid"], rows,
              caption="Grid resolution as a multiple of the tracer's own choice. The image must not depend on "
                      "it (last column); only the time may.")
    if pts:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(5.5, 3.5))
        ax.plot([p[0] for p in pts], [p[1] * 1e3 for p in pts], "o-", label="render")
        ax.plot([p[0] for p in pts], [p[2] * 1e3 for p in pts], "s-", label="upload + grid build")
        ax.set_xlabel("grid cells per axis (× the tracer's choice)")
        ax.set_ylabel("ms (median)")
        ax.grid(True, alpha=0.3)
        ax.legend()
        sec.figure(fig, "rendering_grid.png", "Grid resolution against time (the image is unchanged).")


def _simple_plot(sec, pts, label, name, caption):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(5.5, 3.5))
    ax.plot([p[1] * 1e3 for p in pts], [max(p[2], 1e-12) for p in pts], "o-")
    for p in pts:
        ax.annotate(f"{label.split()[-1]}={p[0]}", (p[1] * 1e3, max(p[2], 1e-12)), fontsize=7, xytext=(3, 3),
                    textcoords="offset points")
    ax.set_yscale("log")
    ax.set_xlabel("GPU render time (ms, median)")
    ax.set_ylabel("RMSE")
    ax.grid(True, which="both", alpha=0.3)
    sec.figure(fig, name, caption)


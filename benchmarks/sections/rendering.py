# SPDX-License-Identifier: GPL-3.0-or-later
"""3. Rendering: samples per pixel, minimum pixel width, grid resolution and alpha layers
against image error and time; the float32 GPU tracer against two float64 references: the
mirror of the shader's model (tracer.reference) and one written from the solids alone
(tracer.reference_solid), which shares no code with the shader's hit test.

Every error is measured over a whole image, as coverage IoU (agreement over the union of
both images' hair pixels, alpha >= 0.5, so an empty image scores 0) and RMSE over those hair
pixels, with at least 10⁴ hair pixels in the full run: the accuracy image is rendered as
large as that takes. Where a reference would take too long for every pixel it traces a
uniform random subset of the image's pixel centres (rays, not a window; "rays" says how
many). Anti-aliasing errors are measured against a 64-sample stratified GPU render, which is
itself checked against the float64 reference at 64 samples.
"""
import numpy as np

from benchmarks.harness import TooSlow, fmt_num, fmt_time, measure, once
from benchmarks.knobs import grid_scale
from benchmarks.metrics import MIN_HAIR_PIXELS, image_error, pareto_front, whole_image_error
from benchmarks.scenes import (crop_camera, groom_scene, pick_window, settings, tracer_api,
                               tracer_camera, view_matrix)
from benchmarks.sections import left, over_budget

WINDOW = 24          # the old method's window, pixels per side (at most)
REF_PAIRS = 1.5e8    # rays × cylinders one float64 window of the old method may cost
MAX_SIDE = 1024      # the accuracy image's largest side
QUICK_HAIR = 2000    # hair pixels the quick run aims at (the full run: MIN_HAIR_PIXELS)


def _err_cells(e):
    """IoU, RMSE over hair pixels, max abs, hair pixels (of how many compared)."""
    if e is None:
        return ["n/a"] * 4
    return [f"{100 * e['iou']:.3f} %", fmt_num(e["rmse_hair"]), fmt_num(e["max_abs"]),
            f"{e['hair_pixels']:,}" + (f" of {e['rays']:,} rays" if "rays" in e else "")]


def _old_cells(e):
    """The old method: RMSE over every pixel and coverage agreement counting background."""
    return f"{fmt_num(e['rmse'])} / {100 * e['coverage_agree']:.2f} %"


def accuracy_camera(strands, renderer, rs, size, target):
    """A camera of the usual view whose image holds about `target` hair pixels (alpha >=
    0.5): `size` scaled up by the square root of what the image at `size` lacks."""
    lo, hi = strands.bounds()
    cam = tracer_camera(view_matrix(lo, hi, size), size)
    hair = int((renderer.render(cam, rs)[..., 3] >= 0.5).sum())
    side = int(np.clip(np.ceil(size[0] * np.sqrt(1.15 * target / max(hair, 1))), size[0], MAX_SIDE))
    return tracer_camera(view_matrix(lo, hi, (side, side)), (side, side))


def reference_error(tracer, which, strands, camera, rs, image, seconds_per_ray=None, budget=None):
    """whole_image_error of the GPU `image` against reference `which` ("model": tracer.
    reference_render, "solid": tracer.reference_solid.solid_render), every pixel unless that
    would take more than `budget` seconds at `seconds_per_ray` (then a random subset of the
    pixel centres that fits). Returns (error dict, seconds, seconds per ray traced)."""
    from tracer.reference_solid import solid_render
    fn = tracer.reference_render if which == "model" else solid_render
    w, h = camera.size
    rays = None
    if seconds_per_ray is None and budget is not None and w * h > 4000:
        # What a ray costs here, from a thousand of them (another subset than the figure's).
        t, e = once(lambda: whole_image_error(image, lambda px: fn(strands, camera, rs, pixels=px), max_rays=1000,
                                              seed=1))
        seconds_per_ray = t / (1000 * rs.spp)
    if seconds_per_ray and budget is not None and seconds_per_ray * w * h * rs.spp > budget:
        rays = max(256, int(budget / (seconds_per_ray * rs.spp)))
    t, e = once(lambda: whole_image_error(image, lambda px: fn(strands, camera, rs, pixels=px), max_rays=rays))
    return e, t, t / max(1, e["rays"] * rs.spp)


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
    base = dict(spp=1, shadows=True, layers=4, shading="kajiya-kay")
    sec.text(__doc__.split("\n\n", 1)[1].strip())
    sec.settings(preset="wavy", strands=strands.num_strands, cylinders=strands.num_segments,
                 image=f"{size[0]}x{size[1]}", alpha_start=0.5, alpha_tip=0.2, shading="kajiya-kay",
                 light="one sun, hard shadows", window=f"up to {WINDOW}x{WINDOW}", runs=cfg.runs)
    img = renderer.render(camera, settings(**base))
    x0, y0 = pick_window(img, WINDOW, WINDOW)
    sec.data["window"] = [x0, y0]
    target = QUICK_HAIR if cfg.mode == "quick" else MIN_HAIR_PIXELS
    acc = accuracy_camera(strands, renderer, settings(**base), size, target)
    sec.data["accuracy_image"] = list(acc.size)
    _gpu_vs_reference(sec, cfg, tracer, renderer, strands, camera, acc, (x0, y0), base)
    _antialiasing(sec, cfg, tracer, renderer, strands, camera, base)
    _layers(sec, cfg, tracer, renderer, strands, camera, base)
    _grid(sec, cfg, tracer, strands, camera, acc, base)


def _gpu_vs_reference(sec, cfg, tracer, renderer, strands, camera, acc, xy, base):
    variants = [
        ("Kajiya-Kay, hard shadows, 4 layers", {}),
        ("Phong", {"shading": "phong"}),
        ("Principled hair (Chiang)", {"shading": "chiang"}),
        ("transmittance shadows", {"shadow_mode": "transmittance"}),
        ("shadows off", {"shadows": False}),
        ("minimum pixel width", {"min_pixel_width": True}),
        ("9 spp", {"spp": 9}),
    ]
    rows = []
    x0, y0 = xy
    per_ray = {"model": None, "solid": None}
    n = len(variants)
    for i, (label, kw) in enumerate(variants):
        if over_budget(sec, 0.3):
            rows.append([label, "not measured: time budget"] + [""] * 10)
            continue
        rs = settings(**{**base, **kw})
        t_full, _ = measure(lambda: renderer.render(camera, rs), runs=cfg.runs)
        img = renderer.render(acc, rs)
        errs = {}
        for which in ("model", "solid"):
            if which == "solid" and rs.min_pixel_width:
                errs[which] = None      # widening is a rendering device, not geometry
                continue
            # Each variant its share of what is left of the part, split between the two.
            share = max(0.0, left(sec, 0.3)) / (2 * (n - i))
            e, t_ref, per_ray[which] = reference_error(tracer, which, strands, acc, rs, img, per_ray[which], share)
            errs[which] = e
            sec.data.setdefault(f"f32_vs_{which}", []).append({"label": label, "seconds": t_ref, **e})
        # The old method beside them, once: a window of the image, every pixel counted.
        side = int(np.clip(np.sqrt(REF_PAIRS / (max(1, strands.num_segments) * rs.spp)), 4, WINDOW))
        win = crop_camera(camera, x0, y0, side, side)
        old = image_error(renderer.render(win, rs), tracer.reference_render(strands, win, rs))
        rows.append([label, str(t_full)] + _err_cells(errs["model"]) + _err_cells(errs["solid"])
                    + [f"{_old_cells(old)} ({side}²)"])
        if not kw:
            e, o = errs["model"], errs["solid"]
            sec.summary.append(f"GPU float32 vs float64, whole {acc.size[0]}² image: IoU {100 * e['iou']:.3f} %, "
                               f"RMSE (hair) {e['rmse_hair']:.2e} vs the model's reference; IoU {100 * o['iou']:.3f} %, "
                               f"RMSE (hair) {o['rmse_hair']:.2e} vs the solids' (old method, window: RMSE "
                               f"{old['rmse']:.2e}, coverage {100 * old['coverage_agree']:.2f} %)")
    head = ["IoU", "RMSE (hair)", "max abs", "hair pixels"]
    sec.table(["settings", f"GPU {camera.size[0]}² (median)"] + [f"{h} vs model reference" for h in head]
              + [f"{h} vs solid reference" for h in head]
              + ["old method: window RMSE / coverage agreement (window size)"], rows,
              caption=f"The float32 GPU tracer against the float64 references on the whole {acc.size[0]}×{acc.size[1]} "
                      "image (same rays, same settings): the model's (tracer.reference, the shader's rules in "
                      "float64) and the solids' (tracer.reference_solid, written from the geometry; it does not "
                      "widen strands, so not for minimum pixel width). IoU over the union of both hair masks, RMSE "
                      "over those pixels. Last column: the figures of the old method, a window whose every pixel "
                      "counted (background included), for comparison.")


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
    # The AA reference itself against float64 at the same samples, over the whole image (a
    # subset of its pixels' rays when all would not fit: rays × samples × cylinders).
    rs64 = settings(**{**base, "spp": ref_spp})
    check = None
    if not over_budget(sec, 0.65):
        check, _, _ = reference_error(tracer, "model", strands, camera, rs64, aa_ref,
                                      seconds_per_ray=2e-4, budget=max(1.0, left(sec, 0.7)))
    sec.table(["spp", "min pixel width", f"GPU {camera.size[0]}² (median)", "IoU", "RMSE (hair)", "max abs",
               "hair pixels"],
              rows, caption=f"Anti-aliasing against a {ref_spp}-sample stratified reference "
                            f"(GPU, {fmt_time(t_ref)} for one render).")
    if check:
        sec.summary.append(f"{ref_spp}-spp GPU reference vs float64 at {ref_spp} spp (whole image, {check['rays']:,} "
                           f"pixels): IoU {100 * check['iou']:.2f} %, RMSE (hair) {check['rmse_hair']:.2e}")
        sec.text(f"Check of that reference: GPU {ref_spp} spp against the float64 reference at {ref_spp} spp over "
                 f"the whole image ({check['rays']:,} of its pixels, {check['hair_pixels']:,} of them hair): IoU "
                 f"{100 * check['iou']:.3f} %, RMSE over hair pixels {fmt_num(check['rmse_hair'])}, max abs "
                 f"{fmt_num(check['max_abs'])} (old method: RMSE {fmt_num(check['rmse'])}, coverage agreement "
                 f"{100 * check['coverage_agree']:.2f} %).")
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
    sec.table(["layers K", f"GPU {camera.size[0]}² (median)", "IoU", "RMSE (hair)", "max abs", "hair pixels"], rows,
              caption="Alpha layers against the same render with 64 layers (alpha 1 → 0.2 along each strand).")
    _simple_plot(sec, pts, "layers K", "rendering_pareto_layers.png", "Alpha layers: time against RMSE.")


def _grid(sec, cfg, tracer, strands, camera, acc, base):
    if over_budget(sec, 0.85):
        sec.not_measured("grid resolution", "time budget")
        return
    rs = settings(**base)
    ref = None
    rows, pts, default_img, default_cells = [], [], None, None
    for scale in sorted(cfg.ren_grid_scale, key=lambda s: s != 1.0):
        try:
            with grid_scale(scale):
                r = tracer.Renderer(accel="grid")   # the grid's own resolution
                t_build, _ = measure(lambda: r.set_strands(strands), runs=cfg.runs, budget=left(sec, 1.0))
            stats = r.stats.as_dict()
            t, img = measure(lambda: r.render(camera, rs), runs=cfg.runs, budget=left(sec, 1.0))
        except TooSlow as e:
            rows.append([f"{scale:g}×", f"not measured: {e}", "", "", "", "", "", ""])
            continue
        whole = r.render(acc, rs)
        if scale == 1.0:
            default_img = whole
            ref = tracer.reference_render(strands, acc, rs) if not over_budget(sec, 0.9) else None
        e = image_error(whole, ref) if ref is not None else None
        diff = float(np.abs(whole - default_img).max()) if default_img is not None else float("nan")
        dims = "×".join(str(d) for d in stats.get("grid_dims", ()))
        cells = float(np.prod(stats.get("grid_dims", (1,))))
        default_cells = default_cells or cells
        actual = (cells / default_cells) ** (1 / 3)
        label = f"{scale:g}×" + (f" (capped at {actual:.2f}×)" if abs(actual - scale) > 0.05 * scale else "")
        rows.append([label, dims, fmt_num(stats.get("cylinders_per_full_cell")), str(t_build), str(t)]
                    + ([f"{100 * e['iou']:.3f} %", fmt_num(e["rmse_hair"])] if e else ["n/a", "n/a"]) + [fmt_num(diff)])
        pts.append((f"{scale:g}×", t.median, t_build.median))
    sec.table(["grid cells per axis", "dims", "cylinders per non-empty cell", "set_strands (upload + grid, median)",
               "render (median)", "IoU vs float64 (whole image)", "RMSE (hair) vs float64", "max abs vs default grid"],
              rows,
              caption="Grid resolution as a multiple of the tracer's own choice. The image must not depend on "
                      f"it (last column, on the whole {acc.size[0]}² accuracy image, as the float64 figures); only the "
                      "time may.")
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


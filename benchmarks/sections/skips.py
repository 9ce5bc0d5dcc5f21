# SPDX-License-Identifier: GPL-3.0-or-later
"""6. Skips: each piece of work a scene does not need, skipped and not skipped, with the time
and the proof that the output is what it should be.

Switches the tracer has no setting for (screen bounds, one layer at alpha 1) are turned off
from outside for this measurement only (benchmarks/knobs.py).
"""
import numpy as np

from benchmarks.harness import fmt_num, measure, ratio
from benchmarks.knobs import all_layers, no_screen_bounds
from benchmarks.metrics import curve_to_polyline_distance, image_error
from benchmarks.scenes import (crop_camera, groom_api, groom_scene, orbit, pick_window, settings, tracer_api,
                               tracer_camera, view_matrix)
from benchmarks.sections import over_budget


def run(sec, cfg):
    tracer = tracer_api()
    size = (cfg.skip_size, cfg.skip_size)
    scalp, keys, params, result = groom_scene("wavy", cfg.skip_strands, resolution="adaptive")
    strands = result.strands
    lo, hi = strands.bounds()
    matrix = view_matrix(lo, hi, size)
    cam = tracer_camera(matrix, size)
    r = tracer.Renderer(accel="grid")     # the skips of the grid walk (the beams': section 6)
    r.set_strands(strands)
    sec.text(__doc__.split("\n", 2)[2].strip())
    sec.settings(preset="wavy", strands=strands.num_strands, cylinders=strands.num_segments,
                 image=f"{size[0]}x{size[1]}", spp=1, layers=4, runs=cfg.runs)
    rows = []

    def row(name, t_on, t_off, proof):
        rows.append([name, str(t_on), str(t_off), f"{ratio(t_off.median, t_on.median):.2f}×", proof])
        sec.summary.append(f"{name}: {t_on} skipped vs {t_off} not skipped — {proof}")

    base = settings(spp=1, layers=4)
    # 1. shadows off: no shadow ray at all
    no_sh = settings(spp=1, layers=4, shadows=False)
    t_off, _ = measure(lambda: r.render(cam, base), runs=cfg.runs)
    t_on, img = measure(lambda: r.render(cam, no_sh), runs=cfg.runs)
    r.render(cam, settings(spp=1, layers=4, shadows=False, count=True))
    rays_off = r.stats.shadow_rays
    r.render(cam, settings(spp=1, layers=4, shadows=True, count=True))
    rays_on = r.stats.shadow_rays
    x0, y0 = pick_window(img, 16, 16)
    win = crop_camera(cam, x0, y0, 16, 16)
    e = image_error(r.render(win, no_sh), tracer.reference_render(strands, win, no_sh))
    row("shadows off (vs on)", t_on, t_off,
        f"shadow rays traced: {rays_off} (with shadows: {rays_on:,}); image vs float64 reference with shadows off: "
        f"IoU {100 * e['iou']:.1f} %, RMSE over the hair {fmt_num(e['rmse_hair'])}, {e['bad_pixels']} of "
        f"{e['hair_pixels']} hair pixels off")

    # 2. alpha 1: one layer
    t_on, img1 = measure(lambda: r.render(cam, base), runs=cfg.runs)
    with all_layers(r):
        t_off, img4 = measure(lambda: r.render(cam, base), runs=cfg.runs)
    row("alpha 1 → one layer (vs 4 layers)", t_on, t_off,
        f"all alpha = 1: {bool(strands.alpha.min() >= 1)}; images differ by max abs "
        f"{fmt_num(float(np.abs(img1 - img4).max()))}")

    # 3. screen bounds
    with no_screen_bounds(r):
        t_off, img_all = measure(lambda: r.render(cam, base), runs=cfg.runs)
        px_all = r.stats.traversed_pixels
    t_on, img_box = measure(lambda: r.render(cam, base), runs=cfg.runs)
    row("screen bounds (vs every pixel)", t_on, t_off,
        f"pixels traced {r.stats.traversed_pixels:,} of {px_all:,}; images differ by max abs "
        f"{fmt_num(float(np.abs(img_box - img_all).max()))}")

    # 4. bounds clipping: measured, not switchable (the walk starts where the ray enters the grid)
    miss, inside = _rays_missing_box(cam, r)
    sec.text(f"Bounds clipping has no off switch: the grid walk starts where the ray enters the hair's "
             f"bounds and stops where it leaves. Of the {inside:,} pixels inside the screen box, "
             f"{miss:,} ({100 * miss / max(1, inside):.1f} %) have rays that miss the bounds entirely and cost one "
             f"slab test; the rest walk only the cells inside the box.")

    # 5. camera move: no re-upload
    moved = tracer_camera(orbit(matrix, np.radians(15), 0.5 * (lo + hi)), size)
    before = r.stats.bytes_uploaded
    state = {"flip": False}

    def rerender():
        state["flip"] = not state["flip"]
        return r.render(moved if state["flip"] else cam, base)

    t_on, _ = measure(rerender, runs=cfg.runs)
    sent = r.stats.bytes_uploaded - before
    t_off, _ = measure(lambda: (r.set_strands(strands), r.render(moved, base)), runs=cfg.runs)
    fresh = tracer.Renderer(accel="grid")
    fresh.set_strands(strands)
    same = float(np.abs(fresh.render(moved, base) - r.render(moved, base)).max())
    row("camera move: render only (vs upload + grid + render)", t_on, t_off,
        f"bytes uploaded by {2 * cfg.runs + 2} re-renders: {sent}; image equals a fresh upload's: max abs {fmt_num(same)}")

    # 6. incremental regeneration (groom) and partial re-upload (tracer). Fixed resolution, so
    # a moved key changes point positions but not counts and the tracer can patch in place.
    try:
        _incremental(sec, cfg, r, fresh, cam, base, scalp, keys, params, row)
    except Exception as e:  # noqa: BLE001 — report it, keep the other rows
        sec.not_measured("incremental regeneration / partial re-upload", f"{type(e).__name__}: {e}")
    try:
        _adaptive(sec, cfg, r, cam, base, scalp, keys, params, strands, row)
    except Exception as e:  # noqa: BLE001
        sec.not_measured("adaptive resolution", f"{type(e).__name__}: {e}")
    sec.table(["skip", "time with the skip (median)", "time without (median)", "speed-up", "proof"], rows)


def _incremental(sec, cfg, r, fresh, cam, base, scalp, keys, params, row):
    if not over_budget(sec, 0.7):
        groom = groom_api()
        fparams = params.replace(resolution_mode="fixed", points_per_strand=32)
        base_strands = groom.generate(scalp, keys, fparams).strands
        gen = groom.Generator(scalp, keys, fparams)
        gen.generate()
        k = keys[0]
        shift = 0.1 * (k.points[-1] - k.points[0])
        moved_key = groom.KeyStrand(np.vstack([k.points[:1], k.points[1:] + shift]), kind=k.kind, color=k.color,
                                    root_radius=k.root_radius, group=k.group)
        flip = {"on": False}

        def update():
            flip["on"] = not flip["on"]
            return gen.update_keys({0: moved_key if flip["on"] else k})

        t_on, _ = measure(update, runs=cfg.runs)
        t_off, _ = measure(lambda: groom.generate(scalp, keys, fparams), runs=cfg.runs)
        inc = gen.update_keys({0: moved_key})
        full = groom.generate(scalp, [moved_key] + list(keys[1:]), fparams)
        same = all(np.array_equal(getattr(inc.strands, n), getattr(full.strands, n))
                   for n in ("points", "counts", "radius", "color", "alpha", "wisp"))
        changed = np.flatnonzero(np.isin(inc.guides, [0]).any(axis=1))
        row(f"incremental regeneration, 1 of {len(keys)} keys moved, {len(changed):,} of "
            f"{inc.strands.num_strands:,} strands affected (vs full)", t_on, t_off,
            f"result bit-identical to a full regeneration: {same}")
        r.set_strands(base_strands)
        fresh.set_strands(inc.strands)
        b = fresh.render(cam, base)
        flip2 = {"on": False}

        def patch():
            flip2["on"] = not flip2["on"]
            r.update_strands(changed, inc.strands if flip2["on"] else base_strands)

        t_on, _ = measure(patch, runs=cfg.runs + (cfg.runs % 2 == 0))   # odd: ends on the moved key
        t_off, _ = measure(lambda: r.set_strands(inc.strands), runs=cfg.runs)
        r.set_strands(base_strands)
        r.update_strands(changed, inc.strands)
        a = r.render(cam, base)
        row(f"re-upload the {len(changed):,} changed strands (vs all)", t_on, t_off,
            f"image equals a full upload's: max abs {fmt_num(float(np.abs(a - b).max()))}")



def _adaptive(sec, cfg, r, cam, base, scalp, keys, params, strands, row):
    """7. adaptive resolution against fixed 25 cylinders, at the same maximum error."""
    if not over_budget(sec, 0.85):
        groom = groom_api()
        sub = params.replace(count=min(40, params.count))
        exact = groom.generate(scalp, keys, sub.replace(resolution_mode="fixed", points_per_strand=2049)).strands
        fx = groom.generate(scalp, keys, sub.replace(resolution_mode="fixed", points_per_strand=26)).strands
        e_fx = float(curve_to_polyline_distance(exact.points, exact.counts, fx.points, fx.counts)[0].max())
        tol = params.replace(resolution_mode="adaptive", tolerance=e_fx, points_per_strand=129)
        ad = groom.generate(scalp, keys, tol.replace(count=sub.count)).strands
        e_ad = float(curve_to_polyline_distance(exact.points, exact.counts, ad.points, ad.counts)[0].max())
        adaptive = groom.generate(scalp, keys, tol).strands
        fixed = groom.generate(scalp, keys, params.replace(resolution_mode="fixed", points_per_strand=26)).strands
        r.set_strands(adaptive)
        t_on, _ = measure(lambda: r.render(cam, base), runs=cfg.runs)
        r.set_strands(fixed)
        t_off, _ = measure(lambda: r.render(cam, base), runs=cfg.runs)
        row("adaptive resolution at fixed 25's maximum error (vs fixed 25)", t_on, t_off,
            f"cylinders {adaptive.num_segments:,} vs {fixed.num_segments:,}; max distance to the exact curve "
            f"{fmt_num(e_ad)} m vs {fmt_num(e_fx)} m (tolerance set to the latter)")


def _rays_missing_box(cam, r):
    """Pixels in the screen box whose primary ray misses the grid bounds (CPU slab test)."""
    box = r.screen_bounds(cam)
    if box is None:
        return 0, 0
    x0, y0, x1, y1 = box
    ys, xs = np.mgrid[y0:y1, x0:x1]
    o, d = cam.rays(xs.ravel() + 0.5, ys.ravel() + 0.5)
    lo, hi = r.grid.lo, r.grid.hi
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        t0 = (lo - o) * inv
        t1 = (hi - o) * inv
    tmin = np.nanmax(np.minimum(t0, t1), axis=1)
    tmax = np.nanmin(np.maximum(t0, t1), axis=1)
    hit = (tmax >= np.maximum(tmin, 0))
    return int((~hit).sum()), int(hit.size)

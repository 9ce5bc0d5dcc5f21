# SPDX-License-Identifier: GPL-3.0-or-later
"""9. Extension and export figures.

Issue 4: time from "Generate" (the `hair.generate` operator: read scalp and keys, run groom,
write the Curves object) to a finished Curves object, against groom alone on the same
arrays; time from "Render Preview" (`hair.render_preview`: camera, render, pixels into the
"Hair Preview" image) to pixels, against the tracer alone. Both measured by
`benchmarks/blender_hooks.py` driving this checkout's add-on (median of runs after a warm-up,
same process; Generate, Generate without Blender's undo step and groom alone called in turn).
Generate grows the new hair in the memory of the hair it replaces (groom.processes.recycling,
docs/DECISIONS.md); groom alone, called as a script would, gets fresh pages each call, which
in a process with Blender cost more (DECISIONS, "Blocks of strands in worker processes"). So
the ratio is what an artist's press costs beside the package's own call, not the write alone.

Issue 5: export time and file size per format for one groom, and the `.tfx` resampling
error (largest distance from the original strand to the resampled one) per vertex count.
"""
import os
import tempfile

import numpy as np

from benchmarks.harness import TooSlow, fmt_num, fmt_time, measure, ratio
from benchmarks.metrics import curve_to_polyline_distance
from benchmarks.scenes import groom_scene
from benchmarks.sections import left, over_budget


def run(sec, cfg):
    sec.text(__doc__.split("\n", 2)[2].strip())
    _export(sec, cfg)       # cheap, and issue 5's figures: first
    _extension(sec, cfg)


def _extension(sec, cfg):
    try:
        import bpy  # noqa: F401
        import addon
        from benchmarks.blender_hooks import BlenderHooks
    except ImportError as e:
        sec.not_measured("extension timings", f"the add-on is not importable here ({e})")
        return
    from benchmarks.blender_anchors import reset_scene
    reset_scene()
    try:
        addon.register()
    except Exception as e:  # noqa: BLE001 — a registration failure is a finding for the report
        sec.not_measured("extension timings", f"addon.register() failed: {type(e).__name__}: {e}")
        return
    count = cfg.int_strands
    try:
        hooks = BlenderHooks("addon")
        scalp = hooks.demo_scene("wavy", count)
        g = hooks.generate_timings(scalp, count=count, runs=cfg.runs)
        rows = [["Generate → Curves object", f"{g['strands']:,} strands, {g['points']:,} points",
                 fmt_time(g["operator_s"]), fmt_time(g["groom_s"]), f"{ratio(g['operator_s'], g['groom_s']):.2f}",
                 f"read scene {fmt_time(g['read_s'])}, write Curves {fmt_time(g['write_s'])}; the operator without "
                 f"Blender's undo step after it {fmt_time(g['operator_no_undo_s'])} "
                 f"({ratio(g['operator_no_undo_s'], g['groom_s']):.2f}× groom)"]]
        sec.summary.append(f"Generate {fmt_time(g['operator_s'])} vs groom {fmt_time(g['groom_s'])} "
                           f"({ratio(g['operator_s'], g['groom_s']):.2f}×; without Blender's undo step "
                           f"{ratio(g['operator_no_undo_s'], g['groom_s']):.2f}×) at {g['strands']:,} strands")
        if not over_budget(sec, 0.8):
            p = hooks.preview_timings(scalp, runs=cfg.runs)
            w, h = p["size"]
            rows.append([f"Render Preview → pixels ({'in process' if p['in_process'] else 'worker process'})",
                         f"{w}×{h}", fmt_time(p["operator_s"]), fmt_time(p["tracer_s"]),
                         f"{ratio(p['operator_s'], p['tracer_s']):.2f}",
                         f"upload {fmt_time(p['upload_s'])}, pixels → image {fmt_time(p['write_image_s'])}, "
                         f"Curves → strands {fmt_time(p['read_strands_s'])}"])
            sec.summary.append(f"Render Preview {fmt_time(p['operator_s'])} vs tracer {fmt_time(p['tracer_s'])}")
        else:
            rows.append(["Render Preview → pixels", "not measured: time budget", "", "", "", ""])
        sec.table(["action", "size", "operator (median)", "package alone (median)", "ratio", "parts"], rows,
                  caption="The extension's overhead over the pure packages (issue 4).")
    except Exception as e:  # noqa: BLE001
        sec.not_measured("extension timings", f"{type(e).__name__}: {e}")
    finally:
        try:
            addon.unregister()
        except Exception:  # noqa: BLE001 — the report is what matters here
            pass


def _export(sec, cfg):
    try:
        from hairio import InputError
        from hairio.formats import write_strands, read_strands, resampling_errors
    except ImportError as e:
        sec.not_measured("export figures", f"hairio.formats is not importable ({e})")
        return
    from groom.generate import strands_with_guides
    _, keys, params, result = groom_scene("wavy", cfg.int_strands, resolution="fixed", points=32)
    strands = result.strands
    # The grooms carry the key strands, guides and weights, as `groom generate` writes them.
    with_guides = strands_with_guides(result, keys, params)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        jobs = [("npz", {}), ("hair", {}), ("tfx", {"vertices_per_strand": 32}), ("data", {})]
        for ext, opts in jobs:
            path = os.path.join(tmp, f"groom.{ext}")
            try:
                t, _ = measure(lambda: write_strands(path, strands, **opts), runs=cfg.runs, budget=left(sec, 0.3))
                rows.append([f".{ext}" + (" (32 vertices)" if ext == "tfx" else ""), str(t),
                             f"{os.path.getsize(path) / 2**20:.1f} MiB"])
            except TooSlow as e:
                rows.append([f".{ext}", f"not measured: {e}", ""])
        for ext, opts in (("abc", {"scale": 100.0}), ("usd", {"scale": 100.0})):
            path = os.path.join(tmp, f"groom.{ext}")
            lib = "alembic3d" if ext == "abc" else "usd-core"
            try:
                t, _ = measure(lambda: write_strands(path, with_guides, **opts), runs=cfg.runs, budget=left(sec, 0.35))
                rows.append([f".{ext} ({lib}, Unreal groom with guides)", str(t),
                             f"{os.path.getsize(path) / 2**20:.1f} MiB"])
            except (InputError, TooSlow) as e:
                rows.append([f".{ext} ({lib})", f"not measured: {e}", ""])
        obj = None
        for ext in ("abc", "usd"):
            path = os.path.join(tmp, f"groom.{ext}")
            try:
                import bpy  # noqa: F401
                from addon.blender_curves import strands_to_curves
                from addon.export_blender import export_curves_object
                if obj is None:
                    from benchmarks.blender_anchors import reset_scene
                    reset_scene()
                    obj = strands_to_curves("hair", strands)
                t, _ = measure(lambda: export_curves_object(obj, path, format=ext), runs=cfg.runs,
                               budget=left(sec, 0.4))
                rows.append([f".{ext} (Blender's exporter)", str(t), f"{os.path.getsize(path) / 2**20:.1f} MiB"])
            except (ImportError, TooSlow) as e:
                rows.append([f".{ext}", f"not measured: {e}", ""])
            except Exception as e:  # noqa: BLE001
                rows.append([f".{ext}", f"not measured: {type(e).__name__}: {e}", ""])
        sec.summary.append(f"export {strands.num_strands:,} strands: " + ", ".join(
            f"{r[0].split()[0]}{' (Blender)' if 'Blender' in r[0] else ''} {r[1]} / {r[2]}"
            for r in rows if not r[1].startswith("not measured")))
        sec.table(["format", "write time (median)", "file size"], rows,
                  caption=f"Export of {strands.num_strands:,} strands × 32 points (issue 5).")
        # .tfx resampling error: the writer's own figure, and ours from the file read back.
        rows = []
        theirs = resampling_errors(strands, cfg.tfx_vertices)
        lengths = np.linalg.norm(np.diff(strands.points.reshape(strands.num_strands, -1, 3), axis=1), axis=-1).sum(1)
        sub = np.arange(min(strands.num_strands, 300))
        for n in cfg.tfx_vertices:
            path = os.path.join(tmp, f"r{n}.tfx")
            write_strands(path, strands, vertices_per_strand=n)
            back = read_strands(path)
            pts = back.points.reshape(back.num_strands, n, 3)[sub].reshape(-1, 3)
            orig = strands.points.reshape(strands.num_strands, -1, 3)[sub].reshape(-1, 3)
            worst, _ = curve_to_polyline_distance(orig, np.full(len(sub), 32), pts, np.full(len(sub), n))
            rows.append([str(n), fmt_num(theirs[n]), fmt_num(float(worst.max())),
                         fmt_num(theirs[n] / float(np.median(lengths)))])
            sec.summary.append(f".tfx {n} vertices: max resampling error {theirs[n]:.3g} m")
        sec.table(["vertices per strand", "max error, all strands (hairio)",
                   f"max error, {len(sub)} strands read back from the file (independent)",
                   "max error / median strand length"], rows,
                  caption="`.tfx` resampling error: distance from the original strand to the resampled one.")

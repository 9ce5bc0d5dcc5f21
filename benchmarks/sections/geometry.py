# SPDX-License-Identifier: GPL-3.0-or-later
"""2. Geometry: cylinders per strand against distance to the exact curve and render time.

The exact curve of an ordinary strand is groom's continuous blend C_j(σ) (SPEC §5) of the
keys as curves, evaluated from key tables of 65,537 samples (groom.interpolate.EXACT_SAMPLES)
at 64 times each polyline's own resolution; the error of a polyline is the distance from each
of those samples to it (SPEC §6). The old method, shown once beside it, sampled the strands
the way they are made (from the 1,025-sample tables whose lerp strays up to several µm from
the curve) at 64 times the densest strand's resolution. The same settings are then generated
at more strands and rendered to time them; "over the tolerance" counts strands the cylinder
cap (points_per_strand) stopped short of it, which groom now reports (GroomResult.warning).
"""
import warnings

import numpy as np

from benchmarks.harness import fmt_num, measure
from benchmarks.metrics import curve_to_polyline_distance, pareto_front
from benchmarks.scenes import groom_api, load_preset, settings, tracer_api, tracer_camera, view_matrix
from benchmarks.sections import over_budget

EXACT_MAX_POINTS = 8193
ADAPTIVE_CAP = 129     # most points an adaptive strand may use (128 cylinders)


def _params(preset, count, resolution, n_points=None, tolerance=None):
    kw = {"count": int(count), "seed": 0, "resolution_mode": resolution}
    if n_points is not None:
        kw["points_per_strand"] = int(n_points)
    if tolerance is not None:
        kw["tolerance"] = float(tolerance)
        kw["tolerance_units"] = "scene"
    return preset.params.replace(**kw)


def run(sec, cfg):
    groom = groom_api()
    tracer = tracer_api()
    sec.text(__doc__.split("\n\n", 1)[1].strip())
    size = (cfg.geo_render_size, cfg.geo_render_size)
    sec.settings(error_strands=cfg.geo_error_strands, render_strands=cfg.geo_render_strands,
                 image=f"{size[0]}x{size[1]}", spp=1, shadows=True, layers=4,
                 exact_points="64n+1", adaptive_cap_points=ADAPTIVE_CAP, runs=cfg.runs)
    scalp = groom.default_scalp()
    renderer = tracer.Renderer()
    rs = settings(spp=1, shadows=True, layers=4)
    all_rows = []
    per_preset = {}
    budget_each = 0.9 / max(1, len(cfg.geo_presets))
    for p_i, name in enumerate(cfg.geo_presets):
        preset = load_preset(name)
        keys = preset.keys_on(scalp)
        exact_cache = {}

        def exact_for(small):
            """The exact curves sampled at 64× the densest strand of `small`."""
            n = int(min(EXACT_MAX_POINTS, 64 * (int(small.counts.max()) - 1) + 1))
            if n not in exact_cache:
                exact_cache[n] = groom.generate(scalp, keys, _params(preset, cfg.geo_error_strands, "fixed", n)).strands
            return exact_cache[n]

        # Most telling first, so a tight budget drops the least telling: the thesis's 25, the
        # adaptive tolerances, then the rest of the fixed sweep.
        fixed = sorted(cfg.geo_fixed, key=lambda n: (n != 25, n))
        configs = ([("fixed", n, None) for n in fixed[:1]] + [("adaptive", None, t) for t in cfg.geo_tolerances]
                   + [("fixed", n, None) for n in fixed[1:]])
        camera = None
        results = []
        for kind, n_cyl, tol in configs:
            if over_budget(sec, budget_each * (p_i + 1)):
                sec.not_measured(f"{name}: {kind} {n_cyl or tol}", "skipped to stay inside the time budget")
                continue
            try:
                n_points = n_cyl + 1 if kind == "fixed" else ADAPTIVE_CAP
                gen = groom.Generator(scalp, keys, _params(preset, cfg.geo_error_strands, kind, n_points, tol))
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")     # counted in the table instead
                    small = gen.generate().strands
                dense, dense_counts = gen.evaluate(np.arange(small.num_strands), 64 * (small.counts - 1), exact=True)
                worst, dists = curve_to_polyline_distance(dense, dense_counts, small.points, small.counts)
                old = exact_for(small)
                old_worst, _ = curve_to_polyline_distance(old.points, old.counts, small.points, small.counts)
                met = gen.tolerance_met
                over = int((met > tol * (1 + 1e-9)).sum()) if met is not None else None
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    big = groom.generate(scalp, keys, _params(preset, cfg.geo_render_strands, kind, n_points,
                                                              tol)).strands
                if camera is None:
                    lo, hi = big.bounds()
                    camera = tracer_camera(view_matrix(lo, hi, size), size)
                renderer.set_strands(big)
                t, _ = measure(lambda: renderer.render(camera, rs), runs=cfg.runs)
                label = f"fixed {n_cyl}" if kind == "fixed" else f"adaptive {tol:g} m"
                row = {"label": label, "kind": kind, "cyl_per_strand": big.num_segments / big.num_strands,
                       "max": float(worst.max()), "p99": float(np.percentile(dists, 99)), "time": t.median,
                       "cylinders": int(big.num_segments), "n_cyl": n_cyl, "tol": tol,
                       "max_old_method": float(old_worst.max()), "over_tolerance": over}
                results.append(row)
                over_cell = "" if over is None else f"{over} of {small.num_strands}"
                all_rows.append((name, kind, n_cyl or -tol, [name, label, f"{row['cyl_per_strand']:.1f}",
                                                             fmt_num(row["max"]), fmt_num(row["p99"]), over_cell,
                                                             fmt_num(row["max_old_method"]), str(t),
                                                             f"{row['cylinders']:,}"]))
            except Exception as e:  # noqa: BLE001 — one configuration failing must not lose the rest
                sec.not_measured(f"{name}: {kind} {n_cyl or tol}", f"{type(e).__name__}: {e}")
        per_preset[name] = results
        if results:
            _plot(sec, name, results)
    sec.table(["preset", "resolution", "cylinders / strand (mean)", "max error (m)", "p99 error (m)",
               "strands over the tolerance (cap)", "max error, old method (m)",
               f"render {size[0]}² (median)", f"cylinders at {cfg.geo_render_strands:,} strands"],
              [r[3] for r in sorted(all_rows, key=lambda r: (cfg.geo_presets.index(r[0]), r[1] != "fixed", r[2]))],
              caption="Geometric error (distance to the exact curve) and render time per resolution.")
    _adaptive_vs_25(sec, cfg, groom, scalp, per_preset)
    sec.data["presets"] = {k: [{kk: vv for kk, vv in r.items()} for r in v] for k, v in per_preset.items()}


def _plot(sec, name, results):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for ax, key, title in ((axes[0], "max", "maximum"), (axes[1], "p99", "99th percentile")):
        xs = np.array([r["time"] * 1e3 for r in results])
        ys = np.array([max(r[key], 1e-12) for r in results])
        for kind, marker in (("fixed", "o"), ("adaptive", "^")):
            idx = [i for i, r in enumerate(results) if r["kind"] == kind]
            ax.scatter(xs[idx], ys[idx], marker=marker, label=kind)
        for r, x, y in zip(results, xs, ys):
            ax.annotate(r["label"].replace("adaptive ", "tol "), (x, y), fontsize=7, xytext=(3, 3),
                        textcoords="offset points")
        front = pareto_front(xs, ys)
        ax.plot(xs[front], ys[front], "k--", lw=0.8, label="Pareto front")
        ax.set_yscale("log")
        ax.set_xlabel("render time (ms, median)")
        ax.set_ylabel(f"{title} distance to exact curve (m)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(f"preset '{name}': geometric error against render time")
    sec.figure(fig, f"geometry_pareto_{name}.png", f"Pareto plot, preset '{name}' (lower left is better).")


def _adaptive_vs_25(sec, cfg, groom, scalp, per_preset):
    """At the maximum error of the thesis's fixed 25 cylinders, how many cylinders does adaptive
    resolution need?"""
    rows = []
    for name, results in per_preset.items():
        fixed25 = [r for r in results if r["kind"] == "fixed" and r["n_cyl"] == 25]
        if not fixed25:
            continue
        if over_budget(sec, 1.0):
            rows.append([name, "not measured: time budget", "", "", ""])
            continue
        target = fixed25[0]["max"]
        preset = load_preset(name)
        keys = preset.keys_on(scalp)
        gen = groom.Generator(scalp, keys, _params(preset, cfg.geo_error_strands, "adaptive", ADAPTIVE_CAP,
                                                   max(target, 1e-12)))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            s = gen.generate().strands
        dense, dense_counts = gen.evaluate(np.arange(s.num_strands), 64 * (s.counts - 1), exact=True)
        worst, _ = curve_to_polyline_distance(dense, dense_counts, s.points, s.counts)
        per = s.num_segments / s.num_strands
        rows.append([name, fmt_num(target), f"{per:.1f}", f"{per / 25:.2f}", fmt_num(float(worst.max()))])
        sec.summary.append(f"{name}: adaptive at fixed-25's max error {target:.2e} m uses {per:.1f} cylinders/strand "
                           f"({per / 25:.2f}× of 25)")
    if rows:
        sec.table(["preset", "max error of fixed 25 (m)", "adaptive cylinders / strand", "ratio to 25",
                   "adaptive max error (m)"], rows,
                  caption="Adaptive resolution against the thesis's fixed 25 cylinders at equal maximum error.")

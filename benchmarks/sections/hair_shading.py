# SPDX-License-Identifier: GPL-3.0-or-later
"""11. Hair shading: the preview's fibre model against Cycles' Principled Hair BSDF (Chiang).

The same strands, camera and sun go to Cycles (Principled Hair BSDF, Chiang model, on the
CPU; set-up in benchmarks/blender_hair_shading.py: direct light only, a delta sun, box pixel
filter, linear EXR) and to the preview (shading "chiang", hard shadows, ambient 0, the same
sun as a directional light of the same irradiance, stratified samples). Both use the node's
sliders as given in each row; the strand colour is the Tint (melanin rows: white strands)
or the colour itself (Direct Coloring rows: a random colour per strand), as in
tracer/shading/chiang.py.

The strands are straight (two points each) and run out of the frame, so both renderers see
the same round tubes, with no curve interpolation (Cycles' Catmull-Rom against the preview's
cylinders) and no end caps to tell them apart: what differs is shading, sampling and
numerics. They lie in two staggered rows at random tilts (so the longitudinal angles vary
across the image) and shadow one another.

Error: mean absolute difference per pixel and channel in linear RGB over the hair (every
pixel the preview covers at all; edge pixels mix hair and black in both), and over the
pixels fully covered; with the mean hair value beside it for scale, and Cycles' own noise at
that sample count (the MAE between two Cycles renders with different seeds, divided by
sqrt(2)) where measured.
"""
import dataclasses

import numpy as np

from benchmarks.harness import NotMeasured, fmt_num, fmt_time
from benchmarks.sections import left, now

SUN_STRENGTH = 3.0                      # W/m^2 in Cycles; the preview's light intensity
RADIUS = 0.008
LOOK_FROM, LOOK_AT = (0.05, -0.55, 0.12), (0.0, 0.02, 0.0)
FRONT = (0.35, 0.8, -0.5)               # light travels away from the camera: R and TRT
BACK = (0.1, -0.95, -0.25)              # toward the camera, from behind the hair: TT
SIDE = (0.9, 0.3, -0.4)
CYCLES = dict(roughness=0.3, radial_roughness=0.3, coat=0.0, ior=1.55, offset=np.radians(2.0))
CASES = (
    # label, light, hair
    ("Cycles defaults (melanin 0.8, redness 1), front light", FRONT,
     dict(CYCLES, parametrization="melanin", melanin=0.8, melanin_redness=1.0)),
    ("Cycles defaults, back light", BACK,
     dict(CYCLES, parametrization="melanin", melanin=0.8, melanin_redness=1.0)),
    ("blond (melanin 0.25, redness 0.3), front light", FRONT,
     dict(CYCLES, parametrization="melanin", melanin=0.25, melanin_redness=0.3)),
    ("blond, back light", BACK,
     dict(CYCLES, parametrization="melanin", melanin=0.25, melanin_redness=0.3)),
    ("strand colours (Direct Coloring), side light", SIDE,
     dict(CYCLES, parametrization="color", melanin=0.0, melanin_redness=0.0)),
    ("blond, rough (0.6 / 0.7), IOR 1.45, tilt 4°, coat 0.3, front light", FRONT,
     dict(parametrization="melanin", melanin=0.25, melanin_redness=0.3, roughness=0.6,
          radial_roughness=0.7, coat=0.3, ior=1.45, offset=np.radians(4.0))),
)


def fibre_strands(white=False):
    """18 straight strands in two staggered rows, random tilts, random colours (white: for
    the melanin rows, where the colour is a Tint and white leaves the melanin alone)."""
    from hairio import Strands
    rng = np.random.default_rng(4)
    points, colors = [], []
    for row, y in enumerate((0.0, 0.05)):
        for k in range(9):
            x = -0.2 + 0.05 * k + 0.025 * row
            tilt, lean = np.radians(rng.uniform(-30, 30)), np.radians(rng.uniform(-35, 35))
            d = np.array([np.sin(tilt) * np.cos(lean), np.sin(lean), np.cos(tilt) * np.cos(lean)])
            c = np.array([x, y, 0.0])
            points += [c - 0.5 * d, c + 0.5 * d]
            colors.append(rng.uniform(0.05, 0.9, 3))
    points = np.array(points)
    color = np.ones((len(points), 3)) if white else np.repeat(np.array(colors), 2, axis=0)
    return Strands.from_arrays(points, np.full(len(points) // 2, 2), radius=np.full(len(points), RADIUS),
                               color=color)


def preview_settings(tracer, spp, light, hair):
    return tracer.RenderSettings(
        spp=spp, shading="chiang", shadows=True, shadow_mode="hard", layers=1, ambient=0.0,
        lights=(tracer.Light("directional", tuple(light), (1.0, 1.0, 1.0), SUN_STRENGTH),),
        hair_color="strand" if hair["parametrization"] == "color" else "melanin",
        hair_melanin=hair["melanin"], hair_melanin_redness=hair["melanin_redness"],
        hair_roughness=hair["roughness"], hair_radial_roughness=hair["radial_roughness"],
        hair_coat=hair["coat"], hair_ior=hair["ior"], hair_cuticle_tilt=float(np.degrees(hair["offset"])))


def errors(ours, cycles):
    """(MAE over the hair, MAE over fully covered pixels, mean hair value in Cycles, pixels)."""
    rgb, alpha = ours[..., :3], ours[..., 3]
    hair, full = alpha > 0.0, alpha >= 0.999
    if hair.sum() < 100:
        raise AssertionError(f"only {hair.sum()} hair pixels in the preview: the strands are not in view")
    diff = np.abs(rgb - cycles)
    return diff[hair].mean(), diff[full].mean() if full.any() else None, cycles[hair].mean(), int(hair.sum())


def _num(x):
    return "– (no pixel fully covered)" if x is None else fmt_num(x)


def run(sec, cfg):
    try:
        import bpy  # noqa: F401
    except ImportError as e:
        raise NotMeasured(f"Blender's Python module (bpy) is missing: {e}") from e
    import tracer
    from benchmarks.blender_anchors import look_at_matrix
    from benchmarks.blender_hair_shading import render_cycles
    from benchmarks.scenes import LENS_MM, SENSOR_MM

    quick = cfg.mode == "quick"
    size = (160, 120) if quick else (240, 180)
    cycles_spp = 128 if quick else 256
    spp = 64 if quick else 256            # the preview's, a square
    sec.text(__doc__.split("\n", 2)[2].strip())
    sec.settings(image=f"{size[0]}x{size[1]}", cycles_samples=cycles_spp, preview_spp=spp,
                 sun_strength=SUN_STRENGTH, strands=18, radius=RADIUS)
    matrix = look_at_matrix(LOOK_FROM, LOOK_AT)
    cam = tracer.Camera.from_blender(matrix, size, type="PERSP", lens=LENS_MM, sensor_width=SENSOR_MM,
                                     sensor_fit="AUTO")
    renderer = tracer.Renderer()
    rows, pictures, maes, breakdown = [], [], [], None
    for i, (label, light, hair) in enumerate(CASES):
        strands = fibre_strands(white=hair["parametrization"] == "melanin")
        renderer.set_strands(strands)
        if left(sec) < 20:
            sec.not_measured(label, "the section's time ran out")
            continue
        settings = preview_settings(tracer, spp, light, hair)
        renderer.render(cam, settings)            # compile outside the timing
        t0 = now()
        ours = renderer.render(cam, settings)
        t_ours = now() - t0
        cyc, t_cycles = render_cycles(strands, matrix, size, light, SUN_STRENGTH, hair, cycles_spp)
        mae, mae_full, mean, n = errors(ours, cyc)
        noise = ""
        if i == 3:          # the brightest case: Cycles' own noise there
            cyc2, _ = render_cycles(strands, matrix, size, light, SUN_STRENGTH, hair, cycles_spp, seed=2)
            noise = fmt_num(np.abs(cyc2 - cyc)[ours[..., 3] > 0].mean() / np.sqrt(2))
        if i == 3:
            breakdown = _by_brightness(ours, cyc)
        maes.append(mae)
        rows.append([label, fmt_num(mae), _num(mae_full), fmt_num(mean), noise, str(n),
                     fmt_time(t_ours), fmt_time(t_cycles)])
        pictures.append((label, ours, cyc))
    sec.table(["case", "MAE over the hair", "MAE, covered pixels", "mean hair value (Cycles)",
               "Cycles' own noise", "hair pixels", f"preview ({spp} spp)",
               f"Cycles ({cycles_spp} samples, sync + render)"], rows)
    if breakdown:
        sec.table(["Cycles' pixel value", "pixels", "MAE", "mean signed difference (preview − Cycles)"], breakdown,
                  caption=f"Where the error is, on the brightest case ({CASES[3][0]}), covered pixels by "
                          "their value in Cycles (mean of RGB):")
    if maes:
        sec.summary.append(f"preview vs Cycles' Principled Hair (Chiang), direct light: MAE over the hair "
                           f"{fmt_num(min(maes))}–{fmt_num(max(maes))} in linear RGB over {len(maes)} cases "
                           f"(goal ≤ 0.03)")
        sec.data["mae"] = [float(m) for m in maes]
    if left(sec) > 60:
        _groom(sec, cfg, tracer, render_cycles, pictures)
    if pictures:
        _side_by_side(sec, pictures)
    if left(sec) > 30:
        _cost(sec, cfg, tracer)


def _by_brightness(ours, cycles):
    """Rows (value range, pixels, MAE, signed mean) of the fully covered pixels binned by
    their value in Cycles: does the error follow the brightness (a scale) or not."""
    full = ours[..., 3] >= 0.999
    value = cycles[full].mean(axis=-1)
    diff = ours[..., :3][full] - cycles[full]
    rows = []
    for lo, hi in ((0.0, 0.05), (0.05, 0.2), (0.2, 0.5), (0.5, 1.0), (1.0, 3.0), (3.0, np.inf)):
        m = (value >= lo) & (value < hi)
        if m.any():
            rows.append([f"{lo:g} – {hi:g}", str(int(m.sum())), fmt_num(np.abs(diff[m]).mean()),
                         f"{fmt_num(diff[m].mean())} ({diff[m].mean() / max(value[m].mean(), 1e-12):+.1%})"])
    return rows


def _groom(sec, cfg, tracer, render_cycles, pictures):
    """A groomed preset under the report's sun: strands thinner than a pixel, bends, and
    curves that Cycles interpolates where the preview joins cylinders, so geometry and
    anti-aliasing add to the shading's error."""
    from benchmarks.scenes import SUN_DIRECTION, groom_scene, tracer_camera, view_matrix
    quick = cfg.mode == "quick"
    count, size = (2000, (160, 120)) if quick else (10000, (240, 180))
    cycles_spp, spp = (128, 64) if quick else (512, 256)
    strands = groom_scene("wavy", count)[3].strands
    matrix = view_matrix(*strands.bounds(), size)
    cam = tracer_camera(matrix, size)
    hair = dict(CYCLES, parametrization="color", melanin=0.0, melanin_redness=0.0)
    light = tuple(float(x) for x in SUN_DIRECTION)
    renderer = tracer.Renderer()
    renderer.set_strands(strands)
    settings = dataclasses.replace(preview_settings(tracer, spp, light, hair), layers=4)
    renderer.render(cam, settings)
    t0 = now()
    ours = renderer.render(cam, settings)
    t_ours = now() - t0
    cyc, t_cycles = render_cycles(strands, matrix, size, light, SUN_STRENGTH, hair, cycles_spp)
    mae, mae_full, mean, n = errors(ours, cyc)
    label = f"wavy preset, {count // 1000}k strands, strand colours, the report's sun"
    sec.table(["groom", "MAE over the hair", "MAE, covered pixels", "mean hair value (Cycles)", "hair pixels",
               f"preview ({spp} spp)", f"Cycles ({cycles_spp} samples, sync + render)"],
              [[label, fmt_num(mae), _num(mae_full), fmt_num(mean), str(n), fmt_time(t_ours), fmt_time(t_cycles)]],
              caption="A groomed preset (geometry and anti-aliasing differ here too):")
    sec.data["groom_mae"] = float(mae)
    pictures.append((label, ours, cyc))


def _cost(sec, cfg, tracer):
    """What the model costs in the default preview: the same groom and camera with each
    shading model of the registry, all else at the defaults (1 spp, hard shadows, 4 layers)."""
    from benchmarks.harness import measure
    from benchmarks.scenes import groom_scene, settings, tracer_camera, view_matrix
    count, side = (3000, 256) if cfg.mode == "quick" else (10000, 512)
    strands = groom_scene("wavy", count)[3].strands
    cam = tracer_camera(view_matrix(*strands.bounds(), (side, side)), (side, side))
    renderer = tracer.Renderer()
    renderer.set_strands(strands)
    rows, base = [], None
    for model in tracer.shading.SHADING_MODELS:
        timing, _ = measure(lambda: renderer.render(cam, settings(shading=model.name)), runs=cfg.runs,
                            budget=left(sec))
        base = base or timing.median
        rows.append([model.label + (" (default)" if model.name == tracer.shading.DEFAULT_SHADING else ""),
                     fmt_time(timing.median), f"{timing.median / base:.2f}×"])
    sec.table(["shading", f"render, {side}² wavy {count // 1000}k strands, defaults", "against the first"], rows,
              caption="The model's cost in the default preview (median of the runs, after a warm-up):")


def _side_by_side(sec, pictures):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from benchmarks.harness import to_srgb8
    fig, axes = plt.subplots(len(pictures), 3, figsize=(9, 2.3 * len(pictures)), squeeze=False)
    for row, (label, ours, cyc) in zip(axes, pictures):
        diff = np.abs(ours[..., :3] - cyc).mean(axis=-1)
        row[0].imshow(to_srgb8(np.concatenate([ours[..., :3], np.ones(ours.shape[:2] + (1,))], axis=-1)))
        row[1].imshow(to_srgb8(np.concatenate([cyc, np.ones(cyc.shape[:2] + (1,))], axis=-1)))
        im = row[2].imshow(diff, cmap="magma", vmin=0, vmax=max(0.05, float(diff.max())))
        fig.colorbar(im, ax=row[2], fraction=0.046)
        row[0].set_ylabel(label, fontsize=6)
        for ax in row:
            ax.set_xticks([])
            ax.set_yticks([])
    axes[0][0].set_title("preview (chiang)", fontsize=8)
    axes[0][1].set_title("Cycles Principled Hair", fontsize=8)
    axes[0][2].set_title("|difference|, mean of RGB", fontsize=8)
    sec.figure(fig, "hair_shading_vs_cycles.png",
               "Preview (left) and Cycles (middle), sRGB for display; right: the absolute difference in "
               "linear RGB")

# SPDX-License-Identifier: GPL-3.0-or-later
"""Contact sheet (issues 13 and 14): every preset grown on the bundled scalp, kept out of the
bundled head, rendered by Cycles and by the preview with the head, the same camera and one
sun, each time beside its error against Cycles.

Both sides compute the same light transport, direct light only. Cycles
(benchmarks/blender_contact_sheet.py, set up as section hair_shading's yardstick): the
hair with the Principled Hair BSDF (Chiang) as the extension's hair material makes it
(Direct Coloring, fed the strands' colours; the sliders as the preview's defaults below,
which are the node's defaults), the head a Diffuse BSDF (Lambert) of base colour HEAD_RGB,
one delta sun, max bounces 0, a black world, a box pixel filter, linear float output. The
preview: its default settings as tracer.settings.RenderSettings gives them (listed below,
read when the section runs), with the same sun, the head at the same base colour (under the
default, physically based shading the preview's meshes are Lambertian as Cycles' diffuse
surface: colour / pi × irradiance × cos) and what the add-on makes of a black world: no
ambient term (addon/preview.py, render_settings: with the scene's lights and this shading a
world of one colour is the ambient term, its radiance's luminance). The last table measures
that rule on the first preset: Cycles under a black world and under Blender's default world
(grey, radiance DEFAULT_WORLD) beside the sun, the preview with the world as the add-on takes
it, with the fixed 0.08 the add-on gave every scene before, and with the world as an
environment light sampled with shadow rays (tracer.Light("environment"), tried); and, in
place of the sun, an artist's lights under each world (studio_lights: a key area light and a
fill sphere light, their shadows soft), which the preview takes as Render Preview does, read
from Cycles' own scene by the add-on.

Error (benchmarks/region_error.py): over the hair pixels (where Cycles' hair covers at least
half the pixel) and over the head pixels (where Cycles' head covers at least half), in
linear RGB per pixel and channel, MAE = mean |preview − Cycles| and RMSE = sqrt(mean
(preview − Cycles)^2), with the MAE relative to Cycles' mean there in brackets, and the
mean ratio (the preview's mean there / Cycles': how bright on the whole, whatever the
per-pixel noise); coverage IoU of the hair = sum(min(a, b)) / sum(max(a, b)) of the
fraction of each pixel the hair covers in each (Cycles': a render of the same scene with
white hair on a black head, MASK_SAMPLES samples; the preview's: the same with its own
sampling). The regions are Cycles', so an empty or black preview scores relative error 1
(100 %) and IoU 0. On the first preset, once every preset has its figures, Cycles' own
noise at its sample count (the same measure between two Cycles renders of different seeds,
divided by sqrt(2); the IoU between the two seeds' masks) stands in its row, and the preview
is measured at CHECK_SPP samples too: whether the per-pixel error falls with the preview's
samples (sampling the coverage of strands thinner than a pixel) or stays (the model, the
curves' shape).

Run alone: `python -m benchmarks --only contact_sheet [--full]` (quick: a quarter of each
preset's strands at 320²; full: the presets' own counts at 512²).
"""
import dataclasses

import numpy as np

from benchmarks.harness import NotMeasured, fmt_num, fmt_time, measure, once
from benchmarks.region_error import compare
from benchmarks.scenes import groom_api, load_preset, tracer_api, tracer_camera, view_matrix
from benchmarks.sections import left, now

HEAD_RGB = (0.62, 0.45, 0.36)              # a skin tone, linear
VIEW = np.array([0.45, 1.0, -0.25])        # the way the camera looks: the face and one side
SUN = np.array([0.3, 0.6, -0.75])          # the way the light travels: from the front, above
SUN_STRENGTH = 3.0                         # W/m² in Cycles, the preview light's intensity
REFINED_SPP = 16                           # the preview's refined image (stratified samples)
MASK_SAMPLES = 64                          # Cycles' coverage render
CHECK_SPP = 64                             # the first preset's convergence check
DEFAULT_WORLD = 0.0508                     # the radiance of Blender's default world (grey, strength 1)
KEY_SIZE, FILL_RADIUS = 0.5, 0.1           # the studio lights' area light (square) and sphere light


def studio_lights(head_vertices):
    """A key area light from the front left and above and a fill sphere light from the right,
    three head sizes away, aimed at the head's centre, each giving it about the sun's
    irradiance (key) and a third of it (fill): (kind, power, location, target, extent) as
    blender_contact_sheet.render_contact takes them."""
    lo, hi = head_vertices.min(axis=0), head_vertices.max(axis=0)
    centre, reach = 0.5 * (lo + hi), 1.5 * float(np.linalg.norm(hi - lo))
    key = centre + reach * np.array([-0.5, -1.0, 0.8]) / np.linalg.norm([-0.5, -1.0, 0.8])
    fill = centre + reach * np.array([0.9, -0.5, 0.1]) / np.linalg.norm([0.9, -0.5, 0.1])
    # Area light: E = (P / pi) / d² on its axis; sphere light: E = P / (4 pi d²).
    return [("AREA", SUN_STRENGTH * np.pi * reach ** 2, key, centre, KEY_SIZE),
            ("POINT", SUN_STRENGTH / 3 * 4 * np.pi * reach ** 2, fill, centre, FILL_RADIUS)]


def hair_material(settings):
    """The Principled Hair node as blender_hair_shading._material takes it, from the
    preview's settings: the same sliders on both sides."""
    return dict(parametrization="color" if settings.hair_color == "strand" else "melanin",
                melanin=settings.hair_melanin, melanin_redness=settings.hair_melanin_redness,
                roughness=settings.hair_roughness, radial_roughness=settings.hair_radial_roughness,
                coat=settings.hair_coat, ior=settings.hair_ior, offset=float(np.radians(settings.hair_cuticle_tilt)))


def defaults_row(settings):
    """The preview's default settings in one line (every field but the lights)."""
    return ", ".join(f"{f.name}={getattr(settings, f.name)!r}" for f in dataclasses.fields(settings)
                     if f.name not in ("lights", "count", "tile"))


def _mask_strands(strands):
    from hairio import Strands
    return Strands.from_arrays(strands.points, strands.counts, strands.radius, np.ones_like(strands.color),
                               strands.alpha, strands.wisp)


def _cell(err):
    return f"{fmt_num(err['mae'])} / {fmt_num(err['rmse'])} ({err['rel']:.0%}); mean ×{err['ratio']:.3f}"


def _noise(err):
    """Cycles against Cycles with another seed: one render's own noise is that over sqrt(2)."""
    return {k: (v / np.sqrt(2) if k in ("mae", "rmse", "rel") else v) for k, v in err.items()}


def _numbers(e):
    return {f"{region}_{k}": e[region][k] for region in ("hair", "head") for k in ("mae", "rmse", "rel", "ratio")} | \
        {"iou": e["iou"]}


def run(sec, cfg):
    try:
        import bpy  # noqa: F401
    except ImportError as e:
        raise NotMeasured(f"bpy is not importable ({e})") from e
    from benchmarks.blender_contact_sheet import render_contact
    groom, tracer = groom_api(), tracer_api()
    full = cfg.mode == "full"
    size = (512, 512) if full else (320, 320)
    cycles_samples = cfg.contact_cycles_samples
    defaults = tracer.RenderSettings()
    sun = tracer.Light("directional", tuple(SUN), (1, 1, 1), SUN_STRENGTH)
    # What the preview renders here: its defaults, the sun, no ambient; and the refinement.
    first = dataclasses.replace(defaults, lights=(sun,), ambient=0.0)
    refined = dataclasses.replace(first, spp=REFINED_SPP)
    # Coverage: white strands on a black head, lit by the ambient term alone.
    mask_of = {s.spp: dataclasses.replace(s, shading="phong", ambient=1.0, shadows=False,
                                          lights=(tracer.Light("directional", tuple(SUN), (1, 1, 1), 0.0),))
               for s in (first, refined)}
    hair = hair_material(defaults)
    scalp, head = groom.default_scalp(), groom.default_head()
    sec.text(__doc__.strip())
    sec.settings(image=f"{size[0]}x{size[1]}", strands="each preset's count" if full else "a quarter of each preset's",
                 cycles_samples=cycles_samples, cycles_mask_samples=MASK_SAMPLES, sun_strength=SUN_STRENGTH,
                 head_rgb=HEAD_RGB, preview_spp=f"{defaults.spp} (default) and {REFINED_SPP}",
                 check_spp=CHECK_SPP)
    sec.table(["the preview's defaults (tracer.settings.RenderSettings), as read when the section ran"],
              [[defaults_row(defaults)]])
    rows, conv_rows, panels, kept = {}, [], [], None
    last = 60.0                      # seconds the last preset took (the next needs about as long)
    for name in groom.list_presets():
        if left(sec) < 1.3 * last:
            rows[name] = [[name, "", f"not measured: {fmt_time(left(sec))} of the section's time left, "
                                     f"the last preset took {fmt_time(last)}", "", "", ""]]
            continue
        t_start = now()
        preset = load_preset(name)
        count = preset.params.count if full else max(1000, preset.params.count // 4)
        params = preset.params.replace(count=count)
        keys = preset.keys_on(scalp)
        strands = groom.generate(scalp, keys, params, collider=(head.vertices, head.triangles)).strands
        lo = np.minimum(strands.bounds()[0], head.vertices.min(axis=0))
        hi = np.maximum(strands.bounds()[1], head.vertices.max(axis=0))
        matrix = view_matrix(lo, hi, size, direction=VIEW)
        camera = tracer_camera(matrix, size)

        renderer = tracer.Renderer()
        renderer.set_strands(strands)
        renderer.set_meshes([(head.vertices, head.triangles, HEAD_RGB, "head")])
        timing, img_first = measure(lambda: renderer.render(camera, first), runs=cfg.runs,
                                    budget=max(left(sec) - 30, 1))
        renderer.render(tracer_camera(matrix, (32, 32)), refined)     # compile the refined draw, untimed
        t_refined, img_refined = once(lambda: renderer.render(camera, refined))
        masker = tracer.Renderer()
        masker.set_strands(_mask_strands(strands))
        masker.set_meshes([(head.vertices, head.triangles, (0.0, 0.0, 0.0), "head")])
        cover_first = masker.render(camera, mask_of[first.spp])[..., 0]
        cover_refined = masker.render(camera, mask_of[refined.spp])[..., 0]

        cyc = render_contact(strands, head.vertices, head.triangles, HEAD_RGB, matrix, size, SUN, SUN_STRENGTH,
                             hair, cycles_samples, MASK_SAMPLES)
        ref, ref_hair, ref_cover = cyc["rgb"][0], cyc["hair"], cyc["cover"]
        e_first = compare(img_first, cover_first, ref, ref_hair, ref_cover)
        e_refined = compare(img_refined, cover_refined, ref, ref_hair, ref_cover)
        sec.data[name] = {
            "strands": int(strands.num_strands), "cycles_seconds": cyc["seconds"][0],
            "hair_pixels": e_first["hair"]["pixels"], "head_pixels": e_first["head"]["pixels"],
            "preview_seconds": {str(first.spp): timing.median, str(REFINED_SPP): t_refined},
            f"{first.spp}spp": _numbers(e_first), f"{REFINED_SPP}spp": _numbers(e_refined)}
        rows[name] = [[f"{name}, {strands.num_strands:,} strands", f"Cycles, {cycles_samples} samples",
                       fmt_time(cyc["seconds"][0]), "the reference", "the reference", ""]]
        for spp, t, e in ((first.spp, timing.median, e_first), (REFINED_SPP, t_refined, e_refined)):
            rows[name].append(["", f"preview, {spp} spp" + (" (default)" if spp == defaults.spp else ""),
                               fmt_time(t), _cell(e["hair"]), _cell(e["head"]), f"{e['iou']:.3f}"])
        if kept is None:            # the first preset: its checks come when every preset has its figures
            kept = (name, strands, matrix, camera, renderer, masker, ref, ref_hair, ref_cover, cover_refined,
                    e_refined)
        diff = np.abs(img_refined[..., :3] - ref).mean(axis=-1)
        panels.append((name, np.concatenate([ref, ref_cover[..., None]], axis=-1), img_first, img_refined, diff))
        last = now() - t_start
        sec.data[name]["section_seconds"] = last

    if kept is not None and left(sec) > 1.5 * last:
        name, strands, matrix, camera, renderer, masker, ref, ref_hair, ref_cover, cover_refined, e_refined = kept
        numbers = sec.data[name]
        # Cycles' own noise: another seed, for the image and the mask.
        cyc2 = render_contact(strands, head.vertices, head.triangles, HEAD_RGB, matrix, size, SUN, SUN_STRENGTH,
                              hair, cycles_samples, MASK_SAMPLES, seeds=(2,), mask_seeds=(2,))
        n = compare(cyc2["rgb"][0], cyc2["hair"], ref, ref_hair, ref_cover)
        hair_noise, head_noise = _noise(n["hair"]), _noise(n["head"])
        rows[name][0][3:] = [f"its own noise: {_cell(hair_noise)}", f"its own noise: {_cell(head_noise)}",
                             f"{n['iou']:.3f} (two seeds)"]
        numbers["cycles_noise"] = {"hair_mae": hair_noise["mae"], "hair_rel": hair_noise["rel"],
                                   "head_mae": head_noise["mae"], "head_rel": head_noise["rel"],
                                   "mask_iou_two_seeds": n["iou"]}
        # Does the per-pixel error fall with the preview's samples (sampling) or stay (the model)?
        check = dataclasses.replace(first, spp=CHECK_SPP)
        renderer.render(tracer_camera(matrix, (32, 32)), check)
        t_check, img_check = once(lambda: renderer.render(camera, check))
        cover_check = masker.render(camera, dataclasses.replace(mask_of[first.spp], spp=CHECK_SPP))[..., 0]
        e_check = compare(img_check, cover_check, ref, ref_hair, ref_cover)
        rows[name].append(["", f"preview, {CHECK_SPP} spp", fmt_time(t_check), _cell(e_check["hair"]),
                           _cell(e_check["head"]), f"{e_check['iou']:.3f}"])
        numbers[f"{CHECK_SPP}spp"] = _numbers(e_check)
        numbers["preview_seconds"][str(CHECK_SPP)] = t_check
        # The world's light: the add-on's rule (the world's radiance is the ambient term) against
        # the fixed ambient it had before, under a black world and under Blender's default one.
        cyc_w = render_contact(strands, head.vertices, head.triangles, HEAD_RGB, matrix, size, SUN, SUN_STRENGTH,
                               hair, cycles_samples, mask_seeds=(), world=DEFAULT_WORLD)
        numbers["world"], grey = {}, cyc_w["rgb"][0]
        environment = tracer.Light("environment", color=(DEFAULT_WORLD,) * 3, intensity=4 * np.pi)
        with_world = dataclasses.replace(refined, lights=refined.lights + (environment,))
        for world, cycles_img, settings, label in (
                (0.0, ref, refined, "none (the add-on's rule for a black world)"),
                (0.0, ref, dataclasses.replace(refined, ambient=defaults.ambient),
                 f"an ambient term of {defaults.ambient:g} (before)"),
                (DEFAULT_WORLD, grey, dataclasses.replace(refined, ambient=DEFAULT_WORLD),
                 f"an ambient term of the world's radiance, {DEFAULT_WORLD:g} (the add-on's rule)"),
                (DEFAULT_WORLD, grey, with_world, "an environment light of the world's radiance, sampled with "
                                                  "shadow rays (tried)"),
                (DEFAULT_WORLD, grey, dataclasses.replace(refined, ambient=defaults.ambient),
                 f"an ambient term of {defaults.ambient:g} (before)")):
            e = e_refined if settings is refined else compare(
                renderer.render(camera, settings), cover_refined, cycles_img, ref_hair, ref_cover)
            conv_rows.append(["black" if world == 0 else f"grey, radiance {world:g} (Blender's default world)",
                              label, _cell(e["hair"]), _cell(e["head"])])
            numbers["world"][f"world {world:g}: {label}"] = _numbers(e)
        # An artist's lights: Blender's default world, a key area light and a fill sphere light,
        # both read by the add-on for the preview (addon/preview.py) as Render Preview does.
        for world in (0.0, DEFAULT_WORLD):
            cyc_l = render_contact(strands, head.vertices, head.triangles, HEAD_RGB, matrix, size, SUN,
                                   SUN_STRENGTH, hair, cycles_samples, mask_seeds=(), world=world,
                                   studio=studio_lights(head.vertices))
            studio = dataclasses.replace(refined, lights=cyc_l["lights"], ambient=cyc_l["ambient"])
            e = compare(renderer.render(camera, studio), cover_refined, cyc_l["rgb"][0], ref_hair, ref_cover)
            conv_rows.append([("black" if world == 0 else f"grey, radiance {world:g}") + f", a key area light "
                              f"({KEY_SIZE:g} m square) and a fill sphere light ({FILL_RADIUS:g} m) in place of "
                              "the sun", "the lights and the world as the add-on reads them",
                              _cell(e["hair"]), _cell(e["head"])])
            numbers["world"][f"world {world:g}, studio lights"] = _numbers(e)
        conv_name = name
    elif kept is not None:
        sec.not_measured("Cycles' own noise, the convergence check and the world's light",
                         f"{fmt_time(left(sec))} of the section's time left")

    rows = [r for name in rows for r in rows[name]]
    sec.table(["preset", "image", f"time (preview at {first.spp} spp: median of {max(cfg.runs, 5)} runs; "
               "the others one run)", "hair: MAE / RMSE (relative); mean ratio", "head: MAE / RMSE (relative); "
               "mean ratio", "hair coverage IoU"], rows,
              caption="Each time beside its error against the Cycles image of the same preset:")
    if conv_rows:
        sec.table(["Cycles' world", "the world in the preview", "hair: MAE / RMSE (relative); mean ratio",
                   "head: MAE / RMSE (relative); mean ratio"],
                  conv_rows, caption=f"The world's light ({conv_name}, the preview at {REFINED_SPP} spp, against "
                                     "Cycles under that world):")
    if panels:
        _figure(sec, panels, first.spp)
        data = [v for v in sec.data.values() if isinstance(v, dict) and "strands" in v]
        rel = {spp: [v[f"{spp}spp"]["hair_rel"] for v in data] for spp in (first.spp, REFINED_SPP)}
        ratio = [v[f"{spp}spp"]["hair_ratio"] for v in data for spp in (first.spp, REFINED_SPP)]
        check = next((v for v in data if f"{CHECK_SPP}spp" in v), None)
        sec.summary.append(
            f"contact sheet, {len(data)} presets with the head against Cycles (direct light): the hair's mean "
            f"×{min(ratio):.2f}–×{max(ratio):.2f} of Cycles'; per-pixel hair MAE {min(rel[first.spp]):.0%}–"
            f"{max(rel[first.spp]):.0%} of Cycles' mean at {first.spp} spp (default), {min(rel[REFINED_SPP]):.0%}–"
            f"{max(rel[REFINED_SPP]):.0%} at {REFINED_SPP}"
            + (f", {check[f'{CHECK_SPP}spp']['hair_rel']:.0%} at {CHECK_SPP} (Cycles' own noise "
               f"{check['cycles_noise']['hair_rel']:.0%})" if check and "cycles_noise" in check else ""))


def _figure(sec, panels, first_spp):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from benchmarks.harness import to_srgb8
    fig, axes = plt.subplots(len(panels), 4, figsize=(12, 3 * len(panels)), squeeze=False)
    for row, (name, cyc, pre, ref, diff) in zip(axes, panels):
        for ax, img, title in zip(row, (cyc, pre, ref), ("Cycles", f"preview, {first_spp} spp",
                                                         f"preview, {REFINED_SPP} spp")):
            ax.imshow(to_srgb8(img))
            ax.set_title(f"{name}: {title}", fontsize=8)
        im = row[3].imshow(diff, cmap="magma", vmin=0, vmax=max(0.05, float(np.percentile(diff, 99.5))))
        fig.colorbar(im, ax=row[3], fraction=0.046)
        row[3].set_title(f"|preview {REFINED_SPP} spp − Cycles|, mean of RGB", fontsize=8)
        for ax in row:
            ax.axis("off")
    fig.tight_layout()
    sec.figure(fig, "contact_sheet.png", "Each preset with the bundled head, direct light only: Cycles (left), "
                                         f"the preview at {first_spp} sample per pixel and at {REFINED_SPP}, "
                                         "and the absolute difference (linear RGB) of the latter; same strands, "
                                         "camera and sun; sRGB over white for display")

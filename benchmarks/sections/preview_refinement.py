# SPDX-License-Identifier: GPL-3.0-or-later
"""Preview refinement (issue 14, "no dust"): how soon the Blender preview's progressive image
reaches the 16-sample error, refined by independent one-sample passes (as before) or by
pixel-sampler passes (`RenderSettings.refinement`, what the preview does now).

Both start from the same first image, the default settings' one sample, on a renderer of
their own (so the pixel sampler's wide grid is paid where it is built), and add passes as
the preview does: pass k at tracer.Camera.for_pass(k, n) (new sub-pixel positions), the
passes' mean weighted by their samples. After each pass: the time of all passes so far (the
renders' wall clock, one run each: a refinement is a sequence of single renders) and the
error of the mean against a 64-sample stratified reference (RMSE of linear premultiplied RGBA
over the pixels where either image has hair, as in the preview-defaults section). A
refinement stops at the 16-sample error (the independent sampler's 16 stratified samples
against the same reference), at 64 samples, or when the section's time runs out.

Run alone: `python -m benchmarks --full --only preview_refinement` (a few minutes, most of it
the references of `wavy`).
"""

import numpy as np

from benchmarks.harness import fmt_num, fmt_time, once
from benchmarks.scenes import tracer_api, tracer_camera, view_matrix
from benchmarks.sections import left
from benchmarks.metrics import hair_rmse
from benchmarks.sections.preview_defaults import PREVIEW_SAMPLES, REF_SPP, TARGET_SPP, _scenes

SIZE = (512, 512)
MAX_SAMPLES = PREVIEW_SAMPLES    # the preview's TARGET_SAMPLES


def _refine(tracer, strands, camera, pixel, target, reference, sec):
    """[(pass, samples so far, seconds so far, RMSE)] of one refinement, and whether it reached
    `target`."""
    renderer = tracer.Renderer()
    renderer.set_strands(strands)
    # The preview's first image, which says how far the refinement goes (samples_to_come).
    first = tracer.RenderSettings(samples_to_come=MAX_SAMPLES - 1)
    renderer.render(camera, first)           # shaders compiled, buffers made: as a warm preview
    rows, total, samples, spent, k = [], None, 0, 0.0, 0
    while samples < MAX_SAMPLES and left(sec) > 0:
        rs = first.refinement(renderer.all_opaque) if (pixel and k > 0) else first
        t, img = once(lambda: renderer.render(camera.for_pass(k, rs.spp_n), rs))
        spent += t
        total = img.astype(np.float64) * rs.spp if total is None else total + img.astype(np.float64) * rs.spp
        samples += rs.spp
        error = hair_rmse(total / samples, reference)
        rows.append((k, samples, spent, error, rs.sampler))
        k += 1
        if error <= target:
            return rows, True
    return rows, False


def run(sec, cfg):
    tracer = tracer_api()
    sec.text(__doc__.split("\n\n", 1)[1].rsplit("\n\nRun alone", 1)[0].strip())
    sec.settings(image=f"{SIZE[0]}x{SIZE[1]}", reference_spp=REF_SPP, target=f"{TARGET_SPP}-spp error",
                 max_samples=MAX_SAMPLES)
    table = []
    for name, make, direction in _scenes(cfg):
        if left(sec) < 0:
            table.append([name, "not measured: the section's time ran out", "", "", "", ""])
            continue
        strands = make()
        camera = tracer_camera(view_matrix(*strands.bounds(), SIZE, direction=direction), SIZE)
        ref_renderer = tracer.Renderer()
        ref_renderer.set_strands(strands)
        reference = ref_renderer.render(camera, tracer.RenderSettings(spp=REF_SPP))
        target = hair_rmse(ref_renderer.render(camera, tracer.RenderSettings(spp=TARGET_SPP)), reference)
        del ref_renderer
        reached = {}
        for label, pixel in (("independent one-sample passes (before)", False),
                             ("pixel-sampler passes (now)", True)):
            rows, ok = _refine(tracer, strands, camera, pixel, target, reference, sec)
            for k, samples, spent, error, sampler in rows:
                table.append([name, label, str(k), f"{samples} ({sampler})" if k else str(samples),
                              fmt_time(spent), fmt_num(error) + (" ✓" if error <= target else "")])
            reached[pixel] = rows[-1][2] if ok else None
            sec.data.setdefault(name, {})[label] = [list(r[:4]) for r in rows]
        sec.data[name]["target"] = target
        before, now = reached[False], reached[True]
        if before and now:
            sec.summary.append(f"{name} {SIZE[0]}×{SIZE[1]}: the {TARGET_SPP}-sample error ({fmt_num(target)}) after "
                               f"{fmt_time(now)} of pixel-sampler refinement against {fmt_time(before)} of "
                               f"one-sample passes ({now / before:.2f}×)")
        else:
            sec.summary.append(f"{name} {SIZE[0]}×{SIZE[1]}: {TARGET_SPP}-sample error {fmt_num(target)} reached "
                               f"by pixel-sampler passes: {'yes, ' + fmt_time(now) if now else 'no'}; "
                               f"by one-sample passes: {'yes, ' + fmt_time(before) if before else 'no'}")
    sec.table(["scene", "refinement", "pass", "samples so far", "time so far", f"RMSE vs {REF_SPP} spp (✓: "
               f"the {TARGET_SPP}-spp error or less)"], table,
              caption="The preview's progressive image, pass by pass, refined two ways from the same first image")

# SPDX-License-Identifier: GPL-3.0-or-later
"""The scene's beams (tracer/beams.py) on the GPU: the camera's, built for the pixels a render
traces and kept while the view stays (a progressive render's passes keep them), and up to
MAX_SUN_BEAMS lights' (suns, and point, spot and area lights from their position:
beams.light_frame), kept while the light stays, each built by the compute passes
(tracer/gpu_beams.py: beams need them, as a camera move must upload nothing); and which rays
they cannot serve or would not pay for (those walk the scene's grid).

Resolution. A camera bin is `bin_px` pixels a side, the smallest of CAMERA_BIN_PX (from
ONE_SAMPLE_BIN_PX for a render of one sample a pixel) whose lists are estimated (from an
even sample of the cylinders) to stay within their share of
layout.BEAM_MAX_REFS; a sun's bins (a light's: of the directions from it) are squares sized
so that a cylinder is listed in about SUN_REFS_PER_CYLINDER bins (fewer for large scenes,
within the same budget), or half as many until the renders have traced rays enough to pay for
those (SUN_FINE_RAYS_PER_BIN). Smaller bins list each cylinder more often but hand a ray fewer
cylinders to test: docs/DECISIONS.md, "Beams".
"""
import time
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from . import layout
from .beams import (Beams, BeamsUnfit, TooManyRefs, box_corners, camera_frame, drift_at, frame_reach, light_frame,
                    light_view, outside_cone, project, sun_basis, sun_frame)
from .cylinders import column_bounds, segment_radius
from .gl_state import beam_builder

# The lists (entries, two uint32 a texel where they come with marks) and bin tables. A sun's
# entries, and the camera's whole bins' for independent samples (a 1-pixel bin lists
# cylinders a sample of the pixel may miss), come with marks: each its cylinder's capsule
# axis in its bin, 8 bits a coordinate (written by the fill: shaders/beams_build.glsl,
# beam_mark). A ray tests a listed cylinder fully only where its point lies within the
# capsule (shaders/accel_beams.glsl, beam_mark_holds), reading the marks in list order beside
# the entries, not each cylinder's axis wherever its id points.
CAMERA_BUFFERS = ("tex_beam", "tex_beam_cell")
# Up to four lights' shadow rays take beams (a key, a fill and a rim light and one more: three-point
# lighting is how hair is lit for look development); a renderer uses as many of the slots as
# the driver's texture units hold (tracer/draw.py, sun_slots_within).
SUN_BUFFERS = tuple((f"tex_sun{k}", f"tex_sun_cell{k}") for k in range(4))
MAX_SUN_BEAMS = len(SUN_BUFFERS)
CAMERA_BIN_PX = (1, 2, 4)
# A render of one sample a pixel starts at 2-pixel bins, which build in about half the time;
# its few camera rays pay little for their longer lists (first render and re-render of
# straight.hair 0.37-0.39 and 0.27-0.30 s against 0.46-0.54 and 0.29-0.44 with 1-pixel bins;
# 10,000 wavy strands 0.48 and 0.24 against 0.62 and 0.30). From two samples on, 1 pixel
# (16 samples of the pixel sampler: 1.4-1.7x faster than on 2-pixel bins).
ONE_SAMPLE_BIN_PX = 2
# A camera's beams are built again at every camera move, the grid once: a render gets them
# when they would list at most CAMERA_REFS_PER_RAY references per camera ray it traces
# (1-pixel bins, estimated from a sample). Measured on llvmpipe (docs/DECISIONS.md, "Beams"):
# a reference costs about two cylinder tests to build, and the beams save a camera ray
# 0.7-1.8 tests per list entry of its pixel against the grid.
CAMERA_REFS_PER_RAY = 100.0
# One independent sample a pixel: each camera ray goes through its pixel's centre, so the
# camera's lists need hold only what those rays may meet (beams.BeamFrame.centres). Measured
# on llvmpipe at 512x512: 10,000 wavy strands, 157 k entries against 2-pixel bins' 2.4 M,
# built in 44 ms against 92 (the build still visits every column the capsules' shadows
# cross, but writes few entries), first render 220 ms against 408, re-render 85 against 203;
# the image the same. They pay against the grid up to about CENTRE_REFS_PER_RAY references of
# 1-pixel bins per camera ray: 100,000 strands (329 a ray) first render 1.89 s against the
# grid's 2.12 and re-render 0.60 against 0.88; 1,000,000 (3,287 a ray) 16.7 and 8.8 s against
# 16.0 and 6.1.
CENTRE_REFS_PER_RAY = 1000.0
# A sun's bins: about SUN_REFS_PER_CYLINDER references a cylinder, fewer where the scene's
# share of the budget is smaller, but never under SUN_MIN_REFS_PER_CYLINDER (coarser bins hand
# a shadow ray more entries than the grid's cells: 1,000,000 strands at 1.5 references a
# cylinder rendered 5x slower than on the grid). Kept across camera moves, a sun's beams are
# built for a render that would otherwise walk the grid anyway only when it casts at least one
# shadow ray (estimated: a ray a traced pixel and sample) per SUN_REFS_PER_RAY references, or
# when the strands are rendered again (their build then serves the renders to come).
SUN_REFS_PER_CYLINDER = 8.0
SUN_MIN_REFS_PER_CYLINDER = 4.0
SUN_REFS_PER_RAY = 100.0
# Which of those two: the finer lists (SUN_REFS_PER_CYLINDER) take longer to build, in
# proportion to the cylinders, and save each shadow ray entries to walk, in proportion to the
# entries its bin lists (the hair's depth seen from the sun, which grows with the cylinders
# too): so they pay once the renders of these strands have traced some rays a bin of the
# lists, SUN_FINE_RAYS_PER_BIN of the fine ones (samples times pixels, this render's and the
# announced ones to come included); fewer take SUN_MIN_REFS_PER_CYLINDER. A render that cannot
# say more are coming builds what its own rays pay for, and the render that brings the rays
# traced to it builds the fine lists (a camera move pays for them once). Where the fine lists
# pay off, measured on llvmpipe (AMD EPYC) at 512x512, 4 layers, interleaved in one process:
# the extra build over the extra trace a ray of the coarse lists, in rays a fine bin:
# straight.hair 12 (24 ms against 10 ms a 1-sample render; 29 k fine bins), 10,000 wavy
# strands 20-23 (154 ms; 4 ms at one sample, 99 ms at 16), 100,000 wavy 18 at one sample and
# 36 at 16 (1.5-1.6 s; 44 ms and 0.74 s; 250 k fine bins). 24 lies within a factor two of each:
# a 16-sample render of 100,000 strands (16.8 rays a fine bin) takes coarse lists (first render
# 7.9 s against 9.0, medians of 6) and its next render the fine ones; straight.hair's fifth
# 1-sample render builds them. The marks made coarse lists cheaper to walk: before them the
# fine lists paid from 1.5 rays a bin (docs/DECISIONS.md, "Beams").
SUN_FINE_RAYS_PER_BIN = 24.0
# A point, spot or area light with an extent: each capsule is listed wider by how far its
# rays drift, so its bins come out coarser than a light's without (for the same references a
# cylinder) and its lists longer. Past this many times fewer bins its rays walk the grid:
# measured on llvmpipe at 512², one sample, 4 layers, a point light three times the hair's
# diagonal away, first render and re-render, beams against the grid: straight.hair of radius
# 0.005, 0.01 and 0.02 of the diagonal (1.6, 2.3 and 3.8 times fewer bins) 301/215, 325/266
# and 425/343 ms against 633/567, 641/548 and 643/568; of 0.05 (21 times) 947/884 against
# 623/592 (docs/DECISIONS.md, "Beams").
LIGHT_MAX_COARSENING = 8.0
SUN_MAX_SIDE = 2048          # bins along either side of a sun's plane
SAMPLE = 20_000              # cylinders whose projections decide a resolution


@dataclass
class BeamState:
    """What a renderer keeps of its beams between renders: the camera's view they were built
    for (position, rotation, pixel size, capsule pad, scene) and the Beams (None: none, with
    `camera_why`), per sun slot (key, Beams or None), and the even sample of the scene's
    cylinders that sizes every family's bins (kept with its plan: _segments_sample)."""
    camera_view: object = None
    camera: Optional[Beams] = None
    camera_why: str = ""
    suns: list = field(default_factory=lambda: [None] * MAX_SUN_BEAMS)
    renders: int = 0            # renders of these strands so far
    traced: int = 0             # rays those renders traced (samples times pixels)
    kept_sample: tuple = (None, None)     # (the plan, its _segments_sample)

    def forget(self):
        self.camera_view = self.camera = None
        self.camera_why = ""
        self.suns = [None] * MAX_SUN_BEAMS
        self.renders = self.traced = 0
        self.kept_sample = (None, None)

    def sample(self, plan):
        """_segments_sample of `plan`, made once for the renders of these strands."""
        if self.kept_sample[0] is not plan:
            self.kept_sample = (plan, _segments_sample(plan))
        return self.kept_sample[1]


@dataclass
class BeamPlan:
    """What one render walks: the camera's beams (None: its rays walk the grid) and how far
    (pixels) this camera's pixel grid lies from the one they were laid for (a pass of a
    progressive render moves by a fraction of a pixel), the sun beams by slot, and per light
    the slot serving it (-1: the grid)."""
    camera: Optional[Beams]
    suns: list
    light_sun: list
    camera_shift: tuple = (0.0, 0.0)


def _segments_sample(plan, n=SAMPLE):
    """An even sample of the plan's cylinders: (top, tip, radius)."""
    step = max(1, len(plan) // n + 1)
    top = plan.top_point[::step]
    return (plan.points[top].astype(np.float64), plan.points[top + 1].astype(np.float64),
            segment_radius(plan.radius, top).astype(np.float64))


def _estimated_refs(frame, sample, pad, count):
    """References a frame's lists would hold, from a sample of segments (the slab listing's
    count of each: the columns along the longer side times the rows each reaches)."""
    top, tip, r = sample
    gx0, gy0, z0 = project(frame, top)
    gx1, gy1, z1 = project(frame, tip)
    rho = r * pad * frame.radius_scale
    if frame.kind == "persp":
        rho = rho / np.maximum(np.minimum(z0, z1), 1e-30)
    rho = rho + frame.drift
    major = np.maximum(np.abs(gx1 - gx0), np.abs(gy1 - gy0))
    minor = np.minimum(np.abs(gx1 - gx0), np.abs(gy1 - gy0))
    cols = major + 2 * rho + 1
    rows = minor / np.maximum(major, 1.0) + 2 * rho + 1
    return float(np.mean(cols * rows)) * count


def camera_beams(state, scene, buffers, camera, box, pad, samples=1, pixel_n=0):
    """The camera's Beams for a render of whole-image pixel box `box` (the pixels it traces)
    with capsules widened `pad` times, built into CAMERA_BUFFERS or kept from an earlier
    render of the same view, and how far this camera's pixels lie from the ones they were laid
    for. `samples`: samples a pixel; `pixel_n`: the pixel sampler's samples a side (0: the
    independent sampler). Returns (beams or None, shift, seconds building or 0.0); None where
    beams cannot serve the camera or would not pay for this render (state.camera_why says why).

    A progressive render's passes move the camera by a fraction of a pixel
    (tracer.Camera.for_pass): they keep the first pass's beams, laid one pixel wider than the
    traced box. An independent sample looks up the bin its ray crosses, wherever the pixel
    grid lies; the pixel sampler looks up its pixel's bin, which holds all its samples only
    when the lists were widened by the shift (`shift_pad`): a pass of n² samples moves by at
    most half of 1/n of a pixel, so the first such pass builds them again that much wider."""
    view = (camera.type, camera.position.tobytes(), camera.rotation.tobytes(), float(camera.pixel_size),
            float(pad), id(scene.plan))
    cx, cy = (float(c) for c in camera.centre_px)
    finest = ONE_SAMPLE_BIN_PX if samples == 1 else CAMERA_BIN_PX[0]
    # One independent sample a pixel: its ray goes through the pixel's centre.
    centred = samples == 1 and not pixel_n
    kept = state.camera if state.camera_view == view else None
    if kept is not None and kept.frame.bin_px > finest:
        kept = None      # coarser than this render's samples want: built again
    need = 0.0
    moving = False
    if kept is not None and kept.frame.centres:
        f = kept.frame
        moving = (f.centre[0], f.centre[1]) != (cx, cy)
        if moving or not centred:
            # Lists for another pixel grid's centres (a pass of the view moved by a fraction
            # of a pixel) or for one sample a pixel: built again, for the moving passes as
            # lists of whole bins, which the next pass keeps.
            kept = None
    if kept is not None:
        f = kept.frame
        shift = (f.centre[0] - cx, f.centre[1] - cy)
        moved = (box[0] + shift[0], box[1] + shift[1], box[2] + shift[0], box[3] + shift[1])
        inside = (max(abs(shift[0]), abs(shift[1])) < 1.0 and moved[0] >= f.box[0] and moved[1] >= f.box[1]
                  and moved[2] <= f.box[2] and moved[3] <= f.box[3])
        need = max(abs(shift[0]), abs(shift[1])) if pixel_n else 0.0
        if inside and need <= f.drift * f.bin_px + 1e-9:
            return kept, shift, 0.0
        if not inside:
            need = 0.0
    t0 = time.perf_counter()
    centre = kept.frame.centre if need > 0.0 else (cx, cy)
    shift_pad = max(need, 0.5 / pixel_n) if need > 0.0 else 0.0
    shift = (centre[0] - cx, centre[1] - cy)
    state.camera_view, state.camera, state.camera_why = view, None, ""
    lo, hi = scene.box
    rmax = float(scene.plan.radius.max())
    sample = state.sample(scene.plan)
    budget = _ref_budget(buffers)
    rays = samples * (box[2] - box[0]) * (box[3] - box[1])
    # The traced box in the bins' pixel grid, one pixel more on every side for the passes that
    # move this camera's.
    domain = (int(np.floor(box[0] + shift[0])) - 1, int(np.floor(box[1] + shift[1])) - 1,
              int(np.ceil(box[2] + shift[0])) + 1, int(np.ceil(box[3] + shift[1])) + 1)
    try:
        # Whether beams pay, by the references of 1-pixel bins (what CAMERA_REFS_PER_RAY was
        # measured with).
        one = _estimated_refs(camera_frame(camera, domain, lo, hi, rmax, pad, 1, shift_pad, centre), sample, pad,
                              scene.num_cylinders)
        if centred and not moving and one <= CENTRE_REFS_PER_RAY * rays:
            frame = camera_frame(camera, domain, lo, hi, rmax, pad, 1, 0.0, centre, centres=True)
            try:        # past the bins or the budget (TooManyRefs): whole bins, as below
                state.camera = _build(scene, buffers, frame, pad, CAMERA_BUFFERS, budget)
                return state.camera, shift, time.perf_counter() - t0
            except TooManyRefs:
                pass
        for b in CAMERA_BIN_PX:
            frame = camera_frame(camera, domain, lo, hi, rmax, pad, b, shift_pad, centre)
            if frame.num_bins > layout.BEAM_MAX_BINS or b < finest:
                continue
            if one > CAMERA_REFS_PER_RAY * rays:
                # Not kept: a render with more samples asks again.
                state.camera_view = None
                state.camera_why = (f"about {one / rays:.0f} list entries per camera ray of this render; "
                                    "the grid, kept between camera moves, costs less")
                break
            estimate = _estimated_refs(frame, sample, pad, scene.num_cylinders)
            if estimate > 0.5 * budget and b != CAMERA_BIN_PX[-1]:
                continue
            try:
                # Independent samples test a cylinder's capsule first (the pixel sampler's
                # walk takes every sample of a pixel at once).
                state.camera = _build(scene, buffers, frame, pad, CAMERA_BUFFERS, budget,
                                      marks=not pixel_n)
                break
            except TooManyRefs:
                continue
        else:
            state.camera_why = "its lists would outgrow one buffer at every bin size"
    except BeamsUnfit as e:
        state.camera_why = str(e)
    return state.camera, shift, time.perf_counter() - t0


# The lights whose shadow rays can take beams: a sun's rays share a direction (within its
# spread, tan of half its angle, which the lists are padded for), a point, spot or area light's
# end within its extent of its position (beams.light_frame); an environment's go everywhere.
BEAM_LIGHTS = ("directional", "point", "spot", "area")


def sun_slots(settings, usable=MAX_SUN_BEAMS):
    """Per light of `settings`, the slot of the sun beams its shadow rays can take (-1: none):
    a light of BEAM_LIGHTS that casts shadows, the first `usable` of them (at most
    MAX_SUN_BEAMS)."""
    if not settings.shadows:
        return [-1] * len(settings.lights)
    slots, n = [], 0
    for light in settings.lights:
        if light.kind in BEAM_LIGHTS and light.shadows and n < min(usable, MAX_SUN_BEAMS):
            slots.append(n)
            n += 1
        else:
            slots.append(-1)
    return slots


def sun_beams(state, scene, buffers, light, slot, rays=None, traced=0, to_come=0):
    """The Beams of shadow rays toward `light` (of BEAM_LIGHTS) in sun slot `slot`, built (or
    kept while a sun's direction and angle, or a light's position and extent, stay) into
    SUN_BUFFERS[slot]; None where beams cannot serve it (a light among the hair:
    beams.light_frame) or would not pay. `rays`: the shadow rays this render may cast, when the
    grid is to be built for it anyway (None: it is not: beams spare it; see SUN_REFS_PER_RAY).
    `traced`: the rays this render traces (samples times pixels), which with those of the
    renders before (state.traced) and `to_come`, the rays later renders are to trace
    (RenderSettings.samples_to_come), choose coarse or fine lists (SUN_FINE_RAYS_PER_BIN).
    Returns (beams, seconds building or 0.0)."""
    packed, _ = light.packed()
    vector = np.asarray(packed[:3], np.float32).astype(np.float64)
    if light.kind == "directional":
        towards = -vector
        spread = float(light.extent()[1][3])
        frames = lambda: (_sun_frames(scene, towards, spread, state.sample(scene.plan)), None)  # noqa: E731
        key = ("sun", towards.tobytes(), spread, id(scene.plan))
    else:
        reach = light_reach(light)
        cone = spot_cone(light)
        frames = lambda: _light_frames(scene, vector, reach, state.sample(scene.plan), cone)  # noqa: E731
        key = ("light", vector.tobytes(), reach, cone, id(scene.plan))
    traced = state.traced + traced + to_come
    kept = state.suns[slot]
    # A kept entry: (key, beams, the fine frame they are to be built again for, or None).
    if kept is not None and kept[0] == key:
        if kept[2] is None or traced < SUN_FINE_RAYS_PER_BIN * kept[2].num_bins:
            return kept[1], 0.0
        return _sun_build(state, scene, buffers, slot, key, kept[2], None, refused=kept[1])
    most = min(0.5 * _ref_budget(buffers) / max(scene.num_cylinders, 1), SUN_REFS_PER_CYLINDER)
    if most < SUN_MIN_REFS_PER_CYLINDER:
        state.suns[slot] = (key, None, None)     # never: as many cylinders next time
        return None, 0.0
    if rays is not None and state.renders == 0 and SUN_MIN_REFS_PER_CYLINDER * scene.num_cylinders > (
            SUN_REFS_PER_RAY * rays):
        return None, 0.0                     # not kept: the next render of these strands asks again
    t0 = time.perf_counter()
    try:
        frame_for, coarsening = frames()
        if coarsening is not None and coarsening(most) > LIGHT_MAX_COARSENING:
            raise BeamsUnfit("a light so wide beside the hair that its lists would be long")
        fine = frame_for(most)
        if most > SUN_MIN_REFS_PER_CYLINDER and traced < SUN_FINE_RAYS_PER_BIN * fine.num_bins:
            frame = frame_for(SUN_MIN_REFS_PER_CYLINDER)
        else:
            frame, fine = fine, None
    except BeamsUnfit:
        state.suns[slot] = (key, None, None)     # a light among the hair, or wide: its rays walk the grid
        return None, time.perf_counter() - t0
    beams, _ = _sun_build(state, scene, buffers, slot, key, frame, fine)
    return beams, time.perf_counter() - t0


def _sun_build(state, scene, buffers, slot, key, frame, later, refused=None):
    """sun_beams's build of `frame` into slot `slot`, kept with `later` (the fine frame to
    build again for once the rays pay, or None): (beams, seconds). Where the build is
    refused, `refused` is kept instead, not to be built again: the coarse lists when the
    fine ones do not fit (the refusal comes before anything is written over), else None."""
    t0 = time.perf_counter()
    try:
        beams = _build(scene, buffers, frame, 1.0, SUN_BUFFERS[slot], _ref_budget(buffers), marks=True)
        state.suns[slot] = (key, beams, later)
    except BeamsUnfit:
        beams = refused
        state.suns[slot] = (key, beams, None)
    return beams, time.perf_counter() - t0


def _ref_budget(buffers):
    """The references one family's lists may hold: layout.BEAM_MAX_REFS, within one buffer."""
    return min(layout.BEAM_MAX_REFS, buffers.max_texels)


def light_reach(light):
    """How far from its position a shadow ray toward a point, spot or area light may end: its
    radius (the disk its points are drawn from), an area light's half diagonal; 0 without an
    extent (tracer.settings.Light.extent)."""
    u, v = (np.asarray(e, np.float64) for e in light.extent())
    if light.kind == "area":
        return float(np.sqrt(u[:3] @ u[:3] + v[:3] @ v[:3]))
    return float(v[3])


def spot_cone(light):
    """A spot light's cone as beams.light_frame takes it (its unit axis and half angle, the
    angle a point must lie within for the light to reach it: settings.Light.cone), else None."""
    if light.kind != "spot":
        return None
    (x, y, z, cos_half), _ = light.cone()
    return (x, y, z, float(np.arccos(np.clip(cos_half, -1.0, 1.0))))


def _light_frames(scene, position, reach, sample, cone=None):
    """(frame_for, coarsening) for a point, spot or area light at `position` whose rays end
    within `reach` of it (beams.light_frame; `cone`: a spot's): frame_for as _sun_frames's
    (bins of side h at unit depth, h by bisection of the same estimate over the cylinders of
    `sample` projected from the light, each as wide as light_frame lists it at its depth, those
    outside a spot's cone left out); coarsening(target) how many times as many bins a light
    without extent would get for the same target (how much longer the extent makes the
    lists). BeamsUnfit as light_frame."""
    lo, hi = scene.box
    rmax = float(scene.plan.radius.max())
    view = light_view(position, reach, lo, hi, rmax, 1.0)
    top, tip, r = sample
    if cone is not None:
        keep = ~outside_cone(cone, position, reach, top, tip, r)
        if keep.any():
            top, tip, r = top[keep], tip[keep], r[keep]
    tx0, ty0, z0 = view.tangents(top)
    tx1, ty1, z1 = view.tangents(tip)
    du, dv = np.abs(tx1 - tx0), np.abs(ty1 - ty0)
    major, minor = np.maximum(du, dv), np.minimum(du, dv)
    slant = view.slant(0.0)
    near = np.maximum(np.minimum(z0, z1) - r, view.nearest)
    drift = drift_at(reach, float(view.depth.max()), view.spread(reach), near)
    widths = (2.0 * r * slant / near, 2.0 * (r + drift) * slant / near)       # without and with the extent
    span = max(float(np.ptp(view.tx)), float(np.ptp(view.ty))) + float(widths[1].max(initial=0.0))

    def frame_for(target):
        return light_frame(position, reach, lo, hi, rmax, 1.0, _bin_side(major, minor, widths[1], span, target), cone)

    def coarsening(target):
        if not reach > 0:
            return 1.0
        return (_bin_side(major, minor, widths[1], span, target) / _bin_side(major, minor, widths[0], span, target)) ** 2
    return frame_for, coarsening


def _sun_frames(scene, towards, spread, sample):
    """A function of `target` giving a sun's frame with bins sized for about `target`
    references a cylinder, within SUN_MAX_SIDE bins a side: the bins' side by bisection of
    _estimated_refs's count, which for a sun's bins of side h is the extents of `sample`
    (_segments_sample) across the sun (scene units, one projection for every target) over h."""
    lo, hi = scene.box
    rmax = float(scene.plan.radius.max())
    u, v, _ = sun_basis(towards)
    corners = box_corners(lo, hi)
    span = max(float(np.ptp(corners @ u)), float(np.ptp(corners @ v)), 1e-30)
    unit = sun_frame(towards, spread, lo, hi, rmax, 1.0, 1.0)      # bins of one scene unit
    top, tip, r = sample
    gx0, gy0, _ = project(unit, top)
    gx1, gy1, _ = project(unit, tip)
    du, dv = np.abs(gx1 - gx0), np.abs(gy1 - gy0)
    major, minor = np.maximum(du, dv), np.minimum(du, dv)
    reach = 2.0 * (r * unit.radius_scale + unit.drift)

    def frame_for(target):
        return sun_frame(towards, spread, lo, hi, rmax, 1.0, _bin_side(major, minor, reach, span, target))
    return frame_for


def _bin_side(major, minor, width, span, target):
    """The side of square bins for which cylinders whose projections reach `major` and `minor`
    along their longer and shorter sides, listed `width` wide, make about `target` references
    each (_estimated_refs's count: a cylinder's columns times its rows), by bisection within
    span / SUN_MAX_SIDE and `span` (references fall as bins grow); the finest where even it
    makes no more."""
    def refs(h):
        return float(np.mean(((major + width) / h + 1.0) * (minor / np.maximum(major, h) + width / h + 1.0)))
    h_lo, h_hi = span / SUN_MAX_SIDE, span
    if refs(h_lo) <= target:
        return h_lo
    for _ in range(20):
        h = 0.5 * (h_lo + h_hi)
        if refs(h) > target:
            h_lo = h
        else:
            h_hi = h
    return h_hi


def _build(scene, buffers, frame, pad, names, budget, marks=False):
    """Beams of `frame` built by the compute passes into buffers `names` (lists, bin table),
    with `marks` every entry with its mark (its cylinder's capsule axis in its bin), over the
    bins widened by the widest listing radius in bins (Beams.reach, beams.frame_reach)."""
    if frame.num_bins > layout.BEAM_MAX_BINS:
        raise TooManyRefs(f"{frame.num_bins:,} bins")
    reach = None
    if marks:
        lo, hi = scene.box
        reach = frame_reach(frame, lo, hi, float(scene.plan.radius.max()), pad)
    return beam_builder().build(frame, scene.num_cylinders, buffers["tex_cyl"], pad, buffers, names[0], names[1],
                                budget, reach)


def read_beams(beams, buffers, names):
    """(start, count, entries, marks) of Beams built on the GPU, read back (for tests and
    tools); marks None where the entries come without."""
    cells = np.frombuffer(buffers[names[1]].read(beams.frame.num_bins), np.int32).reshape(-1, 2)
    lists = np.frombuffer(buffers[names[0]].read(beams.refs), np.uint32)
    lists = lists.reshape(-1, 2) if beams.reach is not None else lists[:, None]
    marks = lists[:, 1].copy() if beams.reach is not None else None
    return cells[:, 0].copy(), cells[:, 1].copy(), lists[:, 0].copy(), marks


def beam_scene_box(plan, bounds, pad):
    """The box every capsule of the plan lies in (its points' column bounds widened by the
    largest radius times `pad` and the reach of a bent cylinder past its tip), as the grid's
    frame widens them (tracer/grid.py, _segments_frame)."""
    lo, hi = column_bounds(plan.points) if bounds is None else bounds
    rmax = float(plan.radius.max()) if len(plan.radius) else 0.0
    reach = rmax * (pad + layout.tan_sharp()) * (1 + 1e-6)
    return np.asarray(lo, np.float64) - reach, np.asarray(hi, np.float64) + reach



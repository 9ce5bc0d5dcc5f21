# SPDX-License-Identifier: GPL-3.0-or-later
"""The scene's beams (tracer/beams.py) on the GPU: the camera's, built for the pixels a render
traces and kept while the camera and those pixels stay, and up to MAX_SUN_BEAMS suns', kept
while the sun stays, each built by the compute passes (tracer/gpu_beams.py) or in numpy and
uploaded; and which rays they cannot serve (those walk the scene's grid).

Resolution. A camera bin is `bin_px` pixels a side, the smallest of CAMERA_BIN_PX whose lists
are estimated (from an even sample of the cylinders) to stay within their share of
layout.BEAM_MAX_REFS; a sun's bins are squares sized so that a cylinder is listed in about
SUN_REFS_PER_CYLINDER bins (fewer for large scenes, within the same budget). Smaller bins list
each cylinder more often but hand a ray fewer cylinders to test: docs/DECISIONS.md, "Beams".
"""
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from . import layout
from .beams import Beams, BeamsUnfit, TooManyRefs, box_corners, build_beams, camera_frame, project, sun_basis, sun_frame
from .cylinders import segment_radius
from .gl_state import beam_builder

CAMERA_BUFFERS = ("tex_beam", "tex_beam_cell")
SUN_BUFFERS = (("tex_sun0", "tex_sun_cell0"), ("tex_sun1", "tex_sun_cell1"))
MAX_SUN_BEAMS = len(SUN_BUFFERS)
CAMERA_BIN_PX = (1, 2, 4)
# A camera's beams are rebuilt at every camera move, the grid is built once: beams are built
# for a render whose camera rays are at least 1 / CAMERA_REFS_PER_RAY of the references they
# would list (1-pixel bins, estimated from a sample). Measured on llvmpipe (docs/DECISIONS.md,
# "Beams"): a reference costs about two cylinder tests to build, and the beams save a camera
# ray 0.7-1.8 tests per list entry of its pixel against the grid.
CAMERA_REFS_PER_RAY = 100.0
SUN_REFS_PER_CYLINDER = 8.0
SUN_MAX_SIDE = 2048          # bins along either side of a sun's plane
SAMPLE = 20_000              # cylinders whose projections decide a resolution


@dataclass
class BeamState:
    """What a renderer keeps of its beams between renders: per family the key it was built
    for and the Beams (None: unfit, with `why`), and the seconds and references of the last
    builds."""
    camera_key: object = None
    camera: Optional[Beams] = None
    camera_why: str = ""
    suns: list = field(default_factory=lambda: [None] * MAX_SUN_BEAMS)    # (key, Beams or None)

    def forget(self):
        self.camera_key = self.camera = None
        self.camera_why = ""
        self.suns = [None] * MAX_SUN_BEAMS


@dataclass
class BeamPlan:
    """What one render walks: the camera's beams (None: its rays walk the grid), the sun beams
    by slot, and per light the slot serving it (-1: the grid)."""
    camera: Optional[Beams]
    suns: list
    light_sun: list

    @property
    def needs_walk(self):
        """Some ray walks the scene's grid: the camera's, or a shadow ray toward a light
        without beams (the caller knows which lights cast shadows: `shadowed`)."""
        return self.camera is None


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


def camera_beams(state, scene, buffers, camera, box, pad, use_gpu, samples=1):
    """The camera's Beams over whole-image pixel box `box` (the render's traced box) with
    capsules widened `pad` times, built (or kept from the last render with the same camera,
    box and pad) into CAMERA_BUFFERS; None where beams cannot serve it or would not pay for a
    render of `samples` samples a pixel (state.camera_why says why). Returns (beams, seconds
    building or 0.0 when kept)."""
    import time
    key = (camera.type, camera.position.tobytes(), camera.rotation.tobytes(), float(camera.pixel_size),
           tuple(float(c) for c in camera.centre_px), tuple(box), float(pad), id(scene.plan))
    if key == state.camera_key:
        return state.camera, 0.0
    t0 = time.perf_counter()
    state.camera_key, state.camera, state.camera_why = key, None, ""
    lo, hi = scene.box
    rmax = float(scene.plan.radius.max())
    sample = _segments_sample(scene.plan)
    budget = min(layout.BEAM_MAX_REFS, buffers.max_texels)
    rays = samples * (box[2] - box[0]) * (box[3] - box[1])
    try:
        for b in CAMERA_BIN_PX:
            frame = camera_frame(camera, box, lo, hi, rmax, pad, b)
            if frame.num_bins > layout.BEAM_MAX_BINS:
                continue
            estimate = _estimated_refs(frame, sample, pad, scene.num_cylinders)
            if b == CAMERA_BIN_PX[0] and estimate > CAMERA_REFS_PER_RAY * rays:
                # Not cached: a render with more samples asks again.
                state.camera_key = None
                state.camera_why = (f"about {estimate / rays:.0f} list entries per camera ray of this render; "
                                    "the grid, kept between camera moves, costs less")
                break
            if estimate > 0.5 * budget and b != CAMERA_BIN_PX[-1]:
                continue
            try:
                state.camera = _build(scene, buffers, frame, pad, use_gpu, CAMERA_BUFFERS, budget)
                break
            except TooManyRefs:
                continue
        else:
            state.camera_why = "its lists would outgrow one buffer at every bin size"
    except BeamsUnfit as e:
        state.camera_why = str(e)
    return state.camera, time.perf_counter() - t0


def sun_slots(settings):
    """Per light of `settings`, whether shadow rays toward it can take sun beams: a
    directional light that casts shadows (its spread, tan of half its angle, is padded for),
    the first MAX_SUN_BEAMS of them."""
    if not settings.shadows:
        return [-1] * len(settings.lights)
    slots, n = [], 0
    for light in settings.lights:
        if light.kind == "directional" and light.shadows and n < MAX_SUN_BEAMS:
            slots.append(n)
            n += 1
        else:
            slots.append(-1)
    return slots


def sun_beams(state, scene, buffers, light, slot, use_gpu):
    """The Beams of shadow rays toward directional `light` in sun slot `slot`, built (or
    kept while the light's direction and angle stay) into SUN_BUFFERS[slot]; None where beams
    cannot serve it. Returns (beams, seconds building or 0.0)."""
    import time
    packed, _ = light.packed()
    towards = -np.asarray(packed[:3], np.float32).astype(np.float64)
    spread = float(light.extent()[1][3])
    key = (towards.tobytes(), spread, id(scene.plan))
    kept = state.suns[slot]
    if kept is not None and kept[0] == key:
        return kept[1], 0.0
    t0 = time.perf_counter()
    beams = None
    try:
        beams = _build(scene, buffers, _sun_frame(scene, buffers, towards, spread), 1.0, use_gpu, SUN_BUFFERS[slot],
                       min(layout.BEAM_MAX_REFS, buffers.max_texels))
    except BeamsUnfit:
        beams = None
    state.suns[slot] = (key, beams)
    return beams, time.perf_counter() - t0


def _sun_frame(scene, buffers, towards, spread):
    """A sun's frame with bins sized for about SUN_REFS_PER_CYLINDER references a cylinder
    (fewer when the scene's share of layout.BEAM_MAX_REFS is smaller), within SUN_MAX_SIDE bins
    a side."""
    lo, hi = scene.box
    rmax = float(scene.plan.radius.max())
    n = scene.num_cylinders
    budget = min(layout.BEAM_MAX_REFS, buffers.max_texels)
    target = float(np.clip(0.5 * budget / max(n, 1), 1.5, SUN_REFS_PER_CYLINDER))
    u, v, _ = sun_basis(towards)
    corners = box_corners(lo, hi)
    span = max(float(np.ptp(corners @ u)), float(np.ptp(corners @ v)), 1e-30)
    sample = _segments_sample(scene.plan)
    floor_h = span / SUN_MAX_SIDE
    h_lo, h_hi = floor_h, span
    frame = sun_frame(towards, spread, lo, hi, rmax, 1.0, h_lo)
    if _estimated_refs(frame, sample, 1.0, 1) <= target:
        return frame
    for _ in range(20):      # bisection: references fall as bins grow
        h = 0.5 * (h_lo + h_hi)
        frame = sun_frame(towards, spread, lo, hi, rmax, 1.0, h)
        if _estimated_refs(frame, sample, 1.0, 1) > target:
            h_lo = h
        else:
            h_hi = h
    return sun_frame(towards, spread, lo, hi, rmax, 1.0, h_hi)


def _build(scene, buffers, frame, pad, use_gpu, names, budget):
    """Beams of `frame` into buffers `names` (lists, bin table)."""
    if frame.num_bins > layout.BEAM_MAX_BINS:
        raise TooManyRefs(f"{frame.num_bins:,} bins")
    if use_gpu:
        return beam_builder().build(frame, scene.num_cylinders, buffers["tex_cyl"], pad, buffers, names[0],
                                    names[1], budget)
    beams = build_beams(frame, scene.cylinders, pad, budget)
    buffers.upload(names[0], beams.entries if beams.refs else np.zeros(1, np.uint32), 1, "u4")
    buffers.upload(names[1], np.stack([beams.start, beams.count], axis=1), 2, "i4")
    return beams


def read_beams(beams, buffers, names):
    """(start, count, entries) of Beams built on the GPU, read back (for tests and tools)."""
    if beams.entries is not None:
        return beams.start, beams.count, beams.entries
    cells = np.frombuffer(buffers[names[1]].read(beams.frame.num_bins), np.int32).reshape(-1, 2)
    entries = np.frombuffer(buffers[names[0]].read(beams.refs), np.uint32)
    return cells[:, 0].copy(), cells[:, 1].copy(), entries.copy()


def beam_scene_box(plan, bounds, pad):
    """The box every capsule of the plan lies in (its points' column bounds widened by the
    largest radius times `pad` and the reach of a bent cylinder past its tip), as the grid's
    frame widens them (tracer/grid.py, _segments_frame)."""
    from .cylinders import column_bounds
    lo, hi = column_bounds(plan.points) if bounds is None else bounds
    rmax = float(plan.radius.max()) if len(plan.radius) else 0.0
    reach = rmax * (pad + layout.tan_sharp()) * (1 + 1e-6)
    return np.asarray(lo, np.float64) - reach, np.asarray(hi, np.float64) + reach



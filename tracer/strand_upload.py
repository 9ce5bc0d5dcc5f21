# SPDX-License-Identifier: GPL-3.0-or-later
"""The two ways strands reach the GPU, behind one interface (`set`, `update`):

* NumpyUpload: cylinders made on the host (tracer/cylinders.py) and sent as texels.
* GpuUpload: the strand points sent as they are (32 bytes a point, half of the 64 a
  cylinder takes), the cylinders made from them by a compute pass (tracer/gpu_build.py).

Both fill the same `Scene` (what the renderer holds of its strands) and the same cylinder
buffer; the grid is built afterwards (tracer/scene_grid.py). Partial updates send the
changed strands' data in whole chunks of UPLOAD_CHUNK cylinders or points, neighbouring
chunks in one write: thousands of scattered strands would otherwise mean thousands of
small writes, which cost more than the data.
"""
import time
from dataclasses import dataclass
from typing import Optional

import numpy as np

from hairio import Strands

from . import layout
from .cylinders import (CylinderPlan, Cylinders, column_bounds, cylinders_from_plan, plan_cylinders,
                        repeat_distance, strands_to_cylinders)
from .grid import Grid
from .gl_state import gpu_builder

UPLOAD_CHUNK = 1024


@dataclass
class Scene:
    """What the renderer holds of its strands: the strands, the CylinderPlan they were made
    from, the cylinders (made on first use by the GPU build, which never needs them on the
    host), their count (None: no scene), whether every alpha is 1, and the acceleration
    structure (the grid or the BVH, tracer/bvh.py) with the pad its capsules were bounded
    with."""
    strands: Optional[Strands] = None
    plan: Optional[CylinderPlan] = None
    cylinders_: Optional[Cylinders] = None
    num_cylinders: Optional[int] = None
    all_opaque: bool = True
    grid: Optional[Grid] = None
    bvh: Optional[object] = None
    # The grid lists cylinders with their true radius until a render asks for minimum
    # pixel width; then it is rebuilt once with radii widened by GRID_WIDEN_CAP and kept.
    grid_pad: float = 1.0
    # References per cylinder the grid aims at beyond the rule for one sample a pixel (0:
    # that rule): raised by a render of many rays (Renderer._grid_aim), kept by the
    # grid's rebuilds after strand updates, reset by new strands.
    grid_aim: float = 0.0
    # An aim whose lists outgrew the buffers (0: none): no render of these strands aims as
    # high again.
    grid_aim_failed: float = 0.0
    # The pixel sampler's own grid (radii widened by GRID_WIDEN_CAP) beside an unpadded one,
    # built on its first render of these strands (tracer/scene_grid.py, build_wide_grid).
    wide_grid: Optional[Grid] = None
    # With beams (Renderer(accel="beams")): the box every capsule lies in (widened for minimum
    # pixel width), which frames the beams and the traced pixels; the grid is then built only
    # when some ray needs it.
    box: Optional[tuple] = None

    @property
    def cylinders(self):
        if self.cylinders_ is None and self.strands is not None:
            self.cylinders_ = strands_to_cylinders(self.strands)
        return self.cylinders_

    def forget(self):
        self.strands = self.grid = self.wide_grid = self.bvh = self.plan = self.cylinders_ = self.box = None
        self.num_cylinders = None

    def set_plan(self, strands, plan):
        self.strands, self.plan, self.num_cylinders = strands, plan, len(plan)
        self.all_opaque = bool(len(plan) == 0 or plan.alpha[plan.top_point].min() >= 1.0)

    def update_plan(self, ids, strands, sub):
        """The plan of `strands` whose strands `ids` changed (their points are `sub`'s, as
        many per strand as before): the strands' own arrays when the plan dropped no point,
        else the plan's copies with the changed strands written into them."""
        old = self.plan
        if len(old.points) == strands.num_points:
            plan = CylinderPlan(strands.points, strands.radius, strands.color, strands.alpha,
                                old.strand, old.counts, old.top_point)
        else:
            first_point = np.concatenate([[0], np.cumsum(old.counts)])
            dest = np.repeat(first_point[ids], sub.counts) + ranks(sub.counts)
            for f in ("points", "radius", "color", "alpha"):
                getattr(old, f)[dest] = getattr(sub, f)
            plan = old
        self.set_plan(strands, plan)


class NumpyUpload:
    """Cylinders made in numpy, uploaded as texels (tracer/layout.py's layout)."""

    drops_repeats = True       # plan_cylinders drops repeated points before the upload

    def __init__(self, buffers):
        self.buffers = buffers

    def set(self, scene, strands, plan, bounds=None):
        """Uploads the scene's cylinders; returns (cylinders_s, upload_s, point bounds or None).
        `bounds`: column_bounds of the strands' points (unused here)."""
        t0 = time.perf_counter()
        scene.set_plan(strands, plan)
        scene.cylinders_ = cylinders_from_plan(plan)
        t1 = time.perf_counter()
        self.buffers.stats.uploads += 1
        self.buffers.upload("tex_cyl", layout.cylinder_texels(scene.cylinders_), 4, "f4")
        return t1 - t0, time.perf_counter() - t1, None

    def update(self, scene, ids, strands, sub):
        """Remakes and uploads the cylinders of strands `ids` (their points `sub`); returns
        (cylinders_s, upload_s)."""
        t0 = time.perf_counter()
        new = cylinders_from_plan(sub)
        old = scene.cylinders
        per_strand_old = np.bincount(old.strand, minlength=strands.num_strands)
        first_old = np.concatenate([[0], np.cumsum(per_strand_old)])
        per_new = np.bincount(new.strand, minlength=len(ids))
        # Positions of the changed cylinders in the full arrays.
        dest = np.repeat(first_old[ids], per_new) + ranks(per_new)
        for f in ("top", "tip", "n2", "radius", "color", "alpha", "flags", "extension"):
            getattr(old, f)[dest] = getattr(new, f)
        scene.update_plan(ids, strands, sub)
        scene.cylinders_ = old
        t1 = time.perf_counter()
        self.buffers.stats.uploads += 1
        per = UPLOAD_CHUNK
        for a, b in runs(dest // per):
            b = min(len(old), b * per)
            self.buffers.write("tex_cyl", layout.cylinder_texels(old, a * per, b), a * per * layout.TEXELS_PER_CYL)
        return t1 - t0, time.perf_counter() - t1


class GpuUpload:
    """Strand points uploaded as they are; the compute pass makes the cylinders."""

    drops_repeats = False      # the compute pass checks for repeated points itself

    _POINT_TEXTURES = (("tex_pos", "points", 3), ("tex_rad", "radius", 1), ("tex_col", "color", 3),
                       ("tex_alpha", "alpha", 1))

    def __init__(self, buffers):
        self.buffers = buffers

    def set(self, scene, strands, plan, bounds=None):
        """Uploads the points and makes the cylinders; returns (cylinders_s, upload_s, point
        bounds for the grid's frame, or None when they must be taken again). `bounds`:
        column_bounds of the strands' points when the caller has them (the plan keeps every
        point, so they are its points' too)."""
        t0 = time.perf_counter()
        scene.set_plan(strands, plan)
        scene.cylinders_ = None
        if not len(plan):       # nothing to make: an empty cylinder buffer, as the numpy build sends
            return NumpyUpload(self.buffers).set(scene, strands, plan)
        self._upload_points(plan)
        t1 = time.perf_counter()
        # Twice the numpy build's distance: float32 rounding on the GPU cannot hide a
        # repeat, and plan_cylinders checks the candidates by the numpy rule.
        if bounds is None or plan.points is not strands.points:
            bounds = column_bounds(plan.points)     # the grid's frame needs them too
        repeats = self._make_cylinders(scene, 2.0 * repeat_distance(plan.points, bounds))
        upload_s = t1 - t0
        if repeats is None or len(repeats):
            # Some points may repeat their predecessor: drop them as the numpy build does.
            plan = plan_cylinders(strands, candidates=repeats)
            scene.set_plan(strands, plan)
            bounds = None       # fewer points: the grid takes their bounds again
            t2 = time.perf_counter()
            self._upload_points(plan)
            upload_s += time.perf_counter() - t2
            self._make_cylinders(scene, 0.0)
        self.buffers.stats.uploads += 1
        return time.perf_counter() - t0 - upload_s, upload_s, bounds

    def update(self, scene, ids, strands, sub):
        """Uploads the points of strands `ids` and remakes their cylinders; returns
        (cylinders_s, upload_s)."""
        t0 = time.perf_counter()
        scene.update_plan(ids, strands, sub)
        scene.cylinders_ = None
        plan = scene.plan
        counts = plan.counts.astype(np.int64)
        first_point = np.concatenate([[0], np.cumsum(counts)])
        per_strand = np.maximum(counts - 1, 0)
        t1 = time.perf_counter()
        # The chunks of points that hold the changed strands' points (see UPLOAD_CHUNK).
        w = UPLOAD_CHUNK
        point_first = first_point[ids]
        ends = point_first + counts[ids]
        r0, r1 = point_first // w, (ends - 1) // w
        chunks = np.repeat(r0, r1 - r0 + 1) + ranks(r1 - r0 + 1)
        n_points = len(plan.points)
        self.buffers.stats.uploads += 1
        for a, b in runs(chunks):
            self._upload_points(plan, a * w, min(n_points, b * w))
        t2 = time.perf_counter()
        # One dispatch from the first changed cylinder to the last: the unchanged ones between
        # are made again from unchanged points (same texels), which costs the GPU less than a
        # dispatch per run of changed strands.
        cyl_first = np.concatenate([[0], np.cumsum(per_strand)])
        first, last = int(cyl_first[ids[0]]), int(cyl_first[ids[-1] + 1])
        self._make_cylinders(scene, 0.0, first, last - first)
        return (t1 - t0) + (time.perf_counter() - t2), t2 - t1

    def _upload_points(self, plan, a=None, b=None):
        """Points a..b (all by default): the plan's arrays as they are, one buffer each; the
        full upload also sends the cylinder -> top point index."""
        if a is None:
            a, b = 0, len(plan.points)
            for name, field, comps in self._POINT_TEXTURES:
                self.buffers.store(name, b, comps, "f4")
            self.buffers.upload("tex_cp", plan.top_point.astype(np.int32), 1, "i4")
        for name, field, _ in self._POINT_TEXTURES:
            self.buffers.write(name, np.ascontiguousarray(getattr(plan, field)[a:b], np.float32), a)

    def _make_cylinders(self, scene, repeat_dist, first=0, count=None):
        """Makes cylinders first..first+count (all, into a fresh buffer, by default); returns
        the top points of those that may join repeated points (checked when repeat_dist > 0;
        None: too many to list)."""
        n = scene.num_cylinders
        if count is None:
            self.buffers.store("tex_cyl", n * layout.TEXELS_PER_CYL, 4, "f4")
        return gpu_builder().make_cylinders(self.buffers, n, repeat_dist, first, count)


def ranks(lengths):
    """0, 1, .., n-1 for every n in `lengths`, concatenated."""
    lengths = np.asarray(lengths, np.int64)
    return np.arange(int(lengths.sum())) - np.repeat(np.cumsum(lengths) - lengths, lengths)


def runs(chunks):
    """[first, end) pairs of the runs of consecutive chunk numbers among `chunks` (any order)."""
    rows = np.unique(chunks)
    breaks = np.flatnonzero(np.diff(rows) > 1)
    return [(int(rows[a]), int(rows[b]) + 1)
            for a, b in zip(np.concatenate([[0], breaks + 1]), np.concatenate([breaks, [len(rows) - 1]]))]


def select_strands(strands, ids):
    """The sub-set of strands `ids` (sorted), as a Strands (already validated data)."""
    offsets = strands.offsets
    counts = strands.counts[ids].astype(np.int64)
    pts = np.repeat(offsets[ids], counts) + ranks(counts)
    per_strand = strands.strand_color is not None and strands.point_color is None
    return Strands(strands.points[pts], strands.counts[ids], strands.radius[pts],
                   None if per_strand else strands.color[pts], strands.alpha[pts], strands.wisp[ids],
                   strand_color=strands.strand_color[ids] if per_strand else None)

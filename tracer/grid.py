# SPDX-License-Identifier: GPL-3.0-or-later
"""Uniform grid over cylinders with a compact (CSR) cell list, built in whole-array numpy.

Every cylinder is listed in every cell its padded capsule (radius times `pad_factor`) may
touch, cut slab by slab along its dominant axis (tighter than its whole bounding box), with
no cap per cell. Both builds (this one and the compute passes, tracer/gpu_build.py) lay the
grid over the scene with one function, `plan_frame`. The resolution comes from the cylinder
count and the extent: the cell size
is the smallest that lists a cylinder in about `MAX_REFS_PER_CYLINDER` cells on average
(see choose_resolution); cells need not be cubes.
"""
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from . import layout
from .cylinders import column_bounds, segment_radius

MAX_REFS_PER_CYLINDER = 8.0
MAX_CELLS_PER_CYLINDER = 4.0
MAX_REFS = 32_000_000   # references in all (128 MB of lists), see choose_resolution
MIN_REFS_PER_CYLINDER = 5.0     # ... but never fewer than this per cylinder
# A render of more rays than one sample a pixel at 512x512 (RAYS_TUNED, where the figures
# above were measured) pays the trace more often for one build, so its grid aims at
# (rays / RAYS_TUNED)^RAYS_EXPONENT times the references per cylinder, up to
# MAX_REFS_PER_CYLINDER_MANY and a share of what the lists' buffers hold: see refs_per_cylinder.
RAYS_TUNED = 512 * 512
RAYS_EXPONENT = 0.4
MAX_REFS_PER_CYLINDER_MANY = 12.0
CAPACITY_SHARE = 0.9
CHUNK = 1 << 16         # cylinders per build job (see build_grid)


@dataclass(frozen=True, eq=False)
class Grid:
    lo: np.ndarray          # (3,) float64 corner of cell (0,0,0)
    cell_size: np.ndarray   # (3,) float64
    dims: np.ndarray        # (3,) int64 cells along x, y, z
    cell_start: np.ndarray  # (nx*ny*nz,) int32 first slot in `indices`; cell id = x + nx*(y + ny*z)
    cell_count: np.ndarray  # (nx*ny*nz,) int32
    indices: np.ndarray     # (R,) int32 cylinder ids, each cell's run sorted by id; None when
                            # the lists exist only on the GPU (Renderer.grid_indices reads them)

    @property
    def hi(self):
        return self.lo + self.cell_size * self.dims

    @property
    def num_cells(self):
        return int(np.prod(self.dims))

    def occupancy(self):
        """Mean cylinders per non-empty cell and the fraction of cells that are non-empty."""
        n_full = int(np.count_nonzero(self.cell_count))
        return (float(self.cell_count.sum(dtype=np.int64)) / n_full if n_full else 0.0,
                n_full / max(1, self.num_cells))


def _dims_for(extent, h):
    dims = np.maximum(1, np.ceil(extent / h)).astype(np.int64)
    return np.minimum(dims, layout.MAX_DIM)


def expected_refs(box_size, h):
    """Mean number of cells of size h the slab listing (see _cells_touched) gives boxes of
    these sizes (N,3), on average over placement: (1 + e_k/h) slabs along the longest side,
    each holding 1/m of the other sides (m = e_k/h, at least 1)."""
    e = -np.sort(-box_size, axis=1) / h
    m = np.maximum(1.0, e[:, 0])
    return float(np.mean((1.0 + e[:, 0]) * (1.0 + e[:, 1] / m) * (1.0 + e[:, 2] / m)))


def refs_per_cylinder(count, rays=None, capacity=None):
    """The references per cylinder a grid of `count` cylinders aims at (choose_resolution's
    `max_refs`) for a render of `rays` camera rays (None: one sample a pixel at RAYS_TUNED)
    whose lists' buffers hold `capacity` references (None: no limit).

    A build costs about the same per reference, and on 1,000,000 wavy strands (61 M
    cylinders, 512x512) a ray's cylinder tests fell as the references to the power -1.5
    (4.2 a cylinder: build 9.5 s, one sample 6.9 s; 7.7: 18.7 s and 2.8 s). Build plus
    trace is least where the build costs 1.5 times the trace, so the references that pay
    grow as the rays to the power 1 / (1 + 1.5) = RAYS_EXPONENT: 16 samples want three times
    as many. Never fewer than the rule for one sample."""
    base = float(np.clip(MAX_REFS / max(1, count), MIN_REFS_PER_CYLINDER, MAX_REFS_PER_CYLINDER))
    work = (rays or 0) / RAYS_TUNED
    if work <= 1.0:
        return base
    aim = min(base * work ** RAYS_EXPONENT, MAX_REFS_PER_CYLINDER_MANY)
    if capacity is not None:
        aim = min(aim, CAPACITY_SHARE * capacity / max(1, count))
    return max(base, aim)


def choose_resolution(box_size, extent, max_refs=None, count=None):
    """Cell counts per axis: the smallest cell size h at which a cylinder is listed in about
    `max_refs` cells on average (found by bisection on a sample of boxes).

    Smaller cells mean fewer cylinder tests per ray but more references to build and more
    cell steps; on dense hair no size gets near a few cylinders per occupied cell without
    listing each segment in dozens of cells. About 8 references per cylinder balance build
    and trace. A floor keeps the cell count within MAX_CELLS and MAX_DIM per axis, and
    within MAX_CELLS_PER_CYLINDER times the cylinder count, so sparse scenes do not get
    millions of nearly empty cells that every build pays for and every ray steps through.
    Past MAX_REFS references in all, fewer per cylinder are aimed at (building costs the
    same per reference, while a ray gains less from smaller cells that are already full),
    but not below MIN_REFS_PER_CYLINDER, under which the trace pays more than the build
    saves. The figures: docs/DECISIONS.md, "Grid resolution". `box_size` (N,3): sizes of the
    cylinders' padded boxes, or of a sample of them; `count`: how many cylinders there are
    (default: len(box_size))."""
    n = len(box_size)
    count = n if count is None else count
    if max_refs is None:
        max_refs = refs_per_cylinder(count)
    sample = box_size if n <= 20_000 else box_size[:: n // 20_000 + 1]
    cells = min(layout.MAX_CELLS, MAX_CELLS_PER_CYLINDER * count)
    floor_h = max(float(extent.max()) / layout.MAX_DIM, float(np.prod(extent) / max(cells, 1)) ** (1 / 3))
    lo_h, hi_h = floor_h, max(floor_h, float(extent.max()))
    if expected_refs(sample, lo_h) <= max_refs:
        return _dims_for(extent, lo_h)
    for _ in range(24):       # bisection: expected_refs falls as h grows
        m = 0.5 * (lo_h + hi_h)
        lo_h, hi_h = (m, hi_h) if expected_refs(sample, m) > max_refs else (lo_h, m)
    return _dims_for(extent, hi_h)


def grid_frame(lo, hi, box_size, dims=None, count=None, max_refs=None):
    """(corner, cell size, cell counts) of the grid over the scene box lo..hi whose `count`
    cylinders (default len(box_size)) have padded boxes of sizes `box_size` (N,3, or a
    sample), aiming at `max_refs` references a cylinder (default: refs_per_cylinder's for
    one sample a pixel); `dims` overrides the resolution."""
    lo = np.asarray(lo, np.float64)
    extent = np.asarray(hi, np.float64) - lo
    # A flat scene (all hair in one plane) still needs a non-zero cell along that axis.
    extent = np.maximum(extent, max(float(extent.max()) * 1e-3, 1e-12))
    # Widen by a hair so boxes on the far faces fall inside the last cell, not past it.
    lo = lo - extent * 1e-6
    extent = extent * (1 + 2e-6)
    if dims is None:
        dims = grid_dims(box_size, extent, count, max_refs)
    dims = np.asarray(dims, np.int64)
    return lo, extent / dims, dims


# Cylinders whose boxes give the resolution: at most about this many, evenly spaced.
FRAME_SAMPLE = 20_000


def plan_frame(plan, pad_factor=1.0, bounds=None, dims=None, max_refs=None):
    """(corner, cell size, cell counts) of the grid over a tracer.cylinders.CylinderPlan
    whose capsules are widened `pad_factor` times: the one frame both builds use, made
    from the plan alone (the GPU build never has the cylinders on the host). `bounds`:
    column_bounds of the plan's points when the caller has them already; `max_refs` as
    grid_frame's; `dims` overrides the resolution. The reach past the points' box comes from
    their largest radius, which bounds every cylinder's (the mean of two of them)."""
    step = max(1, len(plan) // FRAME_SAMPLE + 1)
    top = plan.top_point[::step]
    rmax = float(plan.radius.max()) if len(plan.radius) else 0.0
    return _segments_frame(column_bounds(plan.points) if bounds is None else bounds, rmax,
                           plan.points[top], plan.points[top + 1], segment_radius(plan.radius, top), pad_factor,
                           len(plan), dims, max_refs)


def cylinders_frame(cylinders, pad_factor=1.0, dims=None):
    """The frame of plan_frame for tracer.cylinders.Cylinders (their end points and radii;
    for the cylinders of a plan it is the plan's frame but for the reach, here from the
    largest cylinder's radius, there from the largest point's)."""
    step = max(1, len(cylinders) // FRAME_SAMPLE + 1)
    ends = np.concatenate([cylinders.top, cylinders.tip])
    return _segments_frame(column_bounds(ends), float(cylinders.radius.max()), cylinders.top[::step],
                           cylinders.tip[::step], cylinders.radius[::step], pad_factor, len(cylinders), dims)


def _segments_frame(bounds, rmax, top, tip, radius, pad_factor, count, dims, max_refs=None):
    """The frame over segments whose end points lie within `bounds`, widened by `rmax`:
    every capsule lies within its points' box widened by its radius times the pad, plus
    the reach of a bent cylinder past its tip (at most r·tan(SHARP_BEND_DEG), see
    tracer/cylinders.py), so the scene box needs no per-cylinder work. The resolution comes
    from the padded boxes of `top`..`tip` (the cylinders, or an even sample of `count`)."""
    reach = rmax * (pad_factor + layout.tan_sharp()) * (1 + 1e-6)
    lo, hi = bounds
    a, b = top.astype(np.float64), tip.astype(np.float64)
    size = np.abs(b - a) + 2 * pad_factor * radius[:, None]
    return grid_frame(lo - reach, hi + reach, size, dims, count=count, max_refs=max_refs)


def grid_dims(box_size, extent, count=None, max_refs=None):
    """The resolution every build uses (a seam for measuring other resolutions)."""
    return choose_resolution(box_size, extent, max_refs=max_refs, count=count)


def _cells_touched(cylinders, pad_factor, lo, cs, dims):
    """(cylinder, cell id) for every cell the padded capsule of a cylinder may touch.

    Boxes of whole cylinders are poor for thin diagonal segments longer than a cell (a box
    spans (l/h)³ cells where the capsule touches about 2·l/h), so each capsule is cut into the
    slabs of cells along its dominant axis, and in each slab only the box of the part of the
    segment inside that slab (plus the radius) is listed. Still conservative: every point of
    the capsule within a slab lies within `pad` of the part of the axis inside that slab
    widened by `pad`."""
    axis = cylinders.tip.astype(np.float64) - cylinders.top
    length = np.sqrt(np.einsum("ij,ij->i", axis, axis))
    far = cylinders.tip + axis * (cylinders.extension / np.maximum(length, 1e-30))[:, None]
    g0 = (cylinders.top - lo) / cs
    dg = (far - lo) / cs - g0
    # A little extra pad (a thousandth of a cell) covers the float32 rounding below.
    padg = (cylinders.radius.astype(np.float64) * pad_factor)[:, None] / cs[None, :] + 1e-3
    n = len(g0)
    # Reorder every per-cylinder triple as (dominant axis k, a, b) once, so the expanded
    # stages below only repeat 1-D arrays (sequential copies, not gathers).
    k = np.argmax(np.abs(dg), axis=1)
    order = np.stack([k, (k + 1) % 3, (k + 2) % 3], axis=1)
    G0 = np.take_along_axis(g0, order, 1).astype(np.float32)
    DG = np.take_along_axis(dg, order, 1).astype(np.float32)
    PAD = np.take_along_axis(padg, order, 1).astype(np.float32)
    DIM = dims[order].astype(np.int32)
    STRIDE = np.array([1, dims[0], dims[0] * dims[1]], np.int32)[order]
    i0 = np.clip(np.floor(np.minimum(G0[:, 0], G0[:, 0] + DG[:, 0]) - PAD[:, 0]), 0, DIM[:, 0] - 1).astype(np.int32)
    i1 = np.clip(np.floor(np.maximum(G0[:, 0], G0[:, 0] + DG[:, 0]) + PAD[:, 0]), 0, DIM[:, 0] - 1).astype(np.int32)
    nslab = i1 - i0 + 1
    total = int(nslab.sum())
    first = np.cumsum(nslab) - nslab
    # Expansion by one repeat of the owner index, then gathers: np.repeat with per-element
    # counts copies element by element, a gather from a cache-sized chunk array does not
    # (docs/DECISIONS.md, "The numpy grid build in small chunks").
    c1 = np.repeat(np.arange(n, dtype=np.int32), nslab)
    rep = lambda x: np.take(x, c1)  # noqa: E731
    slab = rep(i0 - first.astype(np.int32)) + np.arange(total, dtype=np.int32)
    # Part of the segment (parameter s in [0, 1]) whose dominant coordinate lies within pad of
    # the slab; a segment too short to have a dominant direction is taken whole.
    dk1, g0k1, pk1 = rep(DG[:, 0]), rep(G0[:, 0]), rep(PAD[:, 0])
    flat = np.abs(dk1) < 1e-12
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.float32(1.0) / np.where(flat, np.float32(1.0), dk1)
        sa = (slab - pk1 - g0k1) * inv
        sb = (slab + 1 + pk1 - g0k1) * inv
    s0 = np.where(flat, np.float32(0.0), np.clip(np.minimum(sa, sb), 0.0, 1.0))
    s1 = np.where(flat, np.float32(1.0), np.clip(np.maximum(sa, sb), 0.0, 1.0))
    del sa, sb, dk1, g0k1, pk1, flat

    def span(col):
        g, d, p, top = rep(G0[:, col]), rep(DG[:, col]), rep(PAD[:, col]), rep(DIM[:, col] - 1)
        e0, e1 = g + s0 * d, g + s1 * d
        j0 = np.clip(np.floor(np.minimum(e0, e1) - p), 0, top).astype(np.int32)
        j1 = np.clip(np.floor(np.maximum(e0, e1) + p), 0, top).astype(np.int32)
        return j0, j1 - j0 + 1

    ja, na = span(1)
    jb, nb = span(2)
    stra, strb = rep(STRIDE[:, 1]), rep(STRIDE[:, 2])
    base = slab * rep(STRIDE[:, 0]) + ja * stra + jb * strb
    per = na * nb
    if np.all(per == 1):        # thin hair in cells longer than its radius: the usual case
        return c1, base
    total2 = int(per.sum())
    first2 = (np.cumsum(per) - per).astype(np.int32)
    owner2 = np.repeat(np.arange(total, dtype=np.int32), per)
    rep2 = lambda x: np.take(x, owner2)  # noqa: E731
    local = np.arange(total2, dtype=np.int32) - rep2(first2)
    na2 = rep2(na)
    cell = rep2(base) + (local % na2) * rep2(stra) + (local // na2) * rep2(strb)
    return rep2(c1), cell


def build_grid(cylinders, pad_factor=1.0, dims=None, frame=None):
    """Grid over `cylinders` (tracer.cylinders.Cylinders) in `frame` (corner, cell size,
    cell counts; default cylinders_frame). `dims` overrides the resolution."""
    n = len(cylinders)
    if n == 0:
        return Grid(np.zeros(3), np.ones(3), np.ones(3, np.int64), np.zeros(1, np.int32),
                    np.zeros(1, np.int32), np.zeros(0, np.int32))
    lo, cs, dims = cylinders_frame(cylinders, pad_factor, dims) if frame is None else frame
    ncell = int(np.prod(dims))
    # Small chunks of cylinders on all cores (numpy drops the GIL in its loops). Small, so the
    # dozen temporaries per reference stay in cache instead of streaming ~40 MB arrays
    # through memory (docs/DECISIONS.md, "The numpy grid build in small chunks").
    # Each chunk comes back as (cell, cylinder) keys sorted by cell.
    step = max(1, min(CHUNK, -(-n // (os.cpu_count() or 1))))
    jobs = [(a, min(n, a + step)) for a in range(0, n, step)]

    def run(job):
        a, b = job
        cyl, cell = _cells_touched(cylinders.select(slice(a, b)), pad_factor, lo, cs, dims)
        key = (cell.astype(np.int64) << 31) | (cyl.astype(np.int64) + a)
        key.sort()
        cell = (key >> 31).astype(np.int32)
        # First entry of every cell's run inside this chunk, and the run lengths.
        head = np.flatnonzero(np.concatenate([[True], cell[1:] != cell[:-1]]))
        length = np.diff(np.append(head, len(cell)))
        return cell[head], head, length, (key & ((1 << 31) - 1)).astype(np.int32)

    workers = min(os.cpu_count() or 1, len(jobs))
    if workers == 1:
        runs = [run(job) for job in jobs]
        count, indices = _merge_runs(runs, ncell)
    else:
        with ThreadPoolExecutor(workers) as pool:
            runs = list(pool.map(run, jobs))
            count, indices = _merge_runs(runs, ncell, pool)
    start = (np.cumsum(count, dtype=np.int64) - count).astype(np.int32)
    return Grid(lo, cs, dims, start, count, indices)


def _merge_runs(runs, ncell, pool=None):
    """Counting-sort merge of per-chunk runs (cells of the chunk's runs, run heads, run
    lengths, cylinder ids sorted by cell) into one CSR list in linear time: a cell's slots
    are its chunks' entries in chunk order, so every cell's run stays sorted by cylinder id
    (chunks hold increasing ids). The slots of each chunk are fixed first (small arrays, in
    chunk order); the scatters touch disjoint slots, so they run on `pool` when given.
    Returns (count, indices)."""
    count = np.zeros(ncell, np.int64)
    for ucell, _, length, _ in runs:
        count[ucell] += length          # cells are unique within a chunk: no lost updates
    fill = np.cumsum(count) - count     # next free slot of every cell
    offsets = []
    for ucell, head, length, _ in runs:
        offsets.append(fill[ucell] - head)   # slot of entry j of a run = this + j
        fill[ucell] += length
    indices = np.empty(int(count.sum()), np.int32)

    def scatter(job):
        (_, _, length, cyl), off = job
        indices[np.repeat(off, length) + np.arange(len(cyl))] = cyl

    jobs = list(zip(runs, offsets))
    if pool is None:
        for job in jobs:
            scatter(job)
    else:
        list(pool.map(scatter, jobs))
    return count.astype(np.int32), indices

# SPDX-License-Identifier: GPL-3.0-or-later
"""Uniform grid over cylinders with a compact (CSR) cell list, built in whole-array numpy.

Every cylinder is listed in every cell its padded bounding box (the capsule's box, radius
times `pad_factor`) touches, with no cap per cell. The resolution comes from the cylinder
count and the extent: the cell size is tuned so that cells that hold anything hold about
`TARGET_PER_CELL` cylinders; cells need not be cubes.
"""
from dataclasses import dataclass

import numpy as np

TARGET_PER_CELL = 3.0
MAX_DIM = 1024          # 3D textures of GL 3.3 guarantee 256; every driver we target has >= 2048
MAX_CELLS = 1 << 23
MAX_REFS_PER_CYLINDER = 8.0


@dataclass(frozen=True, eq=False)
class Grid:
    lo: np.ndarray          # (3,) float64 corner of cell (0,0,0)
    cell_size: np.ndarray   # (3,) float64
    dims: np.ndarray        # (3,) int64 cells along x, y, z
    cell_start: np.ndarray  # (nx*ny*nz,) int32 first slot in `indices`; cell id = x + nx*(y + ny*z)
    cell_count: np.ndarray  # (nx*ny*nz,) int32
    indices: np.ndarray     # (R,) int32 cylinder ids, each cell's run sorted by id

    @property
    def hi(self):
        return self.lo + self.cell_size * self.dims

    @property
    def num_cells(self):
        return int(np.prod(self.dims))

    def occupancy(self):
        """Mean cylinders per non-empty cell and the fraction of cells that are non-empty."""
        full = self.cell_count > 0
        n_full = int(full.sum())
        return (float(self.cell_count[full].mean()) if n_full else 0.0,
                n_full / max(1, self.num_cells))


def _dims_for(extent, h):
    dims = np.maximum(1, np.ceil(extent / h)).astype(np.int64)
    return np.minimum(dims, MAX_DIM)


def expected_refs(box_size, h):
    """Mean number of cells of size h the slab listing (see _cells_touched) gives boxes of
    these sizes (N,3), on average over placement: (1 + e_k/h) slabs along the longest side,
    each holding 1/m of the other sides (m = e_k/h, at least 1)."""
    e = -np.sort(-box_size, axis=1) / h
    m = np.maximum(1.0, e[:, 0])
    return float(np.mean((1.0 + e[:, 0]) * (1.0 + e[:, 1] / m) * (1.0 + e[:, 2] / m)))


def choose_resolution(box_lo, box_hi, scene_lo, extent, target=TARGET_PER_CELL,
                      max_refs=MAX_REFS_PER_CYLINDER):
    """Cell counts per axis. The cell size h starts where non-empty cells hold about `target`
    cylinders (counted at box centres; hair fills a shell, so occupancy grows about like h²,
    hence the square-root step), then grows if needed so that a cylinder is listed in at most
    `max_refs` cells on average: the build costs time per reference, and dense hair would
    otherwise want cells much shorter than its segments."""
    n = len(box_lo)
    size = box_hi - box_lo
    sample = size if n <= 20_000 else size[:: n // 20_000 + 1]
    floor_h = max(float(extent.max()) / MAX_DIM, float(np.prod(extent) / MAX_CELLS) ** (1 / 3))
    h = max(2.0 * float(np.median(size.max(axis=1))), floor_h)
    mid = 0.5 * (box_lo + box_hi)
    for _ in range(3):
        dims = _dims_for(extent, h)
        cs = extent / dims
        c = np.minimum(((mid - scene_lo) / cs).astype(np.int64), dims - 1)
        cid = c[:, 0] + dims[0] * (c[:, 1] + dims[1] * c[:, 2])
        occupied = np.count_nonzero(np.bincount(cid, minlength=int(np.prod(dims))))
        ratio = target / max(n / max(1, occupied), 1e-9)
        if 0.8 < ratio < 1.25:
            break
        h_new = max(h * ratio ** 0.5, floor_h)
        if abs(h_new - h) <= 1e-3 * h:
            break
        h = h_new
    if expected_refs(sample, h) > max_refs:
        lo_h, hi_h = h, max(h, float(extent.max()))
        for _ in range(20):       # bisection: expected_refs falls as h grows
            m = 0.5 * (lo_h + hi_h)
            lo_h, hi_h = (m, hi_h) if expected_refs(sample, m) > max_refs else (lo_h, m)
        h = hi_h
    return _dims_for(extent, h)


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
    padg = (cylinders.radius.astype(np.float64) * pad_factor)[:, None] / cs[None, :]
    n = len(g0)
    rows = np.arange(n)
    k = np.argmax(np.abs(dg), axis=1)
    a, b = (k + 1) % 3, (k + 2) % 3
    g0k, dk, pk = g0[rows, k], dg[rows, k], padg[rows, k]
    dimk = dims[k]
    i0 = np.clip(np.floor(np.minimum(g0k, g0k + dk) - pk), 0, dimk - 1).astype(np.int64)
    i1 = np.clip(np.floor(np.maximum(g0k, g0k + dk) + pk), 0, dimk - 1).astype(np.int64)
    nslab = i1 - i0 + 1
    first = np.cumsum(nslab) - nslab
    c1 = np.repeat(rows, nslab)
    slab = i0[c1] + (np.arange(len(c1)) - first[c1])
    # Part of the segment (parameter s in [0, 1]) whose dominant coordinate lies within pad of
    # the slab; a segment too short to have a dominant direction is taken whole.
    dk1, g0k1, pk1 = dk[c1], g0k[c1], pk[c1]
    flat = np.abs(dk1) < 1e-12
    with np.errstate(divide="ignore", invalid="ignore"):
        sa = (slab - pk1 - g0k1) / dk1
        sb = (slab + 1 + pk1 - g0k1) / dk1
    s0 = np.where(flat, 0.0, np.clip(np.minimum(sa, sb), 0.0, 1.0))
    s1 = np.where(flat, 1.0, np.clip(np.maximum(sa, sb), 0.0, 1.0))

    def span(axes):
        ax = axes[c1]
        g, d, p = g0[c1, ax], dg[c1, ax], padg[c1, ax]
        e0, e1 = g + s0 * d, g + s1 * d
        top = dims[ax] - 1
        j0 = np.clip(np.floor(np.minimum(e0, e1) - p), 0, top).astype(np.int64)
        j1 = np.clip(np.floor(np.maximum(e0, e1) + p), 0, top).astype(np.int64)
        return ax, j0, j1 - j0 + 1

    ax_a, ja, na = span(a)
    ax_b, jb, nb = span(b)
    stride = np.array([1, dims[0], dims[0] * dims[1]], np.int64)
    base = slab * stride[k[c1]] + ja * stride[ax_a] + jb * stride[ax_b]
    per = na * nb
    first2 = np.cumsum(per) - per
    c2 = np.repeat(np.arange(len(c1)), per)
    local = np.arange(len(c2)) - first2[c2]
    na2 = na[c2]
    cell = base[c2] + (local % na2) * stride[ax_a[c2]] + (local // na2) * stride[ax_b[c2]]
    return c1[c2], cell


def build_grid(cylinders, pad_factor=1.0, dims=None):
    """Grid over `cylinders` (tracer.cylinders.Cylinders). `dims` overrides the resolution."""
    n = len(cylinders)
    if n == 0:
        return Grid(np.zeros(3), np.ones(3), np.ones(3, np.int64), np.zeros(1, np.int32),
                    np.zeros(1, np.int32), np.zeros(0, np.int32))
    blo, bhi = cylinders.bounds(pad_factor)
    blo = blo.astype(np.float64)
    bhi = bhi.astype(np.float64)
    lo, hi = blo.min(axis=0), bhi.max(axis=0)
    extent = hi - lo
    # A flat scene (all hair in one plane) still needs a non-zero cell along that axis.
    extent = np.maximum(extent, max(float(extent.max()) * 1e-3, 1e-12))
    # Widen by a hair so boxes on the far faces fall inside the last cell, not past it.
    lo = lo - extent * 1e-6
    extent = extent * (1 + 2e-6)
    if dims is None:
        dims = choose_resolution(blo, bhi, lo, extent)
    # choose_resolution counts whole boxes; the slab listing needs far fewer references.
    dims = np.asarray(dims, np.int64)
    cs = extent / dims
    cyl, cell = _cells_touched(cylinders, pad_factor, lo, cs, dims)
    # One int64 sort of (cell, cylinder) keys orders the list by cell and, inside a cell,
    # by cylinder id; it beats argsort by a factor of about two.
    key = np.sort((cell << 31) | cyl.astype(np.int64))
    indices = (key & ((1 << 31) - 1)).astype(np.int32)
    ncell = int(np.prod(dims))
    count = np.bincount(key >> 31, minlength=ncell).astype(np.int32)
    start = (np.cumsum(count, dtype=np.int64) - count).astype(np.int32)
    return Grid(lo, cs, dims, start, count, indices)

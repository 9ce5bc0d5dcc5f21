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


def choose_resolution(box_lo, box_hi, scene_lo, extent, target=TARGET_PER_CELL):
    """Cell counts per axis: start from cells about twice the typical box, then scale the cell
    size twice by how far the mean occupancy of non-empty cells (counted at box centres) is
    from `target`. Hair fills a shell, so occupancy grows about like h²; the square root
    exponent reflects that."""
    n = len(box_lo)
    size = (box_hi - box_lo).max(axis=1)
    h = 2.0 * float(np.median(size)) if n else 1.0
    h = max(h, float(extent.max()) / MAX_DIM, float(np.prod(extent) / MAX_CELLS) ** (1 / 3))
    mid = 0.5 * (box_lo + box_hi)
    for _ in range(3):
        dims = _dims_for(extent, h)
        cs = extent / dims
        c = np.minimum(((mid - scene_lo) / cs).astype(np.int64), dims - 1)
        cid = c[:, 0] + dims[0] * (c[:, 1] + dims[1] * c[:, 2])
        occupied = np.count_nonzero(np.bincount(cid, minlength=int(np.prod(dims))))
        per_cell = n / max(1, occupied)
        ratio = target / max(per_cell, 1e-9)
        if 0.8 < ratio < 1.25:
            break
        h_new = h * ratio ** 0.5
        h_new = max(h_new, float(np.prod(extent) / MAX_CELLS) ** (1 / 3), float(extent.max()) / MAX_DIM)
        if abs(h_new - h) <= 1e-3 * h:
            break
        h = h_new
    return _dims_for(extent, h)


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
    dims = np.asarray(dims, np.int64)
    cs = extent / dims
    i0 = np.clip(((blo - lo) / cs).astype(np.int64), 0, dims - 1)
    i1 = np.clip(((bhi - lo) / cs).astype(np.int64), 0, dims - 1)
    span = i1 - i0 + 1
    per = span[:, 0] * span[:, 1] * span[:, 2]
    total = int(per.sum())
    first = np.cumsum(per) - per
    cyl = np.repeat(np.arange(n, dtype=np.int64), per)
    local = np.arange(total, dtype=np.int64) - np.repeat(first, per)
    sx = span[cyl, 0]
    sxy = sx * span[cyl, 1]
    cx = i0[cyl, 0] + local % sx
    cy = i0[cyl, 1] + (local // sx) % span[cyl, 1]
    cz = i0[cyl, 2] + local // sxy
    cell = cx + dims[0] * (cy + dims[1] * cz)
    # One int64 sort of (cell, cylinder) keys orders the list by cell and, inside a cell,
    # by cylinder id; it beats argsort by a factor of about two.
    key = np.sort((cell << 31) | cyl)
    indices = (key & ((1 << 31) - 1)).astype(np.int32)
    ncell = int(np.prod(dims))
    count = np.bincount(key >> 31, minlength=ncell).astype(np.int32)
    start = (np.cumsum(count, dtype=np.int64) - count).astype(np.int32)
    return Grid(lo, cs, dims, start, count, indices)

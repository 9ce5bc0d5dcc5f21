# SPDX-License-Identifier: GPL-3.0-or-later
"""A uniform grid over triangles, their own acceleration structure beside the strands'
(tracer/grid.py), built in whole-array numpy: every triangle listed in every cell its
bounding box touches, a compact (CSR) list per cell. Cubic cells, about
CELLS_PER_TRIANGLE per triangle: a head of 10^4-10^5 triangles walks a few dozen cells per
ray with a few triangles in each.
"""
import numpy as np

from . import layout
from .grid import Grid, grid_frame

CELLS_PER_TRIANGLE = 2.0


def build_mesh_grid(mesh_set):
    """Grid (tracer.grid.Grid) over the triangles of a tracer.meshes.MeshSet."""
    corners = mesh_set.corners.astype(np.float64)
    tlo, thi = corners.min(axis=1), corners.max(axis=1)
    lo, hi = tlo.min(axis=0), thi.max(axis=0)
    n = len(corners)
    extent = np.maximum(hi - lo, max(float((hi - lo).max()) * 1e-3, 1e-12))
    cells = min(layout.MAX_CELLS, max(1.0, CELLS_PER_TRIANGLE * n))
    h = max(float(np.prod(extent) / cells) ** (1 / 3), float(extent.max()) / layout.MAX_DIM)
    dims = np.minimum(np.maximum(1, np.ceil(extent / h)), layout.MAX_DIM).astype(np.int64)
    lo, cs, dims = grid_frame(lo, hi, None, dims=dims)
    # Each triangle's box in cells, widened by a thousandth of a cell against rounding.
    i0 = np.clip(np.floor((tlo - lo) / cs - 1e-3), 0, dims - 1).astype(np.int64)
    i1 = np.clip(np.floor((thi - lo) / cs + 1e-3), 0, dims - 1).astype(np.int64)
    span = i1 - i0 + 1
    per = np.prod(span, axis=1)
    tri = np.repeat(np.arange(n, dtype=np.int64), per)
    local = np.arange(int(per.sum())) - np.repeat(np.cumsum(per) - per, per)
    sx, sy = span[tri, 0], span[tri, 1]
    x = i0[tri, 0] + local % sx
    y = i0[tri, 1] + (local // sx) % sy
    z = i0[tri, 2] + local // (sx * sy)
    cell = x + dims[0] * (y + dims[1] * z)
    order = np.lexsort((tri, cell))
    count = np.bincount(cell, minlength=int(np.prod(dims))).astype(np.int32)
    start = (np.cumsum(count, dtype=np.int64) - count).astype(np.int32)
    return Grid(lo, cs, dims, start, count, tri[order].astype(np.int32))

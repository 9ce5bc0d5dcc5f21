# SPDX-License-Identifier: GPL-3.0-or-later
"""The scene's grid on the GPU: laid over the scene by the one frame both builds use
(tracer/grid.py: plan_frame), its lists built by the compute passes (tracer/gpu_build.py)
or in numpy (tracer/grid.py), then the cell table uploaded (tracer/layout.py's layout).
"""
import functools
import time

import numpy as np

from hairio import InputError

from . import layout
from .grid import Grid, build_grid, plan_frame
from .gl_state import gpu_builder


def build_scene_grid(scene, buffers, use_gpu, bounds=None):
    """Builds and uploads the grid of `scene` (tracer/strand_upload.py's Scene) with the
    compute passes when `use_gpu` (falling back to numpy for a scene they cannot list),
    else in numpy. `bounds`: column_bounds of the plan's points when the caller has them
    already. Sets scene.grid and the grid's stats; returns the seconds spent uploading."""
    stats = buffers.stats
    t0 = time.perf_counter()
    scene.grid = None
    upload_s = 0.0      # the GPU build uploads only counters (bytes counted in it)
    frame = plan_frame(scene.plan, scene.grid_pad, bounds) if scene.num_cylinders else None
    if use_gpu and scene.num_cylinders:
        scene.grid = _build_gpu(scene, buffers, frame)
    stats.grid_build = "gpu" if scene.grid is not None else "numpy"
    if scene.grid is None:      # the numpy build, or a scene the GPU passes cannot list
        scene.grid = build_grid(scene.cylinders, pad_factor=scene.grid_pad, frame=frame)
        t1 = time.perf_counter()
        buffers.upload("tex_idx", scene.grid.indices, 1, "i4", slack=layout.IDX_SLACK)
        upload_s = time.perf_counter() - t1
    g = scene.grid
    t2 = time.perf_counter()
    # An empty cell's start is unused; EMPTY_BLOCK there says its whole block of BLOCK³
    # cells is empty, so the DDA learns "skip the block" from the one texel it reads per cell.
    nx, ny, nz = (int(x) for x in g.dims)
    B = layout.BLOCK
    occupied = block_occupancy(g).astype(bool)
    in_full_block = occupied.repeat(B, 0).repeat(B, 1).repeat(B, 2)[:nz, :ny, :nx].ravel()
    buffers.upload("tex_cell", layout.cell_table(g.cell_start, g.cell_count, in_full_block), 2, "i4")
    t3 = time.perf_counter()
    stats.grid_s = (t3 - t0) - upload_s - (t3 - t2)
    stats.grid_dims = tuple(int(x) for x in g.dims)
    stats.grid_refs = grid_refs(g)
    stats.cylinders_per_full_cell, stats.full_cell_fraction = g.occupancy()
    return upload_s + (t3 - t2)


def grid_refs(grid):
    return int(grid.cell_count.sum(dtype=np.int64))


def _build_gpu(scene, buffers, frame):
    """Grid with indices None, or None when a cylinder spans more cells than one
    invocation may list (the caller builds in numpy)."""
    lo, cs, dims = frame
    pad = scene.grid_pad
    builder = gpu_builder()
    n, tex_cyl = scene.num_cylinders, buffers["tex_cyl"]
    counted = builder.count(n, tex_cyl, lo, cs, dims, pad)
    if counted is None:
        return None
    counts, cells = counted
    start = np.cumsum(counts, dtype=np.int64)
    total = int(start[-1])
    start = (start - counts).astype(np.int32)      # fewer than 2^31: a buffer holds them
    try:
        tex_idx = buffers.store("tex_idx", total + layout.IDX_SLACK, 1, "i4")
    except InputError:
        cells.release()
        raise
    builder.fill(n, tex_cyl, lo, cs, dims, pad, cells, start, tex_idx)
    tex_idx.write(np.zeros(layout.IDX_SLACK, np.int32), first=total)
    # Counted as uploads: the zeroed counters, the cursors the two passes start from and
    # the slack after the lists.
    buffers.stats.bytes_uploaded += 2 * counts.size * 4 + layout.IDX_SLACK * 4
    return Grid(lo, cs, dims, start, counts, None)


def grid_indices(grid, buffers):
    """The grid's cell lists as int32 (read back from the GPU when built there)."""
    if grid.indices is not None:
        return grid.indices
    return np.frombuffer(buffers["tex_idx"].read(grid_refs(grid)), np.int32).copy()


def block_occupancy(grid):
    """(Bz, By, Bx) uint8: 1 where a block of BLOCK³ cells holds any cylinder."""
    B = layout.BLOCK
    nx, ny, nz = (int(x) for x in grid.dims)
    bx, by, bz = (-(-d // B) for d in (nx, ny, nz))
    full = np.zeros((bz * B, by * B, bx * B), bool)
    full[:nz, :ny, :nx] = (grid.cell_count > 0).reshape(nz, ny, nx)
    # One axis at a time, OR-ing the B strided slices, not any() over the 6-D view
    # (docs/DECISIONS.md, "The empty-block map by strided ORs").
    for axis in (2, 1, 0):
        parts = [full[(slice(None),) * axis + (slice(k, None, B),)] for k in range(B)]
        full = functools.reduce(np.logical_or, parts)
    return full.astype(np.uint8)

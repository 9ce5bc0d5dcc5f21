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
from .grid import CAPACITY_SHARE, Grid, build_grid, plan_frame, refs_per_cylinder
from .gl_state import gpu_builder
from .scene_buffers import SplitBuffer


def build_scene_grid(scene, buffers, use_gpu, bounds=None):
    """Builds and uploads the grid of `scene` (tracer/strand_upload.py's Scene) with the
    compute passes when `use_gpu` (falling back to numpy for a scene they cannot list),
    else in numpy. `bounds`: column_bounds of the plan's points when the caller has them
    already. Sets scene.grid and the grid's stats (the pixel sampler's wide grid, built from
    the old cylinders, goes); returns the seconds spent uploading. The resolution aims at
    scene.grid_aim references per cylinder where that is set (tracer/grid.py,
    refs_per_cylinder)."""
    stats = buffers.stats
    t0 = time.perf_counter()
    scene.grid = scene.wide_grid = None
    built = None
    while built is None:
        try:
            built = _build(scene, buffers, use_gpu, bounds, scene.grid_pad, MAIN)
        except ListsTooLong as e:
            if not scene.grid_aim:
                raise
            # The finer lists of a render of many rays (scene.grid_aim) outgrew the buffers,
            # which the estimate of their length allows for: once more at the aim that
            # length says fits, then the one-sample grid, and these strands never aim as
            # high again.
            fits = scene.grid_aim * CAPACITY_SHARE * e.capacity / max(e.total, 1)
            retry = not scene.grid_aim_failed and fits > refs_per_cylinder(scene.num_cylinders)
            scene.grid_aim_failed, scene.grid_aim = scene.grid_aim, (fits if retry else 0.0)
    scene.grid, stats.grid_build, upload_s, table_s = built
    g = scene.grid
    stats.grid_s = (time.perf_counter() - t0) - upload_s - table_s
    stats.grid_dims = tuple(int(x) for x in g.dims)
    stats.grid_refs = grid_refs(g)
    stats.cylinders_per_full_cell, stats.full_cell_fraction = g.occupancy()
    return upload_s + table_s


def build_wide_grid(scene, buffers, use_gpu, pad):
    """The pixel sampler's grid of `scene` beside its own (buffers WIDE): every cylinder
    listed where its capsule widened `pad` times reaches, so the cells of a pixel's central
    ray list what its samples hit (shaders/accel_grid.glsl, accel_pixel_nearest). Shadow
    rays and the other samplers keep walking the scene's grid, whose shorter lists they
    test faster. Sets scene.wide_grid; InputError when its lists outgrow one buffer texture
    (the caller then pads the scene's grid instead)."""
    scene.wide_grid = None
    scene.wide_grid = _build(scene, buffers, use_gpu, None, pad, WIDE)[0]
    return scene.wide_grid


# The buffers of the scene's grid (its lists may be split: tracer/scene_buffers.py) and of
# the pixel sampler's wide grid (one buffer texture each).
MAIN = ("tex_idx", "tex_cell")
WIDE = ("tex_idx_w", "tex_cell_w")


def _build(scene, buffers, use_gpu, bounds, pad, names):
    """(Grid, where it was built: "gpu" or "numpy", seconds uploading its lists, seconds
    making and uploading its cell table) of the scene's cylinders bounded `pad` times their radius,
    into buffers `names` (MAIN or WIDE)."""
    grid, upload_s = None, 0.0      # the GPU build uploads only counters (bytes counted in it)
    aim = (scene.grid_aim or None) if names == MAIN else None
    frame = plan_frame(scene.plan, pad, bounds, max_refs=aim) if scene.num_cylinders else None
    if use_gpu and scene.num_cylinders:
        grid = _build_gpu(scene, buffers, frame, pad, names[0])
    build = "gpu" if grid is not None else "numpy"
    if grid is None:      # the numpy build, or a scene the GPU passes cannot list
        grid = build_grid(scene.cylinders, pad_factor=pad, frame=frame)
        t1 = time.perf_counter()
        try:
            buffers.upload(names[0], grid.indices, 1, "i4", slack=layout.IDX_SLACK)
        except InputError as e:
            raise ListsTooLong(str(e), len(grid.indices), lists_capacity(buffers, names[0])) from None
        upload_s = time.perf_counter() - t1
    t2 = time.perf_counter()
    # An empty cell's start is unused; EMPTY_BLOCK there says its whole block of BLOCK³
    # cells is empty, so the DDA learns "skip the block" from the one texel it reads per cell.
    nx, ny, nz = (int(x) for x in grid.dims)
    B = layout.BLOCK
    occupied = block_occupancy(grid).astype(bool)
    in_full_block = occupied.repeat(B, 0).repeat(B, 1).repeat(B, 2)[:nz, :ny, :nx].ravel()
    try:
        buffers.upload(names[1], layout.cell_table(grid.cell_start, grid.cell_count, in_full_block), 2, "i4")
    except InputError as e:     # a table of more cells than one buffer holds: fewer, as for lists
        raise ListsTooLong(str(e), grid.num_cells, buffers.max_texels) from None
    return grid, build, upload_s, time.perf_counter() - t2


class ListsTooLong(InputError):
    """A grid's lists (`total` references) outgrew what their buffers hold (`capacity`), or
    its cell table (`total` cells) one buffer."""

    def __init__(self, message, total, capacity):
        super().__init__(message)
        self.total, self.capacity = int(total), int(capacity)


def lists_capacity(buffers, name):
    """References the lists' buffer `name` may hold: four parts for the scene's, one for the
    pixel sampler's wide grid."""
    parts = layout.MAX_BUFFER_PARTS if name == MAIN[0] else 1
    return parts * buffers.part_size(MAIN[0]) - layout.IDX_SLACK


def grid_refs(grid):
    return int(grid.cell_count.sum(dtype=np.int64))


def _build_gpu(scene, buffers, frame, pad, name):
    """Grid with indices None, its lists in buffer `name`, or None when a cylinder spans
    more cells than one invocation may list (the caller builds in numpy)."""
    lo, cs, dims = frame
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
        tex_idx = buffers.store(name, total + layout.IDX_SLACK, 1, "i4")
    except InputError as e:
        cells.release()
        raise ListsTooLong(str(e), total, lists_capacity(buffers, name)) from None
    if not isinstance(tex_idx, SplitBuffer):        # the wide grid's one buffer
        tex_idx = SplitBuffer([tex_idx], buffers.part_texels("tex_idx"))
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

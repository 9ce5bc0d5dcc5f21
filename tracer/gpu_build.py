# SPDX-License-Identifier: GPL-3.0-or-later
"""Cylinders and grid built on the GPU with compute shaders (GL 4.3+).

The host uploads the strand points once (32 bytes a point, half of the 64 a cylinder takes)
and a cylinder -> point index; one compute pass writes the cylinder buffer the trace shader
reads, two more count and fill the grid's cell lists straight into the index buffer. No
cylinder or list goes through Python.

Both builds follow the numpy ones rule for rule (tracer/cylinders.py, tracer/grid.py), so the
reference tracer, which uses the numpy cylinders, traces the same scene; what differs is the
order of a cell's list (atomics), which the trace shader makes irrelevant by ordering hits
of equal distance by cylinder id. Drivers without compute shaders (macOS stops at GL 4.1)
use the numpy builds.
"""
import math

import numpy as np

from . import layout
from .gl_buffers import storage_limits
from .shader_source import shader_source

MAX_GROUPS = 65535          # per dispatch dimension, the minimum GL guarantees


def compute_available(ctx):
    return ctx.version_code >= 430


def _groups(n):
    g = max(1, -(-n // layout.GROUP))
    gy = -(-g // MAX_GROUPS)
    return -(-g // gy), gy


def set_uniforms(prog, **values):
    """Sets the uniforms of `prog` that it has: the GLSL compiler drops those a variant or
    pass does not use (the renderer's trace shader uses this too)."""
    for name, value in values.items():
        if name in prog:
            prog[name].value = value


class GpuBuilder:
    """Compute passes of one context: make_cylinders, count, fill. The passes are compiled
    with the header of tracer/layout.py as it is when they run (one set per header)."""

    def __init__(self, ctx):
        self.ctx = ctx
        self._passes = {}

    def _program(self, name, **defines):
        """The pass of file `name` with `defines`, for the current layout (the grid's after the
        files it shares with the beams' passes)."""
        key = (layout.glsl_header(), name, tuple(sorted(defines.items())))
        prog = self._passes.get(key)
        if prog is None:
            files = ["build_cylinders.glsl", "capsule.glsl", name] if name == "grid_build.glsl" else [name]
            prog = self._passes[key] = self.ctx.compute_shader(shader_source(430, files, defines))
        return prog

    @property
    def _cyl(self):
        return self._program("cylinders_build.glsl")

    def _grid(self, pass_, tex_cyl, tex_idx=None):
        """The grid pass `pass_` (0 count, 1 fill) for buffers split into these parts."""
        return self._program("grid_build.glsl", PASS=pass_, CYL_PARTS=len(tex_cyl.parts),
                             IDX_PARTS=1 if tex_idx is None else len(tex_idx.parts))

    def make_cylinders(self, store, n_cyl, repeat_distance=0.0, first=0, count=None):
        """Writes cylinders first..first+count (all by default) into store["tex_cyl"] from the
        point buffers store["tex_pos"], "tex_rad", "tex_col", "tex_alpha" and the cylinder ->
        top point index store["tex_cp"] (tracer.gl_buffers.BufferTexture each). Returns the
        top points of the cylinders whose points lie within `repeat_distance` (not checked
        when 0), or None when there are more than layout.MAX_REPEATS of them."""
        count = n_cyl - first if count is None else count
        if count <= 0:
            return np.zeros(0, np.int64)
        prog = self._cyl
        for unit, name in enumerate(("tex_pos", "tex_rad", "tex_col", "tex_alpha", "tex_cp")):
            store[name].use(unit)       # the shader's layout(binding = unit)
        repeats = self.ctx.buffer(reserve=4 * (layout.MAX_REPEATS + 1))
        repeats.clear()
        repeats.bind_to_storage_buffer(1)
        # A dispatch per range of the cylinder buffer bound as a storage buffer: within one
        # part (one below the driver's texel limit, tracer/scene_buffers.py) and within the
        # driver's block size, from an offset it aligns.
        per = store.part_size("tex_cyl")
        size = 16 * layout.TEXELS_PER_CYL
        most, align = storage_limits(self.ctx)
        step = math.lcm(size, align) // size            # cylinders between aligned offsets
        span = max(most // size // step * step, step)   # cylinders one binding holds
        for k, part in enumerate(store["tex_cyl"].parts):
            a, end = max(first, k * per), min(first + count, (k + 1) * per)
            while a < end:
                start = k * per + (a - k * per) // step * step
                b = min(end, start + span)
                set_uniforms(prog, n_items=int(b - a), first_item=int(a), n_cyl=int(n_cyl), out_first=int(start),
                             repeat2=float(repeat_distance) ** 2 if repeat_distance > 0 else -1.0)
                part.buffer.bind_to_storage_buffer(0, offset=(start - k * per) * size, size=(b - start) * size)
                prog.run(*_groups(b - a))
                a = b
        self.ctx.memory_barrier()
        n_found = int(np.frombuffer(repeats.read(size=4), np.int32)[0])
        found = None
        if n_found == 0:
            found = np.zeros(0, np.int64)
        elif n_found <= layout.MAX_REPEATS:
            found = np.sort(np.frombuffer(repeats.read(size=4 * n_found, offset=4), np.int32)).astype(np.int64)
        repeats.release()
        return found

    def _bind_grid(self, prog, n, tex_cyl, lo, cs, dims, pad_factor, tex_idx=None):
        for unit, part in enumerate(tex_cyl.parts):
            part.use(unit)
        set_uniforms(prog, n_items=int(n), grid_lo=tuple(float(x) for x in lo),
                     inv_cell=tuple(float(1.0 / x) for x in cs), dims=tuple(int(x) for x in dims),
                     pad_factor=float(pad_factor), cyl_split=tex_cyl.part_texels // layout.TEXELS_PER_CYL,
                     idx_split=0 if tex_idx is None else tex_idx.part_texels)

    def count(self, n, tex_cyl, lo, cs, dims, pad_factor):
        """(references per cell, flat int32 in cell-id order; the storage buffer holding
        them, for fill), or None when some cylinder spans too many cells for one invocation
        (the caller then builds in numpy). `tex_cyl`: the cylinders
        (tracer.scene_buffers.SplitBuffer)."""
        ctx = self.ctx
        ncell = int(np.prod(dims))
        cells = ctx.buffer(reserve=4 * ncell)
        cells.clear()
        overflow = ctx.buffer(reserve=4)
        overflow.clear()
        prog = self._grid(0, tex_cyl)
        self._bind_grid(prog, n, tex_cyl, lo, cs, dims, pad_factor)
        cells.bind_to_storage_buffer(0)
        overflow.bind_to_storage_buffer(1)
        prog.run(*_groups(n))
        ctx.memory_barrier()
        over = int(np.frombuffer(overflow.read(), np.int32)[0])
        overflow.release()
        if over:
            cells.release()
            return None
        return np.frombuffer(cells.read(), np.int32).copy(), cells

    def fill(self, n, tex_cyl, lo, cs, dims, pad_factor, cells, start, tex_idx):
        """Writes every cell's list into `tex_idx` (int32, a tracer.scene_buffers.SplitBuffer)
        from the cell's `start` on; `cells` (from count) becomes the cursors and is released."""
        cells.write(np.ascontiguousarray(start, np.int32))
        prog = self._grid(1, tex_cyl, tex_idx)
        self._bind_grid(prog, n, tex_cyl, lo, cs, dims, pad_factor, tex_idx)
        cells.bind_to_storage_buffer(0)
        tex_idx.bind_to_image(1, write=True)
        prog.run(*_groups(n))
        self.ctx.memory_barrier()
        cells.release()

# SPDX-License-Identifier: GPL-3.0-or-later
"""The GPU tracer: one standalone OpenGL 3.3 core context per process (EGL or GLX on Linux,
WGL on Windows, CGL on macOS: tracer/gl_context.py), scene data in buffer textures
(tracer/gl_buffers.py), one fragment shader that traces every pixel.

Only `set_strands`/`update_strands` upload; a render with a new camera, light or setting
sends uniforms and nothing else (`stats["bytes_uploaded"]` proves it).
"""
import functools
import pathlib
import time

import numpy as np

from hairio import InputError, Strands
from hairio.validate import check_memory
from .cylinders import (SHARP_BEND_DEG, CylinderPlan, column_bounds, cylinders_from_plan, plan_cylinders,
                        repeat_distance, strands_to_cylinders)
from .bvh import WALK_TEXELS, build_bvh, refit_bvh, walk_texels
from .grid import Grid, build_grid, grid_frame
from .gl_buffers import BufferTexture, set_samplers
from .gl_context import create_context
from .gpu_build import GpuBuilder, compute_available, set_uniforms
from .settings import GRID_WIDEN_CAP, RenderSettings

BLOCK = 4          # cells per side of the empty-space-skipping blocks (the shader's BLOCK)
# Per cylinder, four consecutive RGBA32F texels of one buffer (top+radius, tip+alpha,
# n2+flags, colour): 64 bytes, one cache line, so a cylinder test on a CPU driver touches
# one line where four textures took up to four. The shader's cyl() agrees.
TEXELS_PER_CYL = 4
# Partial uploads send the changed strands' data in whole chunks of this many cylinders or
# points, neighbouring chunks in one write: thousands of scattered strands would otherwise
# mean thousands of small writes, which cost more than the data.
UPLOAD_CHUNK = 1024
# The trace shader reads up to two list entries past a cell's list (it reads ahead); the
# index buffer carries this many zeros after the last list.
IDX_SLACK = 2
# The shader squares distances in float32 (3.4e38 = (1.8e19)^2): past these a hit's
# arithmetic overflows and the image comes out empty while the float64 reference shows
# hair (a strand 1e20 from the origin did). Points within 1e18 seen from a camera within
# 1e19 keep every squared distance finite (measured: hair at 1e18 and cameras out to 3e19
# render as the reference does).
MAX_POINT_COORDINATE = 1e18
MAX_CAMERA_COORDINATE = 1e19
# Host memory of one render: the framebuffer (a driver like llvmpipe keeps it in host memory),
# its read-back bytes and the flipped image, RGBA float32 each.
RENDER_COPIES = 3
SHADER_DIR = pathlib.Path(__file__).resolve().parent / "shaders"

_VERTEX = """#version 330 core
void main() {   // one triangle that covers the screen; the scissor picks the pixels
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
"""

_CONTEXT = None
_BACKEND = None
_BUILDER = None
BUILDS = ("auto", "gpu", "numpy")
# The acceleration structures the trace shader can walk: a BVH over cylinders (tracer/bvh.py)
# or the thesis's uniform grid (tracer/grid.py). Same hits, same image; the default is the one
# that measured faster on typical scenes (benchmarks/sections/accel.py): on llvmpipe the grid,
# 1.9x faster than the BVH on 10,000 wavy strands.
ACCELS = ("bvh", "grid")
DEFAULT_ACCEL = "grid"
# Partial BVH uploads: the walk's texels in chunks of this many entries (see UPLOAD_CHUNK).
NODE_CHUNK = 256


def shared_context():
    """The process's one standalone OpenGL context (created on first use by the backend
    KEYSTRAND_GL_BACKEND asks for; tracer/gl_context.py)."""
    global _CONTEXT, _BACKEND
    if _CONTEXT is None:
        _CONTEXT, _BACKEND = create_context()
    return _CONTEXT


def context_backend():
    """The backend of the shared context ("egl", "glx", "wgl" or "cgl"), creating it first."""
    shared_context()
    return _BACKEND


def load_shader(name):
    return (SHADER_DIR / name).read_text()


def shader_source(name):
    """A shader with its `#include "file"` lines replaced by those files (GLSL 3.3 has no
    include of its own); an included part's #if around the line still decides."""
    out = []
    for line in load_shader(name).splitlines(keepends=True):
        s = line.strip()
        if s.startswith("#include"):
            out.append(shader_source(s.split('"')[1]))
        else:
            out.append(line)
    return "".join(out)


def gpu_builder():
    """The compute passes of the shared context (compiled on first use)."""
    global _BUILDER
    if _BUILDER is None:
        _BUILDER = GpuBuilder(shared_context(), load_shader)
    return _BUILDER


class Renderer:
    """GPU tracer of one scene at a time.

    `stats` (a dict) after each call: cylinders_s, upload_s, grid_s (last set/update),
    render_s, renders, bytes_uploaded and uploads (cumulative: unchanged by renders),
    num_cylinders, grid_dims, grid_refs, cylinders_per_full_cell, full_cell_fraction,
    layers_max (layers the shader was compiled for), screen_box and traversed_pixels (the
    projected bounds that were traced), and with RenderSettings(count=True) also
    shadow_rays, layers_traced, cells_visited, cylinder_tests (summed over samples), and
    gl_backend (the shared context's: egl, glx, wgl or cgl)."""

    def __init__(self, max_buffer_texels=None, build="auto", accel=DEFAULT_ACCEL):
        """`max_buffer_texels`: the most texels one buffer texture may hold (default: the
        driver's GL_MAX_TEXTURE_BUFFER_SIZE, 2^27 on llvmpipe and current desktop GPUs, i.e.
        33 M cylinders or 134 M grid references); scenes past it get an InputError.
        `build`: where cylinders and grid are made — "gpu" (compute shaders, GL 4.3+),
        "numpy", or "auto" (the GPU where the driver has compute shaders).
        `accel`: what rays walk — "bvh" (tracer/bvh.py) or "grid" (tracer/grid.py)."""
        self.ctx = shared_context()
        self.max_buffer_texels = int(max_buffer_texels or self.ctx.info["GL_MAX_TEXTURE_BUFFER_SIZE"])
        if build not in BUILDS:
            raise InputError(f"build: expected one of {', '.join(BUILDS)}, got {build!r}")
        if build == "gpu" and not compute_available(self.ctx):
            raise InputError(f"build: 'gpu' needs compute shaders (OpenGL 4.3); this driver offers "
                             f"{self.ctx.info['GL_VERSION']}; use 'numpy' or 'auto'")
        self.build = "numpy" if build == "numpy" or not compute_available(self.ctx) else "gpu"
        if accel not in ACCELS:
            raise InputError(f"accel: expected one of {', '.join(ACCELS)}, got {accel!r}")
        self.accel = accel
        self.bvh = None
        self._programs = {}
        self._fbos = {}
        self._tex = {}       # name -> BufferTexture: tex_cyl, tex_idx, tex_cell (+ points for the GPU build)
        self._cylinders = None
        self._plan = None
        self.num_cylinders = None     # None until set_strands
        self.grid = None
        self.strands = None
        self.all_opaque = True
        # The grid lists cylinders with their true radius until a render asks for minimum
        # pixel width; then it is rebuilt once with radii widened by GRID_WIDEN_CAP and kept.
        self._grid_pad = 1.0
        self.stats = {"bytes_uploaded": 0, "uploads": 0, "upload_s": 0.0, "grid_s": 0.0,
                      "render_s": 0.0, "renders": 0, "gl_backend": context_backend()}

    # --- data ---------------------------------------------------------------------------
    @property
    def cylinders(self):
        """The scene's tracer.cylinders.Cylinders. The GPU build never needs them on the CPU,
        so there they are made on first access (for tests and tools), not on upload."""
        if self._cylinders is None and self.strands is not None:
            self._cylinders = strands_to_cylinders(self.strands)
        return self._cylinders

    def set_strands(self, strands):
        """Upload `strands` (hairio.Strands) and build the grid. Strands the tracer cannot
        resolve are refused before anything changes; when the upload itself fails (a scene
        too large for the driver's buffers), the renderer holds no scene afterwards: a
        render says so instead of tracing half of one."""
        if not isinstance(strands, Strands):
            raise InputError(f"strands: expected hairio.Strands, got {type(strands).__name__}; "
                             "build one with Strands.from_arrays")
        t0 = time.perf_counter()
        check_gpu_range(strands)
        # The GPU build checks for repeated points itself while it makes the cylinders.
        plan = plan_cylinders(strands, drop_repeats=self.build != "gpu")
        try:
            self._set_strands(strands, plan, t0)
        except Exception:
            self._forget_scene()
            raise

    def _forget_scene(self):
        self.strands = self.grid = self.bvh = self._plan = self._cylinders = self.num_cylinders = None

    def _set_strands(self, strands, plan, t0):
        self.strands = strands
        self._cylinders = None
        self._plan = plan
        self.num_cylinders = len(plan)
        if self.build == "gpu" and len(plan):
            t1 = time.perf_counter()
            self._upload_points(plan)
            t2 = time.perf_counter()
            # Twice the numpy build's distance: float32 rounding on the GPU cannot hide a
            # repeat, and plan_cylinders checks the candidates by the numpy rule.
            bounds = column_bounds(plan.points)     # the grid box needs them too
            repeats = self._make_cylinders_gpu(2.0 * repeat_distance(plan.points, bounds))
            if repeats is None or len(repeats):
                # Some points may repeat their predecessor: drop them as the numpy build does.
                self._plan = plan = plan_cylinders(strands, candidates=repeats)
                self.num_cylinders = len(plan)
                bounds = None       # fewer points: the grid takes their bounds again
                t1b = time.perf_counter()
                self._upload_points(plan)
                t2 += time.perf_counter() - t1b
                self._make_cylinders_gpu(0.0)
            self.stats["uploads"] += 1
            self._set_all_opaque(plan)
            t3 = time.perf_counter()
            self._build_and_upload_accel(bounds)
            self.stats["cylinders_s"] = (t1 - t0) + (t3 - t2)
            self.stats["upload_s"] = (t2 - t1) + self.stats.pop("_grid_upload_s")
        else:
            self._cylinders = cylinders_from_plan(plan)
            self._set_all_opaque(plan)
            t1 = time.perf_counter()
            self.stats["uploads"] += 1
            self._upload_cylinders(0, len(self._cylinders), full=True)
            t2 = time.perf_counter()
            self._build_and_upload_accel()
            self.stats["cylinders_s"] = t1 - t0
            self.stats["upload_s"] = t2 - t1 + self.stats.pop("_grid_upload_s")
        self.stats["num_cylinders"] = self.num_cylinders

    def update_strands(self, strand_ids, strands):
        """`strands` is the whole new set; only strands `strand_ids` changed. When their point
        counts are unchanged, only their data is re-uploaded (their cylinders with the numpy
        build, their points with the GPU build, which then remakes just their cylinders; in
        chunks of UPLOAD_CHUNK) and the grid is rebuilt; otherwise everything is uploaded
        again. As in set_strands, changed strands the tracer cannot resolve are refused
        before anything changes, and a failed upload leaves no scene."""
        if self.strands is None or not isinstance(strands, Strands) \
                or not np.array_equal(strands.counts, self.strands.counts):
            self.set_strands(strands)
            return
        ids = np.unique(np.asarray(strand_ids, np.int64))
        if ids.size and (ids[0] < 0 or ids[-1] >= strands.num_strands):
            raise InputError(f"strand_ids: values must lie in [0, {strands.num_strands}); got {ids.min()}..{ids.max()}")
        if not ids.size:
            self.strands = strands
            return
        t0 = time.perf_counter()
        changed = _select_strands(strands, ids)
        check_gpu_range(changed)
        sub = plan_cylinders(changed)
        if not np.array_equal(sub.counts, self._plan.counts[ids]):
            self.set_strands(strands)    # a repeated point appeared or vanished
            return
        # The same points per strand are left: point and cylinder numbering are unchanged.
        try:
            if self.build == "gpu" and self.num_cylinders:
                self._update_strands_gpu(ids, strands, sub, t0)
            else:
                self._update_strands_numpy(ids, strands, sub, t0)
        except Exception:
            self._forget_scene()
            raise

    def _update_strands_numpy(self, ids, strands, sub, t0):
        new = cylinders_from_plan(sub)
        old = self.cylinders
        per_strand_old = np.bincount(old.strand, minlength=strands.num_strands)
        first_old = np.concatenate([[0], np.cumsum(per_strand_old)])
        per_new = np.bincount(new.strand, minlength=len(ids))
        # Positions of the changed cylinders in the full arrays.
        dest = np.repeat(first_old[ids], per_new) + _ranks(per_new)
        for f in ("top", "tip", "n2", "radius", "color", "alpha", "flags", "extension"):
            getattr(old, f)[dest] = getattr(new, f)
        self.strands = strands
        self.all_opaque = bool(len(old) == 0 or old.alpha.min() >= 1.0)
        t1 = time.perf_counter()
        self.stats["uploads"] += 1
        per = UPLOAD_CHUNK
        for a, b in _runs(dest // per):
            self._upload_cylinders(a * per, min(len(old), b * per))
        t2 = time.perf_counter()
        self._build_and_upload_accel(refit=True)
        self.stats["cylinders_s"] = t1 - t0
        self.stats["upload_s"] = t2 - t1 + self.stats.pop("_grid_upload_s")

    def _update_strands_gpu(self, ids, strands, sub, t0):
        old = self._plan
        first_point = np.concatenate([[0], np.cumsum(old.counts)])
        if len(old.points) == strands.num_points:      # nothing dropped: the arrays as they are
            self._plan = CylinderPlan(strands.points, strands.radius, strands.color, strands.alpha,
                                      None, old.counts, old.top_point)
        else:       # the plan holds its own copies: write the changed strands into them
            dest = np.repeat(first_point[ids], sub.counts) + _ranks(sub.counts)
            for f in ("points", "radius", "color", "alpha"):
                getattr(old, f)[dest] = getattr(sub, f)
        self.strands = strands
        self._cylinders = None
        self._set_all_opaque(self._plan)
        counts = self._plan.counts.astype(np.int64)
        per_strand = np.maximum(counts - 1, 0)
        t1 = time.perf_counter()
        # The chunks of points that hold the changed strands' points (see UPLOAD_CHUNK).
        w = UPLOAD_CHUNK
        point_first = first_point[ids]
        ends = point_first + counts[ids]
        r0, r1 = point_first // w, (ends - 1) // w
        chunks = np.repeat(r0, r1 - r0 + 1) + _ranks(r1 - r0 + 1)
        n_points = len(self._plan.points)
        self.stats["uploads"] += 1
        for a, b in _runs(chunks):
            self._upload_points(self._plan, a * w, min(n_points, b * w))
        t2 = time.perf_counter()
        # One dispatch from the first changed cylinder to the last: the unchanged ones between
        # are made again from unchanged points (same texels), which costs the GPU less than a
        # dispatch per run of changed strands.
        cyl_first = np.concatenate([[0], np.cumsum(per_strand)])
        first, last = int(cyl_first[ids[0]]), int(cyl_first[ids[-1] + 1])
        self._make_cylinders_gpu(0.0, first, last - first)
        t3 = time.perf_counter()
        self._build_and_upload_accel(refit=True)
        self.stats["cylinders_s"] = (t1 - t0) + (t3 - t2)
        self.stats["upload_s"] = (t2 - t1) + self.stats.pop("_grid_upload_s")

    def _set_all_opaque(self, plan):
        self.all_opaque = bool(len(plan) == 0 or plan.alpha[plan.top_point].min() >= 1.0)

    _POINT_TEXTURES = (("tex_pos", "points", 3), ("tex_rad", "radius", 1), ("tex_col", "color", 3),
                       ("tex_alpha", "alpha", 1))

    def _upload_points(self, plan, a=None, b=None):
        """Points a..b (all by default): the plan's arrays as they are, one buffer each; the
        full upload also sends the cylinder -> top point index."""
        if a is None:
            a, b = 0, len(plan.points)
            for name, field, comps in self._POINT_TEXTURES:
                self._store(name, b, comps, "f4")
            self._upload("tex_cp", plan.top_point.astype(np.int32), 1, "i4")
        for name, field, _ in self._POINT_TEXTURES:
            chunk = np.ascontiguousarray(getattr(plan, field)[a:b], np.float32)
            self._tex[name].write(chunk, first=a)
            self.stats["bytes_uploaded"] += chunk.nbytes

    def _make_cylinders_gpu(self, repeat_dist, first=0, count=None):
        """Makes cylinders first..first+count (all, into a fresh buffer, by default); returns
        the top points of those that may join repeated points (checked when repeat_dist > 0;
        None: too many to list)."""
        n = self.num_cylinders
        if count is None:
            self._store("tex_cyl", n * TEXELS_PER_CYL, 4, "f4")
        return gpu_builder().make_cylinders(self._tex, n, repeat_dist, first, count)

    def _store(self, name, texels, components, dtype):
        """The buffer texture `name` with room for `texels`: the one already there when it
        fits and is not much bigger (allocating hundreds of MB costs as much as filling them
        on a CPU driver), else a new one with a little room to spare, so that a rebuild with
        a few more grid references reuses it. InputError past the driver's limit."""
        if texels > self.max_buffer_texels:
            raise InputError(f"scene too large for this GPU: {name} needs {texels:,} texels but the driver's "
                             f"buffer textures hold {self.max_buffer_texels:,}; render fewer strands or fewer "
                             "points per strand")
        old = self._tex.get(name)
        if old is not None and old.fits(texels, components, dtype) and old.capacity <= 2 * texels + (1 << 16):
            return old
        if old is not None:
            old.release()
        capacity = min(self.max_buffer_texels, texels + texels // 64 + 64)
        store = BufferTexture(self.ctx, capacity, components, dtype)
        self._tex[name] = store
        return store

    def _upload(self, name, data, components, dtype, slack=0):
        """`data` (texels x components) into buffer `name`, followed by `slack` zero texels."""
        data = np.ascontiguousarray(data, np.float32 if dtype == "f4" else np.int32)
        texels = len(data)
        store = self._store(name, texels + slack, components, dtype)
        store.write(data)
        if slack:
            store.write(np.zeros(slack * components, data.dtype), first=texels)
        self.stats["bytes_uploaded"] += data.nbytes
        return store

    def _cylinder_texels(self, a, b):
        """Cylinders a..b as RGBA float32 texels, TEXELS_PER_CYL per cylinder one after the
        other."""
        c = self.cylinders
        m = b - a
        out = np.zeros((m, TEXELS_PER_CYL, 4), np.float32)
        out[:, 0, :3], out[:, 0, 3] = c.top[a:b], c.radius[a:b]
        out[:, 1, :3], out[:, 1, 3] = c.tip[a:b], c.alpha[a:b]
        out[:, 2, :3], out[:, 2, 3] = c.n2[a:b], c.flags[a:b]
        out[:, 3, :3] = c.color[a:b]
        return out.reshape(-1, 4)

    def _upload_cylinders(self, a, b, full=False):
        if full:
            self._upload("tex_cyl", self._cylinder_texels(0, len(self.cylinders)), 4, "f4")
        else:
            data = self._cylinder_texels(a, b)
            self._tex["tex_cyl"].write(data, first=a * TEXELS_PER_CYL)
            self.stats["bytes_uploaded"] += data.nbytes

    def _build_and_upload_accel(self, bounds=None, refit=False):
        """The structure of `self.accel` for the current cylinders; `refit`: the cylinders
        moved but kept their ids (update_strands), so a BVH keeps its tree. Sets
        stats["accel_s"] (build or refit time) and the internal "_grid_upload_s"."""
        if self.accel == "grid":
            self.bvh = None
            self._build_and_upload_grid(bounds)
            self.stats["accel_s"] = self.stats["grid_s"]
        else:
            self.grid = None
            self._build_and_upload_bvh(refit)

    def _build_and_upload_bvh(self, refit=False):
        """BVH over the cylinders (numpy, tracer/bvh.py): built anew, or refitted when
        `refit` and one is there; a refit uploads only the chunks of NODE_CHUNK nodes whose
        texels changed (the nodes above the moved cylinders)."""
        t0 = time.perf_counter()
        old = None
        if refit and self.bvh is not None and len(self.bvh.ref_cyl) and self.bvh.ref_cyl[-1] == self.num_cylinders - 1:
            old = walk_texels(self.bvh)
            bvh = refit_bvh(self.bvh, self.cylinders, self._grid_pad)
        else:
            bvh = build_bvh(self.cylinders, self._grid_pad)
        self.bvh = bvh
        texels = walk_texels(bvh)
        self._bvh_entries = len(texels) // WALK_TEXELS
        t1 = time.perf_counter()
        if old is None:
            self._upload("tex_node", texels, 4, "i4")
            self._upload("tex_order", bvh.leaf_texels(), 2, "i4")
        else:
            per = NODE_CHUNK * WALK_TEXELS
            changed = np.flatnonzero(np.any(old != texels, axis=1)) // per
            for a, b in _runs(changed) if changed.size else ():
                chunk = texels[a * per:b * per]
                self._tex["tex_node"].write(chunk, first=a * per)
                self.stats["bytes_uploaded"] += chunk.nbytes
        t2 = time.perf_counter()
        self.stats["bvh_s"] = self.stats["accel_s"] = t1 - t0
        self.stats["_grid_upload_s"] = t2 - t1
        self.stats["bvh_refit"] = old is not None
        self.stats["bvh_nodes"], self.stats["bvh_depth"] = bvh.num_nodes, bvh.depth
        self.stats["accel_bytes"] = bvh.nbytes

    def scene_bounds(self):
        """(lo, hi) float64 (3,) of the structure rays walk (every padded cylinder inside)."""
        if self.grid is not None:
            return self.grid.lo, self.grid.hi
        b = self.bvh
        return (b.lo[0].min(axis=0).astype(np.float64), b.hi[0].max(axis=0).astype(np.float64))

    def _build_and_upload_grid(self, bounds=None):
        """`bounds`: column_bounds of the plan's points when the caller has them already."""
        t0 = time.perf_counter()
        self.grid = None
        upload_s = 0.0      # the GPU build uploads only counters (bytes counted in it)
        if self.build == "gpu" and self.num_cylinders:
            self.grid = self._build_grid_gpu(bounds)
        self.stats["grid_build"] = "gpu" if self.grid is not None else "numpy"
        if self.grid is None:      # the numpy build, or a scene the GPU passes cannot list
            self.grid = build_grid(self.cylinders, pad_factor=self._grid_pad)
            t1 = time.perf_counter()
            self._upload("tex_idx", self.grid.indices, 1, "i4", slack=IDX_SLACK)
            upload_s = time.perf_counter() - t1
        g = self.grid
        t2 = time.perf_counter()
        # An empty cell's start is unused; -1 there says its whole block of BLOCK³ cells is
        # empty, so the DDA learns "skip the block" from the one texel it reads per cell.
        nx, ny, nz = (int(x) for x in g.dims)
        occupied = block_occupancy(g).astype(bool)
        in_full_block = occupied.repeat(BLOCK, 0).repeat(BLOCK, 1).repeat(BLOCK, 2)[:nz, :ny, :nx].ravel()
        cells = np.empty((g.num_cells, 2), np.int32)
        cells[:, 0] = np.where(in_full_block, g.cell_start, -1)
        cells[:, 1] = g.cell_count
        self._upload("tex_cell", cells, 2, "i4")
        t3 = time.perf_counter()
        self.stats["grid_s"] = (t3 - t0) - upload_s - (t3 - t2)
        self.stats["_grid_upload_s"] = upload_s + (t3 - t2)
        self.stats["grid_dims"] = tuple(int(x) for x in g.dims)
        self.stats["grid_refs"] = self._grid_refs
        self.stats["accel_bytes"] = self._grid_refs * 4 + g.num_cells * 8
        self.stats["cylinders_per_full_cell"], self.stats["full_cell_fraction"] = g.occupancy()

    @property
    def _grid_refs(self):
        return int(self.grid.cell_count.sum(dtype=np.int64))

    def _build_grid_gpu(self, bounds=None):
        """Grid with indices None, or None when a cylinder spans more cells than one
        invocation may list (the caller builds in numpy). `bounds`: as _build_and_upload_grid."""
        plan = self._plan
        pad = self._grid_pad
        pts = plan.points
        # Every capsule lies within its points' box widened by its radius times the pad, plus
        # the reach of a bent cylinder past its tip (at most r·tan(SHARP_BEND_DEG), see
        # tracer/cylinders.py): the scene box without per-cylinder work.
        rmax = float(plan.radius.max())
        reach = rmax * (pad + np.tan(np.radians(SHARP_BEND_DEG))) * (1 + 1e-6)
        lo, hi = column_bounds(pts) if bounds is None else bounds
        lo, hi = lo - reach, hi + reach
        # The resolution from a sample of the cylinders' padded boxes, as the numpy build does.
        step = max(1, len(plan) // 20_000 + 1)
        top = plan.top_point[::step]
        a, b = pts[top].astype(np.float64), pts[top + 1].astype(np.float64)
        size = np.abs(b - a) + 2 * pad * plan.radius[top][:, None]
        lo, cs, dims = grid_frame(lo, hi, size, count=len(plan))
        builder = gpu_builder()
        n, tex_cyl = self.num_cylinders, self._tex["tex_cyl"]
        counted = builder.count(n, tex_cyl, lo, cs, dims, pad)
        if counted is None:
            return None
        counts, cells = counted
        start = np.cumsum(counts, dtype=np.int64)
        total = int(start[-1])
        start = (start - counts).astype(np.int32)      # fewer than 2^31: a buffer holds them
        try:
            tex_idx = self._store("tex_idx", total + IDX_SLACK, 1, "i4")
        except InputError:
            cells.release()
            raise
        builder.fill(n, tex_cyl, lo, cs, dims, pad, cells, start, tex_idx)
        tex_idx.write(np.zeros(IDX_SLACK, np.int32), first=total)
        # Counted as uploads: the zeroed counters, the cursors the two passes start from and
        # the slack after the lists.
        self.stats["bytes_uploaded"] += 2 * counts.size * 4 + IDX_SLACK * 4
        return Grid(lo, cs, dims, start, counts, None)

    def grid_indices(self):
        """The grid's cell lists as int32 (read back from the GPU when built there)."""
        if self.grid.indices is not None:
            return self.grid.indices
        return np.frombuffer(self._tex["tex_idx"].read(self._grid_refs), np.int32).copy()

    # --- rendering ----------------------------------------------------------------------
    def _program(self, settings, camera, layers):
        key = (layers, settings.shadows and (1 if settings.shadow_mode == "hard" else 2),
               settings.shading, len(settings.lights), settings.spp_n, settings.min_pixel_width,
               camera.type, settings.count, self.accel)
        prog = self._programs.get(key)
        if prog is None:
            defines = {
                "LAYERS": layers,
                "SHADOWS": int(key[1] or 0),
                "SHADING_KK": int(settings.shading == "kajiya-kay"),
                "NUM_LIGHTS": len(settings.lights),
                "SPP_N": settings.spp_n,
                "MIN_PX": int(settings.min_pixel_width),
                "ORTHO": int(camera.type == "ORTHO"),
                "COUNT": int(settings.count),
                "BLOCK": BLOCK,
                "ACCEL_BVH": int(self.accel == "bvh"),
            }
            head = "#version 330 core\n" + "".join(f"#define {k} {v}\n" for k, v in defines.items())
            prog = self.ctx.program(vertex_shader=_VERTEX, fragment_shader=head + shader_source("trace.glsl"))
            set_samplers(prog, **{name: unit for unit, name in enumerate(self._TRACE_BUFFERS)})
            vao = self.ctx.vertex_array(prog, [])
            prog = (prog, vao)
            self._programs[key] = prog
        return prog

    def effective_layers(self, settings):
        """One layer when every alpha is 1 and nothing lowers it (minimum pixel width does)."""
        if self.all_opaque and not settings.min_pixel_width:
            return 1
        return settings.layers

    def _framebuffer(self, w, h, count):
        key = (w, h, count)
        fbo = self._fbos.get(key)
        if fbo is None:
            import moderngl
            atts = []
            try:
                atts.append(self.ctx.texture((w, h), 4, dtype="f4"))
                if count:
                    atts.append(self.ctx.texture((w, h), 4, dtype="f4"))
                fbo = self.ctx.framebuffer(color_attachments=atts)
            except moderngl.Error as e:
                # Drivers have limits of their own below GL_MAX_TEXTURE_SIZE (llvmpipe refuses
                # a float framebuffer past 2 GiB: 12000² is INCOMPLETE_ATTACHMENT).
                for t in atts:
                    t.release()
                raise InputError(f"camera size {w}x{h}: the GPU driver cannot make a float framebuffer of "
                                 f"{w * h * 16 / 2**30:.2f} GiB ({e}); render a smaller image, or in tiles "
                                 "(python -m tracer render does)") from None
            self._fbos[key] = fbo
        return fbo

    def _check_camera(self, camera, settings):
        """What the GPU cannot draw is refused before the framebuffer is made: a camera so far
        out that squared distances overflow, an image wider than the driver draws, or one
        whose copies need more memory than there is."""
        far = float(np.abs(camera.position).max())
        if not far <= MAX_CAMERA_COORDINATE:
            raise InputError(f"camera: position {far:.3g} from the origin; the GPU tracer squares distances in "
                             f"float32, so it takes cameras within ±{MAX_CAMERA_COORDINATE:.0e}: move it closer "
                             "or scale the scene down")
        w, h = camera.size
        side = min(int(self.ctx.info["GL_MAX_TEXTURE_SIZE"]), *(int(d) for d in self.ctx.info["GL_MAX_VIEWPORT_DIMS"]))
        if max(w, h) > side:
            raise InputError(f"camera size {w}x{h}: this GPU draws at most {side} pixels a side in one image; "
                             "render a larger image in tiles (python -m tracer render does)")
        check_memory(f"camera size {w}x{h}", (RENDER_COPIES + settings.count) * w * h * 16,
                     "render a smaller image, or in tiles (python -m tracer render writes any size band by band)")

    def screen_bounds(self, camera):
        """Pixel rectangle (x0, y0, x1, y1), y from the top, that the grid box can cover;
        None when nothing can be seen."""
        if not self.num_cylinders:
            return None
        lo, hi = self.scene_bounds()
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        w, h = camera.size
        x, y, depth = camera.project(corners)
        if camera.type == "PERSP" and np.any(depth <= 1e-9 * (1 + np.abs(corners).max())):
            return 0, 0, w, h         # the box reaches behind the camera: no projection bound
        if camera.type == "ORTHO" and np.all(depth < 0):
            return None
        x0 = int(np.clip(np.floor(x.min()) - 1, 0, w))
        x1 = int(np.clip(np.ceil(x.max()) + 1, 0, w))
        y0 = int(np.clip(np.floor(y.min()) - 1, 0, h))
        y1 = int(np.clip(np.ceil(y.max()) + 1, 0, h))
        if x0 >= x1 or y0 >= y1:
            return None
        return x0, y0, x1, y1

    def render(self, camera, settings=None):
        """(H, W, 4) float32 linear RGBA, premultiplied, row 0 = top of the image."""
        settings = settings or RenderSettings()
        settings.check()
        if self.num_cylinders is None:
            raise InputError("render: no strands; call set_strands first")
        self._check_camera(camera, settings)
        t0 = time.perf_counter()
        if settings.min_pixel_width and self._grid_pad < GRID_WIDEN_CAP:
            self._grid_pad = GRID_WIDEN_CAP
            self._build_and_upload_accel(refit=True)
            self.stats.pop("_grid_upload_s")
            self.stats["grid_rebuilds"] = self.stats.get("grid_rebuilds", 0) + 1
        w, h = camera.size
        bg = settings.premultiplied_background()
        fbo = self._framebuffer(w, h, settings.count)
        fbo.use()
        self.ctx.scissor = None
        fbo.clear(*bg)
        box = self.screen_bounds(camera)
        layers = self.effective_layers(settings)
        counts = np.zeros(4)
        if box is not None:
            prog, vao = self._program(settings, camera, layers)
            self._set_uniforms(prog, camera, settings)
            import moderngl
            self.ctx.blend_func = moderngl.ONE, moderngl.ONE
            self.ctx.blend_equation = moderngl.FUNC_ADD
            x0, y0, x1, y1 = box
            step = settings.tile
            for ty in range(y0, y1, step):
                for tx in range(x0, x1, step):
                    tw, th = min(step, x1 - tx), min(step, y1 - ty)
                    # GL's window origin is the bottom-left corner.
                    self.ctx.scissor = (tx, h - ty - th, tw, th)
                    # One sample per draw (the shader's main says why): the first replaces the
                    # cleared background, the others add to it (colour and counters alike).
                    for s in range(settings.spp):
                        set_uniforms(prog, sample_index=s)
                        if s == 1:
                            self.ctx.enable(moderngl.BLEND)
                        vao.render(vertices=3)
                    self.ctx.disable(moderngl.BLEND)
                    if (x1 - x0) * (y1 - y0) > step * step:
                        self.ctx.finish()
            self.ctx.scissor = None
            if settings.count:
                raw = fbo.read(viewport=(x0, h - y1, x1 - x0, y1 - y0), components=4, dtype="f4", attachment=1)
                counts = np.frombuffer(raw, np.float32).reshape(-1, 4).sum(axis=0, dtype=np.float64)
        raw = fbo.read(components=4, dtype="f4", attachment=0)
        img = np.frombuffer(raw, np.float32).reshape(h, w, 4)[::-1].copy()
        dt = time.perf_counter() - t0
        self.stats.update(render_s=dt, renders=self.stats["renders"] + 1, layers_max=layers,
                          screen_box=box,
                          traversed_pixels=0 if box is None else (box[2] - box[0]) * (box[3] - box[1]))
        if settings.count:
            self.stats.update(shadow_rays=int(counts[0]), layers_traced=int(counts[1]),
                              cells_visited=int(counts[2]), cylinder_tests=int(counts[3]))
        return img

    # On texture units 0, 1, ...: the grid's or the BVH's buffers after the cylinders.
    _TRACE_BUFFERS = ("tex_cyl", "tex_idx", "tex_cell", "tex_node", "tex_order")

    def _set_uniforms(self, prog, camera, settings):
        g = self.grid
        used = ("tex_cyl", "tex_idx", "tex_cell") if g is not None else ("tex_cyl", "tex_node", "tex_order")
        for name in used:
            self._tex[name].use(self._TRACE_BUFFERS.index(name))
        if g is not None:
            set_uniforms(prog, grid_lo=tuple(float(x) for x in g.lo),
                         cell_size=tuple(float(x) for x in g.cell_size),
                         dims=tuple(int(x) for x in g.dims))
        else:
            set_uniforms(prog, bvh_nodes=int(self._bvh_entries))
        set_uniforms(prog, cam_pos=tuple(float(x) for x in camera.position),
                     cam_rot=tuple(float(x) for x in camera.rotation.T.ravel()),
                     pixel_size=float(camera.pixel_size),
                     shift_px=tuple(float(x) for x in camera.shift_px),
                     image_size=(float(camera.size[0]), float(camera.size[1])))
        packed = [light.packed() for light in settings.lights]
        if "light_vec" in prog:
            prog["light_vec"].write(np.array([p[0] for p in packed], np.float32).tobytes())
        if "light_col" in prog:
            prog["light_col"].write(np.array([p[1] for p in packed], np.float32).tobytes())
        set_uniforms(prog, background=settings.premultiplied_background(),
                     material=(settings.ambient, settings.diffuse, settings.specular, settings.shininess),
                     mpw_cap=float(settings.min_pixel_width_cap), t_eps=float(settings.transmittance_eps))


def check_gpu_range(strands):
    """InputError when strands lie farther from the origin than the GPU's float32 arithmetic
    can square (MAX_POINT_COORDINATE), naming how far they reach."""
    if not strands.num_points:
        return
    far = float(np.abs(strands.points).max()) + float(strands.radius.max())
    if not far <= MAX_POINT_COORDINATE:
        raise InputError(f"points: coordinates reach {far:.3g}; the GPU tracer squares distances in float32, so "
                         f"it takes strands within ±{MAX_POINT_COORDINATE:.0e} of the origin: scale them down "
                         "(and the camera with them) or recentre them")


def block_occupancy(grid):
    """(Bz, By, Bx) uint8: 1 where a block of BLOCK³ cells holds any cylinder."""
    nx, ny, nz = (int(x) for x in grid.dims)
    bx, by, bz = (-(-d // BLOCK) for d in (nx, ny, nz))
    full = np.zeros((bz * BLOCK, by * BLOCK, bx * BLOCK), bool)
    full[:nz, :ny, :nx] = (grid.cell_count > 0).reshape(nz, ny, nx)
    # One axis at a time, OR-ing the BLOCK strided slices: 7x faster than any() over the
    # 6-D view at 2 M cells.
    for axis in (2, 1, 0):
        parts = [full[(slice(None),) * axis + (slice(k, None, BLOCK),)] for k in range(BLOCK)]
        full = functools.reduce(np.logical_or, parts)
    return full.astype(np.uint8)


def _ranks(lengths):
    """0, 1, .., n-1 for every n in `lengths`, concatenated."""
    lengths = np.asarray(lengths, np.int64)
    return np.arange(int(lengths.sum())) - np.repeat(np.cumsum(lengths) - lengths, lengths)


def _runs(chunks):
    """[first, end) pairs of the runs of consecutive chunk numbers among `chunks` (any order)."""
    rows = np.unique(chunks)
    breaks = np.flatnonzero(np.diff(rows) > 1)
    return [(int(rows[a]), int(rows[b]) + 1)
            for a, b in zip(np.concatenate([[0], breaks + 1]), np.concatenate([breaks, [len(rows) - 1]]))]


def _select_strands(strands, ids):
    """The sub-set of strands `ids` (sorted), as a Strands (already validated data)."""
    offsets = strands.offsets
    counts = strands.counts[ids].astype(np.int64)
    pts = np.repeat(offsets[ids], counts) + _ranks(counts)
    return Strands(strands.points[pts], strands.counts[ids], strands.radius[pts], strands.color[pts],
                   strands.alpha[pts], strands.wisp[ids])

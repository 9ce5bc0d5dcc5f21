# SPDX-License-Identifier: GPL-3.0-or-later
"""The GPU tracer: one headless (EGL) OpenGL 3.3 core context per process, scene data in
float textures, one fragment shader that traces every pixel.

Only `set_strands`/`update_strands` upload; a render with a new camera, light or setting
sends uniforms and nothing else (`stats["bytes_uploaded"]` proves it).
"""
import pathlib
import time

import numpy as np

from hairio import InputError, Strands
from .cylinders import (SHARP_BEND_DEG, CylinderPlan, column_bounds, cylinders_from_plan, plan_cylinders,
                        repeat_distance, strands_to_cylinders)
from .grid import Grid, build_grid, grid_frame
from .gpu_build import GpuBuilder, compute_available, set_uniforms
from .settings import GRID_WIDEN_CAP, RenderSettings

BLOCK = 4          # cells per side of the empty-space-skipping blocks (the shader's BLOCK)
TEX_W = 4096       # texels per row of the textures of lists unless more rows than the driver
                   # allows would be needed; see texture_layout
# Per cylinder, four consecutive RGBA32F texels of one texture (top+radius, tip+alpha,
# n2+flags, colour): 64 bytes, one cache line, so a cylinder test on a CPU driver touches
# one line where four textures took up to four. The shader's cyl() agrees.
TEXELS_PER_CYL = 4
SHADER_DIR = pathlib.Path(__file__).resolve().parent / "shaders"

_VERTEX = """#version 330 core
void main() {   // one triangle that covers the screen; the scissor picks the pixels
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
"""

_CONTEXT = None
_BUILDER = None
BUILDS = ("auto", "gpu", "numpy")


def shared_context():
    """The process's one standalone EGL context (created on first use)."""
    global _CONTEXT
    if _CONTEXT is None:
        import moderngl
        try:
            _CONTEXT = moderngl.create_standalone_context(backend="egl", require=330)
        except Exception as e:   # no EGL, no driver: say what is missing
            raise RuntimeError(f"tracer: cannot create a headless OpenGL 3.3 context through EGL ({e}); "
                               "install Mesa's EGL (libegl1) or a GPU driver") from e
    return _CONTEXT


def load_shader(name):
    return (SHADER_DIR / name).read_text()


def gpu_builder():
    """The compute passes of the shared context (compiled on first use)."""
    global _BUILDER
    if _BUILDER is None:
        _BUILDER = GpuBuilder(shared_context(), load_shader)
    return _BUILDER


def texture_layout(name, n_texels, max_size, base_width=TEX_W):
    """(log2 of the row width, rows) of a 2D texture holding `n_texels` in row-major order:
    rows of `base_width` texels while the rows fit the driver's `max_size` per side, wider
    power-of-two rows (up to `max_size`) when they do not. The shader finds texel i at
    (i & (width - 1), i >> log2 width). InputError when even the widest rows do not fit."""
    top = 1 << (int(max_size).bit_length() - 1)        # widest power of two the driver allows
    width = max(TEXELS_PER_CYL, min(int(base_width), top))
    while width < top and -(-n_texels // width) > max_size:
        width *= 2
    rows = max(1, -(-n_texels // width))
    if rows > max_size:
        raise InputError(f"scene too large for this GPU: {name} needs {n_texels} texels but the driver "
                         f"allows {max_size} per side ({top * max_size} in all); render fewer strands "
                         "or fewer points per strand")
    return width.bit_length() - 1, rows


class Renderer:
    """GPU tracer of one scene at a time.

    `stats` (a dict) after each call: cylinders_s, upload_s, grid_s (last set/update),
    render_s, renders, bytes_uploaded and uploads (cumulative: unchanged by renders),
    num_cylinders, grid_dims, grid_refs, cylinders_per_full_cell, full_cell_fraction,
    layers_max (layers the shader was compiled for), screen_box and traversed_pixels (the
    projected bounds that were traced), and with RenderSettings(count=True) also
    shadow_rays, layers_traced, cells_visited, cylinder_tests (summed over samples)."""

    def __init__(self, max_texture_size=None, base_width=TEX_W, build="auto"):
        """`max_texture_size` (default: the driver's GL_MAX_TEXTURE_SIZE) and `base_width`
        shape the 2D textures (texture_layout); smaller values exercise big-scene layouts.
        `build`: where cylinders and grid are made — "gpu" (compute shaders, GL 4.3+),
        "numpy", or "auto" (the GPU where the driver has compute shaders)."""
        self.ctx = shared_context()
        self.max_texture_size = int(max_texture_size or self.ctx.info["GL_MAX_TEXTURE_SIZE"])
        self.base_width = int(base_width)
        if build not in BUILDS:
            raise InputError(f"build: expected one of {', '.join(BUILDS)}, got {build!r}")
        if build == "gpu" and not compute_available(self.ctx):
            raise InputError(f"build: 'gpu' needs compute shaders (OpenGL 4.3); this driver offers "
                             f"{self.ctx.info['GL_VERSION']}; use 'numpy' or 'auto'")
        self.build = "numpy" if build == "numpy" or not compute_available(self.ctx) else "gpu"
        self._shift = {}     # log2 row width of tex_cyl, tex_idx (and tex_pts, tex_cp)
        self._programs = {}
        self._fbos = {}
        self._tex = {}
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
                      "render_s": 0.0, "renders": 0}

    # --- data ---------------------------------------------------------------------------
    @property
    def cylinders(self):
        """The scene's tracer.cylinders.Cylinders. The GPU build never needs them on the CPU,
        so there they are made on first access (for tests and tools), not on upload."""
        if self._cylinders is None and self.strands is not None:
            self._cylinders = strands_to_cylinders(self.strands)
        return self._cylinders

    def set_strands(self, strands):
        """Upload `strands` (hairio.Strands) and build the grid."""
        if not isinstance(strands, Strands):
            raise InputError(f"strands: expected hairio.Strands, got {type(strands).__name__}; "
                             "build one with Strands.from_arrays")
        t0 = time.perf_counter()
        # The GPU build checks for repeated points itself while it makes the cylinders.
        plan = plan_cylinders(strands, drop_repeats=self.build != "gpu")
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
            repeats = self._make_cylinders_gpu(2.0 * repeat_distance(plan.points))
            if repeats is None or len(repeats):
                # Some points may repeat their predecessor: drop them as the numpy build does.
                self._plan = plan = plan_cylinders(strands, candidates=repeats)
                self.num_cylinders = len(plan)
                t1b = time.perf_counter()
                self._upload_points(plan)
                t2 += time.perf_counter() - t1b
                self._make_cylinders_gpu(0.0)
            self.stats["uploads"] += 1
            self._set_all_opaque(plan)
            t3 = time.perf_counter()
            self._build_and_upload_grid()
            self.stats["cylinders_s"] = (t1 - t0) + (t3 - t2)
            self.stats["upload_s"] = (t2 - t1) + self.stats.pop("_grid_upload_s")
        else:
            self._cylinders = cylinders_from_plan(plan)
            self._set_all_opaque(plan)
            t1 = time.perf_counter()
            self._upload_cylinders(0, len(self._cylinders), full=True)
            t2 = time.perf_counter()
            self._build_and_upload_grid()
            self.stats["cylinders_s"] = t1 - t0
            self.stats["upload_s"] = t2 - t1 + self.stats.pop("_grid_upload_s")
        self.stats["num_cylinders"] = self.num_cylinders

    def update_strands(self, strand_ids, strands):
        """`strands` is the whole new set; only strands `strand_ids` changed. When their point
        counts are unchanged, only their data is re-uploaded (their cylinders' texture rows
        with the numpy build, their points' rows with the GPU build, which then remakes just
        their cylinders) and the grid is rebuilt; otherwise everything is uploaded again."""
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
        if self.build == "gpu" and self.num_cylinders:
            self._update_strands_gpu(ids, strands)
            return
        t0 = time.perf_counter()
        sub = _select_strands(strands, ids)
        new = strands_to_cylinders(sub)
        old = self.cylinders
        per_strand_old = np.bincount(old.strand, minlength=strands.num_strands)
        first_old = np.concatenate([[0], np.cumsum(per_strand_old)])
        per_new = np.bincount(new.strand, minlength=len(ids))
        if not np.array_equal(per_new, per_strand_old[ids]):
            self.set_strands(strands)    # a zero-length segment appeared or vanished
            return
        # Positions of the changed cylinders in the full arrays.
        dest = np.repeat(first_old[ids], per_new) + _ranks(per_new)
        for f in ("top", "tip", "n2", "radius", "color", "alpha", "flags", "extension"):
            getattr(old, f)[dest] = getattr(new, f)
        self.strands = strands
        self.all_opaque = bool(len(old) == 0 or old.alpha.min() >= 1.0)
        t1 = time.perf_counter()
        per = self._cyl_per_row
        for a, b in _row_runs(dest // per):
            self._upload_cylinders(a * per, min(len(old), b * per))
        t2 = time.perf_counter()
        self._build_and_upload_grid()
        self.stats["cylinders_s"] = t1 - t0
        self.stats["upload_s"] = t2 - t1 + self.stats.pop("_grid_upload_s")

    def _update_strands_gpu(self, ids, strands):
        t0 = time.perf_counter()
        old = self._plan
        sub = plan_cylinders(_select_strands(strands, ids))
        if not np.array_equal(sub.counts, old.counts[ids]):
            self.set_strands(strands)    # a repeated point appeared or vanished
            return
        # The same points per strand are left: point and cylinder numbering are unchanged.
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
        # The texture rows that hold the changed strands' points, consecutive rows in one
        # write per texture (thousands of scattered strands would otherwise mean thousands of
        # small writes, which cost more than the data).
        w = 1 << self._shift["tex_pts"]
        point_first = first_point[ids]
        ends = point_first + counts[ids]
        r0, r1 = point_first // w, (ends - 1) // w
        rows = np.repeat(r0, r1 - r0 + 1) + _ranks(r1 - r0 + 1)
        n_points = len(self._plan.points)
        for a, b in _row_runs(rows):
            self._upload_points(self._plan, a * w, min(n_points, b * w))
        t2 = time.perf_counter()
        # One dispatch from the first changed cylinder to the last: the unchanged ones between
        # are made again from unchanged points (same texels), which costs the GPU less than a
        # dispatch per run of changed strands.
        cyl_first = np.concatenate([[0], np.cumsum(per_strand)])
        first, last = int(cyl_first[ids[0]]), int(cyl_first[ids[-1] + 1])
        self._make_cylinders_gpu(0.0, first, last - first)
        t3 = time.perf_counter()
        self._build_and_upload_grid()
        self.stats["cylinders_s"] = (t1 - t0) + (t3 - t2)
        self.stats["upload_s"] = (t2 - t1) + self.stats.pop("_grid_upload_s")

    def _set_all_opaque(self, plan):
        self.all_opaque = bool(len(plan) == 0 or plan.alpha[plan.top_point].min() >= 1.0)

    _POINT_TEXTURES = (("tex_pos", "points", 3), ("tex_rad", "radius", 1), ("tex_col", "color", 3),
                       ("tex_alpha", "alpha", 1))

    def _upload_points(self, plan, a=None, b=None):
        """Points a..b (all by default): the plan's arrays as they are, one texture each, in
        rows of 2^shift points; the full upload also sends the cylinder -> top point index."""
        if a is None:
            n = len(plan.points)
            shift, rows = texture_layout("tex_pos", n, self.max_texture_size, self.base_width)
            self._shift["tex_pts"] = shift
            for name, field, comps in self._POINT_TEXTURES:
                self._gpu_texture(name, (1 << shift, rows), comps, "f4")
            a, b = 0, n
            shift, rows = texture_layout("tex_cp", len(plan), self.max_texture_size, self.base_width)
            self._shift["tex_cp"] = shift
            cp = np.zeros(rows << shift, np.int32)
            cp[:len(plan)] = plan.top_point
            self._texture("tex_cp", (1 << shift, rows), 1, "i4", cp)
        # Whole rows in one write, the partial rows at either end in one each: no copies.
        w = 1 << self._shift["tex_pts"]
        pieces = []
        first_row, last_row = a // w, (b - 1) // w
        if first_row == last_row:
            pieces.append((a, b, (a % w, first_row, b - a, 1)))
        else:
            full0 = first_row
            if a % w:
                full0 = first_row + 1
                pieces.append((a, full0 * w, (a % w, first_row, full0 * w - a, 1)))
            full1 = b // w          # rows full0 .. full1 - 1 are whole
            if full1 > full0:
                pieces.append((full0 * w, full1 * w, (0, full0, w, full1 - full0)))
            if b % w:
                pieces.append((full1 * w, b, (0, full1, b - full1 * w, 1)))
        for name, field, _ in self._POINT_TEXTURES:
            data = getattr(plan, field)
            for p0, p1, viewport in pieces:
                chunk = np.ascontiguousarray(data[p0:p1], np.float32)
                self._tex[name].write(chunk, viewport=viewport)
                self.stats["bytes_uploaded"] += chunk.nbytes

    def _make_cylinders_gpu(self, repeat_dist, first=0, count=None):
        """Makes cylinders first..first+count (all, into a new texture, by default); returns
        the top points of those that may join repeated points (checked when repeat_dist > 0;
        None: too many to list)."""
        n = self.num_cylinders
        if count is None:
            shift, rows = texture_layout("tex_cyl", n * TEXELS_PER_CYL, self.max_texture_size, self.base_width)
            self._shift["tex_cyl"] = shift
            self._gpu_texture("tex_cyl", (1 << shift, rows), 4, "f4")
        return gpu_builder().make_cylinders(self._tex, self._shift["tex_pts"], self._shift["tex_cp"], n,
                                            self._shift["tex_cyl"] - 2, repeat_dist, first, count)

    def _gpu_texture(self, name, size, components, dtype):
        """A texture the GPU passes fill: the one already there when its shape and format
        fit (allocating hundreds of MB costs as much as filling them on a CPU driver), else a
        new one."""
        tex = self._tex.get(name)
        if tex is not None and tex.size == tuple(size) and tex.components == components and tex.dtype == dtype:
            return tex
        if tex is not None:
            tex.release()
        tex = self.ctx.texture(size, components, dtype=dtype)
        _nearest(tex)
        self._tex[name] = tex
        return tex

    def _texture(self, name, size, components, dtype, data):
        limit = self.ctx.info["GL_MAX_3D_TEXTURE_SIZE"] if len(size) == 3 else self.max_texture_size
        if max(size) > limit:
            raise InputError(f"scene too large for this GPU: {name} needs {size} texels but the driver "
                             f"allows {limit} per side; render fewer strands or fewer points per strand")
        old = self._tex.get(name)
        if old is not None:
            old.release()
        if len(size) == 3:
            tex = self.ctx.texture3d(size, components, data, dtype=dtype)
        else:
            tex = self.ctx.texture(size, components, data, dtype=dtype)
        _nearest(tex)
        self._tex[name] = tex
        self.stats["bytes_uploaded"] += data.nbytes
        return tex

    def _cylinder_block(self, a, b, rows):
        """Cylinders a..b as RGBA float32 texels, TEXELS_PER_CYL per cylinder one after the
        other, zero-padded to `rows` texture rows."""
        c = self.cylinders
        out = np.zeros((rows * self._cyl_per_row, TEXELS_PER_CYL, 4), np.float32)
        m = b - a
        out[:m, 0, :3], out[:m, 0, 3] = c.top[a:b], c.radius[a:b]
        out[:m, 1, :3], out[:m, 1, 3] = c.tip[a:b], c.alpha[a:b]
        out[:m, 2, :3], out[:m, 2, 3] = c.n2[a:b], c.flags[a:b]
        out[:m, 3, :3] = c.color[a:b]
        return out.reshape(-1, 4)

    def _upload_cylinders(self, a, b, full=False):
        n = len(self.cylinders)
        self.stats["uploads"] += 1
        if full:
            shift, rows = texture_layout("tex_cyl", n * TEXELS_PER_CYL, self.max_texture_size, self.base_width)
            self._shift["tex_cyl"] = shift
            self._texture("tex_cyl", (1 << shift, rows), 4, "f4", self._cylinder_block(0, n, rows))
        else:
            per = self._cyl_per_row
            r0, r1 = a // per, max(1, -(-b // per))
            data = self._cylinder_block(r0 * per, min(n, r1 * per), r1 - r0)
            self._tex["tex_cyl"].write(data, viewport=(0, r0, 1 << self._shift["tex_cyl"], r1 - r0))
            self.stats["bytes_uploaded"] += data.nbytes

    @property
    def _cyl_per_row(self):
        return (1 << self._shift["tex_cyl"]) // TEXELS_PER_CYL

    def _build_and_upload_grid(self):
        t0 = time.perf_counter()
        self.grid = None
        upload_s = 0.0      # the GPU build uploads only counters (bytes counted in it)
        if self.build == "gpu" and self.num_cylinders:
            self.grid = self._build_grid_gpu()
        self.stats["grid_build"] = "gpu" if self.grid is not None else "numpy"
        if self.grid is None:      # the numpy build, or a scene the GPU passes cannot list
            self.grid = build_grid(self.cylinders, pad_factor=self._grid_pad)
            t1 = time.perf_counter()
            g = self.grid
            shift, rows = texture_layout("tex_idx", len(g.indices), self.max_texture_size, self.base_width)
            self._shift["tex_idx"] = shift
            idx = np.zeros(rows << shift, np.int32)
            idx[:len(g.indices)] = g.indices
            self._texture("tex_idx", (1 << shift, rows), 1, "i4", idx)
            upload_s = time.perf_counter() - t1
        g = self.grid
        t2 = time.perf_counter()
        cells = np.column_stack([g.cell_start, g.cell_count]).astype(np.int32)
        # An empty cell's start is unused; -1 there says its whole block of BLOCK³ cells is
        # empty, so the DDA learns "skip the block" from the one texel it reads per cell.
        nx, ny, nz = (int(x) for x in g.dims)
        occupied = block_occupancy(g).astype(bool)
        in_full_block = occupied[np.arange(nz)[:, None, None] // BLOCK, np.arange(ny)[None, :, None] // BLOCK,
                                 np.arange(nx)[None, None, :] // BLOCK].ravel()
        cells[~in_full_block, 0] = -1
        self._texture("tex_cell", tuple(int(x) for x in g.dims), 2, "i4", cells)
        t3 = time.perf_counter()
        self.stats["grid_s"] = (t3 - t0) - upload_s - (t3 - t2)
        self.stats["_grid_upload_s"] = upload_s + (t3 - t2)
        self.stats["grid_dims"] = tuple(int(x) for x in g.dims)
        self.stats["grid_refs"] = self._grid_refs
        self.stats["cylinders_per_full_cell"], self.stats["full_cell_fraction"] = g.occupancy()

    @property
    def _grid_refs(self):
        return int(self.grid.cell_count.sum(dtype=np.int64))

    def _build_grid_gpu(self):
        """Grid with indices None, or None when a cylinder spans more cells than one
        invocation may list (the caller builds in numpy)."""
        plan = self._plan
        pad = self._grid_pad
        pts = plan.points
        # Every capsule lies within its points' box widened by its radius times the pad, plus
        # the reach of a bent cylinder past its tip (at most r·tan(SHARP_BEND_DEG), see
        # tracer/cylinders.py): the scene box without per-cylinder work.
        rmax = float(plan.radius.max())
        reach = rmax * (pad + np.tan(np.radians(SHARP_BEND_DEG))) * (1 + 1e-6)
        lo, hi = column_bounds(pts)
        lo, hi = lo - reach, hi + reach
        # The resolution from a sample of the cylinders' padded boxes, as the numpy build does.
        step = max(1, len(plan) // 20_000 + 1)
        top = plan.top_point[::step]
        a, b = pts[top].astype(np.float64), pts[top + 1].astype(np.float64)
        size = np.abs(b - a) + 2 * pad * plan.radius[top][:, None]
        lo, cs, dims = grid_frame(lo, hi, size, count=len(plan))
        builder = gpu_builder()
        n, tex_cyl, cyl_shift = self.num_cylinders, self._tex["tex_cyl"], self._shift["tex_cyl"] - 2
        counted = builder.count(n, tex_cyl, cyl_shift, lo, cs, dims, pad)
        if counted is None:
            return None
        counts, cells = counted
        start = np.cumsum(counts) - counts
        total = int(start[-1] + counts[-1])
        shift, rows = texture_layout("tex_idx", total, self.max_texture_size, self.base_width)
        self._shift["tex_idx"] = shift
        # Rows rounded up, so a rebuild with a few more references reuses the texture.
        tex_idx = self._gpu_texture("tex_idx", (1 << shift, min(self.max_texture_size, -(-rows // 64) * 64)), 1, "i4")
        builder.fill(n, tex_cyl, cyl_shift, lo, cs, dims, pad, cells, start, tex_idx, shift)
        # Counted as uploads: the zeroed counters and the cursors the two passes start from.
        self.stats["bytes_uploaded"] += 2 * counts.size * 4
        return Grid(lo, cs, dims, start.astype(np.int32), counts.astype(np.int32), None)

    def grid_indices(self):
        """The grid's cell lists as int32 (read back from the GPU when built there)."""
        if self.grid.indices is not None:
            return self.grid.indices
        raw = self._tex["tex_idx"].read()
        return np.frombuffer(raw, np.int32)[:self._grid_refs].copy()

    # --- rendering ----------------------------------------------------------------------
    def _program(self, settings, camera, layers):
        key = (layers, settings.shadows and (1 if settings.shadow_mode == "hard" else 2),
               settings.shading, len(settings.lights), settings.spp_n, settings.min_pixel_width,
               camera.type, settings.count)
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
            }
            head = "#version 330 core\n" + "".join(f"#define {k} {v}\n" for k, v in defines.items())
            prog = self.ctx.program(vertex_shader=_VERTEX, fragment_shader=head + load_shader("trace.glsl"))
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
            atts = [self.ctx.texture((w, h), 4, dtype="f4")]
            if count:
                atts.append(self.ctx.texture((w, h), 4, dtype="f4"))
            fbo = self.ctx.framebuffer(color_attachments=atts)
            self._fbos[key] = fbo
        return fbo

    def screen_bounds(self, camera):
        """Pixel rectangle (x0, y0, x1, y1), y from the top, that the grid box can cover;
        None when nothing can be seen."""
        if not self.num_cylinders:
            return None
        lo, hi = self.grid.lo, self.grid.hi
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
        t0 = time.perf_counter()
        if settings.min_pixel_width and self._grid_pad < GRID_WIDEN_CAP:
            self._grid_pad = GRID_WIDEN_CAP
            self._build_and_upload_grid()
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

    def _set_uniforms(self, prog, camera, settings):
        g = self.grid
        for i, (name, inv) in enumerate((("tex_cyl", "cyl_inv"), ("tex_idx", "idx_inv"), ("tex_cell", "cell_inv"))):
            tex = self._tex[name]
            tex.use(location=i)
            # The shader reads texels at their centres with textureLod (cheaper than
            # texelFetch on llvmpipe), which needs the reciprocal sizes.
            set_uniforms(prog, **{name: i, inv: tuple(1.0 / float(x) for x in tex.size)})
        set_uniforms(prog, cyl_shift=self._shift["tex_cyl"] - 2,      # log2 cylinders per row
                     idx_shift=self._shift["tex_idx"],
                     grid_lo=tuple(float(x) for x in g.lo),
                     cell_size=tuple(float(x) for x in g.cell_size),
                     dims=tuple(int(x) for x in g.dims),
                     cam_pos=tuple(float(x) for x in camera.position),
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


def block_occupancy(grid):
    """(Bz, By, Bx) uint8: 1 where a block of BLOCK³ cells holds any cylinder."""
    nx, ny, nz = (int(x) for x in grid.dims)
    bx, by, bz = (-(-d // BLOCK) for d in (nx, ny, nz))
    full = np.zeros((bz * BLOCK, by * BLOCK, bx * BLOCK), bool)
    full[:nz, :ny, :nx] = (grid.cell_count > 0).reshape(nz, ny, nx)
    return full.reshape(bz, BLOCK, by, BLOCK, bx, BLOCK).any(axis=(1, 3, 5)).astype(np.uint8)


def _nearest(tex):
    import moderngl
    tex.filter = (moderngl.NEAREST, moderngl.NEAREST)


def _ranks(lengths):
    """0, 1, .., n-1 for every n in `lengths`, concatenated."""
    lengths = np.asarray(lengths, np.int64)
    return np.arange(int(lengths.sum())) - np.repeat(np.cumsum(lengths) - lengths, lengths)


def _row_runs(rows):
    """[first, end) pairs of the runs of consecutive texture rows among `rows` (any order)."""
    rows = np.unique(rows)
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

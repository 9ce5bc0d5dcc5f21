# SPDX-License-Identifier: GPL-3.0-or-later
"""Beams built by compute passes (GL 4.3; shaders/beams_build.glsl), by tracer/beams.py's
rules, straight into the buffer textures the trace shader reads: count the references of
every bin, scan the counts into starts on the GPU, then either bucket the cylinders by the
finest slice of their key and fill the lists fine slice after fine slice, or fill them in
one dispatch in id order into a scratch buffer and sort each bin's entries by fine slice
into the lists (tracer/beams.py, fill_plan). Nothing goes up from the host but uniforms and
the fine slices' first places (the scratch buffers are zeroed by a pass), so a camera move
uploads next to nothing; what comes back is the total, the fine slices' sizes and two flags.
"""
import numpy as np

from . import layout
from .beams import Beams, BeamsUnfit, TooManyRefs, fill_plan
from .gpu_build import _groups, set_uniforms
from .shader_source import shader_source

KIND_CODE = {"persp": 0, "ortho": 1, "sun": 2}
BUILD_FILES = ["build_cylinders.glsl", "capsule.glsl", "beams_build.glsl"]


# Scratch buffers up to this many words are kept between builds; bigger ones (a scene of
# tens of millions of cylinders) are given back after the build that needed them.
KEEP_WORDS = 1 << 24


class BeamBuilder:
    """The passes of one context and their scratch buffers (kept and grown, not made again
    for every camera move: allocating is costly on a CPU driver)."""

    def __init__(self, ctx):
        self.ctx = ctx
        self._passes = {}
        self._scratch = {}

    def _program(self, pass_, cyl_parts, centres=False, sort_keys=0, marks=False):
        """Pass `pass_`; sort_keys: 0 the fill a fine slice a dispatch, else the sorted fill
        (PASS 6 in id order, PASS 7 sorting by that many fine slices); marks: entries with
        their marks (MARKS)."""
        key = (layout.glsl_header(), pass_, cyl_parts, bool(centres), sort_keys, bool(marks))
        prog = self._passes.get(key)
        if prog is None:
            prog = self._passes[key] = self.ctx.compute_shader(
                shader_source(430, BUILD_FILES, {"PASS": pass_, "CYL_PARTS": cyl_parts, "CENTRES": int(centres),
                                                 "SORTED": int(sort_keys > 0), "SORT_KEYS": max(sort_keys, 1),
                                                 "MARKS": int(bool(marks))}))
        return prog

    def _buffer(self, name, words):
        """Scratch storage buffer `name` of at least `words` int32."""
        buf = self._scratch.get(name)
        if buf is None or buf.size < 4 * words:
            if buf is not None:
                buf.release()
            buf = self._scratch[name] = self.ctx.buffer(reserve=4 * max(words + words // 8, 64))
        return buf

    def release(self):
        for buf in self._scratch.values():
            buf.release()
        self._scratch.clear()

    def _zero(self, buf, words):
        prog = self._program(0, 1)
        set_uniforms(prog, n_items=int(words))
        buf.bind_to_storage_buffer(0)
        prog.run(*_groups(words))

    def _frame_uniforms(self, prog, frame, pad_factor, tex_cyl, n, sub):
        set_uniforms(prog, n_items=int(n), pad_factor=float(pad_factor), frame_kind=KIND_CODE[frame.kind],
                     frame_origin=tuple(float(x) for x in frame.origin),
                     axis_x=tuple(float(x) for x in frame.axes[0]), axis_y=tuple(float(x) for x in frame.axes[1]),
                     axis_z=tuple(float(x) for x in frame.axes[2]),
                     frame_offset=tuple(float(x) for x in frame.offset), radius_scale=float(frame.radius_scale),
                     drift=float(frame.drift), key0=float(frame.key0), key_step=float(frame.key_step),
                     near_limit=float(frame.near_limit), dims=tuple(int(d) for d in frame.dims),
                     max_bins=int(layout.BEAM_MAX_BINS_PER_CYLINDER), sub_bits=int(sub),
                     cyl_split=tex_cyl.part_texels // layout.TEXELS_PER_CYL)
        for unit, part in enumerate(tex_cyl.parts):
            part.use(unit)

    def build(self, frame, n, tex_cyl, pad_factor, store, list_name, table_name, max_refs, reach=None):
        """Beams of `frame` over the `n` cylinders of `tex_cyl` (a SplitBuffer), their lists
        into buffer `list_name` and bin table into `table_name` of `store` (SceneBuffers).
        With `reach` (bins) every entry comes with its mark, two uint32 a texel: its
        cylinder's capsule axis in its bin, clipped to the bin widened by `reach`, 8 bits a
        coordinate (shaders/beams_build.glsl, beam_mark). Returns Beams without host arrays,
        with that reach; BeamsUnfit where the numpy build would raise it."""
        try:
            return self._build(frame, n, tex_cyl, pad_factor, store, list_name, table_name, max_refs, reach)
        finally:
            for name in [k for k, buf in self._scratch.items() if buf.size > 4 * KEEP_WORDS]:
                self._scratch.pop(name).release()

    def _build(self, frame, n, tex_cyl, pad_factor, store, list_name, table_name, max_refs, reach=None):
        ctx = self.ctx
        nbins = frame.num_bins
        chunks = -(-nbins // layout.BEAM_SCAN_CHUNK)
        parts = len(tex_cyl.parts)
        counts = self._buffer("counts", chunks * layout.BEAM_SCAN_CHUNK)
        top = layout.beam_sub_bits(n)
        fines = layout.BEAM_SLICES << top
        slices = self._buffer("slices", fines)
        flags = self._buffer("flags", 2)
        sums = self._buffer("sums", chunks + 1)
        perm = self._buffer("perm", max(n, 1))
        filed = self._buffer("filed", max(n, 1))
        self._zero(counts, chunks * layout.BEAM_SCAN_CHUNK)
        self._zero(slices, fines)
        self._zero(flags, 2)
        ctx.memory_barrier()
        prog = self._program(1, parts, frame.centres)
        self._frame_uniforms(prog, frame, pad_factor, tex_cyl, n, top)
        for binding, buf in enumerate((counts, slices, perm, sums, flags, filed)):
            buf.bind_to_storage_buffer(binding)
        prog.run(*_groups(n))
        ctx.memory_barrier()
        near, wide = np.frombuffer(flags.read(size=8), np.int32)
        if near:
            raise BeamsUnfit("the hair reaches the camera's plane")
        if wide:
            raise BeamsUnfit(f"{int(wide)} cylinders' projections span more than "
                             f"{layout.BEAM_MAX_BINS_PER_CYLINDER} bins")
        # The scan: chunk sums, their prefix sums (one invocation), each bin's start.
        prog = self._program(2, 1)
        set_uniforms(prog, n_items=chunks)
        counts.bind_to_storage_buffer(0)
        sums.bind_to_storage_buffer(3)
        prog.run(*_groups(chunks))
        ctx.memory_barrier()
        prog = self._program(3, 1)
        set_uniforms(prog, n_items=chunks)
        prog.run(1)
        ctx.memory_barrier()
        total = int(np.frombuffer(sums.read(size=4, offset=4 * chunks), np.int32)[0])
        if total > max_refs:
            raise TooManyRefs(f"{total:,} references, more than {max_refs:,}")
        table = store.store(table_name, nbins, 2, "i4")
        marks = reach is not None
        lists = store.store(list_name, max(total, 1), 2 if marks else 1, "u4")
        prog = self._program(4, 1)
        set_uniforms(prog, n_items=chunks, dims=tuple(int(d) for d in frame.dims))
        counts.bind_to_storage_buffer(0)
        sums.bind_to_storage_buffer(3)
        table.buffer.bind_to_storage_buffer(6)
        prog.run(*_groups(chunks))
        sizes = np.frombuffer(slices.read(size=4 * fines), np.int32).astype(np.int64)
        sort, sub = fill_plan(sizes, total, n, nbins, marks)
        if sort:
            self._sorted_fill(frame, n, tex_cyl, pad_factor, sub, total, (counts, filed), table, lists, reach)
            return Beams(frame, total, sub, reach=reach)
        # The cylinders bucketed by fine slice: every fine slice's first place from its count.
        first = np.cumsum(sizes) - sizes
        slices.write(first.astype(np.int32).tobytes())
        ctx.memory_barrier()
        prog = self._program(5, 1)
        set_uniforms(prog, n_items=int(n))
        for binding, buf in enumerate((counts, slices, perm, sums, flags, filed)):
            buf.bind_to_storage_buffer(binding)
        prog.run(*_groups(n))
        ctx.memory_barrier()
        # The lists, a fine slice of `sub` bits a dispatch in order, so each bin's entries
        # come fine slice by fine slice.
        group = 1 << (top - sub)
        filled = sizes.reshape(-1, group).sum(axis=1)
        prog = self._program(6, parts, frame.centres, marks=marks)
        self._frame_uniforms(prog, frame, pad_factor, tex_cyl, n, sub)
        if marks:
            set_uniforms(prog, mark_reach=float(reach))
        lists.buffer.bind_to_storage_buffer(6)
        for k in np.flatnonzero(filled):
            set_uniforms(prog, n_items=int(filled[k]), first_item=int(first[k * group]))
            prog.run(*_groups(int(filled[k])))
            ctx.memory_barrier()
        return Beams(frame, total, sub, reach=reach)

    def _sorted_fill(self, frame, n, tex_cyl, pad_factor, sub, total, scratch, table, lists, reach):
        """fill_plan's other fill (PASS 6 SORTED, PASS 7): every listed cylinder in id order in
        one dispatch into scratch lists at the bins' cursors, then each bin's entries into
        `lists` sorted by fine slice of `sub` bits (with `reach`, entries with their marks).
        scratch: the build's (cursors, filed); table: the bins' starts and counts."""
        ctx = self.ctx
        ctx.memory_barrier()
        keys = layout.BEAM_SLICES << sub
        marks = reach is not None
        unsorted = self._buffer("unsorted", max(total, 1) * (2 if marks else 1))
        prog = self._program(6, len(tex_cyl.parts), frame.centres, keys, marks)
        self._frame_uniforms(prog, frame, pad_factor, tex_cyl, n, sub)
        if marks:
            set_uniforms(prog, mark_reach=float(reach))
        scratch[0].bind_to_storage_buffer(0)
        scratch[1].bind_to_storage_buffer(5)
        unsorted.bind_to_storage_buffer(6)
        prog.run(*_groups(n))
        ctx.memory_barrier()
        prog = self._program(7, 1, sort_keys=keys, marks=marks)
        set_uniforms(prog, n_items=int(frame.num_bins), sub_bits=int(sub))
        table.buffer.bind_to_storage_buffer(6)
        unsorted.bind_to_storage_buffer(7)
        lists.buffer.bind_to_storage_buffer(8)
        prog.run(*_groups(int(frame.num_bins)))
        ctx.memory_barrier()

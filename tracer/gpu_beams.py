# SPDX-License-Identifier: GPL-3.0-or-later
"""Beams built by compute passes (GL 4.3; shaders/beams_build.glsl), by tracer/beams.py's
rules, straight into the buffer textures the trace shader reads: count the references of
every bin, scan the counts into starts on the GPU, then either bucket the cylinders by the
finest slice of their key and fill the lists fine slice after fine slice, or fill them in
one dispatch in id order into a scratch buffer and sort each bin's entries by fine slice
into the lists (tracer/beams.py, fill_plan). Nothing goes up from the host but uniforms and
the fine slices' first places (the scratch buffers are zeroed by a pass), so a camera move
uploads next to nothing; what comes back is the total, the fine slices' sizes and two flags
(and the chunks' first entries where the lists outgrow a storage block the driver binds no
further: then they are filled a window of bins at a time, BeamBuilder._windows).
"""
import math

import numpy as np

from . import layout
from .beams import Beams, BeamsUnfit, TooManyRefs, anchored, fill_plan
from .gl_buffers import storage_limits
from .gpu_build import _groups, set_uniforms
from .shader_source import shader_source

KIND_CODE = {"persp": 0, "ortho": 1, "sun": 2}
NO_CONE = (0.0, 0.0, 1.0, -1.0)     # frame_cone of a frame without one (w < 0: beams_build.glsl)
BUILD_FILES = ["build_cylinders.glsl", "capsule.glsl", "beams_build.glsl"]


# A word written and read back through a whole binding past GL_MAX_SHADER_STORAGE_BLOCK_SIZE
# (BeamBuilder._binds_past_block): what it read goes to the first word.
PROBE_SOURCE = """#version 430 core
layout(local_size_x = 1) in;
layout(std430, binding = 0) buffer Words { uint words[]; };
uniform int at;
uniform uint word;
void main() {
    words[at] = word;
    memoryBarrierBuffer();
    words[0] = words[at] ^ 1u;
}
"""
PROBE_WORD = 0x9E3779B9

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
        self._past_block = None       # _binds_past_block's answer, once probed

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
        """The frame's uniforms, the whole frame's rows for `band` (a window's fill sets its own)."""
        anchor, at = anchored(frame)
        set_uniforms(prog, frame_anchor=tuple(float(x) for x in anchor), anchor_frame=tuple(float(x) for x in at))
        set_uniforms(prog, band=(0, int(frame.dims[1]) - 1), n_items=int(n), pad_factor=float(pad_factor),
                     frame_kind=KIND_CODE[frame.kind], frame_origin=tuple(float(x) for x in frame.origin),
                     axis_x=tuple(float(x) for x in frame.axes[0]), axis_y=tuple(float(x) for x in frame.axes[1]),
                     axis_z=tuple(float(x) for x in frame.axes[2]),
                     frame_offset=tuple(float(x) for x in frame.offset), radius_scale=float(frame.radius_scale),
                     drift=float(frame.drift), key0=float(frame.key0), key_step=float(frame.key_step),
                     near_limit=float(frame.near_limit), frame_spread=float(frame.spread),
                     frame_extent=float(frame.extent), frame_far=float(frame.far_depth),
                     frame_cone=NO_CONE if frame.cone is None else tuple(float(x) for x in frame.cone),
                     dims=tuple(int(d) for d in frame.dims),
                     max_bins=int(layout.BEAM_MAX_BINS_PER_CYLINDER), sub_bits=int(sub),
                     cyl_split=tex_cyl.part_texels // layout.TEXELS_PER_CYL)
        for unit, part in enumerate(tex_cyl.parts):
            part.use(unit)

    def _binds_past_block(self, buf, most):
        """Whether this context's storage bindings reach past `most` bytes (the driver's
        largest storage block), probed once on `buf` (bigger than that: the lists about to be
        filled, which the fill then writes over): a word written through the whole buffer
        bound, at its last word, lands, and reads back (the sorted fill reads its scratch
        lists). llvmpipe's do, so its lists are filled in one window (three windows cost
        2.4 → 3.5 s for 100,000 strands' camera lists at 16 samples)."""
        if self._past_block is None:
            at = buf.size // 4 - 1
            prog = self._passes.get("probe")
            if prog is None:
                prog = self._passes["probe"] = self.ctx.compute_shader(PROBE_SOURCE)
            set_uniforms(prog, at=int(at), word=PROBE_WORD)
            _ = self.ctx.error                  # (reading it clears an earlier error)
            buf.bind_to_storage_buffer(0)
            if self.ctx.error != "GL_NO_ERROR":
                # Refused: binding 0 still holds an earlier buffer, which the probe must not touch.
                self._past_block = False
                return False
            prog.run(1)
            self.ctx.memory_barrier()
            landed = int(np.frombuffer(buf.read(size=4, offset=4 * at), np.uint32)[0]) == PROBE_WORD
            read = int(np.frombuffer(buf.read(size=4), np.uint32)[0]) == PROBE_WORD ^ 1
            self._past_block = bool(landed and read and 4 * at >= most)
        return self._past_block

    def _windows(self, frame, sums, chunks, total, entry_bytes, lists):
        """The ranges of the lists a fill or sort binds, each within the driver's largest
        storage block (GL_MAX_SHADER_STORAGE_BLOCK_SIZE: 128 MB on llvmpipe and some Mesa
        drivers; a buffer bound whole past it may be cut short) from an offset it aligns:
        (first bin, end bin, first entry, entries, rows (first, last) of those bins), whole
        chunks of bins of the scan (`sums`: their first entries, `total` after the last).
        One range where the lists fit, or where the driver binds past its block anyway
        (_binds_past_block, probed on buffer `lists`); TooManyRefs where one chunk's entries
        do not fit one."""
        nbins, dx = frame.num_bins, int(frame.dims[0])
        most, align = storage_limits(self.ctx)
        if total * entry_bytes <= most or self._binds_past_block(lists, most):
            return [(0, nbins, 0, total, (0, int(frame.dims[1]) - 1))]
        starts = np.frombuffer(sums.read(size=4 * (chunks + 1)), np.int32).astype(np.int64)
        step = math.lcm(entry_bytes, align) // entry_bytes      # entries between aligned offsets
        room = most // entry_bytes - step
        windows, c = [], 0
        while c < chunks:
            base = int(starts[c]) // step * step
            e = min(int(np.searchsorted(starts, base + room, side="right")) - 1, chunks)
            if e <= c:
                raise TooManyRefs(f"{int(starts[c + 1] - starts[c]):,} references in {layout.BEAM_SCAN_CHUNK} bins, "
                                  f"more than one storage block of {most:,} bytes holds")
            b0, b1 = c * layout.BEAM_SCAN_CHUNK, min(e * layout.BEAM_SCAN_CHUNK, nbins)
            if starts[e] > starts[c]:
                windows.append((b0, b1, base, int(starts[e]) - base, (b0 // dx, (b1 - 1) // dx)))
            c = e
        return windows

    def _bind_window(self, prog, buffers, window, entry_bytes):
        """Binds `window` (_windows) of each (buffer, binding) and sets the pass's uniforms."""
        b0, b1, base, count, rows = window
        set_uniforms(prog, window=(int(b0), int(b1)), window_base=int(base), band=tuple(int(r) for r in rows))
        for buf, binding in buffers:
            buf.bind_to_storage_buffer(binding, offset=base * entry_bytes, size=max(count, 1) * entry_bytes)

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
        most, _ = storage_limits(ctx)
        if 4 * n > most:
            # The passes bind a word a cylinder whole (the lists go a window at a time:
            # _windows; the bins' counts and table, BEAM_MAX_BINS at most, take 16 and 32 MB);
            # no scene that beams pay for comes near it (128 MB: 33 M cylinders).
            raise TooManyRefs(f"{n:,} cylinders, more words than one storage block of {most:,} bytes holds")
        chunks = -(-nbins // layout.BEAM_SCAN_CHUNK)
        parts = len(tex_cyl.parts)
        counts = self._buffer("counts", chunks * layout.BEAM_SCAN_CHUNK)
        top = layout.beam_sub_bits(n)
        fines = layout.BEAM_SLICES << top
        slices = self._buffer("slices", fines)
        flags = self._buffer("flags", 3)
        sums = self._buffer("sums", chunks + 1)
        perm = self._buffer("perm", max(n, 1))
        filed = self._buffer("filed", max(n, 1))
        self._zero(counts, chunks * layout.BEAM_SCAN_CHUNK)
        self._zero(slices, fines)
        self._zero(flags, 3)
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
        flags.bind_to_storage_buffer(4)
        prog.run(*_groups(chunks))
        ctx.memory_barrier()
        prog = self._program(3, 1)
        set_uniforms(prog, n_items=chunks)
        prog.run(1)
        ctx.memory_barrier()
        total = int(np.frombuffer(sums.read(size=4, offset=4 * chunks), np.int32)[0])
        longest = int(np.frombuffer(flags.read(size=4, offset=8), np.int32)[0])
        if total > max_refs:
            raise TooManyRefs(f"{total:,} references, more than {max_refs:,}")
        table = store.store(table_name, nbins, 2, "i4")
        marks = reach is not None
        entry_bytes = 8 if marks else 4
        lists = store.store(list_name, max(total, 1), 2 if marks else 1, "u4")
        prog = self._program(4, 1)
        set_uniforms(prog, n_items=chunks, dims=tuple(int(d) for d in frame.dims))
        counts.bind_to_storage_buffer(0)
        sums.bind_to_storage_buffer(3)
        table.buffer.bind_to_storage_buffer(6)
        prog.run(*_groups(chunks))
        sizes = np.frombuffer(slices.read(size=4 * fines), np.int32).astype(np.int64)
        sort, sub = fill_plan(sizes, total, n, nbins, marks)
        windows = self._windows(frame, sums, chunks, total, entry_bytes, lists.buffer)
        if sort:
            self._sorted_fill(frame, n, tex_cyl, pad_factor, sub, total, (counts, filed), table, lists, reach,
                              windows, entry_bytes)
            return Beams(frame, total, sub, reach=reach, longest=longest)
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
        # come fine slice by fine slice (a window of bins after another where they outgrow
        # one storage block).
        group = 1 << (top - sub)
        filled = sizes.reshape(-1, group).sum(axis=1)
        prog = self._program(6, parts, frame.centres, marks=marks)
        self._frame_uniforms(prog, frame, pad_factor, tex_cyl, n, sub)
        if marks:
            set_uniforms(prog, mark_reach=float(reach))
        for window in windows:
            self._bind_window(prog, [(lists.buffer, 6)], window, entry_bytes)
            for k in np.flatnonzero(filled):
                set_uniforms(prog, n_items=int(filled[k]), first_item=int(first[k * group]))
                prog.run(*_groups(int(filled[k])))
                ctx.memory_barrier()
        return Beams(frame, total, sub, reach=reach, longest=longest)

    def _sorted_fill(self, frame, n, tex_cyl, pad_factor, sub, total, scratch, table, lists, reach, windows,
                     entry_bytes):
        """fill_plan's other fill (PASS 6 SORTED, PASS 7): every listed cylinder in id order in
        one dispatch into scratch lists at the bins' cursors, then each bin's entries into
        `lists` sorted by fine slice of `sub` bits (with `reach`, entries with their marks), a
        window of bins at a time (`windows`, _windows, of entries of `entry_bytes`). scratch:
        the build's (cursors, filed); table: the bins' starts and counts."""
        ctx = self.ctx
        ctx.memory_barrier()
        keys = layout.BEAM_SLICES << sub
        marks = reach is not None
        unsorted = self._buffer("unsorted", max(total, 1) * (2 if marks else 1))
        fill = self._program(6, len(tex_cyl.parts), frame.centres, keys, marks)
        self._frame_uniforms(fill, frame, pad_factor, tex_cyl, n, sub)
        if marks:
            set_uniforms(fill, mark_reach=float(reach))
        sort = self._program(7, 1, sort_keys=keys, marks=marks)
        set_uniforms(sort, sub_bits=int(sub))
        scratch[0].bind_to_storage_buffer(0)
        scratch[1].bind_to_storage_buffer(5)
        for window in windows:
            self._bind_window(fill, [(unsorted, 6)], window, entry_bytes)
            fill.run(*_groups(n))
            ctx.memory_barrier()
            table.buffer.bind_to_storage_buffer(6)
            self._bind_window(sort, [(unsorted, 7), (lists.buffer, 8)], window, entry_bytes)
            set_uniforms(sort, n_items=int(window[1] - window[0]))
            sort.run(*_groups(int(window[1] - window[0])))
            ctx.memory_barrier()

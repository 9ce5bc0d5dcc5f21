# SPDX-License-Identifier: GPL-3.0-or-later
"""The scene's buffer textures by name (tracer/gl_buffers.py), allocated within the
driver's limit, reused across uploads, every byte sent counted in the renderer's stats.

Names: tex_cyl (cylinders, tracer/layout.py), tex_idx (cell lists), tex_cell (cell table);
for the GPU build also the point arrays tex_pos, tex_rad, tex_col, tex_alpha and tex_cp
(cylinder -> top point).

tex_cyl and tex_idx may hold more texels than one buffer texture of the driver: past the
limit they continue in tex_cyl1, tex_cyl2, ... (at most layout.MAX_BUFFER_PARTS in all),
every part but the last full (`part_size` items). `buffers["tex_cyl"]` is then a SplitBuffer,
which reads and writes by global texel as one buffer does; the shaders take an id's part
by comparing it with the part size (shaders/trace_scene.glsl: cyl). Below the limit there is
one part, the buffer texture itself, and nothing changes for the shaders.
"""
import numpy as np

from hairio import InputError

from . import layout
from .gl_buffers import BufferTexture

# Names that may be split, with the texels of one item (a cylinder's texels never straddle
# two parts, so a shader finds all of them in one).
SPLIT = {"tex_cyl": layout.TEXELS_PER_CYL, "tex_idx": 1}


def part_names(name):
    """The buffer textures of split buffer `name`, in order: name, name1, name2, ..."""
    return [name] + [f"{name}{k}" for k in range(1, layout.MAX_BUFFER_PARTS)]


def split_part_names():
    """Every part past the first of every split buffer (the samplers a program may add)."""
    return tuple(n for name in SPLIT for n in part_names(name)[1:])


class SplitBuffer:
    """One array over `parts` (BufferTexture each, `part_texels` texels in every part but the
    last): write and read by global texel, as a BufferTexture does."""

    def __init__(self, parts, part_texels):
        self.parts, self.part_texels = list(parts), int(part_texels)

    @property
    def capacity(self):
        return self.part_texels * (len(self.parts) - 1) + self.parts[-1].capacity

    @property
    def glo(self):
        return tuple(p.glo for p in self.parts)

    def _pieces(self, first, texels):
        """(part, texel in part, offset in the range, count) of texels first..first+texels."""
        end = first + texels
        k = first // self.part_texels
        while first < end:
            stop = min(end, (k + 1) * self.part_texels)
            yield self.parts[k], first - k * self.part_texels, first, stop - first
            first, k = stop, k + 1

    def write(self, data, first=0):
        raw = np.ascontiguousarray(data).reshape(-1).view(np.uint8)
        per = self.parts[0].texel_bytes
        start = int(first)
        for part, at, pos, n in self._pieces(start, len(raw) // per):
            part.write(raw[(pos - start) * per:(pos - start + n) * per], first=at)

    def read(self, texels=None, first=0):
        texels = self.capacity - first if texels is None else int(texels)
        return b"".join(part.read(n, at) for part, at, _, n in self._pieces(int(first), texels))

    def bind_to_image(self, unit, read=False, write=True):
        for k, part in enumerate(self.parts):
            part.bind_to_image(unit + k, read, write)

    def release(self):
        for p in self.parts:
            p.release()


class SceneBuffers:
    def __init__(self, ctx, max_texels, stats):
        self.ctx = ctx
        self.max_texels = int(max_texels)
        self.stats = stats
        self._tex = {}

    def __getitem__(self, name):
        if name in SPLIT:
            return SplitBuffer([self._tex[n] for n in part_names(name) if n in self._tex], self.part_texels(name))
        return self._tex[name]

    def items(self):
        return self._tex.items()

    def part_texels(self, name):
        """Texels in each full part of split buffer `name`: the driver's limit, rounded down
        to whole items."""
        unit = SPLIT[name]
        return self.max_texels // unit * unit

    def part_size(self, name):
        """Items (cylinders, list entries) in each full part of split buffer `name`."""
        return self.part_texels(name) // SPLIT[name]

    def parts(self, name):
        """Buffer textures split buffer `name` holds now (1 below the driver's limit)."""
        return sum(n in self._tex for n in part_names(name))

    def store(self, name, texels, components, dtype):
        """The buffer texture `name` with room for `texels` (a SplitBuffer for tex_cyl and
        tex_idx): the one already there when it fits and is not much bigger (allocating
        hundreds of MB costs as much as filling them on a CPU driver), else a new one with a
        little room to spare, so that a rebuild with a few more grid references reuses it.
        InputError past the driver's limit (for a split buffer, past its parts)."""
        if name in SPLIT:
            return self._store_split(name, texels, components, dtype)
        if texels > self.max_texels:
            raise InputError(f"scene too large for this GPU: {name} needs {texels:,} texels but the driver's "
                             f"buffer textures hold {self.max_texels:,}; render fewer strands or fewer "
                             "points per strand")
        return self._store_one(name, texels, components, dtype, self.max_texels)

    def _store_one(self, name, texels, components, dtype, most):
        old = self._tex.get(name)
        if old is not None and old.fits(texels, components, dtype) and old.capacity <= 2 * texels + (1 << 16):
            return old
        if old is not None:
            old.release()
        capacity = min(most, texels + texels // 64 + 64)
        store = BufferTexture(self.ctx, capacity, components, dtype)
        self._tex[name] = store
        return store

    def _store_split(self, name, texels, components, dtype):
        per = self.part_texels(name)
        n = max(1, -(-int(texels) // per))
        if n > layout.MAX_BUFFER_PARTS:
            raise InputError(f"scene too large for this GPU: {name} needs {texels:,} texels but the driver's "
                             f"buffer textures hold {self.max_texels:,} and the tracer splits one buffer over at "
                             f"most {layout.MAX_BUFFER_PARTS} of them ({layout.MAX_BUFFER_PARTS * per:,} texels); "
                             "render fewer strands or fewer points per strand")
        names = part_names(name)
        for k, part in enumerate(names[:n]):
            # Full parts hold `per` texels exactly; the last takes the rest.
            want = per if k < n - 1 else texels - per * (n - 1)
            self._store_one(part, want, components, dtype, per)
        for part in names[n:]:          # parts a bigger scene needed
            old = self._tex.pop(part, None)
            if old is not None:
                old.release()
        return self[name]

    def upload(self, name, data, components, dtype, slack=0):
        """`data` (texels x components) into buffer `name`, followed by `slack` zero texels."""
        data = np.ascontiguousarray(data, {"f4": np.float32, "i4": np.int32, "u4": np.uint32}[dtype])
        texels = len(data)
        store = self.store(name, texels + slack, components, dtype)
        store.write(data)
        if slack:
            store.write(np.zeros(slack * components, data.dtype), first=texels)
        self.stats.bytes_uploaded += data.nbytes
        return store

    def write(self, name, data, first):
        """`data` into buffer `name` from texel `first` on (the buffer holds them already)."""
        self[name].write(data, first=first)
        self.stats.bytes_uploaded += data.nbytes

    def release(self):
        """Gives every buffer back to the driver (hundreds of MB each for a big scene, in host
        memory on a CPU driver); the next set_strands allocates them again."""
        for store in self._tex.values():
            store.release()
        self._tex.clear()

    def bind(self, names):
        """Buffers `names` on texture units 0, 1, ... in that order (names it does not hold,
        such as parts a scene does not need, are skipped: their units stay unused)."""
        for unit, name in enumerate(names):
            store = self._tex.get(name)
            if store is not None:
                store.use(unit)

# SPDX-License-Identifier: GPL-3.0-or-later
"""The scene's buffer textures by name (tracer/gl_buffers.py), allocated within the
driver's limit, reused across uploads, every byte sent counted in the renderer's stats.

Names: tex_cyl (cylinders, tracer/layout.py), tex_idx (cell lists), tex_cell (cell table);
for the GPU build also the point arrays tex_pos, tex_rad, tex_col, tex_alpha and tex_cp
(cylinder -> top point).
"""
import numpy as np

from hairio import InputError

from .gl_buffers import BufferTexture


class SceneBuffers:
    def __init__(self, ctx, max_texels, stats):
        self.ctx = ctx
        self.max_texels = int(max_texels)
        self.stats = stats
        self._tex = {}

    def __getitem__(self, name):
        return self._tex[name]

    def items(self):
        return self._tex.items()

    def store(self, name, texels, components, dtype):
        """The buffer texture `name` with room for `texels`: the one already there when it
        fits and is not much bigger (allocating hundreds of MB costs as much as filling them
        on a CPU driver), else a new one with a little room to spare, so that a rebuild with
        a few more grid references reuses it. InputError past the driver's limit."""
        if texels > self.max_texels:
            raise InputError(f"scene too large for this GPU: {name} needs {texels:,} texels but the driver's "
                             f"buffer textures hold {self.max_texels:,}; render fewer strands or fewer "
                             "points per strand")
        old = self._tex.get(name)
        if old is not None and old.fits(texels, components, dtype) and old.capacity <= 2 * texels + (1 << 16):
            return old
        if old is not None:
            old.release()
        capacity = min(self.max_texels, texels + texels // 64 + 64)
        store = BufferTexture(self.ctx, capacity, components, dtype)
        self._tex[name] = store
        return store

    def upload(self, name, data, components, dtype, slack=0):
        """`data` (texels x components) into buffer `name`, followed by `slack` zero texels."""
        data = np.ascontiguousarray(data, np.float32 if dtype == "f4" else np.int32)
        texels = len(data)
        store = self.store(name, texels + slack, components, dtype)
        store.write(data)
        if slack:
            store.write(np.zeros(slack * components, data.dtype), first=texels)
        self.stats.bytes_uploaded += data.nbytes
        return store

    def write(self, name, data, first):
        """`data` into buffer `name` from texel `first` on (the buffer holds them already)."""
        self._tex[name].write(data, first=first)
        self.stats.bytes_uploaded += data.nbytes

    def bind(self, names):
        """Buffers `names` on texture units 0, 1, ... in that order."""
        for unit, name in enumerate(names):
            self._tex[name].use(unit)

# SPDX-License-Identifier: GPL-3.0-or-later
"""The scene's BVH on the GPU: built in numpy over the scene's cylinders (tracer/bvh.py), or
refitted when strands moved, then its walk texels and leaf pieces uploaded (tracer/layout.py's
layout; shaders/accel_bvh.glsl walks them). A refit sends only the chunks of the walk's texels
that changed: the boxes above the moved cylinders.
"""
import time

import numpy as np

from . import layout
from .bvh import build_bvh, refit_bvh, walk_texels
from .strand_upload import runs

# Partial uploads send the changed entries of the walk in whole chunks of this many entries,
# neighbouring chunks in one write (as tracer/strand_upload.py does for cylinders).
ENTRY_CHUNK = 256


def build_scene_bvh(scene, buffers, refit=False):
    """Builds (or with `refit`, when the scene's tree is over the same cylinders, refits) and
    uploads the BVH of `scene` (tracer/strand_upload.py's Scene). Sets scene.bvh and the
    stats; returns the seconds spent uploading."""
    stats = buffers.stats
    t0 = time.perf_counter()
    old = scene.bvh
    same = (refit and old is not None and scene.num_cylinders and len(old.ref_cyl)
            and old.ref_cyl[-1] == scene.num_cylinders - 1)
    before = walk_texels(old) if same else None
    if same:
        bvh = refit_bvh(old, scene.cylinders, scene.grid_pad)
    else:
        bvh = build_bvh(scene.cylinders, scene.grid_pad)
    texels = walk_texels(bvh)
    scene.bvh = bvh
    t1 = time.perf_counter()
    if before is None:
        buffers.upload("tex_node", texels, 4, "i4")
        buffers.upload("tex_order", bvh.leaf_texels(), 2, "i4")
    else:
        per = ENTRY_CHUNK * layout.WALK_TEXELS
        changed = np.flatnonzero(np.any(before != texels, axis=1)) // per
        if changed.size:
            for a, b in runs(changed):
                chunk = texels[a * per:b * per]
                buffers["tex_node"].write(chunk, first=a * per)
                stats.bytes_uploaded += chunk.nbytes
    t2 = time.perf_counter()
    stats.accel_s = t1 - t0
    stats.bvh_refit = before is not None
    stats.bvh_entries = len(texels) // layout.WALK_TEXELS
    stats.bvh_pieces = len(bvh.order)
    stats.accel_bytes = bvh.nbytes
    return t2 - t1


def bvh_bounds(bvh):
    """(lo, hi) float64 (3,): the box of every piece of the tree."""
    return bvh.lo[0].min(axis=0).astype(np.float64), bvh.hi[0].max(axis=0).astype(np.float64)

# SPDX-License-Identifier: GPL-3.0-or-later
"""A linear BVH over cylinders (Morton order), built and refitted in whole-array numpy.

Build: long cylinders are cut into pieces along their axis (SPLIT_LENGTH); every piece's
padded box (the grid's capsule bound, Cylinders.bounds, over its stretch of the axis) gives a
centre; the centres, quantised to MORTON_BITS per axis in the scene box, interleave into
63-bit Morton codes, and the pieces are sorted by code. The tree is the binary radix tree of the sorted
codes (Karras, HPG 2012), made top-down one level at a time for all ranges of a level
together: a range is split where its highest differing code bit flips (found by one
searchsorted on the sorted codes), in the middle where all its codes are equal, and becomes
a leaf once it holds at most layout.LEAF_MAX pieces. A leaf is a run of `order` (piece
numbers in code order), so every piece sits in exactly one leaf, and every cylinder keeps
its id: the trace shader orders equal distances by id and finds a strand's neighbours at
id ± 1.

Internal nodes are kept in depth-first order, each holding both children's boxes, so the
left child of node i is i + 1 wherever it is a node. The trace shader walks another layout
of the same tree (walk_texels): nodes and leaves in depth-first order, each with its own box
and the entry after its subtree, so that a walk needs no stack (accel_bvh.glsl says why).

Refit: boxes are remade bottom-up for new cylinder positions with the tree and the pieces
kept (a strand edit keeps its cylinders' ids); the renderer then uploads only the chunks of
the walk's texels that changed.

A child link: >= 0 the child node's index; < 0 a leaf, -layout.leaf_code(first, count) - 1
with `first` its first slot in `order`. Leaf size, codes and texel counts are the shader's
too: tracer/layout.py.
"""
from dataclasses import dataclass

import numpy as np

from . import layout

MORTON_BITS = 21        # per axis: 63-bit codes
# Long cylinders are cut into pieces no longer than this times the median cylinder length
# (at most MAX_PIECES): a thin diagonal segment's box is mostly air, and a ray entering it
# tests the cylinder for nothing. A piece is one entry of the tree with its own box; the
# shader keeps a hit only in the piece whose stretch of the axis holds the entry point, so
# every cylinder still counts once. 0 = no cuts. See benchmarks/sections/accel.py.
SPLIT_LENGTH = 1.0
# Boxes are widened by this fraction of the scene's scale (its extent or its distance from
# the origin, the larger): the shader's slab test runs in float32 from a camera that may be
# far off, and a hit point must never fall outside its box by rounding.
BOX_EPS = 2.0 ** -18


@dataclass(eq=False)
class Bvh:
    """`order` (R,) int32 piece numbers, leaf by leaf; per internal node (M of them, depth
    first, root 0): `lo`, `hi` (M, 2, 3) float32 boxes of its two children, `link` (M, 2)
    int32 (see the module); `level` (M,) depth of each node (root 0); `depth` the most nodes
    on a path from the root; `leaf_first`, `leaf_count`, `leaf_node`, `leaf_side` per leaf
    (its slots in `order` and the child slot that links it), for refits; per piece
    `ref_cyl` (R,) its cylinder and `ref_part` (R,) layout.piece_code(k, K), piece k of K."""
    order: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    link: np.ndarray
    level: np.ndarray
    depth: int
    leaf_first: np.ndarray
    leaf_count: np.ndarray
    leaf_node: np.ndarray
    leaf_side: np.ndarray
    ref_cyl: np.ndarray
    ref_part: np.ndarray

    def leaf_texels(self):
        """(R, 2) int32, the shader's tex_order: per slot of `order`, the piece's cylinder id
        and layout.piece_code(k, K) (piece k of K)."""
        return np.stack([self.ref_cyl[self.order], self.ref_part[self.order]], axis=1)

    @property
    def num_nodes(self):
        return len(self.link)

    @property
    def nbytes(self):
        """Bytes the shader reads: the walk's texels (nodes and leaves) and the leaf order."""
        entries = self.num_nodes + int(np.count_nonzero(self.link < 0))
        return entries * layout.WALK_TEXELS * 16 + len(self.order) * 8


def leaf_link(first, count):
    return -layout.leaf_code(first, count) - 1


def unpack_leaf(link):
    """(first, count) of leaf links (< 0)."""
    v = -np.asarray(link, np.int64) - 1
    return v >> layout.LEAF_BITS, v & ((1 << layout.LEAF_BITS) - 1)


def _spread_bits(x):
    """The 21 low bits of x (uint64) moved to every third bit (bit i -> bit 3i)."""
    x = x & np.uint64(0x1FFFFF)
    for shift, mask in ((32, 0x1F00000000FFFF), (16, 0x1F0000FF0000FF), (8, 0x100F00F00F00F00F),
                        (4, 0x10C30C30C30C30C3), (2, 0x1249249249249249)):
        x = (x | (x << np.uint64(shift))) & np.uint64(mask)
    return x


def morton_codes(centres, lo, hi):
    """63-bit Morton codes (uint64) of points (N,3) in the box lo..hi."""
    scale = (1 << MORTON_BITS) - 1
    code = np.zeros(len(centres), np.uint64)
    for j in range(3):
        q = (centres[:, j] - lo[j]) * (scale / max(hi[j] - lo[j], 1e-300))
        code |= _spread_bits(np.clip(q, 0, scale).astype(np.uint64)) << np.uint64(2 - j)
    return code


def _highest_bit(x):
    """Index of the highest set bit of uint64 x > 0, exactly (float64 rounds above 2^53, so
    the two 32-bit halves are taken apart)."""
    hi32 = (x >> np.uint64(32)).astype(np.float64)
    lo32 = (x & np.uint64(0xFFFFFFFF)).astype(np.float64)
    return np.where(hi32 > 0, np.frexp(hi32)[1] + 31, np.frexp(lo32)[1] - 1)


def split_counts(cylinders, split_length=None):
    """Pieces per cylinder (int32, 1..layout.MAX_PIECES): ceil(length / split_length), where
    split_length defaults to SPLIT_LENGTH times the median cylinder length."""
    n = len(cylinders)
    if n == 0 or not SPLIT_LENGTH:
        return np.ones(n, np.int32)
    ax = cylinders.tip.astype(np.float64) - cylinders.top
    length = np.sqrt(np.einsum("ij,ij->i", ax, ax))
    if split_length is None:
        split_length = SPLIT_LENGTH * float(np.median(length))
    return np.clip(np.ceil(length / max(split_length, 1e-300)), 1, layout.MAX_PIECES).astype(np.int32)


def piece_boxes(cylinders, ref_cyl, ref_part, pad_factor=1.0):
    """float64 (lo, hi), each (R, 3), per piece: piece k of K of cylinder c covers the axis
    parameter u in [k/K, (k+1)/K] (u = 0 at the top, 1 at the tip; the last piece on to the
    tip's extension, where a bent cut reaches past it), padded by the radius times
    pad_factor."""
    lo, hi = _piece_rows(cylinders, ref_cyl, ref_part, pad_factor)
    return lo.T, hi.T


def _piece_rows(cylinders, ref_cyl, ref_part, pad_factor):
    """piece_boxes as (3, R) rows: numpy walks an (R, 3) array three values at a time, and
    row by row the build ran twice as fast."""
    top = np.ascontiguousarray(cylinders.top.T, np.float64)
    ax = np.ascontiguousarray(cylinders.tip.T, np.float64) - top
    length = np.sqrt(np.einsum("ij,ij->j", ax, ax))
    k, K = _unpack_piece(ref_part)
    kf, Kf = k.astype(np.float64), K.astype(np.float64)
    u0 = kf / Kf
    reach = 1.0 + cylinders.extension.astype(np.float64) / np.maximum(length, 1e-30)
    u1 = np.where(k == K - 1, reach[ref_cyl], (kf + 1) / Kf)
    r = cylinders.radius.astype(np.float64)[ref_cyl] * pad_factor
    lo, hi = np.empty((3, len(ref_cyl))), np.empty((3, len(ref_cyl)))
    for j in range(3):
        t, a = top[j][ref_cyl], ax[j][ref_cyl]
        e0, e1 = t + u0 * a, t + u1 * a
        lo[j] = np.minimum(e0, e1) - r
        hi[j] = np.maximum(e0, e1) + r
    return lo, hi


def build_bvh(cylinders, pad_factor=1.0, split_length=None):
    """Bvh over `cylinders` (tracer.cylinders.Cylinders), boxes padded as the grid's are;
    long cylinders are cut into pieces (split_counts)."""
    pieces = split_counts(cylinders, split_length)
    ref_cyl = np.repeat(np.arange(len(cylinders), dtype=np.int32), pieces)
    first = np.cumsum(pieces) - pieces
    ref_part = layout.piece_code(np.arange(len(ref_cyl)) - np.repeat(first, pieces),
                                 np.repeat(pieces, pieces)).astype(np.int32)
    blo, bhi = _piece_rows(cylinders, ref_cyl, ref_part, pad_factor)
    n = blo.shape[1]
    if n == 0:
        return _assemble(np.zeros(0, np.int32), [], blo, bhi, ref_cyl, ref_part)
    lo, hi = blo.min(axis=1), bhi.max(axis=1)
    codes = morton_codes((0.5 * (blo + bhi)).T, lo, hi)
    order = np.argsort(codes, kind="stable").astype(np.int32)
    codes = codes[order]
    # Ranges of one level at a time: [a, b) of the sorted codes, their parent and side.
    a, b = np.array([0]), np.array([n])
    levels = []
    while len(a):
        x = codes[a] ^ codes[b - 1]
        same = x == 0
        bit = _highest_bit(np.where(same, np.uint64(1), x)).astype(np.uint64)
        # All codes of a range share the bits above `bit`: the split is the first code with
        # that bit set, i.e. the first code >= (the common prefix | that bit), searched for
        # inside the range.
        prefix = (codes[a] >> (bit + np.uint64(1))) << (bit + np.uint64(1))
        split = _first_at_least(codes, prefix | (np.uint64(1) << bit), a, b)
        split = np.where(same, (a + b) // 2, split)
        levels.append((a, b, split))
        # Children that still hold more than LEAF_MAX pieces are the next level's ranges.
        ca, cb = np.concatenate([a, split]), np.concatenate([split, b])
        inner = cb - ca > layout.LEAF_MAX
        a, b = ca[inner], cb[inner]
    if n <= layout.LEAF_MAX:       # one leaf: a root whose right child is empty
        levels = [(np.array([0]), np.array([n]), np.array([n]))]
    return _assemble(order, levels, blo, bhi, ref_cyl, ref_part)


def _first_at_least(codes, target, a, b):
    """Per range [a, b) of sorted `codes`, the first index whose code is >= target: one
    bisection step for all ranges at a time, log2 of the longest range steps. (searchsorted
    over the whole array took a third of the build at 10 M pieces: every query walks the
    full array's depth through cold memory.)"""
    lo, hi = a.copy(), b.copy()
    while True:
        active = lo < hi
        if not active.any():
            return lo
        mid = (lo + hi) >> 1
        below = codes[np.minimum(mid, len(codes) - 1)] < target
        lo = np.where(active & below, mid + 1, lo)
        hi = np.where(active & ~below, mid, hi)


def _assemble(order, levels, blo, bhi, ref_cyl, ref_part):
    """Nodes in depth-first order from the levels' ranges (level k: arrays a, b, split, the
    ranges in the order their parents listed them: all left children, then all right ones)."""
    if not levels:
        z = np.zeros(0, np.int64)
        return Bvh(order, np.zeros((0, 2, 3), np.float32), np.zeros((0, 2, 3), np.float32),
                   np.zeros((0, 2), np.int32), z, 0, z, z, z, z, ref_cyl, ref_part)
    # Per level: for each node its children's ranges and which of them are nodes; the index
    # of each child node within the next level follows from the concatenation order.
    info = []
    for a, b, s in levels:
        ca, cb = np.concatenate([a, s]), np.concatenate([s, b])
        inner = cb - ca > layout.LEAF_MAX
        nxt = np.cumsum(inner) - 1          # index in the next level where inner
        m = len(a)
        info.append((a, b, s, inner.reshape(2, m).T, nxt.reshape(2, m).T))
    # Subtree sizes (internal nodes), deepest level first.
    sizes = [None] * len(levels)
    below = None
    for k in range(len(levels) - 1, -1, -1):
        inner, nxt = info[k][3], info[k][4]
        size = np.ones(len(inner), np.int64)
        if below is not None:
            for side in (0, 1):
                size += np.where(inner[:, side], below[np.where(inner[:, side], nxt[:, side], 0)], 0)
        sizes[k] = size
        below = size
    # Depth-first positions, root first: left child at parent + 1, right child after the
    # left subtree.
    pos = [None] * len(levels)
    pos[0] = np.zeros(1, np.int64)
    for k in range(len(levels) - 1):
        inner, nxt = info[k][3], info[k][4]
        child_pos = np.empty(len(sizes[k + 1]), np.int64)
        left_size = np.where(inner[:, 0], sizes[k + 1][np.where(inner[:, 0], nxt[:, 0], 0)], 0)
        for side in (0, 1):
            sel = inner[:, side]
            child_pos[nxt[sel, side]] = pos[k][sel] + 1 + (left_size[sel] if side else 0)
        pos[k + 1] = child_pos
    m = int(sizes[0][0])
    link = np.zeros((m, 2), np.int64)
    level = np.zeros(m, np.int64)
    leaves = []
    for k, (a, b, s, inner, nxt) in enumerate(info):
        p = pos[k]
        level[p] = k
        for side in (0, 1):
            first, end = (a, s) if side == 0 else (s, b)
            sel = inner[:, side]
            if sel.any():
                link[p[sel], side] = pos[k + 1][nxt[sel, side]]
            leaves.append((first[~sel], end[~sel] - first[~sel], p[~sel], np.full((~sel).sum(), side)))
    leaf_first, leaf_count, leaf_node, leaf_side = (np.concatenate(x) for x in zip(*leaves))
    link[leaf_node, leaf_side] = leaf_link(leaf_first, leaf_count)
    bvh = Bvh(order, np.zeros((m, 2, 3), np.float32), np.zeros((m, 2, 3), np.float32),
              link.astype(np.int32), level, len(levels), leaf_first, leaf_count, leaf_node, leaf_side,
              ref_cyl, ref_part)
    _fit(bvh, blo, bhi)
    return bvh


def _fit(bvh, blo, bhi):
    """Every node's child boxes from the piece boxes (float64 (3, R) rows), bottom-up. Works
    on (side, axis, node) rows, one contiguous array per side and axis, and writes the
    (node, side, axis) float32 boxes at the end."""
    if not bvh.num_nodes:
        return
    lo_all, hi_all = blo.min(axis=1), bhi.max(axis=1)
    scale = max(float(np.max(hi_all - lo_all)), float(np.max(np.abs(np.concatenate([lo_all, hi_all])))), 1e-30)
    eps = BOX_EPS * scale
    m = bvh.num_nodes
    lo = np.full((2, 3, m), np.inf)
    hi = np.full((2, 3, m), -np.inf)
    full = bvh.leaf_count > 0
    if full.any():
        # Leaves tile `order`; reduceat wants increasing starts.
        srt = np.argsort(bvh.leaf_first[full])
        starts = bvh.leaf_first[full][srt]
        node, side = bvh.leaf_node[full][srt], bvh.leaf_side[full][srt]
        for j in range(3):
            llo = np.minimum.reduceat(blo[j][bvh.order], starts)
            lhi = np.maximum.reduceat(bhi[j][bvh.order], starts)
            for sd in (0, 1):
                mine = side == sd
                lo[sd, j, node[mine]] = llo[mine]
                hi[sd, j, node[mine]] = lhi[mine]
    # Internal children, deepest level first: a child's box is the union of its own two.
    by_level = np.argsort(bvh.level, kind="stable")
    bounds = np.searchsorted(bvh.level[by_level], np.arange(bvh.depth + 1))
    for k in range(bvh.depth - 1, -1, -1):
        nodes = by_level[bounds[k]:bounds[k + 1]]
        for sd in (0, 1):
            child = bvh.link[nodes, sd]
            sel = child >= 0
            c, parent = child[sel], nodes[sel]
            for j in range(3):
                lo[sd, j, parent] = np.minimum(lo[0, j][c], lo[1, j][c])
                hi[sd, j, parent] = np.maximum(hi[0, j][c], hi[1, j][c])
    # Rounded outwards to float32 and widened (see BOX_EPS); an empty child gets an inverted
    # box that no slab test passes.
    empty = ~np.isfinite(lo)
    lo32 = np.nextafter((lo - eps).astype(np.float32), np.float32(-np.inf))
    hi32 = np.nextafter((hi + eps).astype(np.float32), np.float32(np.inf))
    lo32[empty], hi32[empty] = 1.0, -1.0
    bvh.lo[:] = lo32.transpose(2, 0, 1)
    bvh.hi[:] = hi32.transpose(2, 0, 1)


def refit_bvh(bvh, cylinders, pad_factor=1.0):
    """New boxes for moved cylinders (same count and ids), the tree and pieces kept; returns
    `bvh`."""
    if len(bvh.ref_cyl) and bvh.ref_cyl[-1] != len(cylinders) - 1:
        raise ValueError(f"refit_bvh: {len(cylinders)} cylinders for a tree over {bvh.ref_cyl[-1] + 1}")
    blo, bhi = _piece_rows(cylinders, bvh.ref_cyl, bvh.ref_part, pad_factor)
    _fit(bvh, blo, bhi)
    return bvh


def bvh_stats(bvh):
    """Node count, leaves, mean cylinders per leaf, depth and bytes, for reports."""
    full = bvh.leaf_count > 0
    return {"nodes": bvh.num_nodes, "leaves": int(full.sum()),
            "cylinders_per_leaf": float(bvh.leaf_count[full].mean()) if full.any() else 0.0,
            "depth": bvh.depth, "bytes": bvh.nbytes}


# --- traversal in numpy (the shader's walk, one ray at a time: for tests and work counts) ---

def slab(lo, hi, o, inv, t0, t1):
    """Entry distances of a ray into boxes (K,3) clipped to [t0, t1]; inf where it misses."""
    ta, tb = (lo - o) * inv, (hi - o) * inv
    tn = np.maximum(np.minimum(ta, tb).max(axis=-1), t0)
    tf = np.minimum(np.maximum(ta, tb).min(axis=-1), t1)
    return np.where(tn <= tf, tn, np.inf)


def safe_inverse(d):
    s = np.where(d != 0, np.sign(d), 1.0)
    return 1.0 / (s * np.maximum(np.abs(d), 1e-30))


def _unpack_piece(ref_part):
    return ref_part & ((1 << layout.PIECE_BITS) - 1), ref_part >> layout.PIECE_BITS


def piece_holds(ref_part, u):
    """Whether piece k of K (ref_part = layout.piece_code(k, K)) holds axis parameter u:
    [k/K, (k+1)/K), open to -inf for the first piece and to +inf for the last (the shader's
    rule)."""
    k, K = _unpack_piece(ref_part)
    lo = np.where(k == 0, -np.inf, k / K)
    hi = np.where(k == K - 1, np.inf, (k + 1) / K)
    return (u >= lo) & (u < hi)


def traverse(bvh, o, d, hit, t_max=np.inf, any_hit=False, texels=None):
    """The nearest hit of one ray as the shader walks walk_texels: depth-first, into a node
    the ray enters, else past its subtree; boxes clipped to the distance of the hit past
    which nothing can change the image (here: the nearest so far). `hit(ids)` -> (distances,
    inf on a miss; axis parameters u of the entry points). A hit counts only in the piece
    that holds its u. Returns (t, id, boxes tested, pieces tested); (inf, -1, ...) on no
    hit in (0, t_max). `any_hit`: stop at the first hit (hard shadows)."""
    o, d = np.asarray(o, np.float64), np.asarray(d, np.float64)
    inv = safe_inverse(d)
    tex = (walk_texels(bvh) if texels is None else texels).reshape(-1, layout.WALK_TEXELS, 4)
    lo, hi = tex[:, 0, :3].view(np.float32).astype(np.float64), tex[:, 1, :3].view(np.float32).astype(np.float64)
    skip, leaf = tex[:, 0, 3], tex[:, 1, 3]
    best_t, best_id = np.inf, -1
    boxes = tests = 0
    i = 0
    while i < len(tex):
        boxes += 1
        enter = np.isfinite(slab(lo[i], hi[i], o, inv, 0.0, min(best_t, t_max)))
        if enter and leaf[i] != layout.BVH_NODE:
            first, count = leaf[i] >> layout.LEAF_BITS, leaf[i] & ((1 << layout.LEAF_BITS) - 1)
            refs = bvh.order[first:first + count]
            ids = bvh.ref_cyl[refs]
            tests += len(ids)
            t, u = hit(ids)
            ok = (t > 0) & (t < t_max) & piece_holds(bvh.ref_part[refs], u)
            for ti, ci in zip(t[ok], ids[ok]):
                if ti < best_t or (ti == best_t and ci < best_id):
                    best_t, best_id = float(ti), int(ci)
            if any_hit and best_id >= 0:
                break
        i = i + 1 if enter and leaf[i] == layout.BVH_NODE else int(skip[i])
    return best_t, best_id, boxes, tests


def walk_texels(bvh):
    """(K * WALK_TEXELS, 4) int32: every node and leaf (K of them) in depth-first order,
    each as (lo, skip) (hi, code): box corners as float bits, `skip` the position after its
    subtree, `code` layout.BVH_NODE for a node, layout.leaf_code(first, count) for a leaf.
    A walk needs no stack: from position i it goes on to i + 1 when the ray enters box i and
    i is a node, else to skip."""
    m = bvh.num_nodes
    if not m:
        return np.zeros((0, 4), np.int32)
    # Hair is a shell seen from outside: of two children, the one farther from the
    # scene's centre is walked first, so a camera ray tends to meet the near hair first
    # (10,000 wavy strands: 1 % fewer boxes and 5 % fewer tests per primary ray).
    centre = 0.5 * (bvh.lo[0].min(axis=0) + bvh.hi[0].max(axis=0)).astype(np.float64)
    mid = 0.5 * (bvh.lo.astype(np.float64) + bvh.hi)
    dist = np.einsum("ijk,ijk->ij", mid - centre, mid - centre)
    swap = dist[:, 1] > dist[:, 0]
    sw = swap[:, None]
    bvh = Bvh(bvh.order, np.where(sw[..., None], bvh.lo[:, ::-1], bvh.lo),
              np.where(sw[..., None], bvh.hi[:, ::-1], bvh.hi), np.where(sw, bvh.link[:, ::-1], bvh.link),
              bvh.level, bvh.depth, None, None, None, None, bvh.ref_cyl, bvh.ref_part)
    is_leaf = bvh.link < 0
    size = np.ones(m, np.int64)           # nodes and leaves in each node's subtree
    for k in range(bvh.depth - 1, -1, -1):
        nodes = np.flatnonzero(bvh.level == k)
        for side in (0, 1):
            child = bvh.link[nodes, side]
            size[nodes] += np.where(child < 0, 1, size[np.maximum(child, 0)])
    pos = np.zeros(m, np.int64)
    for k in range(bvh.depth):
        nodes = np.flatnonzero(bvh.level == k)
        for side in (0, 1):
            child = bvh.link[nodes, side]
            inner = child >= 0
            left = bvh.link[nodes, 0]
            left_size = np.where(left < 0, 1, size[np.maximum(left, 0)])
            pos[child[inner]] = pos[nodes[inner]] + 1 + (left_size[inner] if side else 0)
    total = int(size[0])
    out = np.zeros((total, 2, 4), np.int32)
    # Nodes: their box is the union of their children's.
    out[pos, 0, :3] = bvh.lo.min(axis=1).view(np.int32)
    out[pos, 1, :3] = bvh.hi.max(axis=1).view(np.int32)
    out[pos, 0, 3] = pos + size
    out[pos, 1, 3] = layout.BVH_NODE
    # Leaves: right after their node (left) or after the left subtree (right).
    left_size = np.where(is_leaf[:, 0], 1, size[np.maximum(bvh.link[:, 0], 0)])
    for side in (0, 1):
        sel = np.flatnonzero(is_leaf[:, side])
        lp = pos[sel] + 1 + (left_size[sel] if side else 0)
        out[lp, 0, :3] = bvh.lo[sel, side].view(np.int32)
        out[lp, 1, :3] = bvh.hi[sel, side].view(np.int32)
        out[lp, 0, 3] = lp + 1
        out[lp, 1, 3] = -bvh.link[sel, side] - 1
    return out.reshape(-1, 4)

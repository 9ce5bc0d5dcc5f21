# SPDX-License-Identifier: GPL-3.0-or-later
"""The BVH's invariants (tracer/bvh.py): every piece of every cylinder in exactly one leaf,
every box holds what is below it, a hit counts in exactly one piece, and the walk finds the
hit a test of every cylinder finds."""
import numpy as np
import pytest

from tracer import layout
from tracer.bvh import (build_bvh, piece_boxes, piece_holds, refit_bvh, split_counts, traverse, unpack_leaf,
                        walk_texels)
from tracer.cylinders import strands_to_cylinders
from tracer.reference.shapes import CylinderSet, intersect

from tracer_scenes import curls, make_strands


def _scenes():
    rng = np.random.default_rng(3)
    # Cylinders with one centre and lengths over a decade: equal Morton codes (split in the
    # middle) and long ones cut into pieces.
    star = [np.array([-d, d]) * s for d, s in zip(rng.normal(size=(40, 3)), rng.uniform(0.2, 3.0, 40))]
    return {"one cylinder": make_strands([[(0, 0, 0), (0, 0, 1)]]),
            "a few": curls(1, 4),
            "tuft": curls(60, 12, seed=5),
            "star of equal centres": make_strands(star, radius=0.01)}


SCENES = _scenes()


def _leaf_pieces(bvh):
    first, count = unpack_leaf(bvh.link[bvh.link < 0])
    return np.concatenate([bvh.order[f:f + n] for f, n in zip(first, count)]), count


@pytest.mark.parametrize("name", list(SCENES))
def test_every_piece_lies_in_exactly_one_leaf(name):
    c = strands_to_cylinders(SCENES[name])
    bvh = build_bvh(c)
    pieces, count = _leaf_pieces(bvh)
    assert count.max() <= layout.LEAF_MAX
    assert np.array_equal(np.sort(pieces), np.arange(len(bvh.ref_cyl)))
    # Each cylinder's pieces are k = 0..K-1 of the K split_counts gives it.
    K = split_counts(c)
    assert np.array_equal(np.bincount(bvh.ref_cyl, minlength=len(c)), K)
    k, KK = bvh.ref_part & ((1 << layout.PIECE_BITS) - 1), bvh.ref_part >> layout.PIECE_BITS
    assert np.array_equal(KK, K[bvh.ref_cyl])
    first = np.cumsum(K) - K
    assert np.array_equal(k, np.arange(len(k)) - first[bvh.ref_cyl])
    # Depth-first: a node's children come after it, the left one right after it; every node
    # but the root is linked exactly once.
    for side in (0, 1):
        child = bvh.link[:, side]
        assert np.all(child[child >= 0] > np.flatnonzero(child >= 0))
    left = bvh.link[:, 0]
    assert np.all(left[left >= 0] == np.flatnonzero(left >= 0) + 1)
    assert np.array_equal(np.sort(bvh.link[bvh.link >= 0]), np.arange(1, bvh.num_nodes))


def test_long_cylinders_are_cut_and_short_ones_are_not():
    c = strands_to_cylinders(SCENES["star of equal centres"])
    K = split_counts(c)
    length = np.linalg.norm(c.tip - c.top, axis=1)
    assert K.max() > 1 and K.min() == 1
    assert np.all(np.diff(K[np.argsort(length)]) >= 0)      # longer, never fewer pieces


def _assert_boxes_contain(bvh, c, pad=1.0):
    blo, bhi = piece_boxes(c, bvh.ref_cyl, bvh.ref_part, pad)
    # Every piece's box holds the part of its capsule along its stretch of the axis.
    clo, chi = c.bounds(pad)
    for cyl in range(len(c)):
        mine = bvh.ref_cyl == cyl
        assert np.allclose(blo[mine].min(axis=0), clo[cyl], atol=1e-6)
        assert np.allclose(bhi[mine].max(axis=0), chi[cyl], atol=1e-6)
    for node in range(bvh.num_nodes):
        for side in (0, 1):
            lo, hi = bvh.lo[node, side], bvh.hi[node, side]
            link = int(bvh.link[node, side])
            if link >= 0:
                assert np.all(lo <= bvh.lo[link].min(axis=0)) and np.all(hi >= bvh.hi[link].max(axis=0))
            else:
                f, n = unpack_leaf(link)
                refs = bvh.order[f:f + n]
                if n == 0:
                    assert np.all(lo > hi)      # an empty child no ray enters
                else:
                    assert np.all(lo <= blo[refs].min(axis=0)) and np.all(hi >= bhi[refs].max(axis=0))


@pytest.mark.parametrize("name", list(SCENES))
@pytest.mark.parametrize("pad", [1.0, 8.0])
def test_boxes_contain_their_children_and_pieces(name, pad):
    c = strands_to_cylinders(SCENES[name])
    _assert_boxes_contain(build_bvh(c, pad), c, pad)


def test_walk_texels_hold_every_box_and_leaf_once_in_depth_first_order():
    c = strands_to_cylinders(SCENES["tuft"])
    bvh = build_bvh(c)
    tex = walk_texels(bvh).reshape(-1, layout.WALK_TEXELS, 4)
    lo, hi = tex[:, 0, :3].view(np.float32), tex[:, 1, :3].view(np.float32)
    skip, code = tex[:, 0, 3], tex[:, 1, 3]
    n = len(tex)
    assert n == bvh.num_nodes + np.count_nonzero(bvh.link < 0)
    assert skip[0] == n                     # the root's subtree is everything
    assert np.all(skip > np.arange(n)) and np.all(skip <= n)
    is_leaf = code != layout.BVH_NODE
    assert np.all(skip[is_leaf] == np.flatnonzero(is_leaf) + 1)
    first, count = code[is_leaf] >> layout.LEAF_BITS, code[is_leaf] & ((1 << layout.LEAF_BITS) - 1)
    pieces = np.concatenate([bvh.order[f:f + m] for f, m in zip(first, count)])
    assert np.array_equal(np.sort(pieces), np.arange(len(bvh.ref_cyl)))
    for i in np.flatnonzero(~is_leaf):
        sub = slice(i + 1, skip[i])
        assert np.all(lo[i] <= lo[sub]) and np.all(hi[i] >= hi[sub])


def _rays(c, n, seed):
    """Rays from outside the scene towards random points near cylinders (most hit)."""
    rng = np.random.default_rng(seed)
    centre = 0.5 * (c.top + c.tip).astype(np.float64)
    target = centre[rng.integers(0, len(c), n)] + rng.normal(scale=0.02, size=(n, 3))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    return target - 3.0 * d, d


def _hit_fn(cyl, o, d):
    """hit(ids) -> (t, u) for one ray: entry distances and the entry points' axis parameter."""
    def hit(ids):
        oo, dd = np.broadcast_to(o, (len(ids), 3)), np.broadcast_to(d, (len(ids), 3))
        t = intersect(cyl, ids, oo, dd)[0]
        ax = cyl.tip[ids] - cyl.top[ids]
        with np.errstate(invalid="ignore"):
            u = np.einsum("ij,ij->i", oo + t[:, None] * dd - cyl.top[ids], ax) / np.einsum("ij,ij->i", ax, ax)
        return t, u
    return hit


@pytest.mark.parametrize("name", list(SCENES))
def test_walk_finds_the_nearest_hit_of_brute_force(name):
    c = strands_to_cylinders(SCENES[name])
    cyl = CylinderSet(c)
    bvh = build_bvh(c)
    every = np.arange(len(c))
    o, d = _rays(c, 60, seed=1)
    hits = total_tests = 0
    for k in range(len(o)):
        hit = _hit_fn(cyl, o[k], d[k])
        t_all = hit(every)[0]
        t_all = np.where(t_all > 0, t_all, np.inf)
        t, i, boxes, tests = traverse(bvh, o[k], d[k], hit)
        total_tests += tests
        if np.isfinite(t_all.min()):
            hits += 1
            assert i == int(np.argmin(t_all)) and t == t_all.min()
        else:
            assert i == -1
        # Any-hit (hard shadows) within a segment: a hit exactly when brute force has one there.
        t_max = 3.0
        ta, ia, _, _ = traverse(bvh, o[k], d[k], hit, t_max=t_max, any_hit=True)
        assert (ia >= 0) == bool(np.any(t_all < t_max))
        if ia >= 0:
            assert 0 < ta < t_max
    assert hits >= 10, "too few rays hit: the test would prove little"
    if name == "tuft":      # spread-out hair: the walk tests a small part of it per ray
        assert total_tests < 0.1 * len(o) * len(c)


def test_a_hit_counts_in_exactly_one_piece():
    c = strands_to_cylinders(SCENES["star of equal centres"])
    cyl = CylinderSet(c)
    bvh = build_bvh(c)
    long = np.flatnonzero(split_counts(c) > 2)
    rng = np.random.default_rng(9)
    counted = 0
    for cid in long:
        K = int(np.count_nonzero(bvh.ref_cyl == cid))
        # Rays aimed at the piece boundaries u = k/K (and between them) from the side.
        for u in np.concatenate([np.arange(K + 1) / K, rng.uniform(0, 1, 4)]):
            target = cyl.top[cid] + u * (cyl.tip[cid] - cyl.top[cid])
            d = np.cross(cyl.tip[cid] - cyl.top[cid], rng.normal(size=3))
            d /= np.linalg.norm(d)
            t, uu = _hit_fn(cyl, target - 2 * d, d)(np.array([cid]))
            if not np.isfinite(t[0]):
                continue
            counted += 1
            parts = bvh.ref_part[bvh.ref_cyl == cid]
            assert np.count_nonzero(piece_holds(parts, uu[0])) == 1
    assert counted > 10


def test_refit_follows_moved_cylinders_and_matches_a_rebuild():
    strands = SCENES["tuft"]
    c = strands_to_cylinders(strands)
    bvh = build_bvh(c)
    pts = strands.points.copy()
    sel = np.repeat(np.arange(strands.num_strands) % 7 == 0, strands.counts)
    pts[sel] += np.array([0.4, -0.2, 0.3])          # some strands move far
    moved = type(strands).from_arrays(pts, strands.counts, radius=strands.radius, color=strands.color,
                                      alpha=strands.alpha)
    c2 = strands_to_cylinders(moved)
    refit_bvh(bvh, c2)
    _assert_boxes_contain(bvh, c2)
    fresh = build_bvh(c2)
    cyl = CylinderSet(c2)
    o, d = _rays(c2, 40, seed=2)
    for k in range(len(o)):
        hit = _hit_fn(cyl, o[k], d[k])
        assert traverse(bvh, o[k], d[k], hit)[:2] == traverse(fresh, o[k], d[k], hit)[:2]
    with pytest.raises(ValueError):
        refit_bvh(bvh, strands_to_cylinders(curls(2, 5)))

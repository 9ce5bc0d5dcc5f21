# SPDX-License-Identifier: GPL-3.0-or-later
"""The BVH's invariants (tracer/bvh.py): every cylinder in exactly one leaf, every box holds
what is below it, and its walk finds the hit a test of every cylinder finds."""
import numpy as np
import pytest

from tracer.bvh import LEAF_MAX, LEAF_SLOTS, WALK_TEXELS, build_bvh, refit_bvh, traverse, unpack_leaf, walk_texels
from tracer.cylinders import strands_to_cylinders
from tracer.reference import _Cyl, intersect

from tracer_scenes import curls, make_strands


def _scenes():
    rng = np.random.default_rng(3)
    # Many cylinders with the same centre: equal Morton codes, split in the middle.
    star = [np.array([-d, d]) for d in rng.normal(size=(40, 3))]
    return {"one cylinder": make_strands([[(0, 0, 0), (0, 0, 1)]]),
            "a few": curls(1, 4),
            "tuft": curls(60, 12, seed=5),
            "star of equal centres": make_strands(star, radius=0.01)}


SCENES = _scenes()


def _leaves(bvh):
    first, count = unpack_leaf(bvh.link[bvh.link < 0])
    return first, count


@pytest.mark.parametrize("name", list(SCENES))
def test_every_cylinder_lies_in_exactly_one_leaf(name):
    c = strands_to_cylinders(SCENES[name])
    bvh = build_bvh(c)
    first, count = _leaves(bvh)
    assert count.max() <= LEAF_MAX
    ids = np.concatenate([bvh.order[f:f + n] for f, n in zip(first, count)])
    assert np.array_equal(np.sort(ids), np.arange(len(c)))
    # Depth-first: a node's children come after it, the left one right after it.
    for side in (0, 1):
        child = bvh.link[:, side]
        inner = child >= 0
        assert np.all(child[inner] > np.flatnonzero(inner))
    left = bvh.link[:, 0]
    assert np.all(left[left >= 0] == np.flatnonzero(left >= 0) + 1)
    # Every node but the root is linked exactly once.
    linked = bvh.link[bvh.link >= 0]
    assert np.array_equal(np.sort(linked), np.arange(1, bvh.num_nodes))


def _assert_boxes_contain(bvh, c, pad=1.0):
    blo, bhi = c.bounds(pad)
    for node in range(bvh.num_nodes):
        for side in (0, 1):
            lo, hi = bvh.lo[node, side], bvh.hi[node, side]
            link = int(bvh.link[node, side])
            if link >= 0:
                assert np.all(lo <= bvh.lo[link].min(axis=0)) and np.all(hi >= bvh.hi[link].max(axis=0))
            else:
                f, n = unpack_leaf(link)
                ids = bvh.order[f:f + n]
                if n == 0:
                    assert np.all(lo > hi)      # an empty child no ray enters
                else:
                    assert np.all(lo <= blo[ids].min(axis=0)) and np.all(hi >= bhi[ids].max(axis=0))


@pytest.mark.parametrize("name", list(SCENES))
@pytest.mark.parametrize("pad", [1.0, 8.0])
def test_boxes_contain_their_children_and_cylinders(name, pad):
    c = strands_to_cylinders(SCENES[name])
    _assert_boxes_contain(build_bvh(c, pad), c, pad)


def test_walk_texels_hold_every_box_and_leaf_once_in_depth_first_order():
    c = strands_to_cylinders(SCENES["tuft"])
    bvh = build_bvh(c)
    tex = walk_texels(bvh).reshape(-1, WALK_TEXELS, 4)
    lo, hi = tex[:, 0, :3].view(np.float32), tex[:, 1, :3].view(np.float32)
    skip, leaf = tex[:, 0, 3], tex[:, 1, 3]
    n = len(tex)
    assert n == bvh.num_nodes + np.count_nonzero(bvh.link < 0)
    assert skip[0] == n                     # the root's subtree is everything
    assert np.all(skip > np.arange(n)) and np.all(skip <= n)
    is_leaf = leaf >= 0
    assert np.all(skip[is_leaf] == np.flatnonzero(is_leaf) + 1)
    # Every leaf's cylinders once; a node's box holds every box of its subtree.
    ids = np.concatenate([bvh.order[v // LEAF_SLOTS:v // LEAF_SLOTS + v % LEAF_SLOTS] for v in leaf[is_leaf]])
    assert np.array_equal(np.sort(ids), np.arange(len(c)))
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


@pytest.mark.parametrize("name", list(SCENES))
def test_walk_finds_the_nearest_hit_of_brute_force(name):
    c = strands_to_cylinders(SCENES[name])
    cyl = _Cyl(c)
    bvh = build_bvh(c)
    every = np.arange(len(c))
    o, d = _rays(c, 60, seed=1)
    hits = total_tests = 0
    for k in range(len(o)):
        def hit(ids):
            return intersect(cyl, ids, np.broadcast_to(o[k], (len(ids), 3)), np.broadcast_to(d[k], (len(ids), 3)))[0]
        t_all = hit(every)
        t_all = np.where(t_all > 0, t_all, np.inf)
        t, i, nodes, tests = traverse(bvh, o[k], d[k], hit)
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
    test_boxes = build_bvh(c2)      # a fresh tree over the moved strands, for the hits
    cyl = _Cyl(c2)
    _assert_boxes_contain(bvh, c2)
    o, d = _rays(c2, 40, seed=2)
    for k in range(len(o)):
        def hit(ids):
            return intersect(cyl, ids, np.broadcast_to(o[k], (len(ids), 3)), np.broadcast_to(d[k], (len(ids), 3)))[0]
        assert traverse(bvh, o[k], d[k], hit)[:2] == traverse(test_boxes, o[k], d[k], hit)[:2]
    with pytest.raises(ValueError):
        refit_bvh(bvh, strands_to_cylinders(curls(2, 5)))

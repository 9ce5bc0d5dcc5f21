# SPDX-License-Identifier: GPL-3.0-or-later
"""The collider's look-ups and the walk's bookkeeping give the same numbers whichever way a
call is split: small and large calls, blocks of strands, one part or several."""
import threading

import numpy as np
import pytest

from groom import default_collider
from groom import collide
from groom.collide import _half_segments, _put, _strand_measures, _turn_limits, _walk


@pytest.fixture(scope="module")
def head():
    return default_collider()


def _points_around(head, n, seed=0):
    """Points over the grid's box and a little beyond it on every side (the clamped cells)."""
    rng = np.random.default_rng(seed)
    lo = head.origin - 3 * head.cell
    hi = head.origin + (np.array(head.shape) + 2) * head.cell
    return lo + rng.random((n, 3)) * (hi - lo)


def _value_plain(head, p):
    """The trilinear look-up written out corner by corner in int64 (the form the fast one
    must equal bit for bit)."""
    base = np.zeros(len(p), np.int64)
    frac = []
    for axis, n in enumerate(head.shape):
        g = (p[:, axis] - head.origin[axis]) * (1.0 / head.cell)
        i = np.clip(g, 0, n - 2).astype(np.int64)
        frac.append(np.clip(g - i, 0.0, 1.0))
        base = base * n + i
    fx, fy, fz = frac
    c = [head.phi[base + o].astype(np.float64) for o in head._corner_offsets]
    c00, c01 = c[0] + fz * (c[1] - c[0]), c[2] + fz * (c[3] - c[2])
    c10, c11 = c[4] + fz * (c[5] - c[4]), c[6] + fz * (c[7] - c[6])
    c0, c1 = c00 + fy * (c01 - c00), c10 + fy * (c11 - c10)
    return c0 + fx * (c1 - c0) - head.cell_error[base], base


def _cells_plain(head, p):
    """The cell index in the points' own precision, one axis at a time in int64."""
    dt = p.dtype.type
    idx = np.zeros(len(p), np.int64)
    for axis, m in enumerate(head.shape):
        col = np.clip((p[:, axis] - dt(head.origin[axis])) * dt(1.0 / head.cell), 0, m - 2)
        idx = idx * m + col.astype(np.int64)
    return idx


@pytest.mark.parametrize("n", [7, 3000, 4097, 20000])
def test_value_and_cells_equal_the_plain_look_up_at_every_size(head, n):
    p = _points_around(head, n, seed=n)
    plain, base = _value_plain(head, p)
    assert np.array_equal(head.value(p), plain)
    assert np.array_equal(head._cells(p), base)
    # float32 points: the cells found in float32 arithmetic, at any split
    p32 = p.astype(np.float32)
    assert np.array_equal(head._cells(p32), _cells_plain(head, p32))
    # with the gradient, the value is the same and the gradient is the same at any split
    val, grad = head.value(p, gradient=True)
    assert np.array_equal(val, plain)
    parts = [head.value(p[i:i + 1000], gradient=True)[1] for i in range(0, n, 1000)]
    assert np.array_equal(grad, np.concatenate(parts))


def _strands(n, seed):
    rng = np.random.default_rng(seed)
    cnt = rng.integers(2, 60, n)
    steps = rng.normal(size=(int(cnt.sum()), 3)) * 0.002
    return np.cumsum(steps, axis=0), cnt, np.cumsum(cnt) - cnt


def test_half_segments_and_turn_limits_in_blocks_equal_the_whole(head):
    pts, cnt, off = _strands(3000, 1)     # some 90,000 points: several blocks
    assert len(pts) > 4 * collide._MEASURE_POINTS
    half, cos, sin = _strand_measures(head, pts, off, cnt)
    whole_cos, whole_sin = _turn_limits(pts, off, cnt)
    assert np.array_equal(half, _half_segments(head, pts, off))
    assert np.array_equal(cos, whole_cos) and np.array_equal(sin, whole_sin)


def test_put_writes_rows_as_indexing_does():
    rng = np.random.default_rng(2)
    a = rng.random((50, 3))
    rows, v = np.array([3, 7, 49, 0]), rng.random((4, 3))
    want = a.copy()
    want[rows] = v
    _put(a, rows, v)
    assert np.array_equal(a, want)
    packed = rng.random((50, 12))
    want = packed.copy()
    want[rows, 3:6] = v
    _put(packed[:, 3:6], rows, v)      # a column slice: not contiguous rows
    assert np.array_equal(packed, want)


def test_a_strand_walks_to_the_same_points_alone_or_with_others(head):
    """The walk keeps its strands' state in packed rows and drops finished ones: each
    strand's points must not depend on the others walked with it."""
    from groom import default_scalp, generate, load_preset
    scalp = default_scalp()
    placement = load_preset("wavy").place_keys(scalp)
    result = generate(scalp, placement.keys, placement.params.replace(count=600, collision=False))
    s = result.strands
    counts = s.counts.astype(np.int64)
    off = np.cumsum(counts) - counts
    collider = collide.with_clearance(head, float(s.radius.max()) + placement.params.collision_margin)
    found = collide._offending(collider, s.points, off, counts, s.radius, placement.params.collision_margin,
                               0, len(counts))
    strands, k0, root_value = found[0], found[1], found[2]
    assert len(strands) > 20
    rows = [np.arange(off[i], off[i] + counts[i]) for i in strands]
    pts = [s.points[r].astype(np.float64) for r in rows]
    target = [s.radius[r].astype(np.float64) + placement.params.collision_margin for r in rows]

    def walk(sel):
        return _walk(collider, np.concatenate([pts[i] for i in sel]), np.concatenate([target[i] for i in sel]),
                     counts[strands[sel]], k0[sel], root_value[sel])[0]
    together = walk(np.arange(len(strands)))
    alone = np.concatenate([walk(np.array([i])) for i in range(len(strands))])
    assert np.array_equal(together, alone)
    assert not np.array_equal(together, np.concatenate(pts))    # the walk moved something


def test_a_field_made_for_no_clearance_serves_the_clearance_its_band_covers_and_the_presets():
    """A Collider says which clearance it serves: the largest for which its band would come
    out the same. Made for that clearance it is the same field, bit for bit, and a little
    more makes a wider one; so with_clearance builds again only where it must, and the
    shipped hair on the bundled head takes the field made for none (a Generate built it
    twice, a second a time)."""
    from groom import default_scalp, list_presets, load_preset
    from groom.scalp import default_head
    head_mesh = default_head()
    none = collide.Collider(head_mesh.vertices, head_mesh.triangles, "head")
    served = none.clearance
    assert 0.1 * none.cell < served < 0.5 * none.cell
    same = collide.Collider(head_mesh.vertices, head_mesh.triangles, "head", served)
    wider = collide.Collider(head_mesh.vertices, head_mesh.triangles, "head", served * 1.05)
    assert same.shape == none.shape and np.array_equal(same.phi, none.phi)
    assert np.array_equal(same.cell_lower, none.cell_lower) and np.array_equal(same.cell_error, none.cell_error)
    assert wider.band > none.band and wider.clearance >= served * 1.05
    # Asked again for what it was made for, the cache has it (no rounding below the ask).
    assert collide.collider_for(head_mesh.vertices, head_mesh.triangles, "h", served * 1.05) is \
        collide.collider_for(head_mesh.vertices, head_mesh.triangles, "h", served * 1.05)
    assert collide.with_clearance(none, served) is none and collide.with_clearance(none, 1.01 * served) is not none
    scalp = default_collider()
    for name in list_presets():
        placement = load_preset(name).place_keys(default_scalp())
        p = placement.params
        needed = max(p.radius if k.root_radius is None else k.root_radius for k in placement.keys) + p.collision_margin
        assert collide.with_clearance(scalp, needed) is scalp, name


def test_a_collider_built_on_another_thread_is_waited_for_not_built_twice(colliders_built):
    from groom import default_head
    built = colliders_built
    head = default_head()
    then = []

    def prepared(collider):
        then.append((threading.current_thread().name, collider))
        raise RuntimeError("what prepares a run may fail: the run does it again")
    thread = collide.prebuild_collider(head.vertices, head.triangles, "Head", then=prepared)
    assert thread is not None
    assert collide.prebuild_collider(head.vertices, head.triangles, "Head") is None     # being made
    got = collide.collider_for(head.vertices, head.triangles, "Head")      # waits for the thread's
    thread.join()
    assert built == ["groom-collider"]
    assert then == [("groom-collider", got)]        # handed the collider on the building thread
    assert collide.collider_for(head.vertices, head.triangles, "Head") is got
    renamed = collide.collider_for(head.vertices, head.triangles, "Other")
    assert renamed.name == "Other" and renamed.phi is got.phi and built == ["groom-collider"]
    assert collide.prebuild_collider(head.vertices, head.triangles, "Head") is None     # made


def test_a_collider_that_fails_on_another_thread_fails_with_its_message_where_it_is_wanted(colliders_built):
    built = colliders_built
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [np.nan, 0, 1]], float)
    t = np.array([[0, 1, 2], [0, 1, 3]])
    thread = collide.prebuild_collider(v, t, "Broken")
    thread.join()                      # no error escapes the thread
    from hairio import InputError
    with pytest.raises(InputError, match="Broken"):
        collide.collider_for(v, t, "Broken")
    assert built == ["groom-collider", "MainThread"] and not collide._BUILDING

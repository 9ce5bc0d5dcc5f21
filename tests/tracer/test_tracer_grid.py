# SPDX-License-Identifier: GPL-3.0-or-later
import numpy as np

from tracer import build_grid, strands_to_cylinders

from tracer_scenes import curls, make_strands


def _cell_of(grid, p):
    c = np.clip(np.floor((p - grid.lo) / grid.cell_size).astype(np.int64), 0, grid.dims - 1)
    return c[..., 0] + grid.dims[0] * (c[..., 1] + grid.dims[1] * c[..., 2])


def _surface_samples(c, k, rng, n=64):
    """Points on the surface of cylinder k (inside its cut planes)."""
    top, tip, r = c.top[k].astype(float), c.tip[k].astype(float), float(c.radius[k])
    ax = tip - top
    u = ax / np.linalg.norm(ax)
    e1 = np.cross(u, [1, 0, 0] if abs(u[0]) < 0.9 else [0, 1, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    s, phi = rng.uniform(0, 1, n), rng.uniform(0, 2 * np.pi, n)
    p = top + s[:, None] * ax + r * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
    keep = (p - tip) @ c.n2[k].astype(float) <= 0
    return p[keep]


def test_every_surface_point_lies_in_a_cell_that_lists_its_cylinder():
    rng = np.random.default_rng(3)
    c = strands_to_cylinders(curls(30, 12, radius=0.01))
    g = build_grid(c)
    assert g.num_cells > 8
    for k in rng.choice(len(c), 60, replace=False):
        for cell in np.unique(_cell_of(g, _surface_samples(c, k, rng))):
            run = g.indices[g.cell_start[cell]:g.cell_start[cell] + g.cell_count[cell]]
            assert k in run, f"cylinder {k} missing from cell {cell}"


def test_cell_lists_are_compact_and_consistent():
    c = strands_to_cylinders(curls(20, 8))
    g = build_grid(c)
    assert g.cell_start.dtype == np.int32 and g.indices.dtype == np.int32
    assert g.cell_count.sum() == len(g.indices)
    np.testing.assert_array_equal(g.cell_start[1:], np.cumsum(g.cell_count)[:-1])
    assert set(np.unique(g.indices)) == set(range(len(c)))   # nobody dropped, no per-cell cap


def test_thousands_of_cylinders_in_one_spot_are_all_listed():
    rng = np.random.default_rng(0)
    lines = [np.array([[0, 0, 0], [0, 0, 1e-3]]) + rng.normal(0, 1e-5, (2, 3)) for _ in range(3000)]
    lines.append(np.array([[1.0, 1, 1], [1.0, 1, 1.001]]))
    c = strands_to_cylinders(make_strands(lines, radius=1e-5))
    g = build_grid(c)
    assert g.cell_count.max() >= 3000


def test_resolution_grows_with_the_number_of_cylinders():
    small = build_grid(strands_to_cylinders(curls(10, 8)))
    big = build_grid(strands_to_cylinders(curls(400, 8)))
    assert big.num_cells > small.num_cells


def test_empty_grid():
    from hairio import Strands
    g = build_grid(strands_to_cylinders(Strands.empty()))
    assert len(g.indices) == 0 and g.cell_count.sum() == 0


def test_renders_of_many_rays_aim_at_more_references_per_cylinder():
    from tracer import grid as tg
    for count in (10_000, 6_000_000, 61_000_000):
        one = tg.refs_per_cylinder(count)
        aims = [tg.refs_per_cylinder(count, k * tg.RAYS_TUNED) for k in (0.25, 1, 2, 4, 16, 64, 1024)]
        assert aims[0] == aims[1] == one                    # one sample at 512x512 or fewer: the rule
        assert all(a <= b for a, b in zip(aims, aims[1:]))  # never coarser for more rays
        assert aims[4] > 1.4 * one                          # 16 samples pay for finer cells
        assert aims[-1] <= max(one, tg.MAX_REFS_PER_CYLINDER_MANY)
    # What the lists' buffers hold bounds the aim, but never below the rule for one sample.
    count, capacity = 61_000_000, 4 * (1 << 27)
    capped = tg.refs_per_cylinder(count, 16 * tg.RAYS_TUNED, capacity)
    assert capped * count <= tg.CAPACITY_SHARE * capacity * (1 + 1e-9)
    assert capped > tg.refs_per_cylinder(count)
    assert tg.refs_per_cylinder(count, 16 * tg.RAYS_TUNED, 2 * count) == tg.refs_per_cylinder(count)


def test_more_references_per_cylinder_give_smaller_cells_and_more_references():
    from tracer.grid import build_grid, cylinders_frame, grid_frame
    c = strands_to_cylinders(curls(300, 12, seed=2))
    lo, cs, dims = cylinders_frame(c)
    size = np.abs(c.tip - c.top) + 2 * c.radius[:, None]
    fine = build_grid(c, frame=grid_frame(lo, lo + cs * dims, size, max_refs=16.0))
    coarse = build_grid(c, frame=grid_frame(lo, lo + cs * dims, size, max_refs=4.0))
    assert fine.num_cells > 2 * coarse.num_cells
    assert len(fine.indices) > 1.5 * len(coarse.indices)
    assert abs(len(fine.indices) / len(c) - 16.0) < 6.0       # near the aim, as estimated

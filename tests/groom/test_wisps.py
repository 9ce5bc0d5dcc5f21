# SPDX-License-Identifier: GPL-3.0-or-later
import numpy as np
import pytest

from groom.wisps import guide_weights, nearest_keys
from hairio import InputError

KEYS = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [3, 3, 0]], float)


def _grid(n=41, lo=-0.5, hi=1.5):
    x, y = np.meshgrid(np.linspace(lo, hi, n), np.linspace(lo, hi, n))
    return np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], 1)


def test_each_strand_joins_the_wisp_of_the_nearest_key_root():
    roots = _grid()
    idx, dist = nearest_keys(roots, KEYS, 1)
    brute = np.linalg.norm(roots[:, None] - KEYS[None], axis=2)
    np.testing.assert_array_equal(idx[:, 0], brute.argmin(axis=1))
    np.testing.assert_allclose(dist[:, 0], brute.min(axis=1))


def test_groups_keep_strands_to_keys_of_their_own_group():
    roots = _grid()
    key_groups = np.array([0, 1, 0, 1, 1])
    root_groups = (roots[:, 0] > 0.5).astype(np.int32)
    for mode in ("key", "root", "interpolate"):
        g, w = guide_weights(roots, KEYS, mode, 50, root_groups, key_groups)
        used = np.where(w > 0, key_groups[g], root_groups[:, None])
        assert (used == root_groups[:, None]).all()


def test_a_group_without_keys_is_an_error():
    with pytest.raises(InputError, match="group"):
        guide_weights(KEYS[:2], KEYS[:2], "root", 50, np.array([0, 2]), np.array([0, 0]))


@pytest.mark.parametrize("mode", ["key", "root", "interpolate"])
def test_weights_are_finite_and_sum_to_one(mode):
    g, w = guide_weights(_grid(), KEYS, mode, 50)
    assert np.isfinite(w).all() and (w >= 0).all()
    np.testing.assert_allclose(w.sum(axis=1), 1, atol=1e-12)


@pytest.mark.parametrize("mode", ["key", "root", "interpolate"])
def test_a_root_on_a_key_root_has_weight_exactly_one(mode):
    with np.errstate(divide="raise", invalid="raise", over="raise"):
        g, w = guide_weights(KEYS.copy(), KEYS, mode, 50)
    np.testing.assert_array_equal(g[:, 0], np.arange(len(KEYS)))
    np.testing.assert_array_equal(w[:, 0], 1.0)
    np.testing.assert_array_equal(w[:, 1:], 0.0)


@pytest.mark.parametrize("mode", ["key", "root"])
def test_n_influence_one_follows_the_main_key(mode):
    roots = _grid()
    _, w1 = guide_weights(roots, KEYS, mode, 1)
    _, w100 = guide_weights(roots, KEYS, mode, 100)
    # (101 - 1) : 1 : 1 at worst (equidistant keys): the main key keeps >= 100/102.
    assert w1[:, 0].min() >= 100 / 102 - 1e-12
    assert w100[:, 0].min() < 0.5


def test_n_influence_100_is_plain_inverse_distance():
    roots = np.array([[0.2, 0.1, 0.0]])
    g, w = guide_weights(roots, KEYS, "root", 100)
    inv = 1 / np.linalg.norm(KEYS[g[0]] - roots[0], axis=1)
    np.testing.assert_allclose(w[0], inv / inv.sum())


def test_reading_a_uses_the_main_keys_neighbours_and_reading_b_the_strands():
    root = np.array([[0.9, 0.45, 0.0]])  # nearest key 1; then key 3 (d 0.56) before key 0 (d 0.95)
    g_b, _ = guide_weights(root, KEYS, "root", 50)
    g_a, _ = guide_weights(root, KEYS, "key", 50)
    assert list(g_b[0]) == [1, 3, 0]
    # Key 1's nearest keys are 0 and 3 (both 1 away; ties by index).
    assert list(g_a[0]) == [1, 0, 3]


def test_one_key_only_gives_that_key_full_weight():
    g, w = guide_weights(_grid(), KEYS[:1], "root", 50)
    assert (g == 0).all()
    np.testing.assert_array_equal(w[:, 0], 1.0)
    g, w = guide_weights(_grid(), KEYS[:1], "interpolate", 50)
    np.testing.assert_array_equal(w[:, 0], 1.0)


@pytest.mark.parametrize("mode", ["key", "root", "interpolate"])
def test_two_coincident_keys_give_finite_weights(mode):
    keys = np.array([[0, 0, 0], [0, 0, 0], [1, 0, 0]], float)
    roots = np.concatenate([_grid(11), [[0, 0, 0]]])
    with np.errstate(divide="raise", invalid="raise", over="raise"):
        g, w = guide_weights(roots, keys, mode, 50)
    assert np.isfinite(w).all()
    np.testing.assert_allclose(w.sum(axis=1), 1, atol=1e-12)


def test_interpolate_mode_weights_are_continuous_across_wisp_borders():
    # Walk across the border between keys 0 and 1 at x = 0.5 in tiny steps.
    x = np.linspace(0.45, 0.55, 2001)
    roots = np.stack([x, np.full_like(x, 0.3), np.zeros_like(x)], 1)
    for mode, continuous in (("interpolate", True), ("root", False)):
        g, w = guide_weights(roots, KEYS, mode, 50)
        full = np.zeros((len(x), len(KEYS)))
        np.add.at(full, (np.arange(len(x))[:, None], g), w)
        jump = np.abs(np.diff(full, axis=0)).max()
        assert (jump < 0.01) == continuous


def test_smallest_rows_is_the_stable_sort_and_leaves_the_distances():
    # Ties (to the lower key index), another group's keys (inf) and a single root (a (K, 1)
    # array whose transpose is contiguous) as the stable sort orders them.
    from groom.wisps import _smallest_rows
    rng = np.random.default_rng(3)
    for roots in (1, 2, 257):
        d = rng.integers(0, 4, (24, roots)).astype(np.float64) ** 2
        d[rng.random(d.shape) < 0.3] = np.inf
        d[:, 0] = np.inf
        before = d.copy()
        for k in (1, 3, 24):
            np.testing.assert_array_equal(_smallest_rows(d, k), np.argsort(d, axis=0, kind="stable")[:k])
        np.testing.assert_array_equal(d, before)

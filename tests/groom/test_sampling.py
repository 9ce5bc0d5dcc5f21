# SPDX-License-Identifier: GPL-3.0-or-later
import numpy as np
import pytest

from groom import Scalp
from groom.sampling import allocate_counts, sample_roots
from hairio import InputError

# Chi-square critical value for 15 degrees of freedom at p = 0.001.
CHI2_15_P001 = 37.70


def _one_triangle():
    return Scalp([[0, 0, 0], [1, 0, 0], [0.3, 0.8, 0]], [[0, 1, 2]])


def _sub_triangle_index(bary, n):
    """Index of the sub-triangle (of n² equal ones, barycentric grid) holding each point."""
    a, b = bary[:, 0] * n, bary[:, 1] * n
    i = np.minimum(np.floor(a), n - 1)
    j = np.minimum(np.floor(b), n - 1)
    up = (a - i) + (b - j) < 1
    return ((i * n + j) * 2 + (~up)).astype(int)


def _chi_square(bary, n=4):
    idx = _sub_triangle_index(bary, n)
    counts = np.bincount(idx, minlength=2 * n * n)
    cells = [c for c in range(2 * n * n) if (c // 2) // n + (c // 2) % n <= n - 1 - (c % 2)]
    observed = counts[cells]
    assert len(cells) == n * n and observed.sum() == len(bary)
    expected = len(bary) / (n * n)
    return float(((observed - expected) ** 2 / expected).sum())


@pytest.mark.parametrize("m", [1, 7, 999, 12345])
def test_root_counts_sum_to_exactly_m(scalp, m):
    s = sample_roots(scalp, m, seed=1)
    assert len(s.points) == m
    assert allocate_counts(scalp.face_areas, m).sum() == m


def test_counts_follow_area_within_one():
    w = np.array([1.0, 2.0, 3.0, 0.0, 4.0])
    c = allocate_counts(w, 101)
    assert c.sum() == 101
    assert np.abs(c - w / w.sum() * 101).max() < 1
    assert c[3] == 0


def test_density_weights_the_root_counts():
    v = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]
    s = Scalp(v, [[0, 1, 2], [1, 3, 2]], density=[0, 0, 0, 1.0])
    # Triangle 0 has density 0 at all corners, triangle 1 a mean density of 1/3.
    r = sample_roots(s, 500, seed=2)
    assert (r.tri == 1).all()


def test_uniform_mode_passes_chi_square_over_sub_triangles():
    r = sample_roots(_one_triangle(), 20000, seed=5, mode="uniform")
    assert _chi_square(r.bary) < CHI2_15_P001


def test_seed_mode_fails_chi_square_and_is_biased_toward_t_z():
    r = sample_roots(_one_triangle(), 20000, seed=5, mode="seed")
    assert _chi_square(r.bary) > 10 * CHI2_15_P001
    # T_z is the third corner: its barycentric weight averages 1/2 instead of 1/3.
    assert r.bary[:, 2].mean() == pytest.approx(0.5, abs=0.01)
    u = sample_roots(_one_triangle(), 20000, seed=5, mode="uniform")
    assert u.bary[:, 2].mean() == pytest.approx(1 / 3, abs=0.01)


def test_sampling_is_deterministic_for_a_seed_and_changes_with_it(scalp):
    a = sample_roots(scalp, 500, seed=9)
    b = sample_roots(scalp, 500, seed=9)
    c = sample_roots(scalp, 500, seed=10)
    np.testing.assert_array_equal(a.points, b.points)
    assert not np.array_equal(a.points, c.points)


def test_roots_lie_on_their_triangles(scalp):
    r = sample_roots(scalp, 1000, seed=4)
    assert (r.bary >= 0).all()
    np.testing.assert_allclose(r.bary.sum(axis=1), 1, atol=1e-12)
    np.testing.assert_allclose(scalp.points_at(r.tri, r.bary), r.points)


def test_zero_area_and_sliver_triangles_get_no_roots_or_finite_ones():
    v = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0], [1, 1e-9, 0]]
    s = Scalp(v, [[0, 1, 2], [0, 1, 3], [0, 3, 4]])
    r = sample_roots(s, 1000, seed=1)
    assert np.isfinite(r.points).all()
    assert (r.tri != 1).all()


@pytest.mark.parametrize("m", [0, -3, 2.5, "10"])
def test_bad_counts_are_rejected(scalp, m):
    with pytest.raises(InputError, match="count"):
        sample_roots(scalp, m)


def test_a_scalp_without_area_is_rejected():
    with pytest.raises(InputError, match="area"):
        sample_roots(Scalp([[0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 1, 2]]), 10)
    flat = Scalp([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], density=[0, 0, 0])
    with pytest.raises(InputError, match="area"):
        sample_roots(flat, 10)

# SPDX-License-Identifier: GPL-3.0-or-later
import numpy as np
import pytest

from groom import Generator, GroomParams, KeyStrand, Scalp, generate
from groom.measure import strand_errors
from groom.sampling import RootSamples
from hairio import InputError



def _same(a, b):
    for name in ("points", "counts", "radius", "color", "alpha", "wisp"):
        np.testing.assert_array_equal(getattr(a.strands, name), getattr(b.strands, name), err_msg=name)
    np.testing.assert_array_equal(a.guides, b.guides)
    np.testing.assert_array_equal(a.guide_weights, b.guide_weights)


def test_result_has_the_documented_arrays(scalp, small_params, keys_around):
    r = generate(scalp, keys_around(scalp), small_params)
    s = r.strands
    assert s.num_strands == small_params.count
    assert r.roots.shape == (s.num_strands, 3) and r.root_uv.shape == (s.num_strands, 2)
    assert r.guides.shape == (s.num_strands, 3) and r.guides.dtype == np.int32
    assert r.guide_weights.shape == (s.num_strands, 3) and r.guide_weights.dtype == np.float32
    np.testing.assert_array_equal(s.wisp, r.guides[:, 0])
    # Point 0 of every strand is its root.
    np.testing.assert_allclose(s.points[s.offsets], r.roots, atol=1e-6)
    for a in (s.points, s.radius, s.color, s.alpha):
        assert np.isfinite(a).all()


def test_generation_is_deterministic_for_a_seed(scalp, small_params, keys_around):
    keys = keys_around(scalp)
    _same(generate(scalp, keys, small_params), generate(scalp, keys, small_params))
    other = generate(scalp, keys, small_params.replace(seed=small_params.seed + 1))
    assert not np.array_equal(other.roots, generate(scalp, keys, small_params).roots)


@pytest.mark.parametrize("mode", ["interpolate", "root", "key"])
@pytest.mark.parametrize("resolution", ["adaptive", "fixed"])
def test_incremental_update_equals_full_regeneration(scalp, mode, resolution, keys_around):
    params = GroomParams(count=3000, seed=1, neighbour_mode=mode, resolution_mode=resolution,
                         color_variation_point=(0.02, 0.02, 0.02))
    keys = keys_around(scalp, 8)
    gen = Generator(scalp, keys, params)
    before = gen.generate().strands.counts
    # Reshape key 2 (same root), then move key 5's root (wisp borders move).
    reshaped = KeyStrand(keys[2].points + [[0, 0, 0], [0.01, 0, 0], [0, 0.02, 0], [0.01, 0.01, 0]])
    inc = gen.update_keys({2: reshaped})
    assert 0 < gen.last_recomputed < params.count
    # Adaptive: some strands change their point counts, so the unchanged ones move in the arrays.
    assert (inc.strands.counts != before).any() == (resolution == "adaptive")
    keys[2] = reshaped
    _same(inc, generate(scalp, keys, params))
    moved = KeyStrand(keys[5].points + [0.01, -0.01, 0])
    inc = gen.update_keys({5: moved})
    keys[5] = moved
    _same(inc, generate(scalp, keys, params))


def test_reshaping_a_key_recomputes_only_the_strands_it_guides(scalp, keys_around):
    params = GroomParams(count=2000, seed=2, resolution_mode="fixed")
    keys = keys_around(scalp, 6)
    gen = Generator(scalp, keys, params)
    before = gen.generate()
    # Same root, new shape: wisps and weights stay, so only key 1's strands are redone.
    reshaped = KeyStrand(keys[1].points + [[0, 0, 0], [0.0, 0.01, 0], [0.01, 0, 0], [0, 0, 0.01]])
    after = gen.update_keys({1: reshaped})
    guided = (before.guides == 1).any(axis=1)
    assert gen.last_recomputed == guided.sum() > 0
    np.testing.assert_array_equal(after.guide_weights, before.guide_weights)
    pts_before = before.strands.points.reshape(2000, -1, 3)
    pts_after = after.strands.points.reshape(2000, -1, 3)
    np.testing.assert_array_equal(pts_after[~guided], pts_before[~guided])
    assert (pts_after[guided] != pts_before[guided]).any(axis=(1, 2)).mean() > 0.5


@pytest.mark.parametrize("resolution", ["fixed", "adaptive"])
def test_updating_a_key_that_guides_no_strand_changes_nothing(scalp, keys_around, resolution):
    far = KeyStrand(np.array([[0, 0, 5.0], [0, 0, 5.1], [0, 0.1, 5.2]]))  # never among the nearest
    gen = Generator(scalp, keys_around(scalp, 6) + [far], GroomParams(count=500, resolution_mode=resolution))
    before = gen.generate()
    after = gen.update_keys({6: KeyStrand(far.points + [[0, 0, 0], [0, 0.1, 0], [0, 0, 0]])})
    assert gen.last_recomputed == 0
    _same(before, after)


@pytest.mark.parametrize("resolution", ["fixed", "adaptive"])
def test_splitting_the_work_over_threads_changes_no_number(scalp, keys_around, monkeypatch, resolution):
    import groom.parallel as parallel
    params = GroomParams(count=9000, seed=5, resolution_mode=resolution, points_per_strand=12)
    keys = keys_around(scalp, 6)
    runs = {}
    for threads in (1, 3):
        monkeypatch.setattr(parallel, "cpu_threads", lambda t=threads: t)
        runs[threads] = generate(scalp, keys, params)
    _same(runs[1], runs[3])


def test_tidiness_one_means_no_rotation(scalp, curl_key):
    key = curl_key([0, 0, 0.1])
    base = dict(count=500, seed=2, min_length=1.0, max_length=1.0, resolution_mode="fixed", theta_max=0.6)
    shapes = {}
    for tidy in (1.0, 0.5):
        gen = Generator(scalp, [key], GroomParams(tidiness=tidy, **base))
        s = gen.generate().strands
        pts = s.points.astype(np.float64).reshape(500, -1, 3) - gen.result.roots[:, None]
        # Each strand's shape in its own root frame: identical for all strands iff no rotation.
        shapes[tidy] = np.einsum("skd,sde->ske", pts, gen.frames)
    spread = {t: np.abs(v - v[0]).max() for t, v in shapes.items()}
    assert spread[1.0] < 1e-6
    assert spread[0.5] > 1e-3


def _local_shapes(gen):
    s = gen.result.strands
    pts = s.points.astype(np.float64).reshape(s.num_strands, -1, 3) - gen.result.roots[:, None]
    return np.einsum("skd,sde->ske", pts, gen.frames)


def test_untidy_rotation_angles_stay_within_theta_max(scalp, curl_key):
    base = dict(count=400, seed=4, theta_max=0.3, min_length=1, max_length=1, resolution_mode="fixed")
    key = curl_key([0, 0, 0.1])
    ref = Generator(scalp, [key], GroomParams(tidiness=1.0, **base))
    ref.generate()
    messy = Generator(scalp, [key], GroomParams(tidiness=0.25, **base))
    messy.generate()
    p, q = _local_shapes(ref)[0], _local_shapes(messy)
    limit = 0.75 * 0.3
    angles = []
    for shape in q[:100]:  # recover each strand's rotation (Kabsch) and its x, y, z angles
        u, _, vt = np.linalg.svd(p.T @ shape)
        fix = np.diag([1.0, 1.0, np.sign(np.linalg.det(vt.T @ u.T))])  # a planar key allows a mirror
        r = vt.T @ fix @ u.T
        angles.append([np.arctan2(r[2, 1], r[2, 2]), -np.arcsin(r[2, 0]), np.arctan2(r[1, 0], r[0, 0])])
    angles = np.abs(np.array(angles))
    assert angles.max() <= limit + 1e-6
    assert (angles.max(axis=0) > 0.8 * limit).all()


def test_strand_lengths_fall_within_min_and_max(scalp, curl_key):
    key = curl_key([0, 0, 0.1], length=0.1)
    full = key.length()
    p = GroomParams(count=2000, seed=5, min_length=0.4, max_length=0.7, resolution_mode="fixed",
                    points_per_strand=200, tidiness=0.5)
    s = generate(scalp, [key], p).strands
    pts = s.points.astype(np.float64).reshape(2000, 200, 3)
    length = np.linalg.norm(np.diff(pts, axis=1), axis=2).sum(axis=1) / full
    assert length.min() >= 0.4 - 1e-3 and length.max() <= 0.7 + 1e-4
    assert length.min() < 0.41 and length.max() > 0.69


def test_lengths_are_trimmed_not_scaled(scalp):
    # A tight curl trimmed to half its length keeps its curl: the short strand lies on the long one.
    key = KeyStrand(np.array([[0, 0, 0.1], [0.02, 0, 0.11], [0.02, 0.02, 0.12], [0, 0.02, 0.13],
                              [0, 0, 0.14]]), kind="bezier")
    common = dict(count=50, seed=6, tidiness=1.0, resolution_mode="fixed", points_per_strand=400)
    long = generate(scalp, [key], GroomParams(min_length=1, max_length=1, **common)).strands
    short = generate(scalp, [key], GroomParams(min_length=0.5, max_length=0.5, **common)).strands
    a = long.points.reshape(50, 400, 3)[0].astype(np.float64)
    b = short.points.reshape(50, 400, 3)[0].astype(np.float64)
    d = np.linalg.norm(b[:, None] - a[None], axis=2).min(axis=1)
    assert d.max() < 2e-4


def test_intelligence_off_translates_the_key_shape(scalp, curl_key):
    key = curl_key([0, 0, 0.1])
    p = GroomParams(count=300, seed=7, intelligence=False, tidiness=1.0, min_length=1, max_length=1,
                    resolution_mode="fixed")
    r = generate(scalp, [key], p)
    offs = r.strands.points.astype(np.float64).reshape(300, -1, 3) - r.roots[:, None]
    np.testing.assert_allclose(offs, np.broadcast_to(offs[0], offs.shape), atol=1e-6)
    q = generate(scalp, [key], p.replace(intelligence=True))
    offs_i = q.strands.points.astype(np.float64).reshape(300, -1, 3) - q.roots[:, None]
    assert np.abs(offs_i - offs_i[0]).max() > 1e-2


@pytest.mark.parametrize("units, tol", [("scene", 2e-4), ("scene", 2e-5), ("radius", 1.0)])
def test_adaptive_resolution_meets_its_tolerance(scalp, units, tol, keys_around):
    keys = keys_around(scalp, 6)
    keys.append(KeyStrand(np.array([[0.0, 0.05, 0.087], [0.0, 0.1, 0.12]])))  # a straight one
    p = GroomParams(count=300, seed=8, tolerance=tol, tolerance_units=units, points_per_strand=200,
                    radius=1e-4)
    gen = Generator(scalp, keys, p)
    s = gen.generate().strands
    limit = tol * (1e-4 if units == "radius" else 1.0)
    err = strand_errors(gen)
    assert err.max() <= limit * (1 + 1e-3) + 1e-7
    cyl = s.counts - 1
    assert cyl.min() < cyl.max()   # the resolution does adapt per strand
    assert cyl.max() < 199         # and no strand hit the cap


def test_fixed_resolution_gives_every_strand_the_same_count(scalp, keys_around):
    s = generate(scalp, keys_around(scalp), GroomParams(count=100, resolution_mode="fixed",
                                                       points_per_strand=26)).strands
    assert (s.counts == 26).all()


def test_radius_color_and_alpha_profiles(scalp, keys_around):
    p = GroomParams(count=200, seed=9, resolution_mode="fixed", points_per_strand=11, radius=2e-4,
                    radius_mode="linear", color=(0.5, 0.5, 0.5), color_variation=(0.1, 0.0, 0.0),
                    alpha_start=0.6, alpha_tip=0.2)
    s = generate(scalp, keys_around(scalp), p).strands
    r = s.radius.reshape(200, 11)
    np.testing.assert_allclose(r[:, 0], 2e-4, rtol=1e-6)
    np.testing.assert_allclose(r[:, -1], 0, atol=1e-12)
    assert (np.diff(r, axis=1) <= 0).all()
    c = s.color.reshape(200, 11, 3)
    assert np.abs(c[:, :, 0] - 0.5).max() <= 0.1 + 1e-6 and np.abs(c[:, :, 0] - 0.5).max() > 0.05
    np.testing.assert_allclose(c[:, :, 1], 0.5, atol=1e-6)
    a = s.alpha.reshape(200, 11)
    np.testing.assert_allclose(a[:, :7], 1.0)
    np.testing.assert_allclose(a[:, -1], 0.2, atol=1e-6)
    const = generate(scalp, keys_around(scalp), p.replace(radius_mode="constant")).strands
    np.testing.assert_allclose(const.radius, 2e-4, rtol=1e-6)


def _grow_blocks(side_by_side, monkeypatch):
    """Blocks grown one after another (None), side by side on threads ("threads") or dealt to
    worker processes ("processes"; skipped where groom.processes is not available), whatever
    their size."""
    import importlib
    from groom import processes
    module = importlib.import_module("groom.generate")
    if side_by_side == "processes" and not processes.available():
        pytest.skip("worker processes need Linux's memfd")
    monkeypatch.setenv(processes.ENV_SWITCH, "1" if side_by_side == "processes" else "0")
    for name in ("PARALLEL_BLOCK", "PROCESS_BLOCK"):
        monkeypatch.setattr(module, name, 100 if side_by_side else 10 ** 9)


@pytest.mark.parametrize("side_by_side", [None, "threads", "processes"])
def test_an_opaque_groom_keeps_one_alpha_for_all_its_points(scalp, side_by_side, monkeypatch):
    """wavy is opaque: its alpha is a read-only view of one value (no memory a point), however
    its blocks grew and after an incremental update; a fade gets its values a point, the
    same in every way of growing."""
    from groom import default_collider, load_preset
    _grow_blocks(side_by_side, monkeypatch)
    placement = load_preset("wavy").place_keys(scalp)
    params = placement.params.replace(count=1200, seed=2)
    assert params.alpha_start >= 1.0
    keys = list(placement.keys)
    gen = Generator(scalp, keys, params, collider=default_collider(), block_strands=200)
    for result in (gen.generate(), gen.update_keys({3: keys[4]})):
        a = result.strands.alpha
        assert a.shape == (result.strands.num_points,) and a.dtype == np.float32
        assert a.strides == (0,) and not a.flags.writeable and (a == 1.0).all()
    fade = params.replace(alpha_start=0.5, alpha_tip=0.3)
    got = Generator(scalp, keys, fade, collider=default_collider(), block_strands=200).generate().strands.alpha
    one = Generator(scalp, keys, fade, collider=default_collider(), block_strands=10_000).generate().strands.alpha
    assert got.strides == (4,) and 0.3 <= got.min() < 0.35 and got.max() == 1.0
    np.testing.assert_array_equal(got, one)


@pytest.mark.parametrize("side_by_side, resolution", [(None, "adaptive"), ("threads", "fixed"),
                                                      ("processes", "adaptive"), ("processes", "fixed")])
def test_a_groom_of_one_colour_along_each_strand_keeps_it_a_strand_at_a_time(scalp, side_by_side, resolution,
                                                                             monkeypatch):
    """Without colour variation along the strands, the result holds each strand's colour once
    (strand_color (S,3), no (P,3) array), however its blocks grew and after an incremental
    update; the colour a point, made from it on first use, equals what the same groom with
    colour a point gives (a variation along the strands too small to change a float32)."""
    from groom import default_collider, load_preset
    _grow_blocks(side_by_side, monkeypatch)
    placement = load_preset("wavy").place_keys(scalp)
    params = placement.params.replace(count=1200, seed=4, resolution_mode=resolution,
                                      color_variation=(0.1, 0.05, 0.02))
    keys = list(placement.keys)
    moved = KeyStrand(keys[4].points + np.linspace(0, 1, len(keys[4].points))[:, None] * [0.0, 0.01, 0.0],
                      keys[4].kind, color=(0.9, 0.1, 0.1))
    per_point = params.replace(color_variation_point=(1e-30,) * 3)
    gens = [Generator(scalp, list(keys), q, collider=default_collider(), block_strands=200) for q in (params, per_point)]
    for results in ([g.generate() for g in gens], [g.update_keys({4: moved}) for g in gens]):
        held, pointwise = (r.strands for r in results)
        assert held.point_color is None and pointwise.strand_color is None
        assert held.strand_color.shape == (held.num_strands, 3) and held.strand_color.dtype == np.float32
        np.testing.assert_array_equal(held.points, pointwise.points)
        np.testing.assert_array_equal(held.color, pointwise.color)
        assert held.point_color is not None    # made once, on first use, and kept
        assert len(np.unique(held.strand_color, axis=0)) > held.num_strands // 2   # per-strand variation
    s = results[0].strands      # the update's key colour reached its wisp
    assert s.strand_color[s.wisp == 4, 0].mean() > 0.6 > s.strand_color[s.wisp != 4, 0].mean()


# --- SPEC §9 stress cases ------------------------------------------------------------------

def _samples_at(scalp, points):
    tri, bary, pts = scalp.closest_points(np.asarray(points, float))
    return RootSamples(pts, tri, bary, np.arange(len(pts)))


def test_roots_on_the_crown_and_on_key_roots_give_finite_strands(scalp, keys_around):
    keys = keys_around(scalp, 5)
    crown = [0, 0, 0.1]
    pts = [crown] + [k.root for k in keys]
    p = GroomParams(tidiness=1.0, min_length=1, max_length=1, resolution_mode="fixed")
    with np.errstate(divide="raise", invalid="raise", over="raise"):
        gen = Generator(scalp, keys, p, samples=_samples_at(scalp, pts))
        r = gen.generate()
    assert np.isfinite(r.strands.points).all()
    # A strand on a key root (d = 0) is that key, resampled.
    k0 = r.strands.points.reshape(len(pts), -1, 3)[1].astype(np.float64)
    ref = keys[0].resample(4000)
    d = np.linalg.norm(k0[:, None] - ref[None], axis=2).min(axis=1)
    assert d.max() < 1e-5
    np.testing.assert_array_equal(r.guide_weights[1:, 0], 1.0)


def test_two_coincident_keys_and_one_key_only_give_finite_strands(scalp, curl_key):
    a = curl_key([0, 0, 0.1])
    b = curl_key([0, 0, 0.1], length=0.03)
    for keys in ([a], [a, b], [a, b, a]):
        r = generate(scalp, keys, GroomParams(count=500))
        assert np.isfinite(r.strands.points).all()
        assert np.isfinite(r.guide_weights).all()


def test_zero_area_and_sliver_triangles_in_the_scalp_give_finite_strands(curl_key):
    v = np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0.2, 0, 0], [0.1, 1e-12, 0], [0.3, 0, 0]], float)
    s = Scalp(v, [[0, 1, 2], [1, 3, 5], [0, 3, 4], [2, 2, 2]])
    r = generate(s, [curl_key([0.02, 0.02, 0])], GroomParams(count=400))
    assert np.isfinite(r.strands.points).all()


@pytest.mark.parametrize("scale, offset", [(1.0, 1e4), (1e-3, 0.0), (1e3, 0.0)])
def test_moved_and_scaled_heads_give_the_same_hair_moved_and_scaled(scalp, scale, offset, keys_around):
    keys = keys_around(scalp, 5)
    p = GroomParams(count=400, seed=3, resolution_mode="fixed", radius=1e-4)
    ref = generate(scalp, keys, p)
    moved = Scalp(scalp.vertices * scale + offset, scalp.triangles, uv=scalp.uv)
    moved_keys = [KeyStrand(k.points * scale + offset) for k in keys]
    r = generate(moved, moved_keys, p.replace(radius=1e-4 * scale))
    pts = r.strands.points.astype(np.float64)
    assert np.isfinite(pts).all()
    expect = ref.strands.points.astype(np.float64) * scale + offset
    # float32 output: allow its rounding at the new magnitude, nothing more.
    tol = 4 * np.finfo(np.float32).eps * (0.4 * scale + offset)
    assert np.abs(pts - expect).max() <= tol
    np.testing.assert_array_equal(r.guides, ref.guides)


def test_keys_beyond_float32_are_a_clear_error_not_infinite_points(scalp):
    # Finite in float64, but the float32 points of SPEC §0 would overflow.
    key = KeyStrand(np.array([[0, 0, 0.1], [0, 0, 1e38], [0, 1e38, 1e38]]))
    with pytest.raises(InputError, match="float32"):
        generate(scalp, [key], GroomParams(count=50))


def test_non_finite_key_points_are_rejected_naming_the_array():
    with pytest.raises(InputError, match="key strand points"):
        KeyStrand(np.array([[0, 0, 0], [np.inf, 0, 0]]))


def test_bad_inputs_to_generate_are_clear_errors(scalp, curl_key):
    with pytest.raises(InputError, match="keys"):
        generate(scalp, [], GroomParams(count=10))
    with pytest.raises(InputError, match="keys\\[0\\]"):
        generate(scalp, [np.zeros((3, 3))], GroomParams(count=10))
    with pytest.raises(InputError, match="group"):
        generate(scalp, [curl_key([0, 0, 0.1], group=1)], GroomParams(count=10))


def test_adaptive_resolution_gives_straight_strands_one_cylinder(scalp):
    key = KeyStrand(np.array([[0, 0, 0.1], [0, 0.02, 0.15], [0, 0.04, 0.2]]))  # collinear: straight
    s = generate(scalp, [key], GroomParams(count=300, tidiness=0.3)).strands
    assert (s.counts == 2).all()


def test_adaptive_points_gather_where_the_strand_bends(scalp):
    # Straight for 10 cm (a cubic segment), then a tight hook (a second one).
    key = KeyStrand(np.array([[0, 0, 0.1], [0, 0, 0.15], [0, 0, 0.2], [0, 0, 0.2],
                              [0, 0, 0.2], [0.01, 0, 0.21], [0.02, 0, 0.2]]), kind="cubic")
    gen = Generator(scalp, [key], GroomParams(count=50, tidiness=1.0, min_length=1, max_length=1,
                                              tolerance=1e-5, points_per_strand=200))
    s = gen.generate().strands
    pts = s.strand_points(0).astype(np.float64) - gen.result.roots[0]
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    assert seg[0] > 0.04            # one long cylinder for the straight part
    assert seg[-3:].max() < 0.005   # short ones in the hook


def test_incremental_update_rejects_bad_changes(scalp, keys_around):
    gen = Generator(scalp, keys_around(scalp, 3), GroomParams(count=100))
    gen.generate()
    with pytest.raises(InputError, match="out of range"):
        gen.update_keys({7: keys_around(scalp, 1)[0]})
    with pytest.raises(InputError, match="KeyStrand"):
        gen.update_keys({0: np.zeros((3, 3))})


def test_interpolate_mode_has_the_smallest_seam(scalp, keys_around):
    from groom.measure import seam_jumps_by_mode
    keys = keys_around(scalp, 6)
    r = seam_jumps_by_mode(scalp, keys, GroomParams(points_per_strand=16), pairs=3000)
    assert r["interpolate"]["pairs_across"] > 0
    assert r["interpolate"]["across_max"] < 0.5 * min(r["root"]["across_max"], r["key"]["across_max"])


def test_adaptive_strands_end_without_a_sliver_segment(scalp):
    # Trim fractions fall anywhere, often just past a curvature bin's edge, where the greedy
    # search used to leave a last segment of a few nanometres: a point repeating its
    # predecessor, which renderers must drop. The last segment is now merged or balanced.
    from groom import load_preset
    preset = load_preset("wavy")
    s = generate(scalp, preset.keys_on(scalp), preset.params.replace(count=20000, seed=3)).strands
    assert s.counts.max() > 2
    seg = np.diff(s.points.astype(np.float64), axis=0)
    inside = np.ones(len(seg), bool)
    inside[np.cumsum(s.counts)[:-1] - 1] = False          # steps from one strand to the next
    length = np.sqrt((seg[inside] ** 2).sum(axis=1))
    assert length.min() > 1e-6


@pytest.mark.parametrize("resolution, variation, side_by_side", [("adaptive", 0.02, None), ("fixed", 0.02, None),
                                                                  ("adaptive", 0.0, None), ("adaptive", 0.02, "threads"),
                                                                  ("fixed", 0.0, "threads"),
                                                                  ("adaptive", 0.02, "processes"),
                                                                  ("fixed", 0.0, "processes")])
def test_growing_in_blocks_changes_no_number(scalp, resolution, variation, side_by_side, monkeypatch):
    """Blocks of 200 strands against one block, on the wavy preset with
    its clump and collision: every array, the resolution notes, the collision's report and an
    incremental update spanning blocks. Without per-point colour variation the blocks' points
    and attributes are written straight into the whole's arrays; with it, copied there.
    side_by_side: the blocks grown at once (as from generate.PARALLEL_BLOCK strands a block
    on), on the worker threads ("threads") or dealt out to this process's one worker thread
    and worker processes ("processes", where groom.processes.available()), reporting
    progress from the calling thread either way."""
    import importlib
    import threading
    from groom import default_collider, load_preset, processes
    from groom.parallel import cpu_threads
    module = importlib.import_module("groom.generate")
    if side_by_side == "processes" and not processes.available():
        pytest.skip("worker processes need Linux's memfd")
    monkeypatch.setenv(processes.ENV_SWITCH, "1" if side_by_side == "processes" else "0")
    grown_on = []

    def blocks_do(call):
        """call() with the blocks side by side or not, whatever their size, noting the
        threads the blocks of this process grew on."""
        grow = module._Grower._grow

        def noted(self, *args, **kwargs):
            grown_on.append(threading.current_thread())
            return grow(self, *args, **kwargs)
        with monkeypatch.context() as m:
            for name in ("PARALLEL_BLOCK", "PROCESS_BLOCK"):
                m.setattr(module, name, 100 if side_by_side else 10 ** 9)
            m.setattr(module._Grower, "_grow", noted)
            return call()
    placement = load_preset("wavy").place_keys(scalp)
    params = placement.params.replace(count=3000, seed=4, resolution_mode=resolution,
                                      points_per_strand=96 if resolution == "adaptive" else 24,
                                      color_variation_point=(variation,) * 3)
    keys = list(placement.keys)
    one = Generator(scalp, keys, params, collider=default_collider(), block_strands=10_000)
    reports = []
    blocks = Generator(scalp, keys, params, collider=default_collider(), block_strands=200,
                       progress=lambda f, stage: reports.append((f, threading.current_thread())))
    a, b = one.generate(), blocks_do(blocks.generate)
    assert {t for _, t in reports} == {threading.current_thread()}
    workers = {t for t in grown_on if t is not threading.current_thread()}
    n_blocks, sides = 3000 // 200, min(2, cpu_threads())
    if side_by_side == "processes" and sides > 1:
        # This process grew its share (every second block) on its one thread; the others grew
        # in a worker process.
        assert len(grown_on) == -(-n_blocks // sides) and len(workers) == 1
    else:
        assert len(grown_on) >= n_blocks and len(workers) == (sides if side_by_side else 0)
    assert [f for f, _ in reports] == sorted(f for f, _ in reports) and reports[-1][0] == 1.0
    _same(a, b)
    assert a.collision.strands_moved == b.collision.strands_moved > 0
    assert a.collision.last == b.collision.last
    if resolution == "adaptive":
        for x, y in zip(one._resolution, blocks._resolution):
            np.testing.assert_array_equal(x, y)
    assert np.array_equal(one._collision.moved, blocks._collision.moved)
    k = keys[3]
    reshaped = KeyStrand(k.points * [1.0, 1.0, 1.0] + np.linspace(0, 0.01, len(k.points))[:, None] * [1, 0, 0],
                         kind=k.kind, color=k.color, root_radius=k.root_radius, group=k.group)
    a, b = one.update_keys({3: reshaped}), blocks_do(lambda: blocks.update_keys({3: reshaped}))
    assert blocks.last_recomputed > 200
    _same(a, b)
    assert np.array_equal(one._collision.moved, blocks._collision.moved)
    assert a.collision == b.collision


def test_this_process_starts_its_blocks_before_a_worker_takes_its_messages():
    """generate._deal: a message larger than a pipe holds waits until the worker reads it,
    which it does between its jobs; this process's own jobs must already be running by then
    (sending first left it idle until the worker had begun its last block). The fake
    worker's send waits for this process's first job to begin."""
    import threading
    from concurrent.futures import ThreadPoolExecutor
    from groom.generate import _deal
    began = threading.Event()

    class Piped:
        def __init__(self):
            self.answers = []

        def send(self, fn, *args):
            assert began.wait(5), "this process's job had not begun while a worker's message was sent"
            self.answers.append(fn(*args))

        def receive(self):
            return self.answers.pop(0)

    def job(i):
        began.set()
        return ("here", i)
    worker, futures, done = Piped(), [], []
    with ThreadPoolExecutor(1) as here:
        got = _deal([None, worker, None, worker], here, lambda i: (lambda j: ("worker", j), i), job,
                    done.append, futures)
    assert got == [("here", 0), ("worker", 1), ("here", 2), ("worker", 3)]
    assert done == [0, 1, 2, 3] and [f is None for f in futures] == [False, True, False, True]

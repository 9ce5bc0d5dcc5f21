# SPDX-License-Identifier: GPL-3.0-or-later
from math import comb

import numpy as np
import pytest

from groom import KeyStrand, place_key
from groom.frames import root_frames
from hairio import InputError


def _bernstein(ctrl, t):
    n = len(ctrl) - 1
    basis = np.stack([comb(n, i) * t ** i * (1 - t) ** (n - i) for i in range(n + 1)], 1)
    return basis @ ctrl


@pytest.mark.parametrize("degree", [1, 2, 3, 7, 12])
def test_bezier_of_any_degree_matches_the_bernstein_form(degree):
    ctrl = np.random.default_rng(degree).normal(size=(degree + 1, 3))
    t = np.linspace(0, 1, 57)
    np.testing.assert_allclose(KeyStrand(ctrl).evaluate(t), _bernstein(ctrl, t), atol=1e-12)


def test_piecewise_cubic_passes_through_its_knots_and_uses_its_handles():
    ctrl = np.array([[0, 0, 0], [1, 0, 0], [2, 1, 0], [2, 2, 0], [2, 3, 0], [1, 4, 1], [0, 4, 2]], float)
    k = KeyStrand(ctrl, kind="cubic")
    np.testing.assert_allclose(k.evaluate([0, 0.5, 1]), ctrl[[0, 3, 6]], atol=1e-12)
    np.testing.assert_allclose(k.evaluate([0.25]), _bernstein(ctrl[:4], np.array([0.5])), atol=1e-12)
    np.testing.assert_allclose(k.evaluate([0.75]), _bernstein(ctrl[3:], np.array([0.5])), atol=1e-12)


def test_arc_length_resampling_spaces_points_equally():
    ctrl = np.array([[0, 0, 0], [0, 0, 1], [3, 0, 1], [3, 0, 0.2]], float)
    pts = KeyStrand(ctrl).resample(40)
    step = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    assert step.std() / step.mean() < 1e-3
    np.testing.assert_allclose(pts[[0, -1]], ctrl[[0, -1]], atol=1e-12)


def test_zero_length_key_resamples_to_its_root_without_nan():
    k = KeyStrand(np.tile([[1.0, 2.0, 3.0]], (4, 1)))
    pts = k.resample(10)
    assert np.isfinite(pts).all()
    np.testing.assert_array_equal(pts, np.tile([1.0, 2.0, 3.0], (10, 1)))
    assert k.length() == 0


def test_repeated_control_points_resample_evenly():
    ctrl = np.array([[0, 0, 0], [0, 0, 0], [0, 0, 0], [1, 0, 0], [1, 0, 0], [2, 0, 0], [2, 0, 0]], float)
    for kind in ("bezier", "cubic"):
        pts = KeyStrand(ctrl, kind=kind).resample(21)
        assert np.isfinite(pts).all()
        np.testing.assert_allclose(pts[:, 0], np.linspace(0, 2, 21), atol=2e-3)


def test_hairpin_keeps_both_legs():
    # A 180° bend: up 1, across 0.01, down 1.
    ctrl = np.array([[0, 0, 0], [0, 0, 1], [0.01, 0, 1], [0.01, 0, 0]], float)
    k = KeyStrand(ctrl, kind="cubic")
    pts = k.resample(101)
    assert np.isfinite(pts).all()
    step = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    assert step.std() / step.mean() < 1e-2
    assert pts[:, 2].max() > 0.7 and pts[-1, 0] == pytest.approx(0.01)


def test_evaluation_is_exact_far_from_the_origin():
    ctrl = np.array([[0, 0, 0], [0, 0, 0.01], [0.01, 0, 0.02]], float)
    near = KeyStrand(ctrl).arc_length_table(30)[0]
    far = KeyStrand(ctrl + 1e4).arc_length_table(30)[0]
    np.testing.assert_allclose(far, near, atol=1e-12)


@pytest.mark.parametrize("points, kind, word", [
    ([[0, 0, 0]], "bezier", "at least 2"),
    ([[0, 0, 0], [1, 0, 0], [2, 0, 0]], "cubic", "3k\\+1"),
    ([[0, 0, 0], [1, np.nan, 0]], "bezier", "key strand points"),
    ([[0, 0], [1, 0]], "bezier", "shape"),
    ([[0, 0, 0], [1, 0, 0]], "nurbs", "kind"),
])
def test_bad_keys_are_rejected_naming_the_problem(points, kind, word):
    with pytest.raises(InputError, match=word):
        KeyStrand(np.array(points, float), kind=kind)


def test_place_key_maps_local_axes_to_the_root_frame():
    frame = root_frames(np.array([[1.0, 0, 0]]))[0]
    root = np.array([0.1, 0, 0])
    prof = np.array([[0, 0, 0], [0, 0, 1.0], [1.0, 0, 1.0]])
    pts = place_key(prof, root, frame)
    np.testing.assert_allclose(pts[1] - root, frame[:, 2], atol=1e-12)         # z -> normal
    np.testing.assert_allclose(pts[2] - pts[1], frame[:, 0], atol=1e-12)       # x -> main tangent


def test_place_key_angles_rotate_about_the_root_axes():
    frame = np.eye(3)
    prof = np.array([[0, 0, 0], [0, 0, 1.0]])
    # 90° about the main tangent (x) turns the normal (z) toward -y.
    pts = place_key(prof, np.zeros(3), frame, (np.pi / 2, 0, 0))
    np.testing.assert_allclose(pts[1], [0, -1, 0], atol=1e-12)
    # The curve moves with its control points (Bézier curves are affine invariant).
    k = KeyStrand(place_key([[0, 0, 0], [0, 1, 1], [1, 0, 2]], np.ones(3), frame, (0.3, -0.2, 1.1)))
    k0 = KeyStrand(np.array([[0, 0, 0], [0, 1, 1], [1, 0, 2]], float))
    assert k.length() == pytest.approx(k0.length(), rel=1e-9)


# --- the shapes a new key starts with, and the keys' fingerprint ---------------------------

@pytest.mark.parametrize("shape", ["straight", "wavy", "curly", "swept"])
def test_a_key_shape_starts_at_the_root_and_has_the_length_asked_for(shape):
    from groom.keys import shape_profile
    p = shape_profile(shape, 0.23)
    np.testing.assert_array_equal(p[0], 0.0)
    assert np.linalg.norm(np.diff(p, axis=0), axis=1).sum() == pytest.approx(0.23, rel=1e-12)


def test_key_shapes_leave_the_scalp_and_differ_from_each_other():
    from groom.keys import KEY_SHAPES, shape_profile
    profiles = {s: shape_profile(s, 1.0) for s in KEY_SHAPES}
    for s, p in profiles.items():
        assert p[1:, 2].max() > 0.0, f"{s} never rises off the scalp"
    assert profiles["straight"][-1, 0] > 0.5, "straight does not fall down the head"
    assert profiles["swept"][-1, 0] < 0.0, "swept does not sweep back"
    assert np.ptp(profiles["curly"][:, 1]) > np.ptp(profiles["straight"][:, 1])
    ends = np.array([p[-1] for p in profiles.values()])
    assert len(np.unique(ends.round(6), axis=0)) == len(KEY_SHAPES)


@pytest.mark.parametrize("shape, length", [("spiky", 0.2), ("wavy", 0.0), ("wavy", float("nan"))])
def test_an_unknown_shape_or_a_length_that_is_not_positive_is_refused(shape, length):
    from groom.keys import shape_profile
    with pytest.raises(InputError, match="key (shape|length)"):
        shape_profile(shape, length)


def test_changed_keys_names_exactly_the_keys_edited():
    from groom.keys import changed_keys, keys_signature
    rng = np.random.default_rng(3)
    keys = [KeyStrand(rng.normal(size=(4, 3)), kind="cubic") for _ in range(4)]
    old = keys_signature(keys)
    assert changed_keys(keys_signature(keys), old) == []
    edited = list(keys)
    moved = keys[1].points.copy()
    moved[-1, 2] += 1e-9
    edited[1] = KeyStrand(moved, kind="cubic")
    edited[3] = KeyStrand(keys[3].points, kind="cubic", color=(1, 0, 0))
    assert changed_keys(keys_signature(edited), old) == [1, 3]
    regrouped = keys[:2] + [KeyStrand(keys[2].points, kind="cubic", group=1), keys[3]]
    assert changed_keys(keys_signature(regrouped), old) == [2]
    longer = keys[:3] + [KeyStrand(rng.normal(size=(7, 3)), kind="cubic")]
    assert changed_keys(keys_signature(longer), old) == [3]


def test_a_different_number_of_keys_or_no_old_fingerprint_means_every_key_is_new():
    from groom.keys import changed_keys, keys_signature
    keys = [KeyStrand(np.eye(3)), KeyStrand(np.eye(3) * 2)]
    assert changed_keys(keys_signature(keys), None) is None
    assert changed_keys(keys_signature(keys[:1]), keys_signature(keys)) is None

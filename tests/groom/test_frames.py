# SPDX-License-Identifier: GPL-3.0-or-later
import numpy as np
import pytest

from groom.frames import root_frames, rotation_xyz, whorl_direction
from hairio import InputError


def _orthonormality_error(frames):
    eye = np.einsum("nij,nik->njk", frames, frames)
    return np.abs(eye - np.eye(3)).max()


def _sphere_normals(n, seed=0):
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def test_frames_are_orthonormal_at_the_crown_and_on_the_central_line():
    crown = np.array([[0, 0, 1.0], [0, 0, 2.0], [0, 0, -1.0], [1e-12, 0, 1.0], [0, 1e-15, 1.0]])
    f = root_frames(crown)
    assert np.isfinite(f).all()
    assert _orthonormality_error(f) < 1e-6
    # At the crown the main tangent is the front direction.
    np.testing.assert_allclose(f[0][:, 0], [0, -1, 0], atol=1e-12)


def test_frames_are_orthonormal_and_finite_everywhere():
    normals = np.concatenate([_sphere_normals(20000), np.eye(3), -np.eye(3), [[0, -1, 1e-17]],
                              [[0, 0, 0]], [whorl_direction()]])
    f = root_frames(normals)
    assert np.isfinite(f).all()
    assert _orthonormality_error(f) < 1e-6
    # Right-handed: second tangent = normal × main tangent.
    np.testing.assert_allclose(np.cross(f[:, :, 2], f[:, :, 0]), f[:, :, 1], atol=1e-9)


def test_frame_normal_is_the_given_normal():
    n = _sphere_normals(100, seed=1)
    np.testing.assert_allclose(root_frames(n)[:, :, 2], n, atol=1e-12)


def test_main_tangent_points_down_the_head_away_from_the_crown():
    polar = np.radians(70)
    az = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    n = np.stack([np.sin(polar) * np.cos(az), np.sin(polar) * np.sin(az), np.full_like(az, np.cos(polar))], 1)
    t = root_frames(n)[:, :, 0]
    assert (t[:, 2] < -0.9).all()


def _largest_tangent_step(step_deg, exclude_deg):
    """Largest change of the main tangent between grid neighbours over the upper 110° of a
    sphere, ignoring pairs within exclude_deg of the whorl."""
    polar = np.radians(np.arange(0, 110 + 1e-9, step_deg))
    az = np.radians(np.arange(0, 360 + 1e-9, step_deg))
    P, A = np.meshgrid(polar, az, indexing="ij")
    n = np.stack([np.sin(P) * np.cos(A), np.sin(P) * np.sin(A), np.cos(P)], -1)
    t = root_frames(n.reshape(-1, 3)).reshape(n.shape[:2] + (3, 3))[..., 0]
    far = np.arccos(np.clip(n @ whorl_direction(), -1, 1)) > np.radians(exclude_deg)
    worst = 0.0
    for axis in (0, 1):
        dt = np.linalg.norm(np.diff(t, axis=axis), axis=-1)
        ok = np.logical_and(np.take(far, range(far.shape[axis] - 1), axis=axis),
                            np.take(far, range(1, far.shape[axis]), axis=axis))
        worst = max(worst, float(dt[ok].max()))
    return worst


def test_frames_are_continuous_away_from_the_whorl():
    # Continuity: halving the grid step halves the largest jump between neighbours (a seam
    # would keep it). Only a disc around the one documented seam point is left out.
    coarse = _largest_tangent_step(1.0, exclude_deg=10)
    fine = _largest_tangent_step(0.5, exclude_deg=10)
    assert fine < 0.6 * coarse
    assert fine < 0.5


def test_the_whorl_is_where_the_frame_breaks():
    w = whorl_direction()
    back = np.array([0, 1.0, 0])
    assert w @ back > 0  # on the side opposite the front
    # Either side of the whorl along the back meridian the main tangent flips.
    e = np.cross(w, np.cross([0, 0, 1.0], w))
    e /= np.linalg.norm(e)
    before = (w + 0.02 * e) / np.linalg.norm(w + 0.02 * e)
    after = (w - 0.02 * e) / np.linalg.norm(w - 0.02 * e)
    t = root_frames(np.array([before, after]))[:, :, 0]
    assert t[0] @ t[1] < -0.5


def test_frames_reject_front_parallel_to_up():
    with pytest.raises(InputError, match="front"):
        root_frames(np.array([[0, 0, 1.0]]), up=(0, 0, 1), front=(0, 0, -2))


def test_rotation_xyz_of_zero_angles_is_exactly_identity():
    np.testing.assert_array_equal(rotation_xyz(np.zeros((3, 3))), np.broadcast_to(np.eye(3), (3, 3, 3)))


def test_rotation_xyz_rotates_about_the_named_axes():
    r = rotation_xyz([[np.pi / 2, 0, 0], [0, np.pi / 2, 0], [0, 0, np.pi / 2]])
    np.testing.assert_allclose(r[0] @ [0, 1, 0], [0, 0, 1], atol=1e-12)   # about x
    np.testing.assert_allclose(r[1] @ [0, 0, 1], [1, 0, 0], atol=1e-12)   # about y
    np.testing.assert_allclose(r[2] @ [1, 0, 0], [0, 1, 0], atol=1e-12)   # about z

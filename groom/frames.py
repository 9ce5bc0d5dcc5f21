# SPDX-License-Identifier: GPL-3.0-or-later
"""Root frames (SPEC §1): normal, main tangent, second tangent at every root.

The thesis takes the main tangent along the meridian through the root and the central line
(the vertical axis of the head). That frame is undefined on the central line (the crown,
where hair is densest) and its Euler-angle form divides by zero there.

Here the main tangent is the downhill direction of the tangent plane, proj_N(-up), which is
the thesis's meridian tangent on any head symmetric about the central line and depends only
on the normal (so moving or scaling the head changes nothing). Near the crown, where the
downhill direction vanishes, it blends smoothly toward proj_N(front):

    s = smoothstep(cos(outer), cos(inner), N·up)
    t = normalise((1 - s)·proj_N(-up) + s·proj_N(front))
    b = N × t

Within `inner` of the crown hair points to the front; beyond `outer` it points down the head.

The seam. A tangent field that points down the head all around the crown must turn once
around the crown, and one that points to the front does not turn at all, so the blend must
break somewhere (a hairy-ball argument). With the vector blend above it breaks at ONE point:
the whorl, on the back half (the side opposite `front`) of the meridian plane through up and
front, at the polar angle where (1 - s)·|proj_N(-up)| = s·|proj_N(front)| (about 31° behind
the crown for the defaults; `whorl_direction` computes it). Everywhere else the frame is
continuous; close to the whorl it turns quickly, as real hair does at a crown whorl. At the
whorl itself (and wherever the blended vector is shorter than 1e-9) the main tangent falls
back to proj_N(up × front), then to any unit vector perpendicular to N, so a frame is never
NaN. Below the equator the downhill field has a second zero at N = -up (the chin side of a
full sphere); scalps do not grow hair there, and the same fallback applies.
"""
import numpy as np

from hairio import InputError, check_finite

DEFAULT_UP = (0.0, 0.0, 1.0)
DEFAULT_FRONT = (0.0, -1.0, 0.0)


def _axis(name, v):
    v = check_finite(name, np.asarray(v, dtype=np.float64))
    if v.shape != (3,) or np.linalg.norm(v) < 1e-12:
        raise InputError(f"{name}: expected a non-zero 3-vector, got {v!r}")
    return v / np.linalg.norm(v)


def _project(v, n):
    """Component of v (3,) or (N,3) in the planes with unit normals n (N,3)."""
    return v - np.einsum("nd,nd->n", np.broadcast_to(v, n.shape), n)[:, None] * n


def root_frames(normals, up=DEFAULT_UP, front=DEFAULT_FRONT, inner_deg=10.0, outer_deg=40.0):
    """Frames (N,3,3) whose COLUMNS are (main tangent, second tangent, normal).

    normals (N,3) need not be exactly unit. A local offset (x, y, z) maps to the world as
    frame @ (x, y, z): x runs down the head, y across it, z out of the scalp.
    """
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    axes = frame_axes(n.T, up, front, inner_deg, outer_deg)
    return np.stack([a.T for a in axes], axis=2)


def frame_axes(normals, up=DEFAULT_UP, front=DEFAULT_FRONT, inner_deg=10.0, outer_deg=40.0):
    """root_frames component-major: normals (3, N); returns (main tangent, second tangent,
    normal), each (3, N) float64. Whole-array work on one contiguous row per component is
    several times faster than on (N,3) rows of three."""
    up = _axis("up", up)
    front = _axis("front", front)
    if abs(float(up @ front)) > 0.999:
        raise InputError("front: must not be parallel to up; give the direction the face looks")
    if not 0.0 <= inner_deg < outer_deg <= 180.0:
        raise InputError("crown blend angles: need 0 <= inner_deg < outer_deg <= 180")
    n = np.ascontiguousarray(normals, dtype=np.float64).reshape(3, -1)
    length = _norm(n)
    ok = length > 1e-300
    n = np.where(ok, n / np.where(ok, length, 1.0), up[:, None])
    c = _dot(up, n)
    lo, hi = np.cos(np.radians(outer_deg)), np.cos(np.radians(inner_deg))
    x = np.clip((c - lo) / (hi - lo), 0.0, 1.0)
    s = x * x * (3.0 - 2.0 * x)
    # (1 - s)·proj_N(-up) + s·proj_N(front), with proj_N(v) = v - (v·N) N
    v = (1.0 - s) * (c * n - up[:, None]) + s * (front[:, None] - _dot(front, n) * n)
    side = np.cross(up, front)
    # Fallbacks are projected only for the rows that need them (almost none on a scalp).
    for fallback in (side, front, up):
        short = _norm(v) < 1e-9
        if not short.any():
            break
        v[:, short] = _project(fallback, n[:, short].T).T
    # n is parallel to none of up, front, side at once, but guard the last possibility anyway.
    short = _norm(v) < 1e-9
    if short.any():
        e = np.eye(3)[np.argmin(np.abs(n[:, short]), axis=0)]
        v[:, short] = _project(e, n[:, short].T).T
    v -= _dot(v, n) * n  # exact tangency after the blend
    t = v / _norm(v)
    b = np.stack([n[1] * t[2] - n[2] * t[1], n[2] * t[0] - n[0] * t[2], n[0] * t[1] - n[1] * t[0]])
    b /= _norm(b)
    return t, b, n


def _dot(a, b):
    """Row-wise dot product of component-major (3, N) arrays (either may be a plain 3-vector)."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _norm(v):
    return np.sqrt(_dot(v, v))


def whorl_direction(up=DEFAULT_UP, front=DEFAULT_FRONT, inner_deg=10.0, outer_deg=40.0):
    """Unit normal at which the frame field of a sphere has its one break (the seam point)."""
    up, front = _axis("up", up), _axis("front", front)
    back = -(front - (front @ up) * up)
    back /= np.linalg.norm(back)
    theta = np.radians(np.linspace(0.0, outer_deg, 20001))
    normals = np.cos(theta)[:, None] * up + np.sin(theta)[:, None] * back
    lo, hi = np.cos(np.radians(outer_deg)), np.cos(np.radians(inner_deg))
    x = np.clip((normals @ up - lo) / (hi - lo), 0.0, 1.0)
    s = x * x * (3.0 - 2.0 * x)
    # On that meridian both terms are collinear; the blend changes sign at the whorl.
    along = (1.0 - s) * np.sin(theta) - s * np.cos(theta) * np.abs(front @ back)
    i = int(np.argmin(np.abs(along)))
    return normals[i]


def rotation_xyz(angles):
    """Rotation matrices (N,3,3) = Rz(angles[:,2]) @ Ry(angles[:,1]) @ Rx(angles[:,0]):
    angles about the frame's main tangent (x), second tangent (y), normal (z), in radians."""
    a = np.asarray(angles, dtype=np.float64).reshape(-1, 3)
    return np.stack(rotation_entries(a.T), axis=1).reshape(-1, 3, 3)


def rotation_entries(angles):
    """rotation_xyz entry-major: angles (3, N); returns the nine entries, entry (i, j) at
    3i + j, each (N,)."""
    cx, sx = np.cos(angles[0]), np.sin(angles[0])
    cy, sy = np.cos(angles[1]), np.sin(angles[1])
    cz, sz = np.cos(angles[2]), np.sin(angles[2])
    return [cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx,
            sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx,
            -sy, cy * sx, cy * cx]

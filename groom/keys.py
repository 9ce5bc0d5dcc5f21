# SPDX-License-Identifier: GPL-3.0-or-later
"""Key strands (SPEC §3): Bézier curves whose first control point is the root.

Two kinds: `bezier`, one curve of any degree (n+1 control points, the thesis), and
`cubic`, a piecewise cubic spline with handles `[P0, H0out, H1in, P1, H1out, ...]`
(3k+1 rows, what Blender artists draw). Evaluation is de Casteljau in float64 on control
points taken relative to the root, so a head placed 1e4 units from the origin loses nothing.
"""
import functools

import numpy as np

from hairio import InputError, check_finite

from .frames import rotation_xyz

KINDS = ("bezier", "cubic")


def _de_casteljau(ctrl, t):
    """Points of one Bézier curve (control points (n,3)) at parameters t (M,)."""
    work = np.broadcast_to(ctrl, (len(t),) + ctrl.shape).copy()
    tt = t[:, None, None]
    for r in range(len(ctrl) - 1, 0, -1):
        work = work[:, :r] + tt * (work[:, 1:r + 1] - work[:, :r])
    return work[:, 0]


class KeyStrand:
    """points (n,3) absolute positions, point 0 the root; kind 'bezier' | 'cubic';
    color (3,) linear RGB or None (use the parameters' colour); root_radius or None
    (use the parameters' radius); group (parting) id."""

    def __init__(self, points, kind="bezier", color=None, root_radius=None, group=0):
        if kind not in KINDS:
            raise InputError(f"key strand kind: expected one of {KINDS}, got {kind!r}")
        p = np.asarray(points)
        if p.ndim != 2 or p.shape[1] != 3:
            raise InputError(f"key strand points: expected shape (n, 3), got {p.shape}")
        if p.dtype.kind not in "fiu":
            raise InputError(f"key strand points: expected numbers, got dtype {p.dtype}")
        p = check_finite("key strand points", p.astype(np.float64))
        if kind == "bezier" and len(p) < 2:
            raise InputError("key strand points: a Bézier key needs at least 2 control points")
        if kind == "cubic" and (len(p) < 4 or (len(p) - 1) % 3):
            raise InputError(f"key strand points: a piecewise cubic key needs 3k+1 rows "
                             f"[P0, H0out, H1in, P1, ...], got {len(p)}")
        self.points = p
        self.kind = kind
        if color is not None:
            color = check_finite("key strand color", np.asarray(color, dtype=np.float64))
            if color.shape != (3,):
                raise InputError(f"key strand color: expected 3 values (RGB), got shape {color.shape}")
            color = np.clip(color, 0.0, 1.0)
        self.color = color
        if root_radius is not None:
            root_radius = float(root_radius)
            if not np.isfinite(root_radius) or root_radius < 0:
                raise InputError(f"key strand root_radius: expected a finite value >= 0, got {root_radius}")
        self.root_radius = root_radius
        if isinstance(group, bool) or not isinstance(group, (int, np.integer)):
            raise InputError(f"key strand group: expected an integer, got {group!r}")
        self.group = int(group)

    @property
    def root(self):
        return self.points[0]

    @property
    def num_segments(self):
        return (len(self.points) - 1) // 3 if self.kind == "cubic" else 1

    def evaluate(self, t):
        """Positions at curve parameters t in [0, 1] (cubic: segment i covers [i/k, (i+1)/k])."""
        t = np.clip(np.asarray(t, dtype=np.float64).ravel(), 0.0, 1.0)
        return self.points[0] + self.evaluate_offsets(t)

    def evaluate_offsets(self, t):
        """Positions relative to the root (float64): the precise form for far-away heads."""
        t = np.clip(np.asarray(t, dtype=np.float64).ravel(), 0.0, 1.0)
        if self.kind == "bezier":
            return _de_casteljau(self.points - self.points[0], t)
        return _cubic_offsets(self, t)

    def arc_length_table(self, samples, dense=None):
        """Offsets from the root at `samples` points equally spaced in arc length (float64),
        and the total length. Robust to zero-length curves (all points at the root),
        repeated control points (stretches of zero speed) and hairpins."""
        return arc_length_tables([self], samples, dense)[0]

    def resample(self, samples):
        """Absolute points equally spaced in arc length (float64)."""
        off, _ = self.arc_length_table(samples)
        return self.points[0] + off

    def length(self):
        return self.arc_length_table(2)[1]


def _cubic_offsets(key, t, basis=None):
    """Points relative to the root of a cubic key at parameters t (clipped to [0, 1]).
    Cubic Bernstein form, all segments at once, one coordinate at a time (rows of three
    would make every operation loop over three numbers). basis: _cubic_basis(t, segments)
    when the caller has it."""
    rel = key.points - key.points[0]
    weights, rows = basis or _cubic_basis(t, key.num_segments)
    w0, w1, w2, w3 = weights
    out = np.empty((len(t), 3))
    for d, column in enumerate(rel.T):
        c0, c1, c2, c3 = (column.take(r) for r in rows)
        out[:, d] = w0 * c0 + w1 * c1 + w2 * c2 + w3 * c3
    return out


def _cubic_basis(t, k):
    """Bernstein weights (4 arrays) and control-point rows (4 arrays) of parameters t on a
    spline of k cubic segments."""
    seg = np.minimum((t * k).astype(np.int64), k - 1)
    u = t * k - seg
    v = 1.0 - u
    first = 3 * seg
    return (v * v * v, 3.0 * v * v * u, 3.0 * v * u * u, u * u * u), (first, first + 1, first + 2, first + 3)


@functools.lru_cache(maxsize=16)
def _dense_grid(n, segments):
    """The dense parameter grid of arc_length_tables and, for cubic keys, its Bernstein
    basis: constants of (n, segments), made once rather than for every key and call."""
    t = np.linspace(0.0, 1.0, n)
    basis = _cubic_basis(t, segments) if segments else None
    for a in (t,) + (sum(basis, ()) if basis else ()):
        a.flags.writeable = False
    return t, basis


def arc_length_tables(keys, samples, dense=None):
    """KeyStrand.arc_length_table of several keys: [(offsets (samples,3), length)]. One key
    at a time on purpose: batching them made arrays large enough for the allocator to map
    fresh pages on every call, which cost more than the calls it saved."""
    out = []
    for k in keys:
        t, basis = _dense_grid(dense or max(2048, 128 * k.num_segments, 4 * samples),
                               k.num_segments if k.kind == "cubic" else 0)
        pts = _cubic_offsets(k, t, basis) if basis else k.evaluate_offsets(t)
        step = np.diff(pts, axis=0)
        step = np.sqrt(np.einsum("nd,nd->n", step, step))
        cum = np.concatenate([[0.0], np.cumsum(step)])
        length = float(cum[-1])
        scale = float(np.abs(k.points - k.points[0]).max())
        if not length > 1e-12 * max(scale, 1e-300) or length == 0.0:
            out.append((np.zeros((samples, 3)), 0.0))
            continue
        # Keep strictly increasing arc lengths only: zero-speed stretches would make the
        # inverse ambiguous (any parameter there gives the same point anyway).
        keep = np.concatenate([[True], step > 0])
        target = np.linspace(0.0, length, samples)
        out.append((k.evaluate_offsets(np.interp(target, cum[keep], t[keep])), length))
    return out


def place_key(profile, root, frame, angles=(0.0, 0.0, 0.0)):
    """World control points of a key drawn in a root's local frame.

    profile (n,3): control points in local coordinates (x down the head along the main
    tangent, y along the second tangent, z along the normal); its first row is the root.
    frame (3,3): columns (main tangent, second tangent, normal), see frames.root_frames.
    angles: rotations (radians) about the local x, y, z axes, applied x first.
    Control points transform exactly with the curve (Bézier curves are affine invariant).
    """
    prof = check_finite("key profile", np.asarray(profile, dtype=np.float64))
    if prof.ndim != 2 or prof.shape[1] != 3:
        raise InputError(f"key profile: expected shape (n, 3), got {prof.shape}")
    root = check_finite("key root", np.asarray(root, dtype=np.float64).reshape(3))
    frame = check_finite("key frame", np.asarray(frame, dtype=np.float64).reshape(3, 3))
    rot = rotation_xyz(np.asarray(angles, dtype=np.float64).reshape(1, 3))[0]
    local = (prof - prof[0]) @ rot.T
    return root + local @ frame.T


# The shapes a new key strand starts with (Add Key Strand), by name.
KEY_SHAPES = ("straight", "wavy", "curly", "swept")


def shape_profile(shape, length):
    """Control points (n,3) of a key shape in a root's local frame (x down the head, y across
    it, z out of the scalp; place_key's profile), first row the root, scaled to arc length
    `length` along its control polygon. shape: one of KEY_SHAPES."""
    if shape not in KEY_SHAPES:
        raise InputError(f"key shape: expected one of {KEY_SHAPES}, got {shape!r}")
    length = float(length)
    if not np.isfinite(length) or length <= 0:
        raise InputError(f"key length: expected a positive finite length, got {length}")
    s = np.linspace(0.0, 1.0, 9)
    if shape == "straight":
        # Lift off the scalp, then fall down the head.
        p = np.stack([s, np.zeros_like(s), 0.12 * np.sin(np.pi * np.minimum(s * 1.5, 1.0)) * (1 - 0.5 * s)], 1)
        p[1] = (0.0, 0.0, 0.06)
    elif shape == "wavy":
        s = np.linspace(0.0, 1.0, 13)
        p = np.stack([s, 0.07 * np.sin(4 * np.pi * s) * np.minimum(s * 4, 1.0),
                      0.1 * np.sin(np.pi * np.minimum(s * 1.5, 1.0))], 1)
    elif shape == "curly":
        s = np.linspace(0.0, 1.0, 33)
        turn = 6 * np.pi * s
        ramp = np.minimum(s * 5, 1.0)
        p = np.stack([0.6 * s, 0.08 * np.sin(turn) * ramp, 0.08 * (1 - np.cos(turn)) * ramp + 0.05 * ramp], 1)
    else:  # swept
        p = np.stack([-0.35 * s * s, np.zeros_like(s), s], 1)
    p -= p[0]
    arc = float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())
    return p * (length / arc)


def keys_signature(keys):
    """A fingerprint of each key, one float64 array per key: its control points, colour,
    root radius and group, so an edit of any of them shows. Compare two with changed_keys."""
    return [np.concatenate([k.points.ravel(), np.asarray(k.color if k.color is not None else (-1, -1, -1)),
                            [k.root_radius if k.root_radius is not None else -1.0, k.group]])
            for k in keys]


def changed_keys(signature, old):
    """Indices of the keys whose fingerprint (keys_signature) differs from `old`'s, or None
    when there is no old one or the number of keys changed (every key counts as new)."""
    if old is None or len(signature) != len(old):
        return None
    return [i for i, (a, b) in enumerate(zip(signature, old)) if a.shape != b.shape or not (a == b).all()]

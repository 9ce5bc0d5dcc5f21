# SPDX-License-Identifier: GPL-3.0-or-later
"""Key strands drawn as an artist draws them: a stroke projected onto a surface through its
root, fitted with a few cubic Bézier segments, mirrored across the head, combed.

Everything works on plain arrays in one space (the scalp's); the viewer is a view direction
and, for a perspective view, the eye. Results are control points in groom's piecewise cubic
layout `[P0, H0out, H1in, P1, ...]` (KeyStrand kind 'cubic').

- `project_to_plane`, `project_to_shell`: each stroke point slides along its own view ray, so
  it stays under the pixel it was drawn at, onto the plane through the root that faces the
  viewer, or onto the shell `offset` outside the scalp (where the ray misses the shell, past
  the head's outline, the plane point is kept).
- `fit_bezier`: Schneider's algorithm ("An algorithm for automatically fitting digitized
  curves", Graphics Gems, 1990): chord-length parameters, least-squares handle lengths along
  fixed end tangents, Newton reparametrisation, and a split at the worst point when that is
  not enough. The first tangent can be imposed: a key leaves its root along the normal.
- `mirror_points`, `mirror_key`: the reflection across one of the head frame's planes.
- `comb`, `comb_stroke`: a brush that bends a key's control points toward a drag and then
  restores the key's length.
"""
import numpy as np

from hairio import InputError, check_finite

from .head import vector3

#: Mirror planes by the head-frame axis they are perpendicular to.
AXES = ("X", "Y", "Z")

# A fit needing more segments than this is refused: the tolerance is far too small for the
# stroke (a key has a handful).
MAX_SEGMENTS = 2000
# Newton reparametrisation before a piece is split: at most this many steps, each of which
# must bring the worst error below STALLED times the last. Schneider reparametrises only
# pieces already within 4 tolerances; strokes drawn at an uneven speed start farther off and
# converge all the same (measured: a cubic sampled at equal parameters, 60 to 1000 points,
# fits as one segment after 20-60 steps instead of splitting into four or five).
NEWTON_STEPS = 64
STALLED = 0.98
# Where between two stroke points the curve's distance to their chord is checked. Eight,
# not three: a first segment made to leave against the stroke (a root normal pointing back)
# overshoots the root with its peak near an eighth of the chord, which three samples missed
# (found by a property test: 1.7 tolerances off).
CHORD_SAMPLES = tuple(np.arange(1, 9) / 9.0)
# The curve may come closer to the tolerance between those samples than at them; a chord
# counts as fitted within this share of the tolerance, so the curve stays within all of it
# (measured between samples: up to 6 % more than at the nearest one).
CHORD_SHARE = 0.9
# Samples per cubic segment for lengths (a polyline that close to a smooth curve is within
# 1e-7 of its length) and for the comb's weights.
LENGTH_SAMPLES = 512
COMB_SAMPLES = 32


def _points(name, points, minimum=1):
    p = np.asarray(points)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < minimum:
        raise InputError(f"{name}: expected shape (n, 3) with n >= {minimum}, got {p.shape}")
    if p.dtype.kind not in "fiu":
        raise InputError(f"{name}: expected numbers, got dtype {p.dtype}")
    return check_finite(name, p.astype(np.float64))




def _direction(name, v):
    a = vector3(name, v)
    length = float(np.linalg.norm(a))
    if not length > 1e-300:
        raise InputError(f"{name}: must not be the zero vector")
    return a / length


def _positive(name, value):
    try:
        x = float(value)
    except (TypeError, ValueError):
        x = float("nan")
    if not (np.isfinite(x) and x > 0):
        raise InputError(f"{name}: expected a finite number > 0, got {value!r}")
    return x


def _dot(a, b):
    return np.einsum("...d,...d->...", a, b)


def _unit_rows(v):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


# --- projection ------------------------------------------------------------------------

def _view_rays(points, view_direction, eye):
    """Unit directions of the view rays through the points: from the eye (perspective), or
    the view direction itself (orthographic)."""
    if eye is None:
        return np.broadcast_to(view_direction, points.shape)
    eye = vector3("eye", eye)
    rays = points - eye
    length = np.linalg.norm(rays, axis=1)
    if not (length > 0).all():
        raise InputError("stroke: a point lies at the eye; give points in front of the view")
    return rays / length[:, None]


def project_to_plane(points, root, view_direction, eye=None):
    """The stroke (n,3) on the plane through `root` perpendicular to `view_direction` (the
    way the viewer looks), each point moved along its view ray: from `eye` for a perspective
    view, along the view direction when eye is None. Returns (n,3)."""
    p = _points("stroke", points)
    root = vector3("root", root)
    d = _direction("view_direction", view_direction)
    rays = _view_rays(p, d, eye)
    facing = rays @ d
    if not (np.abs(facing) > 1e-9).all():
        raise InputError("stroke: a view ray runs along the drawing plane; the eye must look at the plane")
    t = ((root - p) @ d) / facing
    return p + t[:, None] * rays


def shell_triangles(scalp, offset):
    """Corners (a, b, c) (T,3) each of the shell `offset` outside the scalp (a groom.Scalp):
    its vertices moved along their normals. Offsets are relative to the scalp's bounding-box
    centre, returned as the fourth item, so a head far from the origin keeps its precision."""
    offset = float(offset)
    if not np.isfinite(offset) or offset < 0:
        raise InputError(f"shell offset: expected a finite distance >= 0, got {offset!r}")
    centre = 0.5 * (scalp.vertices.min(axis=0) + scalp.vertices.max(axis=0))
    v = scalp.vertices - centre + offset * scalp.vertex_normals
    t = scalp.triangles
    return v[t[:, 0]], v[t[:, 1]], v[t[:, 2]], centre


def _first_hits(origins, rays, a, b, c, chunk_pairs=1 << 18):
    """Distance along each ray (origin + t·ray, t > 0) to the nearest triangle it crosses
    (inf where none): Möller–Trumbore over every (ray, triangle) pair, a block of rays at a
    time. Edges are closed (u, v >= 0, u + v <= 1), so a ray through a shared edge hits."""
    e1, e2 = b - a, c - a
    best = np.full(len(origins), np.inf)
    step = max(1, chunk_pairs // max(len(a), 1))
    scale = float(np.abs(e1).max() + np.abs(e2).max()) or 1.0
    for lo in range(0, len(origins), step):  # blocks of rays, not single rays
        o = origins[lo:lo + step, None, :]
        r = rays[lo:lo + step, None, :]
        pvec = np.cross(r, e2)
        det = _dot(e1, pvec)
        # A ray grazing a triangle's plane has det ~ 0: no crossing to speak of.
        ok = np.abs(det) > 1e-12 * scale * scale
        inv = 1.0 / np.where(ok, det, 1.0)
        tvec = o - a
        u = _dot(tvec, pvec) * inv
        qvec = np.cross(tvec, e1)
        v = _dot(r, qvec) * inv
        t = _dot(e2, qvec) * inv
        hit = ok & (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0) & (t > 0.0)
        best[lo:lo + step] = np.where(hit, t, np.inf).min(axis=1)
    return best


def project_to_shell(points, scalp, offset, view_direction, eye=None):
    """The stroke (n,3) on the shell `offset` outside the scalp (a groom.Scalp), each point
    moved along its view ray (as in project_to_plane) to where the ray first crosses the
    shell as seen from the viewer. Points whose ray misses the shell stay where they are (give
    the plane points: a strand drawn past the head's outline keeps its drawn shape there).
    Returns (points (n,3), on_shell (n,) bool)."""
    p = _points("stroke", points)
    d = _direction("view_direction", view_direction)
    rays = _view_rays(p, d, eye)
    a, b, c, centre = shell_triangles(scalp, offset)
    local = p - centre
    if eye is None:
        # Orthographic: start every ray on the viewer's side of the whole shell and stroke.
        corners = np.concatenate([a, b, c])
        reach = float(np.linalg.norm(corners, axis=1).max() + np.linalg.norm(local, axis=1).max())
        origins = local - 2.0 * reach * rays
    else:
        origins = np.broadcast_to(vector3("eye", eye) - centre, p.shape)
    t = _first_hits(np.ascontiguousarray(origins), np.ascontiguousarray(rays), a, b, c)
    on = np.isfinite(t)
    out = p.copy()
    out[on] = centre + origins[on] + t[on, None] * rays[on]
    return out, on


# --- fitting ---------------------------------------------------------------------------

def _bernstein3(u):
    v = 1.0 - u
    return v * v * v, 3.0 * u * v * v, 3.0 * u * u * v, u * u * u


def _cubic_at(ctrl, u):
    b0, b1, b2, b3 = _bernstein3(u)
    return b0[:, None] * ctrl[0] + b1[:, None] * ctrl[1] + b2[:, None] * ctrl[2] + b3[:, None] * ctrl[3]


def _cubic_derivatives(ctrl, u):
    d1 = 3.0 * np.diff(ctrl, axis=0)
    d2 = 2.0 * np.diff(d1, axis=0)
    v = 1.0 - u
    q1 = (v * v)[:, None] * d1[0] + (2.0 * u * v)[:, None] * d1[1] + (u * u)[:, None] * d1[2]
    q2 = v[:, None] * d2[0] + u[:, None] * d2[1]
    return q1, q2


def _clean(points):
    """The stroke without consecutive repeats (a mouse held still adds nothing)."""
    scale = float(np.abs(points - points[0]).max()) or 1.0
    keep = np.concatenate([[True], np.linalg.norm(np.diff(points, axis=0), axis=1) > 1e-12 * scale])
    return points[keep]


def _end_tangent(points, tolerance):
    """Unit direction the stroke leaves its first point in, read over a stretch of a few
    tolerances (the first mouse step alone is mostly jitter)."""
    dist = np.linalg.norm(points - points[0], axis=1)
    far = np.flatnonzero(dist >= 2.0 * tolerance)
    # A short stroke (or one that ends where it began): toward its farthest point.
    i = int(far[0]) if len(far) else int(np.argmax(dist))
    return (points[i] - points[0]) / dist[i]


def _chord_parameters(d):
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(d, axis=0), axis=1))])
    return cum / cum[-1]


def _handles(d, u, t1, t2):
    """Schneider's least-squares cubic through d[0] and d[-1] with handles along t1 (leaving
    the start) and t2 (from the end back into the curve), at parameters u: (4,3)."""
    p0, p3 = d[0], d[-1]
    b0, b1, b2, b3 = _bernstein3(u)
    a1 = b1[:, None] * t1
    a2 = b2[:, None] * t2
    c00, c01, c11 = float(_dot(a1, a1).sum()), float(_dot(a1, a2).sum()), float(_dot(a2, a2).sum())
    rest = d - ((b0 + b1)[:, None] * p0 + (b2 + b3)[:, None] * p3)
    x0, x1 = float(_dot(rest, a1).sum()), float(_dot(rest, a2).sum())
    det = c00 * c11 - c01 * c01
    chord = float(np.linalg.norm(p3 - p0))
    alpha_1 = alpha_2 = 0.0
    if abs(det) > 1e-12 * max(c00 * c11, 1e-300):
        alpha_1 = (x0 * c11 - x1 * c01) / det
        alpha_2 = (c00 * x1 - c01 * x0) / det
    # A handle that is backwards or vanishing would turn the curve against its tangent:
    # Wu and Barsky's third of the chord instead, as Schneider does.
    if not (alpha_1 > 1e-6 * chord and alpha_2 > 1e-6 * chord):
        alpha_1 = alpha_2 = chord / 3.0
    return np.stack([p0, p0 + alpha_1 * t1, p3 + alpha_2 * t2, p3])


def _worst(d, ctrl, u):
    """(largest error, where to split) of a cubic fitted to points d (m,3) at parameters u.
    Both ways: each point's distance to its curve point, and the curve's distance to each
    chord of the stroke at CHORD_SAMPLES parameters across the chord's (a curve that bulges
    or overshoots between two points drawn far apart fails there). The split is at the worst
    interior point, or the interior end of the worst chord."""
    err = np.linalg.norm(_cubic_at(ctrl, u) - d, axis=1)
    a, b = d[:-1], d[1:]
    ab = b - a
    len2 = np.maximum(_dot(ab, ab), 1e-300)
    gap = np.zeros(len(ab))
    for f in CHORD_SAMPLES:
        q = _cubic_at(ctrl, u[:-1] + f * np.diff(u))
        t = np.clip(_dot(q - a, ab) / len2, 0.0, 1.0)
        gap = np.maximum(gap, np.linalg.norm(q - a - t[:, None] * ab, axis=1))
    gap /= CHORD_SHARE
    worst_point, worst_chord = int(np.argmax(err)), int(np.argmax(gap))
    if err[worst_point] >= gap[worst_chord]:
        split = worst_point
    else:
        split = worst_chord + 1 if err[worst_chord + 1] >= err[worst_chord] else worst_chord
    return max(float(err[worst_point]), float(gap[worst_chord])), int(np.clip(split, 1, len(d) - 2))


def _reparametrise(d, ctrl, u):
    """One Newton step per point on |Q(u) - d|², toward each point's nearest curve point."""
    q = _cubic_at(ctrl, u)
    q1, q2 = _cubic_derivatives(ctrl, u)
    diff = q - d
    num = _dot(diff, q1)
    den = _dot(q1, q1) + _dot(diff, q2)
    step = np.where(np.abs(den) > 1e-300, num / np.where(den == 0, 1.0, den), 0.0)
    out = np.clip(u - step, 0.0, 1.0)
    out[0], out[-1] = 0.0, 1.0
    return out


def _fit_piece(d, t1, t2, tolerance):
    """A cubic (4,3) for points d (m,3) within tolerance, or None and where to split: (None,
    points, index). A two-point piece that does not fit is split at its chord's midpoint."""
    if len(d) == 2:
        chord = float(np.linalg.norm(d[1] - d[0]))
        ctrl = np.stack([d[0], d[0] + chord / 3.0 * t1, d[1] + chord / 3.0 * t2, d[1]])
        if _worst(d, ctrl, np.array([0.0, 1.0]))[0] <= tolerance:
            return ctrl, None, None
        return None, np.stack([d[0], 0.5 * (d[0] + d[1]), d[1]]), 1
    u = _chord_parameters(d)
    ctrl = _handles(d, u, t1, t2)
    err, split = _worst(d, ctrl, u)
    if err <= tolerance:
        return ctrl, None, None
    # Newton steps while they pay: the error must shrink by a few percent each time.
    for _ in range(NEWTON_STEPS):
        u = _reparametrise(d, ctrl, u)
        ctrl_next = _handles(d, u, t1, t2)
        err_next, split_next = _worst(d, ctrl_next, u)
        if err_next <= tolerance:
            return ctrl_next, None, None
        if err_next > STALLED * err:
            break
        ctrl, err, split = ctrl_next, err_next, split_next
    return None, d, split


def fit_bezier(points, tolerance, first_tangent=None):
    """A piecewise cubic (3k+1, 3) through the stroke's first and last points within
    `tolerance` of the stroke both ways: every stroke point lies that close to the curve
    (measured at the point's own curve parameter, so the distance to the curve is smaller
    still), and the curve that close to the stroke's polyline. first_tangent: the direction
    the curve must leave its first point in (a key's root normal); by default the stroke's
    own. Segments join with matching tangent directions."""
    p = _points("stroke", points, minimum=2)
    tolerance = _positive("tolerance", tolerance)
    d = _clean(p)
    if not np.linalg.norm(d - d[0], axis=1).max() > tolerance:
        raise InputError(f"stroke: no point is farther than the tolerance ({tolerance:.4g}) from the first; "
                         "drag away from the root to draw a strand")
    t_first = _end_tangent(d, tolerance) if first_tangent is None else _direction("first_tangent", first_tangent)
    t_last = _end_tangent(d[::-1], tolerance)
    # Depth first, left part before right: the segments come out in order along the stroke.
    todo = [(d, t_first, t_last)]
    segments = []
    while todo:
        piece, t1, t2 = todo.pop()
        ctrl, piece, split = _fit_piece(piece, t1, t2, tolerance)
        if ctrl is not None:
            segments.append(ctrl)
            continue
        if len(segments) + len(todo) >= MAX_SEGMENTS:
            length = float(np.linalg.norm(np.diff(d, axis=0), axis=1).sum())
            raise InputError(f"tolerance: {tolerance:.4g} needs more than {MAX_SEGMENTS} segments for a stroke "
                             f"{length:.4g} long; use a larger tolerance")
        centre = piece[split - 1] - piece[split + 1]
        if not np.linalg.norm(centre) > 0:  # a hairpin at the split: back along the way in
            centre = piece[split - 1] - piece[split]
        centre = centre / np.linalg.norm(centre)
        todo.append((piece[split:], -centre, t2))
        todo.append((piece[:split + 1], t1, centre))
    return np.vstack([segments[0]] + [seg[1:] for seg in segments[1:]])


def sample_cubic(control, per_segment=LENGTH_SAMPLES):
    """Points along a piecewise cubic (3k+1, 3): per_segment + 1 per segment, the joints
    included once. (k·per_segment + 1, 3)."""
    c = _points("control points", control, minimum=4)
    if (len(c) - 1) % 3:
        raise InputError(f"control points: a piecewise cubic needs 3k+1 rows, got {len(c)}")
    u = np.linspace(0.0, 1.0, per_segment + 1)
    parts = [_cubic_at(c[i:i + 4], u)[:-1] for i in range(0, len(c) - 1, 3)]
    return np.vstack(parts + [c[-1:]])


def distance_to_polyline(points, polyline):
    """Distance (n,) of each point to the nearest point of a polyline (m,3)."""
    q = _points("points", points)
    a, b = polyline[:-1], polyline[1:]
    ab = b - a
    len2 = np.maximum(_dot(ab, ab), 1e-300)
    out = np.empty(len(q))
    step = max(1, (1 << 20) // max(len(a), 1))
    for lo in range(0, len(q), step):  # blocks of points x segments
        p = q[lo:lo + step, None, :]
        t = np.clip(_dot(p - a, ab) / len2, 0.0, 1.0)
        near = a + t[..., None] * ab
        out[lo:lo + step] = np.sqrt(_dot(p - near, p - near).min(axis=1))
    return out


def curve_deviation(control, points):
    """Distance (n,) from each stroke point to a fitted piecewise cubic (3k+1, 3)."""
    return distance_to_polyline(points, sample_cubic(control))


# --- mirror ----------------------------------------------------------------------------

def mirror_plane(frame, axis="X"):
    """(point, unit normal) of the head frame's mirror plane across `axis`: X = left-right
    (the head's symmetry), Y = front-back, Z = up-down, each through the head's centre."""
    if axis not in AXES:
        raise InputError(f"mirror axis: expected one of {AXES}, got {axis!r}")
    normal = {"X": frame.right, "Y": frame.front, "Z": frame.up}[axis]
    return frame.centre, normal


def mirror_points(points, frame, axis="X"):
    """Points (n,3) reflected across the head frame's plane (see mirror_plane). Reflection is
    linear, so the control points of a curve mirror into those of the mirrored curve."""
    p = _points("points", points)
    centre, n = mirror_plane(frame, axis)
    return p - 2.0 * ((p - centre) @ n)[:, None] * n


def mirror_key(points, frame, axis="X", scalp=None):
    """A key's control points (n,3) mirrored; with a scalp (groom.Scalp), moved as a whole so
    its root lands on the scalp's nearest point (a scalp is never exactly symmetric)."""
    out = mirror_points(points, frame, axis)
    if scalp is not None:
        _, _, root = scalp.closest_points(out[:1])
        out += root[0] - out[0]
    return out


# --- comb ------------------------------------------------------------------------------

def _groups(n, kind):
    """The comb's rigid groups of control rows and their anchor rows. cubic: one per joint
    (the joint and its two handles move together, so the curve stays smooth there); bezier:
    one per control point. The root's group (and a Bézier's second point, which holds the
    root's tangent) never moves."""
    if kind == "cubic":
        if n < 4 or (n - 1) % 3:
            raise InputError(f"key points: a piecewise cubic key needs 3k+1 rows, got {n}")
        k = (n - 1) // 3
        groups = [np.arange(max(0, 3 * j - 1), min(n, 3 * j + 2)) for j in range(k + 1)]
        return groups, np.arange(0, n, 3), 1
    if kind == "bezier":
        if n < 2:
            raise InputError("key points: a Bézier key needs at least 2 control points")
        return [np.array([i]) for i in range(n)], np.arange(n), min(2, n)
    raise InputError(f"key kind: expected 'cubic' or 'bezier', got {kind!r}")


def _group_basis(n, kind, per_segment=COMB_SAMPLES):
    """(curve samples (m,3) of the control points given later, influence (m, groups)): how
    much each group moves each curve point, normalised so a group's peak is 1."""
    if kind == "cubic":
        k = (n - 1) // 3
        u = np.linspace(0.0, 1.0, per_segment + 1)
        smooth = u * u * (3.0 - 2.0 * u)   # the joint's share at the segment's end (B2 + B3)
        basis = np.zeros((k * (per_segment + 1), k + 1))
        for i in range(k):
            rows = slice(i * (per_segment + 1), (i + 1) * (per_segment + 1))
            basis[rows, i] = 1.0 - smooth
            basis[rows, i + 1] = smooth
        return np.tile(u, k), np.repeat(np.arange(k), per_segment + 1), basis
    from math import comb as binomial
    u = np.linspace(0.0, 1.0, per_segment * max(1, n - 1) + 1)
    deg = n - 1
    basis = np.stack([binomial(deg, i) * u ** i * (1.0 - u) ** (deg - i) for i in range(n)], 1)
    return u, None, basis / basis.max(axis=0)


def _curve_samples(points, kind, u, seg):
    if kind == "cubic":
        out = np.empty((len(u), 3))
        for i in np.unique(seg):
            m = seg == i
            out[m] = _cubic_at(points[3 * i:3 * i + 4], u[m])
        return out
    work = np.broadcast_to(points, (len(u),) + points.shape).copy()
    for r in range(len(points) - 1, 0, -1):
        work = work[:, :r] + u[:, None, None] * (work[:, 1:r + 1] - work[:, :r])
    return work[:, 0]


def segment_lengths(points, kind="cubic"):
    """Lengths of a key's segments (k,) (one for a single Bézier), from polylines of
    LENGTH_SAMPLES points per segment (within ~1e-7 of the curve's length)."""
    p = _points("key points", points, minimum=2)
    if kind == "cubic":
        u = np.linspace(0.0, 1.0, LENGTH_SAMPLES + 1)
        return np.array([np.linalg.norm(np.diff(_cubic_at(p[i:i + 4], u), axis=0), axis=1).sum()
                         for i in range(0, len(p) - 1, 3)])
    u = np.linspace(0.0, 1.0, LENGTH_SAMPLES * max(1, len(p) - 1) + 1)
    return np.array([np.linalg.norm(np.diff(_curve_samples(p, kind, u, None), axis=0), axis=1).sum()])


def curve_length(points, kind="cubic"):
    return float(segment_lengths(points, kind).sum())


def _falloff(distance, radius):
    x = np.clip(distance / radius, 0.0, 1.0)
    return (1.0 - x * x) ** 2


def comb(points, centre, delta, radius, kind="cubic", view_direction=None, length=None):
    """One comb step on a key's control points (n,3): the part of the key within `radius` of
    the brush `centre` moves by up to `delta` (a smooth falloff), the root and the direction
    it leaves in stay, then the key gets back its length (`length`, by default the length it
    had): each rigid group keeps its distance to the previous one (follow the leader, the
    rest of the key trails the comb), and the part from the first moved group on is scaled
    about the group before it to the exact length.

    view_direction: distances are measured across it (the brush is a cylinder through the
    screen, as a brush on a 2-D view is); None measures them in 3-D. Returns (n,3)."""
    p = _points("key points", points, minimum=2)
    centre = vector3("brush centre", centre)
    delta = vector3("brush delta", delta)
    radius = _positive("brush radius", radius)
    groups, anchors, fixed = _groups(len(p), kind)
    target = curve_length(p, kind) if length is None else _positive("key length", length)
    u, seg, basis = _group_basis(len(p), kind)
    offset = _curve_samples(p, kind, u, seg) - centre
    if view_direction is not None:
        d = _direction("view_direction", view_direction)
        offset = offset - (offset @ d)[:, None] * d
    w_curve = _falloff(np.linalg.norm(offset, axis=1), radius)
    # A group moves as much as the most it carries of the brushed part of the curve; the
    # factor 2 lets a stroke across the middle of a segment move both its ends fully.
    weight = (np.minimum(1.0, 2.0 * basis) * w_curve[:, None]).max(axis=0)
    weight[:fixed] = 0.0
    moved = np.flatnonzero(weight > 0)
    if not len(moved):
        return p.copy()
    out = p.copy()
    for g, w in zip(groups, weight):
        out[g] += w * delta
    chords = np.linalg.norm(np.diff(p[anchors], axis=0), axis=1)
    for j in range(max(fixed, int(moved[0])), len(groups)):  # a handful of groups
        prev = out[anchors[j - 1]]
        step = out[anchors[j]] - prev
        norm = float(np.linalg.norm(step))
        if norm > 0:
            out[groups[j]] += prev + chords[j - 1] * step / norm - out[anchors[j]]
    return _restore_length(out, kind, int(moved[0]), target)


def _restore_length(points, kind, first_moved, target):
    """Scale the key past its last unmoved joint about that joint (a Bézier about its root)
    so its length is `target`: the segments before it are untouched and the ones after keep
    their shape, so the factor is exact."""
    lengths = segment_lengths(points, kind)
    if kind == "cubic":
        pivot_joint = first_moved - 1
        before = float(lengths[:pivot_joint].sum())
        start = 3 * pivot_joint
    else:
        before, start = 0.0, 0
    tail = float(lengths.sum()) - before
    if not tail > 0 or not target > before:
        return points
    scale = (target - before) / tail
    out = points.copy()
    out[start + 1:] = points[start] + scale * (points[start + 1:] - points[start])
    return out


def comb_stroke(points, stroke, radius, kind="cubic", view_direction=None):
    """The key (n,3) combed along a brush path (m,3), one comb step per move from one path
    point to the next (the brush grabs the key where it was and pulls it to where it goes),
    keeping the key's length as it was before the stroke."""
    p = _points("key points", points, minimum=2)
    path = _points("stroke", stroke, minimum=2)
    length = curve_length(p, kind)
    for a, b in zip(path[:-1], path[1:]):  # one step per mouse move, as the modal tool does
        p = comb(p, a, b - a, radius, kind, view_direction, length)
    return p

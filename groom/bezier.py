# SPDX-License-Identifier: GPL-3.0-or-later
"""A piecewise cubic key as points with two handles each, the way Blender's Bézier splines
(and most drawing tools) hold it, and back.

groom keeps a `cubic` key as one array `[P0, H0out, H1in, P1, H1out, H2in, P2, ...]` (3k+1
rows, SPEC §3); an editor keeps k+1 points, each with a left (incoming) and a right
(outgoing) handle. The first point's left handle and the last point's right handle shape
nothing; they are laid out straight on from the curve's ends, so a key written and read back
is the same curve and the free ends look as an artist expects.
"""
import numpy as np

from hairio import InputError


def _rows(name, a, rows=None):
    a = np.asarray(a, np.float64)
    if a.ndim != 2 or a.shape[1] != 3 or (rows is not None and len(a) != rows):
        want = f"({rows}, 3)" if rows is not None else "(n, 3)"
        raise InputError(f"{name}: expected shape {want}, got {a.shape}")
    return a


def handles_to_cubic(co, left, right):
    """(k+1, 3) points with their left and right handles -> groom's piecewise cubic
    control points (3k+1, 3). The first left and the last right handle are dropped."""
    co = _rows("points", co)
    if len(co) < 2:
        raise InputError(f"points: a Bézier spline needs at least 2 points, got {len(co)}")
    left, right = _rows("left handles", left, len(co)), _rows("right handles", right, len(co))
    out = np.empty((3 * (len(co) - 1) + 1, 3))
    out[0::3] = co
    out[1::3] = right[:-1]
    out[2::3] = left[1:]
    return out


def cubic_to_handles(control):
    """groom's piecewise cubic control points (3k+1, 3) -> (points, left, right), (k+1, 3)
    each; the free end handles mirror the first and last inner handle through their point
    (straight on from the curve's ends)."""
    p = _rows("control points", control)
    if len(p) < 4 or (len(p) - 1) % 3:
        raise InputError(f"control points: a piecewise cubic needs 3k+1 rows (k >= 1), got {len(p)}")
    co = p[0::3]
    right = np.vstack([p[1::3], [2 * co[-1] - p[-2]]])
    left = np.vstack([[2 * co[0] - p[1]], p[2::3]])
    return co, left, right


def smooth_handles(points):
    """(left, right) handles, (n, 3) each, of a smooth piecewise cubic through `points`
    (n >= 2): Catmull-Rom tangents, one-sided at the ends, a third of a tangent either side
    (so each segment's handles lie a third of the way along it on a straight line)."""
    p = _rows("points", points)
    if len(p) < 2:
        raise InputError(f"points: a curve needs at least 2 points, got {len(p)}")
    tangent = np.empty_like(p)
    tangent[1:-1] = (p[2:] - p[:-2]) / 2.0
    tangent[0] = p[1] - p[0]
    tangent[-1] = p[-1] - p[-2]
    return p - tangent / 3.0, p + tangent / 3.0

# SPDX-License-Identifier: GPL-3.0-or-later
"""Rewrite an existing key strand object's curve from groom control points (the stroke tools'
edits: Comb Key, and the mirror of an edited key). scene_data makes new key objects; this
changes one in place, so the object, its name, its settings and its place in the key order
(its wisp) stay."""
import numpy as np
import bpy

from .scene_data import _matrix


def _to_object(obj, scalp, points):
    """Scalp-space points -> the key object's own coordinates (exact where, as Add Key Strand
    makes them, the two spaces coincide)."""
    m = np.linalg.inv(_matrix(obj.matrix_world)) @ _matrix(scalp.matrix_world)
    if np.allclose(m, np.eye(4), rtol=0.0, atol=1e-9):
        return np.asarray(points, np.float64)
    return np.asarray(points, np.float64) @ m[:3, :3].T + m[:3, 3]


def write_key_points(obj, scalp, points, kind="cubic"):
    """Set the first spline of key object `obj` to control points (scalp space) of `kind`
    ('cubic': a Bézier spline, FREE handles so Blender keeps them where they are put;
    'bezier': a poly spline through the control points). Works in edit mode too (Blender's
    splines are then the edit curve's)."""
    local = _to_object(obj, scalp, points)
    curve = obj.data
    if kind == "cubic":
        from groom.bezier import cubic_to_handles
        co, left, right = cubic_to_handles(local)
        spline = curve.splines[0] if len(curve.splines) else None
        if spline is None or spline.type != 'BEZIER' or len(spline.bezier_points) != len(co):
            spline = _replace_first_spline(curve, 'BEZIER')
            spline.bezier_points.add(len(co) - 1)
        bp = spline.bezier_points
        for p in bp:  # a key has a few points
            p.handle_left_type = 'FREE'
            p.handle_right_type = 'FREE'
        bp.foreach_set("co", co.astype(np.float32).ravel())
        bp.foreach_set("handle_left", left.astype(np.float32).ravel())
        bp.foreach_set("handle_right", right.astype(np.float32).ravel())
    else:
        spline = curve.splines[0] if len(curve.splines) else None
        if spline is None or spline.type == 'BEZIER' or len(spline.points) != len(local):
            spline = _replace_first_spline(curve, 'POLY')
            spline.points.add(len(local) - 1)
        co4 = np.hstack([local, np.ones((len(local), 1))]).astype(np.float32)
        spline.points.foreach_set("co", co4.ravel())
    curve.update_tag()
    obj.update_tag()


def _spline_state(spline):
    """A spline's type and points as plain values: (type, [(co, left, right, left type, right
    type)]) for a Bézier spline, (type, [co]) (4-D) for the others."""
    if spline.type == 'BEZIER':
        return 'BEZIER', [(tuple(p.co), tuple(p.handle_left), tuple(p.handle_right),
                           p.handle_left_type, p.handle_right_type) for p in spline.bezier_points]
    return spline.type, [tuple(p.co) for p in spline.points]


def _fill_spline(spline, points):
    if spline.type == 'BEZIER':
        for p, (co, left, right, left_type, right_type) in zip(spline.bezier_points, points):
            p.handle_left_type, p.handle_right_type = 'FREE', 'FREE'  # so Blender keeps the handles set
            p.co, p.handle_left, p.handle_right = co, left, right
            p.handle_left_type, p.handle_right_type = left_type, right_type
    else:
        for p, co in zip(spline.points, points):
            p.co = co


def _new_spline(curve, kind, count):
    spline = curve.splines.new(kind)
    if kind == 'BEZIER':
        spline.bezier_points.add(count - 1)
    else:
        spline.points.add(count - 1)
    return spline


def _replace_first_spline(curve, kind):
    """A new empty spline of `kind` in place of the curve's first (the others are kept)."""
    rest = [_spline_state(s) for s in list(curve.splines)[1:]]  # keys have one; others stay
    curve.splines.clear()
    first = curve.splines.new(kind)
    for kind_, points in rest:
        _fill_spline(_new_spline(curve, kind_, len(points)), points)
    return first


def snapshot(obj):
    """The key's first spline as it is (for restore)."""
    return _spline_state(obj.data.splines[0])


def restore(obj, state):
    """Put back a key's first spline as `snapshot` saw it, handle types included."""
    kind, points = state
    curve = obj.data
    spline = curve.splines[0] if len(curve.splines) else None
    count = len(spline.bezier_points) if spline is not None and spline.type == 'BEZIER' else \
        (len(spline.points) if spline is not None else 0)
    if spline is None or spline.type != kind or count != len(points):
        spline = _replace_first_spline(curve, kind)
        if kind == 'BEZIER':
            spline.bezier_points.add(len(points) - 1)
        else:
            spline.points.add(len(points) - 1)
    _fill_spline(spline, points)
    curve.update_tag()
    obj.update_tag()

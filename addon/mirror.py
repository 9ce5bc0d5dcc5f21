# SPDX-License-Identifier: GPL-3.0-or-later
"""Mirrored key strands: pairs of keys across a plane of the head, kept mirrored.

Draw Key Strand with the scalp's Symmetry on makes both keys of a pair, each pointing at the
other (`Object.keystrand_mirror`, registered here). When either is edited (its points in edit mode, its
object moved, Comb Key), the other is rewritten as its mirror image: by a depsgraph handler
for Blender's own tools, and by `sync` called from this extension's tools, so both keys
change in the same undo step. The mirror is taken in the head frame fitted to the scalp
(groom.fit_head_frame, with the scalp's Up and Front), across the plane Symmetry names, and the
mirrored key is moved as a whole so its root lies on the scalp (no scalp is exactly symmetric).

Rewriting the partner is itself an edit, seen by the handler on the next update; the points
written are remembered per key (`_written`), so that echo is told from the artist's own edit
and a pair never rewrites itself back and forth.
"""
import hashlib

import numpy as np
import bpy
from bpy.app.handlers import persistent
from bpy.props import PointerProperty
from hairio import InputError

from . import app_handlers, head, key_points, scene_data
from .transaction import clear_background, report_background

TASK = "Mirror"
_heads = {}      # scalp session_uid -> (fingerprint, groom.Scalp, groom.HeadFrame)
_written = {}    # key session_uid -> its control points as this module last wrote them
_busy = False


def head_of(scalp, depsgraph=None):
    """(groom.Scalp, groom.HeadFrame) of a scalp object, cached while its mesh, modifiers and
    head axes stay as they were."""
    from groom import fit_head_frame
    mesh = scalp.data
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    axes = head.scalp_axes(scalp)
    fingerprint = (hashlib.sha1(co.tobytes()).hexdigest(), axes, tuple(m.name for m in scalp.modifiers))
    cached = _heads.get(scalp.session_uid)
    if cached is not None and cached[0] == fingerprint:
        return cached[1], cached[2]
    data = scene_data.read_scalp(scalp, depsgraph or bpy.context.evaluated_depsgraph_get())
    frame = fit_head_frame(data, *axes)
    _heads[scalp.session_uid] = (fingerprint, data, frame)
    return data, frame


def mirrored(points, scalp, depsgraph=None, scalp_data=None, frame=None):
    """A key's control points (scalp space) mirrored across the scalp's Symmetry plane, the
    root put on the scalp."""
    from groom.stroke import mirror_key
    if scalp_data is None or frame is None:
        scalp_data, frame = head_of(scalp, depsgraph)
    return mirror_key(points, frame, scalp.keystrand_hair.symmetry, scalp_data)


def pair(a, b):
    """Make two key objects a mirrored pair."""
    a.keystrand_mirror = b
    b.keystrand_mirror = a
    remember_written(b)


def partner_of(obj):
    """The key mirrored with `obj`, or None (none set, Symmetry off, or a pairing that is no
    longer mutual: a duplicate of a paired key points at its original's partner)."""
    s = obj.keystrand_hair
    other = obj.keystrand_mirror
    if other is None or s.role != 'KEY' or s.scalp is None or s.scalp.keystrand_hair.symmetry == 'NONE':
        return None
    if other.keystrand_mirror != obj or other.keystrand_hair.scalp != s.scalp or other.type != 'CURVE':
        return None
    return other


def remember_written(obj):
    """Note `obj`'s points as this module's own: its next update is an echo, not an edit."""
    s = obj.keystrand_hair
    try:
        _written[obj.session_uid] = scene_data.key_control_points(obj, s.scalp)[0]
    except InputError:
        _written.pop(obj.session_uid, None)


def _same(a, b, tolerance=0.0):
    return a is not None and b is not None and a.shape == b.shape and bool(np.abs(a - b).max() <= tolerance)


def sync(obj, depsgraph=None):
    """Rewrite `obj`'s partner as the mirror image of `obj`; True when it was written (False:
    no partner, `obj`'s points are this module's own echo, or the partner already mirrors it)."""
    other = partner_of(obj)
    if other is None:
        return False
    scalp = obj.keystrand_hair.scalp
    try:
        points, kind = scene_data.key_control_points(obj, scalp)
    except InputError:
        return False  # mid-edit (a key with one point): nothing to mirror yet
    if _same(points, _written.get(obj.session_uid)):
        return False
    scalp_data, frame = head_of(scalp, depsgraph)
    target = mirrored(points, scalp, scalp_data=scalp_data, frame=frame)
    try:
        current, current_kind = scene_data.key_control_points(other, scalp)
    except InputError:
        current, current_kind = None, None
    # Float32 coordinates and the root's snap make a pair mirror to within rounding, not bits.
    if current_kind == kind and _same(current, target, 1e-6 * frame.size):
        return False
    key_points.write_key_points(other, scalp, target, kind)
    remember_written(other)
    return True


def _edited_keys(depsgraph):
    """Paired key objects among the depsgraph's updates (by session_uid)."""
    out = {}
    curves = set()
    for update in depsgraph.updates:
        ident = update.id.original if update.id is not None else None
        if isinstance(ident, bpy.types.Object):
            # Objects are also listed when only their relations were re-evaluated (another
            # object was added); only a moved or reshaped key needs its partner rewritten.
            moved = update.is_updated_transform or update.is_updated_geometry
            if moved and ident.type == 'CURVE' and ident.keystrand_mirror is not None:
                out[ident.session_uid] = ident
        elif isinstance(ident, bpy.types.Curve):
            curves.add(ident.session_uid)
    if curves:
        for obj in bpy.data.objects:
            if obj.type == 'CURVE' and obj.data.session_uid in curves and obj.keystrand_mirror is not None:
                out[obj.session_uid] = obj
    return out


@persistent
def on_depsgraph_update(scene, depsgraph):
    global _busy
    if _busy:
        return
    edited = _edited_keys(depsgraph)
    if not edited:
        return
    active = getattr(bpy.context, "active_object", None)
    # The key the artist holds goes first; its partner, rewritten, is then an echo.
    order = sorted(edited.values(), key=lambda o: (o != active, o.name))
    _busy = True
    try:
        done = set()
        for obj in order:
            if obj.session_uid in done:
                continue
            scalp = obj.keystrand_hair.scalp
            try:
                if sync(obj, depsgraph):
                    done.add(obj.keystrand_mirror.session_uid)
            except Exception as e:  # e.g. a scalp whose head cannot be read: the pair waits
                if scalp is None:
                    raise
                report_background(scalp, TASK, e)
            else:
                if scalp is not None:
                    clear_background(scalp, TASK)
    finally:
        _busy = False


@persistent
def on_load(*_args):
    _heads.clear()
    _written.clear()


HANDLERS = ((bpy.app.handlers.depsgraph_update_post, on_depsgraph_update),
            (bpy.app.handlers.load_pre, on_load))


def register():
    bpy.types.Object.keystrand_mirror = PointerProperty(
        type=bpy.types.Object, name="Mirror Key",
        description="The key strand this one is kept the mirror image of (Symmetry)")
    app_handlers.add(HANDLERS)


def unregister():
    app_handlers.remove(HANDLERS)
    on_load()
    del bpy.types.Object.keystrand_mirror

# SPDX-License-Identifier: GPL-3.0-or-later
"""Comb Key Strand: press near a key strand and drag to bend it; its length stays.

A simple comb brush on the key's control points (groom.stroke.comb): the part of the key
under the brush follows the drag, the root and the way it leaves the scalp stay, the rest of
the key trails, and the key keeps its length. Each mouse move is one comb step, written to
the key at once (so the hair regrows around it as it does for any edit, and its mirrored
partner follows); release keeps the result, Esc or a right-click puts the key (and its
partner) back exactly. Called with a stroke (the brush's path, world points), as scripts and
tests do, it makes the same steps without a viewport.
"""
import numpy as np
import bpy
from bpy.props import FloatProperty, StringProperty
from bpy.types import Operator
from bpy_extras import view3d_utils
from hairio import InputError

from . import key_points, mirror, scene_data, stroke_input
from .scene_data import find_scalp
from .transaction import reports_errors, transaction


def _key_of(context, name=""):
    """The key strand object to comb: the one named, or the active one."""
    obj = bpy.data.objects.get(name) if name else context.active_object
    if obj is None or obj.type != 'CURVE' or obj.keystrand_hair.role != 'KEY' or obj.keystrand_hair.scalp is None:
        return None
    return obj


class CombState:
    """One comb stroke on one key: its points (scalp space, float64 between steps, so a stroke
    made of many steps is the same as one execute of the whole path), the brush in scalp space."""

    def __init__(self, op, key, depth_world):
        from groom.stroke import curve_length
        self.key = key
        self.scalp = key.keystrand_hair.scalp
        self.points, self.kind = scene_data.key_control_points(key, self.scalp)
        self.length = curve_length(self.points, self.kind)
        _, frame = mirror.head_of(self.scalp)
        scale = stroke_input.object_scale(self.scalp)
        self.radius = op.radius * stroke_input.pixel_world_size(op, frame, self.scalp) / scale
        direction, _eye = stroke_input.view_of(op)
        self.view_direction = stroke_input.direction_to_local(self.scalp, direction)
        self.last = stroke_input.to_local(self.scalp, np.asarray(depth_world, np.float64)[None])[0]

    def step(self, world_point):
        """Comb from the brush's last place to `world_point`; True when the key changed."""
        from groom.stroke import comb
        here = stroke_input.to_local(self.scalp, np.asarray(world_point, np.float64)[None])[0]
        combed = comb(self.points, self.last, here - self.last, self.radius, self.kind,
                      self.view_direction, self.length)
        self.last = here
        if np.array_equal(combed, self.points):
            return False
        self.points = combed
        return True

    def write(self):
        key_points.write_key_points(self.key, self.scalp, self.points, self.kind)
        mirror.sync(self.key)


class HAIR_OT_comb_key(stroke_input.StrokeView, Operator):
    """Comb a key strand: press near it and drag to bend it; its length stays (Esc puts it back)"""
    bl_idname = "hair.comb_key"
    bl_label = "Comb Key Strand"
    bl_options = {'REGISTER', 'UNDO'}

    radius: FloatProperty(name="Radius", default=40.0, min=1.0, soft_max=300.0, subtype='PIXEL',
                          description="The comb's reach around the mouse, in screen pixels")
    key: StringProperty(name="Key", default="", options={'HIDDEN', 'SKIP_SAVE'},
                        description="The key strand object to comb; empty = the active one")

    @classmethod
    def poll(cls, context):
        if find_scalp(context) is None:
            cls.poll_message_set("Select a scalp mesh, or one of its key strands")
            return False
        return True

    # --- the modal tool -----------------------------------------------------------------

    def invoke(self, context, event):
        self._view = stroke_input.ViewUnderMouse(context)
        if self._view.area is None:
            return self.execute(context)  # a script: the stroke is given
        self._scalp = find_scalp(context)
        self._state = None
        self._saved = None
        self._path = []
        context.window_manager.modal_handler_add(self)
        context.workspace.status_text_set("Press near a key strand and drag to comb it; Esc or right-click cancels")
        return {'RUNNING_MODAL'}

    def modal(self, context, event):
        if event.type in {'ESC', 'RIGHTMOUSE'} and event.value == 'PRESS':
            self._cancel(context)
            return {'CANCELLED'}
        if self._state is None:
            if event.type == 'LEFTMOUSE' and event.value == 'PRESS':
                return self._press(context, event)
            if event.type in stroke_input.VIEW_NAVIGATION:
                return {'PASS_THROUGH'}
            return {'RUNNING_MODAL'}
        if event.type in {'MOUSEMOVE', 'INBETWEEN_MOUSEMOVE'}:
            self._drag(self._view.coord(event))
            return {'RUNNING_MODAL'}
        if event.type == 'LEFTMOUSE' and event.value == 'RELEASE':
            self._drag(self._view.coord(event))
            context.workspace.status_text_set(None)
            stroke_input.set_stroke(self, self._path)
            self.key = self._state.key.name
            return {'FINISHED'}
        return {'RUNNING_MODAL'}

    def _nearest_key(self, context, coord):
        """(key object, world point of its curve nearest the mouse) within the brush, or None."""
        from groom.stroke import sample_cubic
        region, rv3d = self._view.region, self._view.rv3d
        best = None
        active = _key_of(context)
        for obj in scene_data.key_objects(self._scalp):  # a handful of keys
            try:
                points, kind = scene_data.key_control_points(obj, self._scalp)
            except InputError:
                continue
            samples = sample_cubic(points, 24) if kind == "cubic" else points
            world = stroke_input.to_world(self._scalp, samples)
            for p in world:
                at = view3d_utils.location_3d_to_region_2d(region, rv3d, p)
                if at is None:
                    continue
                d = float(np.hypot(at.x - coord[0], at.y - coord[1]))
                # The active key wins ties within the brush: it is the one being worked on.
                rank = (obj != active, d)
                if d <= self.radius and (best is None or rank < best[0]):
                    best = (rank, obj, p)
        return None if best is None else best[1:]

    def _press(self, context, event):
        view = self._view
        found = self._nearest_key(context, view.coord(event)) if view.pick(event) else None
        if found is None:
            self.report({'WARNING'}, "Press near a key strand (within the comb's radius) to comb it")
            return {'RUNNING_MODAL'}
        key, depth = found
        stroke_input.capture_view(self, view.region, view.rv3d, depth)
        try:
            start = stroke_input.screen_to_world(view.region, view.rv3d, [view.coord(event)], depth)[0]
            self._state = CombState(self, key, start)
        except InputError as e:
            self.report({'ERROR'}, str(e))
            context.workspace.status_text_set(None)
            return {'CANCELLED'}
        partner = mirror.partner_of(key)
        self._saved = [(obj, key_points.snapshot(obj)) for obj in (key, partner) if obj is not None]
        self._depth = depth
        self._path = [start]
        return {'RUNNING_MODAL'}

    def _drag(self, coord):
        world = stroke_input.screen_to_world(self._view.region, self._view.rv3d, [coord], self._depth)[0]
        if np.array_equal(world, self._path[-1]):
            return
        self._path.append(world)
        try:
            if self._state.step(world):
                self._state.write()
        except InputError as e:
            self.report({'WARNING'}, str(e))

    def _cancel(self, context):
        context.workspace.status_text_set(None)
        for obj, saved in self._saved or ():
            key_points.restore(obj, saved)
            mirror.remember_written(obj)

    # --- the work ------------------------------------------------------------------------

    @reports_errors
    def execute(self, context):
        key = _key_of(context, self.key)
        if key is None:
            self.report({'ERROR'}, f"No key strand named {self.key!r}" if self.key else
                        "Make a key strand the active object to comb it")
            return {'CANCELLED'}
        path = stroke_input.stroke_points(self, context)
        if self.stroke_space != 'WORLD':
            raise InputError("Comb Key Strand takes its stroke as world points (stroke_space 'WORLD')")
        if len(path) < 2:
            raise InputError("The comb stroke needs at least two points: where it starts and where it goes")
        state = CombState(self, key, path[0])
        changed = False
        for p in path[1:]:  # one comb step per stroke point, as the modal tool makes them
            changed |= state.step(p)
        if changed:
            with transaction() as tx:
                for obj in (key, mirror.partner_of(key)):
                    if obj is not None:
                        saved = key_points.snapshot(obj)
                        tx.undo(lambda obj=obj, saved=saved: key_points.restore(obj, saved))
                state.write()
        if not changed:
            self.report({'WARNING'}, f"The comb did not reach key strand {key.name!r}: "
                                     "comb closer to it or with a larger radius")
            return {'CANCELLED'}
        self.report({'INFO'}, f"Combed key strand {key.name!r}")
        return {'FINISHED'}


CLASSES = (HAIR_OT_comb_key,)

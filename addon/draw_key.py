# SPDX-License-Identifier: GPL-3.0-or-later
"""Draw Key Strand: press on the scalp where the strand grows, drag its shape, release.

The stroke is projected onto a surface through the root (the plane facing the view, or a
shell just outside the scalp), fitted with a few cubic Bézier segments within a tolerance in
pixels, the first leaving the root along the scalp's normal (groom.stroke), and becomes an
ordinary key strand object. With the scalp's Symmetry on, its mirror image is made too, and
the two are kept mirrored (mirror.py). The fitted key is drawn while dragging; Esc or a
right-click cancels and leaves nothing. Called with a stroke (world points), as scripts and
tests do, it makes the same key without a viewport.
"""
import time

import numpy as np
import bpy
from bpy.props import EnumProperty, FloatProperty
from bpy.types import Operator
from hairio import InputError

from . import head, mirror, scene_data, stroke_input
from .scene_data import find_scalp
from .transaction import reports_errors, transaction

SURFACES = (
    ('VIEW', "View Plane", "Draw on the plane through the root that faces you: the strand keeps the "
                           "shape you see"),
    ('SHELL', "Over the Scalp", "Draw on a shell just outside the scalp (Shell Offset): the strand lies "
                                "along the head; past its outline it stays on the view plane"),
)

# The preview is refitted at most this often while dragging (a fit takes a few ms to 50 ms).
PREVIEW_INTERVAL_S = 0.03


class StrokeFit:
    """One stroke's way from world points to a key: the scalp, the root on it and its normal,
    the projection, the fit and the mirror image. The modal tool feeds it points as the mouse
    moves (each projected once); execute feeds it the whole stroke. Scalp space throughout."""

    def __init__(self, op, context, scalp, first_point_world):
        from groom import fit_head_frame
        self.op, self.scalp = op, scalp
        settings = scalp.keystrand_hair
        self.scalp_data = scene_data.read_scalp(scalp, context.evaluated_depsgraph_get())
        self.frame = fit_head_frame(self.scalp_data, *head.scalp_axes(scalp))
        first = stroke_input.to_local(scalp, np.asarray(first_point_world, np.float64)[None])
        tri, bary, root = self.scalp_data.closest_points(first)
        self.root = root[0]
        self.normal = self.scalp_data.normals_at(tri, bary, settings.normal_mode)[0]
        self.root_world = stroke_input.to_world(scalp, self.root[None])[0]
        self.scale = stroke_input.object_scale(scalp)
        self.tolerance = op.tolerance * stroke_input.pixel_world_size(op, self.frame, scalp) / self.scale
        self.view_direction, self.eye = stroke_input.view_of(op)
        self.points = [self.root]

    def add(self, world_points):
        """Project further stroke points (world) onto the drawing surface."""
        from groom.stroke import project_to_plane, project_to_shell
        if len(world_points) == 0:
            return
        plane = project_to_plane(world_points, self.root_world, self.view_direction, self.eye)
        local = stroke_input.to_local(self.scalp, plane)
        if self.op.surface == 'SHELL':
            eye = None if self.eye is None else stroke_input.to_local(self.scalp, self.eye[None])[0]
            local, _ = project_to_shell(local, self.scalp_data, self.op.shell_offset / self.scale,
                                        stroke_input.direction_to_local(self.scalp, self.view_direction), eye)
        self.points.extend(local)

    def fit(self):
        """Control points (3k+1, 3) of the key, in scalp space."""
        from groom.stroke import fit_bezier
        return fit_bezier(np.array(self.points), self.tolerance, first_tangent=self.normal)

    def mirror_of(self, control):
        """The mirror image of the key, or None when Symmetry is off or the key's root lies on
        the mirror plane (its image would be the same key)."""
        if self.scalp.keystrand_hair.symmetry == 'NONE':
            return None
        image = mirror.mirrored(control, self.scalp, scalp_data=self.scalp_data, frame=self.frame)
        if np.linalg.norm(image[0] - control[0]) <= self.tolerance:
            return None
        return image


def _poll_scalp(cls, context):
    if find_scalp(context) is None:
        cls.poll_message_set("Select a scalp mesh, or one of its key strands or its hair")
        return False
    return True


class HAIR_OT_draw_key_strand(stroke_input.StrokeView, Operator):
    """Draw a key strand: press on the scalp where it grows, drag its shape, release (Esc cancels)"""
    bl_idname = "hair.draw_key_strand"
    bl_label = "Draw Key Strand"
    bl_options = {'REGISTER', 'UNDO'}

    surface: EnumProperty(name="Surface", items=SURFACES, default='VIEW',
                          description="What the stroke is drawn on")
    shell_offset: FloatProperty(name="Shell Offset", default=0.01, min=0.0, soft_max=0.1, subtype='DISTANCE',
                                description="How far outside the scalp a stroke drawn Over the Scalp lies")
    tolerance: FloatProperty(name="Tolerance", default=2.0, min=0.05, soft_max=20.0, subtype='PIXEL',
                             description="How far the key may stray from the stroke, in screen pixels: "
                                         "larger = fewer, smoother segments")

    @classmethod
    def poll(cls, context):
        return _poll_scalp(cls, context)

    # --- the modal tool -----------------------------------------------------------------

    def invoke(self, context, event):
        self._view = stroke_input.ViewUnderMouse(context)
        if self._view.area is None:
            return self.execute(context)  # a script: the stroke is given
        self._scalp = find_scalp(context)
        self._fit = None
        self._world, self._mouse = [], []
        self._last_preview = 0.0
        self._preview = stroke_input.PreviewLines()
        context.window_manager.modal_handler_add(self)
        context.workspace.status_text_set("Press on the scalp and drag to draw a key strand; "
                                          "Esc or right-click cancels")
        return {'RUNNING_MODAL'}

    def _end(self, context):
        self._preview.remove()
        context.workspace.status_text_set(None)
        self._view.redraw()

    def modal(self, context, event):
        if event.type in {'ESC', 'RIGHTMOUSE'} and event.value == 'PRESS':
            self._end(context)
            return {'CANCELLED'}
        if self._fit is None:
            if event.type == 'LEFTMOUSE' and event.value == 'PRESS':
                return self._press(context, event)
            if event.type in stroke_input.VIEW_NAVIGATION:
                return {'PASS_THROUGH'}  # look around before drawing
            return {'RUNNING_MODAL'}
        if event.type in {'MOUSEMOVE', 'INBETWEEN_MOUSEMOVE'}:
            self._drag(self._view.coord(event))
            return {'RUNNING_MODAL'}
        if event.type == 'LEFTMOUSE' and event.value == 'RELEASE':
            self._drag(self._view.coord(event), preview=False)
            self._end(context)
            stroke_input.set_stroke(self, self._world, self._mouse)
            return self.execute(context)
        return {'RUNNING_MODAL'}

    def _press(self, context, event):
        view = self._view
        hit = None
        if view.pick(event):
            hit = stroke_input.ray_cast_scalp(context, view.region, view.rv3d, self._scalp, view.coord(event))
        if hit is None:
            self.report({'WARNING'}, "Press on the scalp mesh where the strand should grow")
            return {'RUNNING_MODAL'}
        stroke_input.capture_view(self, view.region, view.rv3d, hit)
        try:
            self._fit = StrokeFit(self, context, self._scalp, hit)
        except InputError as e:
            self._end(context)
            self.report({'ERROR'}, str(e))
            return {'CANCELLED'}
        self._world, self._mouse = [self._fit.root_world], [view.coord(event)]
        return {'RUNNING_MODAL'}

    def _drag(self, coord, preview=True):
        last = self._mouse[-1]
        if (coord[0] - last[0]) ** 2 + (coord[1] - last[1]) ** 2 < 1.0:
            return
        world = stroke_input.screen_to_world(self._view.region, self._view.rv3d, [coord], self._fit.root_world)
        try:
            self._fit.add(world)
        except InputError:
            return  # a point the surface cannot take (at a perspective eye): left out
        self._world.append(world[0])
        self._mouse.append(coord)
        now = time.monotonic()
        if not preview or now - self._last_preview < PREVIEW_INTERVAL_S:
            return
        self._last_preview = now
        self._show_preview()

    def _show_preview(self):
        from groom.stroke import sample_cubic
        try:
            control = self._fit.fit()
        except InputError:
            return  # too short yet
        strips = [control, self._fit.mirror_of(control)]
        self._preview.set(*[stroke_input.to_world(self._scalp, sample_cubic(c, 16)) for c in strips
                            if c is not None])
        self._view.redraw()

    # --- the work ------------------------------------------------------------------------

    @reports_errors
    def execute(self, context):
        from groom import KeyStrand
        from groom.stroke import distance_to_polyline, sample_cubic
        scalp = find_scalp(context)
        if scalp is None:
            self.report({'ERROR'}, "Select a scalp mesh first")
            return {'CANCELLED'}
        world = self._stroke_world(context, scalp)
        fit = StrokeFit(self, context, scalp, world[0])
        fit.add(world[1:])
        control = fit.fit()
        image = fit.mirror_of(control)
        # For the report only: a coarser polyline than curve_deviation's (a tenth of the cost).
        deviation = float(distance_to_polyline(np.array(fit.points), sample_cubic(control, 48)).max())
        with transaction() as tx:
            tx.keep_settings(scalp)
            scalp.keystrand_hair.role = 'SCALP'
            made = [scene_data.key_strand_to_object(scalp, KeyStrand(control, kind="cubic"),
                                                    name=f"{scalp.name} Key")]
            if image is not None:
                made.append(scene_data.key_strand_to_object(scalp, KeyStrand(image, kind="cubic"),
                                                            name=f"{scalp.name} Key"))
                mirror.pair(made[0], made[1])
        for obj in context.selected_objects:
            obj.select_set(False)
        for obj in made:
            obj.select_set(True)
        context.view_layer.objects.active = made[0]
        segments = (len(control) - 1) // 3
        pixels = deviation * fit.scale / stroke_input.pixel_world_size(self, fit.frame, scalp)
        names = " and its mirror " + repr(made[1].name) if len(made) > 1 else ""
        self.report({'INFO'}, f"Drew key strand {made[0].name!r}{names}: {segments} segment"
                              f"{'s' if segments != 1 else ''}, within {pixels:.2g} px of the stroke")
        return {'FINISHED'}

    def _stroke_world(self, context, scalp):
        """The stroke as world points; a screen stroke is carried onto the view plane through
        the scalp point under its first mouse position (and the view is noted)."""
        points = stroke_input.stroke_points(self, context)
        if self.stroke_space == 'WORLD':
            return points
        region, rv3d = stroke_input.region_view(context)
        hit = stroke_input.ray_cast_scalp(context, region, rv3d, scalp, tuple(points[0]))
        if hit is None:
            raise InputError("The stroke's first point is not over the scalp: start the stroke on the scalp")
        stroke_input.capture_view(self, region, rv3d, hit)
        world = stroke_input.screen_to_world(region, rv3d, points, hit)
        world[0] = hit
        return world


CLASSES = (HAIR_OT_draw_key_strand,)

# SPDX-License-Identifier: GPL-3.0-or-later
"""Add Head: the bundled head (a closed mesh) with its scalp on it, so a hairstyle can start
without a mesh of one's own (3D Viewport > Add > Hair Head, and the Hair panel).

The scalp is a child of the head with an identity parent inverse: its coordinates are the
head's, so the scalp lies on the head wherever the head is moved, and `scalp.parent` is the
head, which is also the scalp's Collider. The scalp is drawn as a wire and left out of
renders: it coincides with the head's surface, and two coincident faces flicker in the
viewport.
"""
import numpy as np
import bpy
from bpy.types import Operator
from bpy_extras.object_utils import AddObjectHelper, add_object_align_init

from . import hair
from .transaction import reports_errors, transaction

HEAD_NAME = "Hair Head"
SCALP_NAME = "Hair Scalp"


def _add_mesh_object(name, surface, collection):
    """A mesh object of a groom.Scalp (vertices, triangles, UVs when it has them), linked
    into `collection`."""
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(surface.vertices.tolist(), [], surface.triangles.tolist(), shade_flat=False)
    if surface.uv is not None:
        loop_vertex = np.empty(len(mesh.loops), np.int32)
        mesh.loops.foreach_get("vertex_index", loop_vertex)
        layer = mesh.uv_layers.new(name="UVMap")
        layer.data.foreach_set("uv", surface.uv[loop_vertex].astype(np.float32).ravel())
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    collection.objects.link(obj)
    return obj


class HAIR_OT_add_head(Operator, AddObjectHelper):
    """Add a head with a scalp on it, ready for Load Preset"""
    bl_idname = "hair.add_head"
    bl_label = "Add Hair Head"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        if context.mode != 'OBJECT':
            cls.poll_message_set("Switch to Object Mode to add a head")
            return False
        return super().poll(context)

    @reports_errors
    def execute(self, context):
        from groom import default_head, default_scalp
        from groom.head import CANONICAL_FRONT, CANONICAL_UP
        # add_object_align_init takes the user's alignment preference unless a rotation is given.
        align = self.align if self.properties.is_property_set("rotation") else context.preferences.edit.object_align
        space = context.space_data
        if align == 'VIEW' and (space is None or space.type != 'VIEW_3D'):
            self.report({'ERROR'}, "Align to View needs a 3D Viewport: use World or 3D Cursor")
            return {'CANCELLED'}
        matrix = add_object_align_init(context, self)
        head_surface, scalp_surface = default_head(), default_scalp()
        collection = context.collection or context.scene.collection
        # A failure part-way removes every datablock made so far (the transaction).
        with transaction():
            head = _add_mesh_object(HEAD_NAME, head_surface, collection)
            scalp = _add_mesh_object(SCALP_NAME, scalp_surface, collection)
            head.matrix_world = matrix
            scalp.parent = head
            scalp.matrix_parent_inverse.identity()
            scalp.display_type = 'WIRE'
            scalp.hide_render = True
            settings = scalp.keystrand_hair
            settings.role = 'SCALP'
            # The bundled head is drawn Z up, face to -Y: its axes are known in the mesh,
            # so they turn with it when the head is turned or tilted.
            settings.head_axes = 'LOCAL'
            settings.up, settings.front = CANONICAL_UP, CANONICAL_FRONT
            # The hair stays out of the whole head, not only off the scalp cap.
            settings.collider = head
            # Selecting can fail (a collection outside the view layer): inside the
            # transaction, before the other objects are deselected.
            scalp.select_set(True)
        for obj in context.selected_objects:
            if obj != scalp:
                obj.select_set(False)
        context.view_layer.objects.active = scalp
        # The preset loaded next places its keys out of the head: its collider is built now,
        # while the artist picks one.
        hair.prebuild_collider(scalp, context.evaluated_depsgraph_get(), collision=True)
        self.report({'INFO'}, f"Added {head.name!r} with scalp {scalp.name!r}: load a preset onto it")
        return {'FINISHED'}


def menu_add(self, context):
    self.layout.operator(HAIR_OT_add_head.bl_idname, text="Hair Head", icon='USER')


CLASSES = (HAIR_OT_add_head,)

# SPDX-License-Identifier: GPL-3.0-or-later
"""Panels: a "Hair" tab in the 3D Viewport sidebar (N) and in the Image Editor sidebar."""
from bpy.types import Panel

from . import draw_tools, progressive
from .scene_data import find_scalp, key_objects
from .transaction import background_errors


class _HairPanel:
    bl_region_type = 'UI'
    bl_category = "Hair"

    @classmethod
    def poll(cls, context):
        return find_scalp(context) is not None


class VIEW3D_PT_keystrand_hair(_HairPanel, Panel):
    bl_space_type = 'VIEW_3D'
    bl_label = "Key-Strand Hair"

    @classmethod
    def poll(cls, context):
        return True

    def draw(self, context):
        layout = self.layout
        scalp = find_scalp(context)
        if scalp is None:
            layout.label(text="Select a scalp mesh, or start from a head", icon='INFO')
            layout.operator("hair.add_head", text="Add Head", icon='USER')
            return
        s = scalp.keystrand_hair
        layout.label(text=scalp.name, icon='MESH_DATA')
        row = layout.row(align=True)
        row.operator("hair.load_preset", icon='PRESET')
        row.operator("hair.save_preset", text="", icon='FILE_TICK')
        layout.separator()
        col = layout.column(align=True)
        col.prop(s, "key_shape")
        col.prop(s, "key_length")
        col.operator("hair.add_key_strand", icon='CURVE_BEZCURVE')
        draw_tools.draw_buttons(col, context, s)
        layout.label(text=f"{len(key_objects(scalp))} key strands")
        layout.separator()
        col = layout.column(align=True)
        col.prop(s, "count")
        col.prop(s, "viewport_count")
        col.prop(s, "live_update")
        # What live update or the mirrored keys could not do (transaction.report_background).
        for message in background_errors(scalp):
            layout.label(text=message, icon='ERROR')
        layout.operator("hair.generate", icon='OUTLINER_OB_CURVES')
        layout.operator("hair.export", icon='EXPORT')


class VIEW3D_PT_keystrand_hair_shape(_HairPanel, Panel):
    bl_space_type = 'VIEW_3D'
    bl_label = "Shape"
    bl_parent_id = "VIEW3D_PT_keystrand_hair"

    def draw(self, context):
        s = find_scalp(context).keystrand_hair
        col = self.layout.column()
        col.use_property_split = True
        for name in ("min_length", "max_length", "tidiness", "theta_max", "n_influence", "neighbour_mode",
                     "intelligence", "seed", "sampling_mode", "normal_mode", "head_axes", "up", "front"):
            col.prop(s, name)


class VIEW3D_PT_keystrand_hair_look(_HairPanel, Panel):
    bl_space_type = 'VIEW_3D'
    bl_label = "Thickness and Colour"
    bl_parent_id = "VIEW3D_PT_keystrand_hair"

    def draw(self, context):
        s = find_scalp(context).keystrand_hair
        col = self.layout.column()
        col.use_property_split = True
        for name in ("radius", "radius_mode", "taper_start", "color", "color_variation",
                     "color_variation_point", "alpha_start", "alpha_tip", "resolution_mode",
                     "points_per_strand", "tolerance", "tolerance_units"):
            col.prop(s, name)


class VIEW3D_PT_keystrand_hair_wisps(_HairPanel, Panel):
    bl_space_type = 'VIEW_3D'
    bl_label = "Clumps and Curls"
    bl_parent_id = "VIEW3D_PT_keystrand_hair"

    def draw(self, context):
        s = find_scalp(context).keystrand_hair
        col = self.layout.column()
        col.use_property_split = True
        for name in ("clump", "clump_shape", "frizz", "curl", "curl_period"):
            col.prop(s, name)


class VIEW3D_PT_keystrand_hair_parting(_HairPanel, Panel):
    bl_space_type = 'VIEW_3D'
    bl_label = "Parting"
    bl_parent_id = "VIEW3D_PT_keystrand_hair"
    bl_options = {'DEFAULT_CLOSED'}

    def draw_header(self, context):
        self.layout.prop(find_scalp(context).keystrand_hair, "use_parting", text="")

    def draw(self, context):
        s = find_scalp(context).keystrand_hair
        col = self.layout.column()
        col.use_property_split = True
        col.active = s.use_parting
        col.prop(s, "parting_point")
        col.prop(s, "parting_normal")
        col.prop(s, "parting_use_end")
        sub = col.column()
        sub.active = s.use_parting and s.parting_use_end
        sub.prop(s, "parting_end")


class VIEW3D_PT_keystrand_hair_collision(_HairPanel, Panel):
    bl_space_type = 'VIEW_3D'
    bl_label = "Collision"
    bl_parent_id = "VIEW3D_PT_keystrand_hair"

    def draw_header(self, context):
        self.layout.prop(find_scalp(context).keystrand_hair, "collision", text="")

    def draw(self, context):
        s = find_scalp(context).keystrand_hair
        col = self.layout.column()
        col.use_property_split = True
        col.active = s.collision
        col.prop(s, "collider")
        col.prop(s, "collision_margin")


class VIEW3D_PT_keystrand_hair_key(_HairPanel, Panel):
    bl_space_type = 'VIEW_3D'
    bl_label = "Active Key Strand"
    bl_parent_id = "VIEW3D_PT_keystrand_hair"

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and obj.keystrand_hair.role == 'KEY'

    def draw(self, context):
        k = context.active_object.keystrand_hair
        col = self.layout.column()
        col.use_property_split = True
        col.prop(k, "use_key_color")
        sub = col.column()
        sub.active = k.use_key_color
        sub.prop(k, "key_color")
        col.prop(k, "key_radius")
        col.prop(k, "key_group")


def draw_render_settings(layout, s):
    col = layout.column()
    col.use_property_split = True
    for name in ("preview_size", "preview_samples", "preview_shading", "preview_shadows",
                 "preview_shadow_mode", "preview_layers", "preview_min_pixel_width",
                 "preview_scene_lights", "preview_in_process"):
        col.prop(s, name)


class VIEW3D_PT_keystrand_hair_preview(_HairPanel, Panel):
    bl_space_type = 'VIEW_3D'
    bl_label = "Preview Render"
    bl_parent_id = "VIEW3D_PT_keystrand_hair"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        draw_render_settings(self.layout, find_scalp(context).keystrand_hair)
        self.layout.operator("hair.render_preview", icon='RENDER_STILL')


class IMAGE_PT_keystrand_hair_preview(_HairPanel, Panel):
    bl_space_type = 'IMAGE_EDITOR'
    bl_label = "Hair Preview"

    @classmethod
    def poll(cls, context):
        return True

    def draw(self, context):
        scalp = find_scalp(context)
        if scalp is None:
            self.layout.label(text="Select a scalp mesh", icon='INFO')
            return
        self.layout.label(text=scalp.name, icon='MESH_DATA')
        draw_render_settings(self.layout, scalp.keystrand_hair)
        self.layout.operator("hair.render_preview", icon='RENDER_STILL')
        refining = progressive.status(scalp)
        if refining is not None:
            self.layout.label(text=refining, icon='TIME')


CLASSES = (VIEW3D_PT_keystrand_hair, VIEW3D_PT_keystrand_hair_shape, VIEW3D_PT_keystrand_hair_look,
           VIEW3D_PT_keystrand_hair_wisps, VIEW3D_PT_keystrand_hair_parting, VIEW3D_PT_keystrand_hair_collision, VIEW3D_PT_keystrand_hair_key,
           VIEW3D_PT_keystrand_hair_preview, IMAGE_PT_keystrand_hair_preview)

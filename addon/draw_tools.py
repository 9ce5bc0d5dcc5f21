# SPDX-License-Identifier: GPL-3.0-or-later
"""The drawing tools as one unit for registration and the Hair tab: Draw Key Strand (with a
shortcut), Comb Key Strand, the mirror of paired keys, the wisp overlay."""
import bpy

from . import comb_key, draw_key, mirror, overlay_wisps, stroke_input

CLASSES = stroke_input.CLASSES + draw_key.CLASSES + comb_key.CLASSES

# Shift+Alt+D in Object Mode: D for draw; free in Blender's default keymap (Shift+D and
# Alt+D duplicate).
SHORTCUT = dict(type='D', value='PRESS', shift=True, alt=True)

_keymap_items = []


def register():
    mirror.register()
    overlay_wisps.register()
    kc = bpy.context.window_manager.keyconfigs.addon
    if kc is not None:  # None where Blender runs without key configurations
        km = kc.keymaps.new(name="Object Mode", space_type='EMPTY')
        _keymap_items.append((km, km.keymap_items.new(draw_key.HAIR_OT_draw_key_strand.bl_idname, **SHORTCUT)))


def unregister():
    for km, kmi in _keymap_items:
        km.keymap_items.remove(kmi)
    _keymap_items.clear()
    overlay_wisps.unregister()
    mirror.unregister()


def draw_buttons(layout, context, settings):
    """The tools' buttons in the Hair tab, under Add Key Strand."""
    row = layout.row(align=True)
    row.operator(draw_key.HAIR_OT_draw_key_strand.bl_idname, icon='GREASEPENCIL')
    row.operator(comb_key.HAIR_OT_comb_key.bl_idname, text="Comb", icon='PARTICLEMODE')
    layout.prop(settings, "symmetry", icon='MOD_MIRROR')
    layout.prop(context.window_manager, "keystrand_show_wisps", icon='COLOR')

# SPDX-License-Identifier: GPL-3.0-or-later
"""Blender glue for key-strand hair: properties, operators, panels, bpy <-> numpy.

register() walks one `classes` tuple and adds the object property, the live-update
handlers, the File > Export entries and Add > Hair Head; unregister() removes every one of
them and stops the preview renderer. Nothing heavy is imported here: groom, tracer and
moderngl load inside the operators.
"""
import bpy

from . import add_head, draw_tools, live, operators, panels, preview, progressive, properties

classes = properties.CLASSES + operators.CLASSES + add_head.CLASSES + draw_tools.CLASSES + panels.CLASSES


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    properties.register_properties()
    live.register_handlers()
    progressive.register()
    draw_tools.register()
    bpy.types.TOPBAR_MT_file_export.append(operators.menu_export)
    bpy.types.VIEW3D_MT_add.append(add_head.menu_add)


def unregister():
    bpy.types.VIEW3D_MT_add.remove(add_head.menu_add)
    bpy.types.TOPBAR_MT_file_export.remove(operators.menu_export)
    draw_tools.unregister()
    live.unregister_handlers()
    progressive.unregister()
    preview.close()
    properties.unregister_properties()
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)

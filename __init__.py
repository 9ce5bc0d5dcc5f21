# SPDX-License-Identifier: GPL-3.0-or-later
"""Key-Strand Hair: Blender extension entry point."""
from . import addon


def register():
    addon.register()


def unregister():
    addon.unregister()

# SPDX-License-Identifier: GPL-3.0-or-later
"""Key-Strand Hair: Blender extension entry point."""
# pytest imports a checkout's root __init__.py as a bare module (no package) when the
# folder's name is no Python identifier (a clone named keystrand-hair): there is nothing to
# register then, and a relative import would fail.
if __package__:
    from . import addon


def register():
    addon.register()


def unregister():
    addon.unregister()

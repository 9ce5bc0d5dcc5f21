# SPDX-License-Identifier: GPL-3.0-or-later
"""Key-Strand Hair: Blender extension entry point.

The add-on is imported when Blender registers it, not when this file is imported: pytest
imports a checkout's root __init__.py as a bare module when the folder's name is no Python
identifier (a clone named keystrand-hair), where a relative import at the top would fail.
"""


def register():
    from . import addon
    addon.register()


def unregister():
    from . import addon
    addon.unregister()

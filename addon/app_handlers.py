# SPDX-License-Identifier: GPL-3.0-or-later
"""Adding and removing a module's Blender app handlers, once each.

A module lists its handlers as ((bpy.app.handlers.<list>, function), ...); adding twice
(a reload, an enable after a failed disable) must not run a handler twice, and removing
takes every copy."""


def add(pairs):
    for handlers, fn in pairs:
        if fn not in handlers:
            handlers.append(fn)


def remove(pairs):
    for handlers, fn in pairs:
        while fn in handlers:
            handlers.remove(fn)

# SPDX-License-Identifier: GPL-3.0-or-later
"""Blender glue for key-strand hair: properties, operators, panels, bpy <-> numpy."""

# SPDX-License-Identifier: GPL-3.0-or-later
"""Strand arrays (SPEC §0) and the files that carry them: numpy only, no Blender, no GL.

`Strands` is the one container every package passes around; `read_strands` and
`write_strands` pick a format by file extension.
"""
from .strands import Guides, Strands
from .validate import InputError, check_finite
from .atomic import atomic_write

__all__ = ["Strands", "Guides", "InputError", "check_finite", "atomic_write"]

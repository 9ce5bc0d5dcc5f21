# SPDX-License-Identifier: GPL-3.0-or-later
"""Which way is up in a file, and bringing it into our frame (Z up, -Y front, SPEC §0).

Our arrays never guess: a reader returns a file's coordinates as they are. Commands that
show or convert files take `--up z|y|auto`: `z` keeps the coordinates, `y` reads the file as
right-handed Y up with the face toward +Z (x, y, z -> x, -z, y: the face toward our -Y, the
front), `auto` does so for the formats whose files are Y up (their `frame` in the format
registry, hairio/formats/registry.py) and keeps the others. The turn is a signed permutation of the axes (hairio/formats/axes.py), exact in
float32. TressFX files are read right-handed too: the TressFX-OpenGL Sintel's hair and body
then face the front, and Ratboy's mohawk sweeps back from its brow.
"""
import os

from ..validate import InputError
from .axes import unconvert_points, unconvert_strands

UP_CHOICES = ("z", "y", "auto")


def file_frame(path, up="auto"):
    """The frame (a name of axes.AXES) the coordinates of the file at `path` are in, for
    the `up` choice."""
    if up not in UP_CHOICES:
        raise InputError(f"--up {up!r}: choose one of {', '.join(UP_CHOICES)}")
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if up == "z":
        return "none"
    if up == "y":
        return "y-up"
    from .registry import BY_EXTENSION
    fmt = BY_EXTENSION.get(ext)
    return "none" if fmt is None else fmt.frame


def points_to_z_up(points, path, up="auto"):
    """`points` (N,3) read from the file at `path`, in our Z-up frame (float32)."""
    frame = file_frame(path, up)
    return points if frame == "none" else unconvert_points(points, frame)


def strands_to_z_up(strands, path, up="auto"):
    """`strands` read from the file at `path`, in our Z-up frame (their key strands too)."""
    return unconvert_strands(strands, file_frame(path, up))

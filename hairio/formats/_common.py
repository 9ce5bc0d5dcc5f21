# SPDX-License-Identifier: GPL-3.0-or-later
"""What every reader and writer shares: the tool's name, file reading with clear errors,
and dropping strands too short for `Strands` (which needs >= 2 points per strand)."""
import os

import numpy as np

from ..strands import Strands
from ..validate import InputError

TOOL_NAME = "keystrand-hair"
TOOL_VERSION = "0.1.0"


def read_bytes(path, what):
    """The whole file as bytes; a missing or unreadable file is an InputError naming it."""
    path = os.fspath(path)
    try:
        with open(path, "rb") as f:
            return f.read()
    except OSError as e:
        raise InputError(f"{path}: cannot read this {what} file ({e.strerror or e})") from e


def need(data, end, path, what):
    """Reject a truncated file before numpy reads past its end, or allocates what a header
    claims: `end` is computed in Python integers, which do not overflow."""
    if end > len(data):
        raise InputError(f"{path}: truncated {what} file: needs {end:,} bytes, has {len(data):,}; "
                         f"re-export it")


def strands_without_short(points, counts, min_points=2, source=None, **per_point):
    """Strands from arrays, dropping strands with fewer than `min_points` points (and their
    per-point values: keyword arrays of length P) in one masked copy, no loop. `source`
    (a file) is named in the message when the arrays are refused."""
    counts = np.asarray(counts, np.int64)
    keep = counts >= min_points
    if not keep.all():
        point_keep = np.repeat(keep, counts)
        points = points[point_keep]
        per_point = {k: (None if v is None else v[point_keep]) for k, v in per_point.items()}
        counts = counts[keep]
    try:
        return Strands.from_arrays(points, counts, **per_point)
    except InputError as e:
        if source is None:
            raise
        raise InputError(f"{source}: {e}") from None


def check_strands(strands):
    if not isinstance(strands, Strands):
        raise InputError(f"strands: expected hairio.Strands, got {type(strands).__name__}; "
                         f"build one with Strands.from_arrays")
    return strands


def check_export_options(path, kind, extensions, axes, axis, scale):
    """The scale as a float after checking a groom export's file name, axis and scale."""
    if os.path.splitext(os.fspath(path))[1].lower() not in extensions:
        raise InputError(f"{path}: a {kind} file must end in {' or '.join(extensions)}")
    if axis not in axes:
        raise InputError(f"--axis {axis}: for {kind} choose one of {', '.join(axes)}")
    scale = float(scale)
    if not np.isfinite(scale) or scale <= 0:
        raise InputError(f"--scale {scale}: must be a positive number")
    return scale

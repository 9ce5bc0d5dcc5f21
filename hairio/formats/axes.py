# SPDX-License-Identifier: GPL-3.0-or-later
"""Axis and unit conversions applied on export, always explicit (SPEC §0: nothing is assumed).

Our arrays are in Blender's frame: right-handed, Z up, -Y front, metres. Each target frame
below is a signed permutation of those axes, so a conversion is exact in float32 (it only
moves and negates coordinates); the scale multiplies points and radii.
"""
import numpy as np

from ..strands import Guides, Strands
from ..validate import InputError

# Rows: where each target axis takes its value from, as (source axis, sign).
AXES = {
    # Keep Blender's frame.
    "none": ((0, 1), (1, 1), (2, 1)),
    # Right-handed Y up (Maya, Alembic, USD's Y-up stages): x, z, -y. Front -Y becomes +Z.
    "y-up": ((0, 1), (2, 1), (1, -1)),
    # Unreal: left-handed Z up: mirror Y (what Unreal's importers do to right-handed Z-up data).
    "unreal": ((0, 1), (1, -1), (2, 1)),
    # DirectX / TressFX samples: left-handed Y up: swap Y and Z (front -Y becomes -Z, toward the viewer).
    "directx": ((0, 1), (2, 1), (1, 1)),
}


def convert_points(points, axis="none", scale=1.0):
    """`points` (N,3) in Blender's frame -> the `axis` frame, times `scale`; float32."""
    if axis not in AXES:
        raise InputError(f"axis: unknown {axis!r}; choose one of {', '.join(AXES)}")
    scale = float(scale)
    if not np.isfinite(scale) or scale <= 0:
        raise InputError(f"scale: {scale} is not a positive finite number")
    points = np.asarray(points)
    out = np.empty(points.shape, np.float32)
    for dst, (src, sign) in enumerate(AXES[axis]):
        out[..., dst] = points[..., src] * (sign * scale)
    return out


def convert_strands(strands, axis="none", scale=1.0):
    """A copy of `strands` in the `axis` frame with points and radii times `scale` (its key
    strands too; guides, weights and root UVs are kept)."""
    if axis == "none" and float(scale) == 1.0:
        return strands
    points = convert_points(strands.points, axis, scale)
    radius = strands.radius * np.float32(scale)
    guides = strands.guides
    if guides is not None:
        guides = Guides(convert_strands(guides.keys, axis, scale), guides.group, guides.index, guides.weights)
    return Strands.from_arrays(points, strands.counts, radius, strands.color, strands.alpha, strands.wisp,
                               guides=guides, root_uv=strands.root_uv)


def unconvert_points(points, axis="none", scale=1.0):
    """The inverse of convert_points: `points` in the `axis` frame, times 1/`scale`, back in
    Blender's frame; float32. Exact for scale 1 (the permutation only moves and negates)."""
    scale = float(scale)
    if axis not in AXES:
        raise InputError(f"axis: unknown {axis!r}; choose one of {', '.join(AXES)}")
    points = np.asarray(points)
    out = np.empty(points.shape, np.float32)
    for dst, (src, sign) in enumerate(AXES[axis]):
        # float64 before the division, so x * s rounded to float32 and divided by s gives x back.
        out[..., src] = points[..., dst] * sign if scale == 1.0 else points[..., dst].astype(np.float64) * (sign / float(scale))
    return out


def unconvert_strands(strands, axis="none"):
    """The inverse of convert_strands at scale 1: `strands` in the `axis` frame back in
    Blender's frame (their key strands too; radii, guides, weights and root UVs kept)."""
    if axis == "none":
        return strands
    guides = strands.guides
    if guides is not None:
        guides = Guides(unconvert_strands(guides.keys, axis), guides.group, guides.index, guides.weights)
    return Strands.from_arrays(unconvert_points(strands.points, axis), strands.counts, strands.radius,
                               strands.color, strands.alpha, strands.wisp, guides=guides, root_uv=strands.root_uv)

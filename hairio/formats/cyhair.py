# SPDX-License-Identifier: GPL-3.0-or-later
"""Cem Yuksel's HAIR format (.hair), little-endian.

Header, 128 bytes:
    char[4]  "HAIR"
    uint32   hair_count, point_count
    uint32   arrays: bit flags 1 segments, 2 points, 4 thickness, 8 transparency, 16 colors
    uint32   default segments (used when the segments array is absent)
    float32  default thickness, default transparency, default color[3]
    char[88] info (free text; ours names the tool)
then the arrays that are present, in this order: segments uint16[hair_count] (segments per
strand = points - 1), points float32[point_count][3], thickness float32[point_count],
transparency float32[point_count], colors float32[point_count][3].

Conventions (documented, the same both ways):
- thickness is the strand's full width, a diameter: thickness = 2 * radius. cyHair's
  viewer and renderers draw a strand `thickness` wide, and the sample files' default 0.1
  against heads ~60 units tall is a width. Both operations are exact in float32.
- transparency = 1 - alpha.
- colors are stored as given (our colors are linear RGB).
- A strand with 0 segments (1 point) cannot be a `Strands` strand; the reader drops it.
"""
import numpy as np

from ..atomic import atomic_write
from ..validate import InputError
from ._common import TOOL_NAME, TOOL_VERSION, check_strands, need, read_bytes, strands_without_short

SEGMENTS, POINTS, THICKNESS, TRANSPARENCY, COLORS = 1, 2, 4, 8, 16

HEADER = np.dtype([
    ("signature", "S4"), ("hair_count", "<u4"), ("point_count", "<u4"), ("arrays", "<u4"),
    ("d_segments", "<u4"), ("d_thickness", "<f4"), ("d_transparency", "<f4"),
    ("d_color", "<f4", (3,)), ("info", "S88"),
])
assert HEADER.itemsize == 128

INFO = f"{TOOL_NAME} {TOOL_VERSION} (key-strand hair)".encode("ascii")


def read_hair(path):
    """Strands from a .hair file (radius = thickness / 2, alpha = 1 - transparency).
    Every size the header claims is checked against the file's length before an array is
    made, so memory stays within a few times the file's size."""
    data = read_bytes(path, ".hair")
    need(data, HEADER.itemsize, path, ".hair")
    h = np.frombuffer(data, HEADER, count=1)[0]
    if h["signature"] != b"HAIR":
        raise InputError(f"{path}: not a .hair file (signature {bytes(h['signature'])!r}, expected b'HAIR')")
    n_s, n_p, flags = int(h["hair_count"]), int(h["point_count"]), int(h["arrays"])
    if not flags & POINTS:
        raise InputError(f"{path}: .hair file without a points array (flags {flags:#x}); nothing to read")
    sizes = [(SEGMENTS, "segments", 2 * n_s), (POINTS, "points", 12 * n_p), (THICKNESS, "thickness", 4 * n_p),
             (TRANSPARENCY, "transparency", 4 * n_p), (COLORS, "colors", 12 * n_p)]
    need(data, HEADER.itemsize + sum(size for bit, _, size in sizes if flags & bit), path,
         f".hair ({', '.join(name for bit, name, _ in sizes if flags & bit)} arrays of {n_s:,} strands, "
         f"{n_p:,} points)")
    if not flags & SEGMENTS and n_s * (int(h["d_segments"]) + 1) != n_p:
        raise InputError(f"{path}: {n_s:,} strands of {int(h['d_segments']) + 1:,} points (the default segments) "
                         f"are {n_s * (int(h['d_segments']) + 1):,} points but the header says {n_p:,}; "
                         "the file is inconsistent")
    pos = HEADER.itemsize

    def take(dtype, count):
        nonlocal pos
        arr = np.frombuffer(data, dtype, count=count, offset=pos)
        pos += arr.nbytes
        return arr

    if flags & SEGMENTS:
        counts = take("<u2", n_s).astype(np.int64) + 1
        if int(counts.sum()) != n_p:
            raise InputError(f"{path}: segments add up to {int(counts.sum()):,} points but the header says "
                             f"{n_p:,}; the file is inconsistent")
    else:
        counts = np.full(n_s, int(h["d_segments"]) + 1, np.int64)
    points = take("<f4", 3 * n_p).reshape(n_p, 3)
    radius = (take("<f4", n_p) if flags & THICKNESS
              else np.full(n_p, h["d_thickness"], np.float32)) * np.float32(0.5)
    transparency = (take("<f4", n_p) if flags & TRANSPARENCY
                    else np.full(n_p, h["d_transparency"], np.float32))
    color = (take("<f4", 3 * n_p).reshape(n_p, 3) if flags & COLORS
             else np.broadcast_to(h["d_color"].astype(np.float32), (n_p, 3)))
    # Other tools write transparency slightly outside [0, 1] (rounding); clamp, don't fail.
    # NaN stays NaN through the clip and is refused with the other arrays' NaN.
    alpha = np.clip(np.float32(1) - transparency, 0, 1)
    return strands_without_short(points, counts, source=path, radius=radius, color=color, alpha=alpha)


def _uniform(a):
    """(True, first value) when every element (row) is equal, else (False, None)."""
    if len(a) == 0 or (a == a[0]).all():
        return True, (a[0] if len(a) else None)
    return False, None


def write_hair(path, strands, info=None, compact=True):
    """Write `strands` as .hair, atomically.

    compact: leave out the segments / thickness / transparency / colors arrays when every
    value is the same (the header's default then holds it), as cyHair intends; False writes
    every array (points are always written).
    """
    s = check_strands(strands)
    segments = s.counts.astype(np.int64) - 1
    if len(segments) and segments.max() > 0xFFFF:
        raise InputError(f"strands: a strand has {int(segments.max()) + 1} points; .hair stores at most "
                         f"65536 per strand; resample it first")
    thickness = s.radius * np.float32(2)
    transparency = np.float32(1) - s.alpha
    flags = POINTS
    same_seg, seg0 = _uniform(segments)
    same_th, th0 = _uniform(thickness)
    same_tr, tr0 = _uniform(transparency)
    same_co, co0 = _uniform(s.color)
    arrays = []
    if not (compact and same_seg):
        flags |= SEGMENTS
        arrays.append(segments.astype("<u2"))
    arrays.append(s.points.astype("<f4"))
    if not (compact and same_th):
        flags |= THICKNESS
        arrays.append(thickness.astype("<f4"))
    if not (compact and same_tr):
        flags |= TRANSPARENCY
        arrays.append(transparency.astype("<f4"))
    if not (compact and same_co):
        flags |= COLORS
        arrays.append(s.color.astype("<f4"))
    text = INFO if info is None else str(info).encode("utf-8")
    h = np.zeros(1, HEADER)
    h["signature"] = b"HAIR"
    h["hair_count"], h["point_count"], h["arrays"] = s.num_strands, s.num_points, flags
    h["d_segments"] = int(seg0) if (same_seg and seg0 is not None) else 0
    h["d_thickness"] = th0 if th0 is not None else 0.0
    h["d_transparency"] = tr0 if tr0 is not None else 0.0
    h["d_color"] = co0 if co0 is not None else 0.0
    h["info"] = text[:87]  # keep a terminating NUL for C readers
    with atomic_write(path) as f:
        f.write(h.tobytes())
        for a in arrays:
            f.write(np.ascontiguousarray(a).tobytes())

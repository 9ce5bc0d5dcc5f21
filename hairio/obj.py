# SPDX-License-Identifier: GPL-3.0-or-later
"""Wavefront .obj meshes as plain arrays: `v` positions and `f` faces (polygons
fan-triangulated; v, v/vt, v//vn and v/vt/vn corners; negative indices count back from the
last vertex read). Everything else (normals, UVs, groups, materials) is skipped. Bad files
are an InputError naming the file, the line and what is wrong."""
import os

import numpy as np

from .validate import InputError


def read_obj(path, what="mesh"):
    """(vertices (V,3) float64, triangles (F,3) int64) of the .obj at `path`; `what` names
    the mesh's role in messages ("mesh", "scalp mesh", ...)."""
    path = os.fspath(path)
    try:
        with open(path, "r", encoding="utf-8", errors="replace") as f:
            lines = f.readlines()
    except OSError as e:
        raise InputError(f"{what} {path!r}: cannot read it ({e.strerror or e}); check the path") from None
    verts, tris = [], []
    for no, line in enumerate(lines, 1):
        parts = line.split()
        if not parts or parts[0] not in ("v", "f"):
            continue
        try:
            if parts[0] == "v":
                v = [float(x) for x in parts[1:4]]
                if len(v) != 3:
                    raise ValueError("a vertex needs 3 coordinates")
                verts.append(v)
            else:
                corners = [_index(item.split("/")[0], len(verts)) for item in parts[1:]]
                tris.extend((corners[0], corners[k], corners[k + 1]) for k in range(1, len(corners) - 1))
        except ValueError as e:
            raise InputError(f"{what} {path!r} line {no}: cannot parse {line.strip()!r} ({e})") from None
    if not verts:
        raise InputError(f"{what} {path!r}: no vertices ('v' lines); is it an .obj mesh?")
    if not tris:
        raise InputError(f"{what} {path!r}: no faces ('f' lines with 3 or more corners)")
    verts = np.array(verts, np.float64)
    tris = np.array(tris, np.int64)
    if tris.min() < 0 or tris.max() >= len(verts):
        raise InputError(f"{what} {path!r}: a face refers to a vertex that does not exist")
    return verts, tris


def _index(text, count):
    """0-based from an OBJ index: 1-based, or negative counting back from the last of the
    `count` vertices read so far (0 is no OBJ index)."""
    i = int(text)
    if i == 0:
        raise ValueError("vertex index 0: OBJ indices count from 1")
    return i - 1 if i > 0 else count + i

# SPDX-License-Identifier: GPL-3.0-or-later
"""Wavefront .obj meshes as plain arrays: `v` positions, `vt` texture coordinates and `f`
faces (polygons fan-triangulated; v, v/vt, v//vn and v/vt/vn corners; negative indices count
back from the last vertex read). Everything else (normals, groups, materials) is skipped.
Bad files are an InputError naming the file, the line and what is wrong. The one OBJ
parser of the project: the tracer's meshes (read_obj) and groom's scalps (parse_obj) both
read through it."""
import os
from dataclasses import dataclass

import numpy as np

from .validate import InputError

# An index past this names no vertex of any mesh (and would not fit in int64).
_MAX_INDEX = 1 << 62


@dataclass(frozen=True)
class ObjMesh:
    vertices: np.ndarray        # (V, 3) float64, as written (NaN and Inf are the caller's to judge)
    triangles: np.ndarray       # (F, 3) int64, every index a vertex of the file
    uvs: np.ndarray             # (T, 2) float64, the `vt` lines (a missing v is 0)
    triangle_uvs: np.ndarray    # (F, 3) int64 indices into uvs; None unless every corner gives one


def read_obj(path, what="mesh"):
    """(vertices (V,3) float64, triangles (F,3) int64) of the .obj at `path`; `what` names
    the mesh's role in messages ("mesh", "scalp mesh", ...)."""
    mesh = parse_obj(path, what)
    return mesh.vertices, mesh.triangles


def parse_obj(path, what="mesh"):
    """The ObjMesh of the .obj at `path`. Refused, naming `what` and the file: an unreadable
    file, a line that does not parse (with its number), an index 0 (OBJ counts from 1) or one
    outside the file, no vertices, no faces, a face corner past the last vertex."""
    path = os.fspath(path)
    try:
        with open(path, "r", encoding="utf-8", errors="replace") as f:
            lines = f.readlines()
    except OSError as e:
        raise InputError(f"{what} {path!r}: cannot read it ({e.strerror or e}); check the path") from None
    verts, uvs, tris, tri_uv = [], [], [], []
    for no, line in enumerate(lines, 1):
        parts = line.split()
        if not parts or parts[0] not in ("v", "vt", "f"):
            continue
        try:
            if parts[0] == "v":
                v = [float(x) for x in parts[1:4]]
                if len(v) != 3:
                    raise ValueError("a vertex needs 3 coordinates")
                verts.append(v)
            elif parts[0] == "vt":
                uvs.append([float(x) for x in (parts[1:3] + ["0"])[:2]])
            else:
                corners = []
                for item in parts[1:]:
                    fields = item.split("/")
                    vt = _index(fields[1], len(uvs), "texture coordinate") if len(fields) > 1 and fields[1] else None
                    corners.append((_index(fields[0], len(verts), "vertex"), vt))
                for k in range(1, len(corners) - 1):
                    tri = (corners[0], corners[k], corners[k + 1])
                    tris.append([c[0] for c in tri])
                    tri_uv.append([c[1] for c in tri])
        except ValueError as e:
            raise InputError(f"{what} {path!r} line {no}: cannot parse {line.strip()!r} ({e})") from None
    if not verts:
        raise InputError(f"{what} {path!r}: no vertices ('v' lines); is it an .obj mesh?")
    if not tris:
        raise InputError(f"{what} {path!r}: no faces ('f' lines with 3 or more corners); a {what} needs triangles")
    verts = np.array(verts, np.float64)
    tris = np.array(tris, np.int64)
    if tris.min() < 0 or tris.max() >= len(verts):
        raise InputError(f"{what} {path!r}: a face refers to a vertex that does not exist")
    with_uv = all(t is not None for tri in tri_uv for t in tri)
    return ObjMesh(verts, tris, np.array(uvs, np.float64).reshape(-1, 2),
                   np.array(tri_uv, np.int64) if with_uv else None)


def _index(text, count, what):
    """A 0-based index from an OBJ face corner: 1-based, or negative counting back from the
    last of the `count` read so far. 0 is no index in OBJ (it would wrap to a later vertex),
    and one past int64 names no vertex of any mesh."""
    i = int(text)
    if i == 0:
        raise ValueError(f"{what} index 0: OBJ indices count from 1")
    i = i - 1 if i > 0 else count + i
    if not 0 <= i < _MAX_INDEX:
        raise ValueError(f"{what} index {text} lies outside the file")
    return i


def write_obj(path, vertices, triangles, comment=None):
    """Write a triangle mesh as .obj (`v` lines that read back to the same float64 values,
    `f` lines counting from 1), all or nothing: a failure leaves no file."""
    from .atomic import atomic_write
    vertices = np.asarray(vertices, np.float64)
    triangles = np.asarray(triangles, np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or not np.isfinite(vertices).all():
        raise InputError(f"{path}: vertices must be finite (V, 3); got shape {vertices.shape}")
    if triangles.ndim != 2 or triangles.shape[1] != 3 or len(triangles) == 0 \
            or triangles.min() < 0 or triangles.max() >= len(vertices):
        raise InputError(f"{path}: triangles must be (F, 3) indices of the {len(vertices)} vertices")
    lines = [] if comment is None else [f"# {line}" for line in comment.splitlines()]
    lines += [f"v {x!r} {y!r} {z!r}" for x, y, z in vertices.tolist()]
    lines += [f"f {a} {b} {c}" for a, b, c in triangles + 1]
    with atomic_write(path) as f:
        f.write(("\n".join(lines) + "\n").encode("ascii"))

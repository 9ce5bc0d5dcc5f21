# SPDX-License-Identifier: GPL-3.0-or-later
"""Opaque triangle meshes beside the strands (a head, a body, a floor), checked where they
enter: `mesh_set` turns what a caller gives (a list of (vertices, triangles, rgb), each
optionally followed by a name) into one MeshSet, or raises an InputError naming the mesh
and what to fix. Deeper code then trusts the arrays.

A mesh is opaque and shaded diffusely with its base colour: where a ray meets it first the
pixel is rgb × (ambient + Σ light colour · max(N·L, 0) · shadow), N the triangle's normal
facing the ray. It hides the hair behind it, from the camera and from the lights.
"""
from dataclasses import dataclass

import numpy as np

from hairio import InputError

from . import layout


@dataclass(frozen=True, eq=False)
class MeshSet:
    """Every mesh's triangles, concatenated: corners (F, 3, 3) float32 as the GPU gets them
    (the reference promotes these), color (F, 3) float64 base colour, mesh (F,) index of
    each triangle's mesh, names (one per mesh)."""
    corners: np.ndarray
    color: np.ndarray
    mesh: np.ndarray
    names: tuple

    def __len__(self):
        return len(self.corners)

    def bounds(self):
        """(lo, hi) float64 (3,) of every corner."""
        flat = self.corners.reshape(-1, 3)
        return flat.min(axis=0).astype(np.float64), flat.max(axis=0).astype(np.float64)

    def shadow_offset(self):
        """How far shadow rays leave the surface (layout.MESH_SHADOW_OFFSET × the diagonal)."""
        lo, hi = self.bounds()
        return float(layout.MESH_SHADOW_OFFSET * max(np.linalg.norm(hi - lo), 1e-30))


def mesh_set(meshes):
    """A MeshSet of `meshes`: a sequence of (vertices (V,3), triangles (F,3) int, rgb) or
    (vertices, triangles, rgb, name); None or an empty sequence for none (returns None).
    InputError naming the mesh ("mesh 2" or its name) for anything that cannot be drawn:
    a wrong shape, NaN or infinite coordinates or colour, indices outside its vertices, no
    faces, coordinates too far out for float32."""
    if meshes is None:
        return None
    if isinstance(meshes, MeshSet):
        return meshes if len(meshes) else None
    try:
        items = list(meshes)
    except TypeError:
        raise InputError(f"meshes: expected a list of (vertices, triangles, rgb), got {type(meshes).__name__}") from None
    if not items:
        return None
    corners, colors, owner, names = [], [], [], []
    for k, item in enumerate(items):
        if not isinstance(item, (tuple, list)) or len(item) not in (3, 4):
            raise InputError(f"mesh {k}: expected (vertices, triangles, rgb) or (vertices, triangles, rgb, name)")
        name = str(item[3]) if len(item) == 4 else f"mesh {k}"
        c, rgb = _check_mesh(name, *item[:3])
        corners.append(c)
        colors.append(np.broadcast_to(rgb, (len(c), 3)))
        owner.append(np.full(len(c), k, np.int32))
        names.append(name)
    return MeshSet(np.concatenate(corners), np.concatenate(colors).astype(np.float64), np.concatenate(owner),
                   tuple(names))


def _check_mesh(name, vertices, triangles, rgb):
    """(corners (F,3,3) float32, rgb (3,) float64) of one mesh, checked."""
    try:
        v = np.asarray(vertices, np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{name}: vertices must be numbers, an array of shape (V, 3)") from None
    if v.ndim != 2 or v.shape[1] != 3:
        raise InputError(f"{name}: vertices have shape {v.shape}; expected (V, 3)")
    if not np.isfinite(v).all():
        bad = int(np.argmax(~np.isfinite(v).all(axis=1)))
        raise InputError(f"{name}: vertex {bad} has NaN or infinite coordinates; repair the mesh")
    if v.size and np.abs(v).max() > layout.MAX_POINT_COORDINATE:
        raise InputError(f"{name}: coordinates reach {np.abs(v).max():.3g}; the GPU tracer takes meshes within "
                         f"±{layout.MAX_POINT_COORDINATE:.0e} of the origin: scale or recentre it")
    t = np.asarray(triangles)
    if t.size == 0:
        raise InputError(f"{name}: no faces; a mesh needs at least one triangle")
    if t.ndim != 2 or t.shape[1] != 3:
        raise InputError(f"{name}: triangles have shape {t.shape}; expected (F, 3) vertex indices")
    if not np.issubdtype(t.dtype, np.integer):
        if not (np.issubdtype(t.dtype, np.floating) and np.isfinite(t).all() and np.all(t == np.round(t))):
            raise InputError(f"{name}: triangle indices must be whole numbers")
        t = t.astype(np.int64)
    if t.min() < 0 or t.max() >= len(v):
        bad = int(np.argmax((t < 0).any(axis=1) | (t >= len(v)).any(axis=1)))
        raise InputError(f"{name}: triangle {bad} refers to vertex {int(t[bad][(t[bad] < 0) | (t[bad] >= len(v))][0])}, "
                         f"but the mesh has {len(v)} vertices (0..{len(v) - 1})")
    try:
        c = np.asarray(rgb, np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{name}: colour must be three numbers (R, G, B)") from None
    if c.shape != (3,) or not np.isfinite(c).all() or (c < 0).any():
        raise InputError(f"{name}: colour {rgb!r}; expected three finite numbers >= 0 (R, G, B)")
    return v[t.astype(np.int64)].astype(np.float32), c

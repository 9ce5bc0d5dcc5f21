# SPDX-License-Identifier: GPL-3.0-or-later
"""Meshes in float64: the mirror of tracer/shaders/shapes_triangle.glsl (Möller-Trumbore,
two-sided, the same edge overlap) and of accel_mesh_grid.glsl's two questions, answered by
brute force over every triangle (no grid)."""
import numpy as np

from .. import layout
from .shapes import BIG

PAIRS_PER_STEP = 2_000_000      # ray x triangle pairs held in memory at once


class TriangleSet:
    """A tracer.meshes.MeshSet's triangles in float64 (from the float32 corners the GPU gets)."""

    def __init__(self, mesh_set):
        c = mesh_set.corners.astype(np.float64)
        self.v0, self.e1, self.e2 = c[:, 0], c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]
        self.color = mesh_set.color
        self.offset = mesh_set.shadow_offset()

    def __len__(self):
        return len(self.v0)


def _hits(tris, o, d, ids):
    """t (inf on a miss) and the unit normal facing the ray, per (o[k], d[k], ids[k]); the
    shader's hit_triangle."""
    dot = lambda x, y: np.einsum("ij,ij->i", x, y)  # noqa: E731
    v0, e1, e2 = tris.v0[ids], tris.e1[ids], tris.e2[ids]
    pv = np.cross(d, e2)
    det = dot(e1, pv)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        tv = o - v0
        u = dot(tv, pv) * inv
        qv = np.cross(tv, e1)
        v = dot(d, qv) * inv
        t = dot(e2, qv) * inv
    eps = layout.TRI_EDGE_EPS
    miss = (det == 0) | (u < -eps) | (v < -eps) | (u + v > 1 + eps)
    g = np.cross(e1, e2)
    g = np.where((dot(g, d) > 0)[:, None], -g, g)
    n = g / np.maximum(np.linalg.norm(g, axis=1), 1e-300)[:, None]
    return np.where(miss, np.inf, t), n


def _pairs(tris, n_rays):
    """(ray, triangle) index arrays over every pair, in steps of PAIRS_PER_STEP."""
    step = max(1, PAIRS_PER_STEP // max(1, len(tris)))
    for a in range(0, n_rays, step):
        rays = np.arange(a, min(n_rays, a + step))
        yield np.repeat(rays, len(tris)), np.tile(np.arange(len(tris)), len(rays))


def mesh_nearest(tris, o, d, tmax):
    """The nearest triangle hit in (0, tmax) of every ray: (t (BIG: none), triangle (-1:
    none), unit normal facing the ray); equal distances go to the lower triangle id."""
    t_best = np.full(len(o), BIG)
    tri = np.full(len(o), -1, np.int64)
    normal = np.zeros((len(o), 3))
    tmax = np.broadcast_to(np.asarray(tmax, np.float64), (len(o),))
    for rr, tt in _pairs(tris, len(o)):
        t, n = _hits(tris, o[rr], d[rr], tt)
        ok = (t > 0) & (t < tmax[rr])
        rr, tt, t, n = rr[ok], tt[ok], t[ok], n[ok]
        order = np.lexsort((tt, t, rr))
        rr, tt, t, n = rr[order], tt[order], t[order], n[order]
        first = np.ones(len(rr), bool)
        first[1:] = rr[1:] != rr[:-1]
        rr, tt, t, n = rr[first], tt[first], t[first], n[first]
        better = (t < t_best[rr]) | ((t == t_best[rr]) & (tt < tri[rr]))
        rr, tt, t, n = rr[better], tt[better], t[better], n[better]
        t_best[rr], tri[rr], normal[rr] = t, tt, n
    return t_best, tri, normal


def mesh_blocked(tris, o, d, tmax, own=None):
    """Whether any triangle but own[k] is hit in (0, tmax[k]) by each ray."""
    blocked = np.zeros(len(o), bool)
    tmax = np.broadcast_to(np.asarray(tmax, np.float64), (len(o),))
    own = np.full(len(o), -1) if own is None else np.asarray(own)
    for rr, tt in _pairs(tris, len(o)):
        t, _ = _hits(tris, o[rr], d[rr], tt)
        hit = (t > 0) & (t < tmax[rr]) & (tt != own[rr])
        blocked[rr[hit]] = True
    return blocked

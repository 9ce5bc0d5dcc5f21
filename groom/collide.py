# SPDX-License-Identifier: GPL-3.0-or-later
"""Collision with the head (SPEC §5, Collision): a collider mesh, its signed distance, and
strands moved out of it the way a groomer would comb them.

Signed distance. The distance to the nearest triangle, signed by the angle-weighted
pseudo-normal of the feature (face, edge or vertex) the nearest point lies on (Bærentzen &
Aanæs 2005): outside where the point lies on the side the pseudo-normal points to. On a
closed, consistently oriented mesh that is the exact inside/outside; a closed mesh whose
faces all point inwards is turned round first (its volume says so), one whose faces disagree
is refused (recalculate its normals). An OPEN mesh (a scalp used as its own collider) has no
inside, only a back: a point counts as inside when its nearest point lies on a face or an
inner edge or vertex and the point is behind it, within `band` of it (a shell behind the
faces); a point whose nearest point is on the open border, or that lies deeper, is outside.
So an open cap keeps hair off and out from under itself, and past its edge it holds nothing.

Acceleration. The distance is sampled on a uniform grid over the mesh (about 2 M nodes, a
cell of 1.6 mm on the bundled head, 2.3 mm on the USC head with its neck): exact at every
node within `band` (2 cells, more for a clearance that needs it) of the surface, found by
visiting, for each triangle, the nodes near it; farther nodes are clamped to ±band, their
sign by ray parity along the grid's z lines (a closed mesh) or outside (an open one). A
query interpolates trilinearly and subtracts the cell's error bound: 1.5 times the largest
interpolation error measured at the centres of the cell and its six neighbours against the
exact distance there (the centres are a second grid treated like the nodes). Near a smooth
surface that bound is some 0.02 mm; near a sharp feature (an eyelid, an ear's rim) it grows
to a millimetre or two, and hair keeps that much more clear of it. Measured against the
exact distance, no point within 1 mm of either head was put more than 0.03 mm nearer than
it is. `signed_distance` is the exact form, for checks and reports. Building the grid takes
about a second (the bundled head 1 s, the USC head 2 s on two cores); `collider_for` keeps
the last few, so regenerating on the same head does not pay it again.

Resolution (`resolve_strands`), root to tip, each strand on its own (so a strand's result
never depends on which others are computed with it: incremental regeneration stays
bit-identical). Point k must end at least its clearance outside, radius_k + margin (near a
root that the scalp puts inside the collider, less: the clearance rises from the root's own
depth by half the distance from the root, so the hair may leave at 30°). Points before the
first one too close stay as they are. From there each segment keeps its length and, where it
can, its direction, so the rest of the strand follows by translation; a segment that would
end too close turns about its start toward the surface's outward direction, by the least
angle that clears it (its end and its middle). Where that does not clear it (a crease, as
between an ear and the skull), the worse of its end and middle is moved out along its own
outward direction and the segment aimed through it; failing that, the clearing direction
nearest its own of 200 spread over the sphere. A segment never turns away from the one
before by more than the strand's sharpest original bend (or 20°, for a straight strand),
unless that is the only way out; so a strand let go by the surface bends back toward its own
direction gradually instead of kinking. The root never moves.
"""
import hashlib
import threading
import time
import weakref
from collections import OrderedDict
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from hairio import InputError

from .parallel import cpu_threads, free_memory, ranges, run_jobs
from .scalp import Scalp, _closest_on_triangles

# Points _locate takes all three axes of at once (see there).
_LOCATE_ROWS = 4096
# Grid nodes of the sampled distance (memory: 3 float32 per node, 24 MB).
_TARGET_NODES = 2_000_000
# The band of exact distances, in cells: a point of a cell closer to the surface than its
# clearance (a fraction of a cell) has all 8 corners within sqrt(3) cells of it, so inside
# the band: its interpolated distance is made of exact values.
_BAND_CELLS = 2.0
# Cell centres are sampled this near the surface: any point within a fifth of a cell of it
# (clearances are smaller) lies in a cell whose centre is this near, and every corner of
# such a cell is within 1.1 + sqrt(3)/2 < 2 cells, inside the band: exact.
_CENTRE_CELLS = 1.1
# For a clearance of c cells the band reaches c + this (the corners of a cell within c of the
# surface lie within c + sqrt(3) cells of it, rounded up), the cell centres c + the other.
_BAND_BEYOND, _CENTRE_BEYOND = 1.8, 0.9
# The error bound per cell: this times the largest interpolation error at the centres of the
# cell and its six neighbours (_neighbourhood_max), plus this fraction of a cell (the error
# elsewhere in a cell can exceed that at the centres a little).
_ERROR_SAFETY = 1.5
_ERROR_FLOOR = 1e-3
# Triangles per block of the node visits (bounds the (triangle, node) pairs held at once).
_PAIR_BLOCK = 1 << 21
# Faces with less area than this (relative to the mesh's size squared) have no direction.
_DEGENERATE_AREA = 1e-14
# The clearance near a root inside the collider rises by this per unit distance from it.
RAMP_SLOPE = 0.5
# A segment turns from the one before by at most the strand's sharpest bend or this (cosine
# of 20°), unless it must turn more to clear the collider.
_MIN_TURN_COS = float(np.cos(np.radians(20.0)))
# Attempts at each of the two ways of clearing a segment (see _push_out), and how far past
# the clearance each aims (of a cell: 2 µm on the bundled head), so the tries converge.
_PUSH_ITERATIONS = 5
_OVERSHOOT = 1e-3


def _fibonacci_sphere(n):
    """n unit directions spread evenly over the sphere (a golden-angle spiral)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    r = np.sqrt(1.0 - z * z)
    a = np.pi * (3.0 - np.sqrt(5.0)) * k
    return np.stack([r * np.cos(a), r * np.sin(a), z], 1)


# The last resort of _push_out: directions 15° apart.
_SEARCH_DIRECTIONS = _fibonacci_sphere(200)
# Strands walked together at most (see resolve_strands), and at least where there are more
# (the walk goes point by point: two parts of fewer strands each pay its steps' overhead, and
# only take more CPU time, measured at 10,000 strands of wavy).
_WALK_PART = 8192
_MIN_WALK_PART = 2048
# Points a strand's translated rest is checked ahead at a time (_first_offence), the first
# few of them on their own.
_CHECK_AHEAD = 16
_CHECK_FIRST = 4
# Samples along each key strand when looking for keys inside the collider, and how deep
# (of the collider's size: 1 mm on the bundled head) a key may dip before it is reported.
_KEY_CHECK_SAMPLES = 257
_KEY_DEPTH = 0.005
# More than this share of the scalp's area farther than `band` from the collider: it is not
# this scalp's head.
_FAR_SCALP_SHARE = 0.5


class Collider:
    """A triangle mesh hair must stay outside of.

    vertices (V,3), triangles (T,3) vertex indices; `name` names the mesh in messages (e.g.
    the Blender object's name). Bad input is an InputError naming it: NaN/Inf vertices, no
    faces, faces of no area, faces that disagree about which side is outside.

    closed: every edge between exactly two faces. band: the distance (scene units) within
    which the sampled distance is exact. size: the mesh's largest extent."""

    def __init__(self, vertices, triangles, name="collider", clearance=0.0):
        self.name = str(name)
        v = np.asarray(vertices)
        if v.ndim != 2 or v.shape[1:] != (3,) or len(v) == 0 or v.dtype.kind not in "fiu":
            raise InputError(f"collider {self.name!r}: expected vertices of shape (V, 3) with V >= 1, got "
                             f"{v.shape} of {v.dtype}")
        v = v.astype(np.float64)
        bad = ~np.isfinite(v).all(axis=1)
        if bad.any():
            raise InputError(f"collider {self.name!r}: vertex {int(np.argmax(bad))} has NaN/Inf coordinates "
                             f"({int(bad.sum())} such vertices); repair the mesh or choose another collider")
        t = np.asarray(triangles)
        if t.ndim != 2 or t.shape[1:] != (3,) or len(t) == 0:
            raise InputError(f"collider {self.name!r}: no faces (triangles of shape {t.shape}); a collider "
                             "needs a closed triangle mesh such as a head, not only vertices")
        if t.dtype.kind not in "iu":
            raise InputError(f"collider {self.name!r}: expected integer vertex indices, got {t.dtype}")
        t = t.astype(np.int64)
        if t.min() < 0 or t.max() >= len(v):
            raise InputError(f"collider {self.name!r}: faces refer to vertices outside [0, {len(v) - 1}]")
        a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
        size = float(np.ptp(v[np.unique(t)], axis=0).max())
        area2 = np.linalg.norm(np.cross(b - a, c - a), axis=1)
        keep = area2 > 2.0 * _DEGENERATE_AREA * max(size, 1e-300) ** 2
        if not keep.any():
            raise InputError(f"collider {self.name!r}: its faces have no area; a collider needs a surface")
        self.vertices, self.triangles = v, t[keep]
        self.size = size
        self.closed = self._orient()
        self._pseudo_normals()
        clearance = float(clearance)
        if not (np.isfinite(clearance) and clearance >= 0):
            raise InputError(f"collider {self.name!r}: clearance must be a finite distance >= 0, got {clearance}")
        self._build_field(clearance)
        free_memory()

    # --- the mesh ---------------------------------------------------------------------------

    def _orient(self):
        """Closed or not; a closed mesh is turned outward-facing (positive volume)."""
        t = self.triangles
        directed = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
        key = np.sort(directed, axis=1)
        edges, inverse, uses = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        inverse = inverse.ravel()
        self._edge_uses = uses
        self._tri_edges = inverse.reshape(3, -1).T  # edge ids of (v0v1, v1v2, v2v0)
        if not (uses == 2).all():
            return False
        # Each edge used twice must be used once in each direction by consistent faces.
        forward = (directed[:, 0] < directed[:, 1]).astype(np.int64)
        per_edge = np.bincount(inverse, weights=forward, minlength=len(edges))
        flipped = int((per_edge != 1).sum())
        if flipped:
            raise InputError(f"collider {self.name!r}: a closed mesh whose faces disagree about which side is "
                             f"outside ({flipped} edges run the same way in both their faces); recalculate its "
                             "normals (in Blender: Mesh > Normals > Recalculate Outside)")
        centre = self.vertices.mean(axis=0)
        a, b, c = (self.vertices[t[:, i]] - centre for i in range(3))
        if np.einsum("td,td->t", a, np.cross(b, c)).sum() < 0:
            self.triangles = t[:, ::-1].copy()
            return self._orient()
        return True

    def _pseudo_normals(self):
        """Face normals, and angle-weighted pseudo-normals of edges and vertices
        (Bærentzen & Aanæs); border features of an open mesh are flagged."""
        v, t = self.vertices, self.triangles
        p = [v[t[:, i]] for i in range(3)]
        n = np.cross(p[1] - p[0], p[2] - p[0])
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        self.face_normals = n
        edge_n = np.zeros((len(self._edge_uses), 3))
        for i in range(3):
            np.add.at(edge_n, self._tri_edges[:, i], n)
        vert_n = np.zeros_like(v)
        for i in range(3):
            e1, e2 = p[(i + 1) % 3] - p[i], p[(i + 2) % 3] - p[i]
            cos = np.einsum("td,td->t", e1, e2) / (np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1))
            np.add.at(vert_n, t[:, i], np.arccos(np.clip(cos, -1.0, 1.0))[:, None] * n)
        self._edge_normals, self._vertex_normals = edge_n, vert_n
        border_edge = self._edge_uses == 1
        border_vertex = np.zeros(len(v), bool)
        if border_edge.any():
            # The vertices of border edges: from the faces that use them.
            for i in range(3):
                on = border_edge[self._tri_edges[:, i]]
                border_vertex[t[on, i]] = True
                border_vertex[t[on, (i + 1) % 3]] = True
        self._border_edge, self._border_vertex = border_edge, border_vertex

    def _signs(self, points, tri, bary):
        """+1 outside, -1 inside, for points whose nearest surface point is (tri, bary)."""
        t = self.triangles[tri]
        zero = bary == 0.0
        nz = zero.sum(axis=1)
        normal = self.face_normals[tri].copy()
        border = np.zeros(len(tri), bool)
        edge = nz == 1  # on the edge opposite the zero corner: v1v2 (0), v2v0 (1), v0v1 (2)
        if edge.any():
            which = np.array([1, 2, 0])[np.argmax(zero[edge], axis=1)]
            e = self._tri_edges[tri[edge], which]
            normal[edge] = self._edge_normals[e]
            border[edge] = self._border_edge[e]
        vert = nz == 2
        if vert.any():
            corner = t[vert, np.argmax(~zero[vert], axis=1)]
            normal[vert] = self._vertex_normals[corner]
            border[vert] = self._border_vertex[corner]
        q = np.einsum("nd,nd->n", points - self.surface_points(tri, bary), normal)
        return np.where((q >= 0) | border, 1.0, -1.0)

    def surface_points(self, tri, bary):
        v, t = self.vertices, self.triangles[tri]
        return bary[:, :1] * v[t[:, 0]] + bary[:, 1:2] * v[t[:, 1]] + bary[:, 2:] * v[t[:, 2]]

    def signed_distance(self, points, chunk=1 << 14):
        """Exact signed distance (N,) float64 of points (N,3), positive outside (on an open
        mesh, see the module's notes). Near the surface the candidates are the triangles
        within `band` of the point's nearest grid node, which hold every triangle within
        band - sqrt(3)/2 cells of the point; farther points are searched among all triangles
        (Scalp.closest_points). For checks and reports; generation uses `value`."""
        q = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        out = np.empty(len(q))
        for lo in range(0, len(q), chunk):  # bounded (point, candidate) pairs
            out[lo:lo + chunk] = self._signed_distance(q[lo:lo + chunk])
        return out

    def _signed_distance(self, q):
        start, tris = self._node_triangles()
        g = np.rint((q - self.origin) / self.cell).astype(np.int64)
        inside = ((g >= 0) & (g < np.array(self.shape))).all(axis=1)
        node = np.clip(g, 0, np.array(self.shape) - 1) @ self._strides
        n_cand = np.where(inside, start[node + 1] - start[node], 0)
        query = np.repeat(np.arange(len(q)), n_cand)
        cand = tris[np.repeat(start[node] - (np.cumsum(n_cand) - n_cand), n_cand) + np.arange(int(n_cand.sum()))]
        v, t = self.vertices, self.triangles
        bary = _closest_on_triangles(q[query], v[t[cand, 0]], v[t[cand, 1]], v[t[cand, 2]])
        d2 = ((q[query] - self.surface_points(cand, bary)) ** 2).sum(axis=1)
        order = np.lexsort((cand, d2, query))
        first = order[np.r_[True, query[order][1:] != query[order][:-1]]] if len(order) else order
        tri = np.full(len(q), -1)
        b = np.zeros((len(q), 3))
        dist = np.full(len(q), np.inf)
        tri[query[first]], b[query[first]], dist[query[first]] = cand[first], bary[first], np.sqrt(d2[first])
        far = dist > self.band - 0.87 * self.cell  # beyond what the node's list surely holds
        if far.any():
            tri[far], b[far], near = self._mesh().closest_points(q[far])
            dist[far] = np.linalg.norm(q[far] - near, axis=1)
        s = self._signs(q, tri, b)
        if not self.closed:
            s = np.where((s < 0) & (dist > self.band), 1.0, s)
        return s * dist

    def _node_triangles(self):
        """CSR lists (start (nodes + 1,), triangles) of the triangles within band of each
        node, made on first use (the build keeps only each node's nearest)."""
        if getattr(self, "_near_lists", None) is None:
            pairs = []
            self._sample_exact(np.zeros(3), np.array(self.shape), self.band, pairs)
            flat = np.concatenate([f for f, _ in pairs])
            key = np.concatenate([k for _, k in pairs])
            d = np.sqrt((key >> np.uint64(32)).astype(np.uint32).view(np.float32).astype(np.float64))
            tri = (key & np.uint64(0xFFFFFFFF)).astype(np.int64)
            # A point within sqrt(3)/2 cells of the node has its nearest triangle within
            # sqrt(3) cells plus the node's own nearest distance of the node: the rest can go.
            nearest = np.full(int(np.prod(self.shape)), np.inf)
            np.minimum.at(nearest, flat, d)
            keep = d <= nearest[flat] + 1.75 * self.cell
            flat, tri = flat[keep], tri[keep]
            order = np.argsort(flat, kind="stable")
            start = np.zeros(int(np.prod(self.shape)) + 1, np.int64)
            np.cumsum(np.bincount(flat, minlength=len(start) - 1), out=start[1:])
            self._near_lists = (start, tri[order])
        return self._near_lists

    def _mesh(self):
        if getattr(self, "_as_scalp", None) is None:
            self._as_scalp = Scalp(self.vertices, self.triangles)
        return self._as_scalp

    # --- the sampled distance ---------------------------------------------------------------

    def _build_field(self, clearance):
        a, b, c = (self.vertices[self.triangles[:, i]] for i in range(3))
        lo = np.minimum(np.minimum(a, b), c).min(axis=0)
        hi = np.maximum(np.maximum(a, b), c).max(axis=0)
        extent = np.maximum(hi - lo, 1e-9 * max(self.size, 1e-300))
        h = float(np.cbrt(np.prod(extent) / _TARGET_NODES))
        for _ in range(3):  # the padding depends on the cell
            h = max(h, float(extent.max()) / 1000.0)
            h = float(np.cbrt(np.prod(extent + 2 * (_BAND_CELLS + 2.0) * h) / _TARGET_NODES))
        # Wide enough that every corner of a cell holding a point closer than the clearance
        # is exact (see _BAND_CELLS), and so are the centres of such cells.
        band_cells = max(_BAND_CELLS, clearance / h + _BAND_BEYOND)
        centre_cells = max(_CENTRE_CELLS, clearance / h + _CENTRE_BEYOND)
        pad = (band_cells + 2.0) * h
        self.cell, self.band = h, band_cells * h
        # The clearance this field serves: the largest for which the two lines above give the
        # same band (one made for none serves a fifth of a cell, 0.33 mm on the bundled head,
        # more than the shipped hair needs), so that a Generate does not build it again.
        self.clearance = max(clearance, min(band_cells - _BAND_BEYOND, centre_cells - _CENTRE_BEYOND) * h)
        self.origin = lo - pad
        shape = np.ceil((extent + 2 * pad) / h).astype(np.int64) + 1
        self.shape = tuple(int(s) for s in shape)
        self._strides = np.array([shape[1] * shape[2], shape[2], 1], np.int64)
        self._corner_offsets = np.array([dx * self._strides[0] + dy * self._strides[1] + dz
                                         for dx in (0, 1) for dy in (0, 1) for dz in (0, 1)], np.int64)
        # (3, 1) columns for _locate's and _cells' (3, N) rows: the origin, and the last
        # cell's coordinates along each axis (the cells' upper clamp).
        self._origin_column = self.origin[:, None].copy()
        self._upper_cell = shape.astype(np.float64)[:, None] - 2
        phi = self._sample_exact(np.zeros(3), shape, self.band)
        inside = self._parity(shape) if self.closed else np.zeros(self.shape, bool)
        far = np.isnan(phi)
        phi[far] = np.where(inside[far], -self.band, self.band)
        self.phi = phi.ravel().astype(np.float32)
        # Cell centres: a grid offset by half a cell, one centre per cell (C order).
        centre = self._sample_exact(np.full(3, 0.5), shape - 1, centre_cells * h).ravel()
        i, j, k = np.meshgrid(*(np.arange(s - 1) for s in shape), indexing="ij")
        base = (i * self._strides[0] + j * self._strides[1] + k).ravel()
        del i, j, k
        total = np.zeros(len(base), np.float32)
        low = np.full(len(base), np.inf, np.float32)
        for dx in (0, 1):
            for dy in (0, 1):
                for dz in (0, 1):
                    corner = self.phi[base + dx * self._strides[0] + dy * self._strides[1] + dz]
                    total += corner
                    np.minimum(low, corner, out=low)
        err = np.abs(total / np.float32(8.0) - centre)
        err = _neighbourhood_max(np.where(np.isnan(centre), 0.0, err).reshape(tuple(shape - 1)).astype(np.float32))
        # Per cell, stored at its lowest corner's node index (the index a query finds).
        self.cell_error = np.zeros(self.phi.shape, np.float32)
        self.cell_error[base] = _ERROR_SAFETY * err + _ERROR_FLOOR * h
        # The least value any point of a cell can have: a first test for many points at once.
        self.cell_lower = np.zeros(self.phi.shape, np.float32)
        self.cell_lower[base] = low - self.cell_error[base]

    def _sample_exact(self, offset, shape, reach, pairs=None):
        """Signed distance at the nodes origin + (index + offset)·cell of a grid of `shape`,
        exact within `reach` of the surface, NaN elsewhere. For each block of triangles the
        nodes in its box grown by reach are visited (after a cheap test against the
        triangle's plane), blocks on the worker threads; each node keeps its nearest
        triangle, whose nearest feature then gives the sign. `pairs`: a list that receives
        every (node, triangle) within reach, for the exact search (signed_distance)."""
        h = self.cell
        org = self.origin + offset * h
        strides = np.array([shape[1] * shape[2], shape[2], 1], np.int64)
        v = self.vertices - org  # relative coordinates: float32 keeps 1e-7 of the box
        t = self.triangles
        a, b, c = (v[t[:, i]] for i in range(3))
        tlo = np.clip(np.ceil((np.minimum(np.minimum(a, b), c) - reach) / h).astype(np.int64), 0, shape - 1)
        thi = np.clip(np.floor((np.maximum(np.maximum(a, b), c) + reach) / h).astype(np.int64), -1, shape - 1)
        # Boxes rounded up to even sizes: fewer shapes, so fewer and larger blocks of work.
        dims = np.maximum(thi - tlo + 1, 0)
        dims = np.where(dims > 0, dims + (dims & 1), 0)
        geom = _TriangleGeometry(a, b, c)
        # Triangles grouped by the shape of their box of nodes: each group's pairs are a
        # broadcast of its boxes' corners and one table of offsets, with each triangle's
        # constants broadcast over its nodes (no per-pair gathers).
        shapes, group = np.unique(dims, axis=0, return_inverse=True)
        group = group.ravel()
        jobs = []
        for gi, dim in enumerate(shapes):
            n_box = int(np.prod(dim))
            if not n_box:
                continue
            members = np.flatnonzero(group == gi)
            step = max(1, _PAIR_BLOCK // n_box)
            for lo in range(0, len(members), step):
                jobs.append((members[lo:lo + step], dim))
        r2 = np.float32(reach * reach)
        limit = shape - 1

        def visit(tris, dim):
            """(node, key) of the pairs within reach: key orders by squared distance, then
            triangle index (a positive float32's bits sort as integers)."""
            offs = np.stack(np.meshgrid(*(np.arange(x) for x in dim), indexing="ij"), -1).reshape(-1, 3)
            node = tlo[tris][:, None, :] + offs[None]
            d2 = geom.distance2_boxes(tris, (node * h).astype(np.float32))
            keep = (d2 <= r2) & (node <= limit).all(axis=2)
            tri = np.broadcast_to(tris[:, None], keep.shape)[keep]
            key = (d2[keep].view(np.uint32).astype(np.uint64) << np.uint64(32)) | tri.astype(np.uint64)
            return node[keep] @ strides, key

        n_nodes = int(np.prod(shape))
        best = np.full(n_nodes, np.iinfo(np.uint64).max, np.uint64)
        for flat, key in (visit(tris, dim) for tris, dim in jobs):  # threads only slowed it (measured)
            np.minimum.at(best, flat, key)  # the nearest triangle, the lowest index on a tie
            if pairs is not None:
                pairs.append((flat, key))
        best_tri = np.where(best == np.iinfo(np.uint64).max, -1,
                            (best & np.uint64(0xFFFFFFFF)).astype(np.int64))
        found = np.flatnonzero(best_tri >= 0)
        out = np.full(n_nodes, np.nan)
        if found.size:
            idx = np.stack(np.unravel_index(found, tuple(shape)), 1)
            pts = org + idx * h
            tri = best_tri[found]
            pa, pb, pc = (self.vertices[self.triangles[tri, i]] for i in range(3))
            bary = _closest_on_triangles(pts, pa, pb, pc)
            near = bary[:, :1] * pa + bary[:, 1:2] * pb + bary[:, 2:] * pc
            out[found] = self._signs(pts, tri, bary) * np.linalg.norm(pts - near, axis=1)
        return out.reshape(tuple(shape))

    def _parity(self, shape):
        """Inside (odd number of surface crossings above) per node, along z lines shifted by
        an irrational sliver of a cell so that no line meets an edge or a vertex exactly."""
        h = self.cell
        shift = np.array([np.sqrt(2.0) - 1.0, np.sqrt(3.0) - 1.0]) * 1e-4 * h
        v = self.vertices - self.origin
        t = self.triangles
        a, b, c = (v[t[:, i]] for i in range(3))
        xy_lo = np.minimum(np.minimum(a, b), c)[:, :2]
        xy_hi = np.maximum(np.maximum(a, b), c)[:, :2]
        ilo = np.clip(np.ceil((xy_lo - shift) / h).astype(np.int64), 0, np.array(shape[:2]) - 1)
        ihi = np.clip(np.floor((xy_hi - shift) / h).astype(np.int64), -1, np.array(shape[:2]) - 1)
        dims = np.maximum(ihi - ilo + 1, 0)
        count = dims.prod(axis=1)
        tri = np.repeat(np.arange(len(t)), count)
        local = np.arange(len(tri)) - np.repeat(np.cumsum(count) - count, count)
        ix = local // dims[tri, 1] + ilo[tri, 0]
        iy = local % dims[tri, 1] + ilo[tri, 1]
        x, y = ix * h + shift[0], iy * h + shift[1]
        pa, pb, pc = a[tri], b[tri], c[tri]
        # 2-D barycentrics of the line's point in the triangle's shadow.
        det = (pb[:, 0] - pa[:, 0]) * (pc[:, 1] - pa[:, 1]) - (pc[:, 0] - pa[:, 0]) * (pb[:, 1] - pa[:, 1])
        ok = det != 0
        safe = np.where(ok, det, 1.0)
        u = ((pb[:, 0] - x) * (pc[:, 1] - y) - (pc[:, 0] - x) * (pb[:, 1] - y)) / safe
        w = ((pc[:, 0] - x) * (pa[:, 1] - y) - (pa[:, 0] - x) * (pc[:, 1] - y)) / safe
        hit = ok & (u >= 0) & (w >= 0) & (u + w <= 1)
        z = u * pa[:, 2] + w * pb[:, 2] + (1 - u - w) * pc[:, 2]
        # Nodes k <= kz lie below the crossing.
        kz = np.floor(z / h).astype(np.int64)
        hit &= kz >= 0
        kz = np.minimum(kz, shape[2] - 1)
        marks = np.zeros(shape, np.int32)
        np.add.at(marks, (ix[hit], iy[hit], kz[hit]), 1)
        above = np.cumsum(marks[:, :, ::-1], axis=2)[:, :, ::-1]
        return (above & 1).astype(bool)

    def _locate(self, p):
        """Cell base index (N,) and fractions (3, N) of points (N,3), float64. Points beyond the
        grid fall in its border cells, whose corners are all `band` outside (the padding), so
        they read as far outside with no gradient."""
        # The cell's coordinates stay floats (whole numbers: trunc of the clamped position,
        # exact) and make the flat index in float64 (exact below 2**53), cast once: the same
        # numbers as int64 arithmetic per axis. Up to _LOCATE_ROWS points the three axes go
        # through each call together, as (3, N) rows (the walk's many small calls pay numpy's
        # per-call cost a third as often); more points, one axis at a time (value hands it no
        # more than _LOCATE_ROWS).
        n_pts = len(p)
        frac = np.empty((3, n_pts))
        if n_pts <= _LOCATE_ROWS:
            np.subtract(p.T, self._origin_column, out=frac)
            frac *= 1.0 / self.cell
            cell = np.maximum(frac, 0)
            np.minimum(cell, self._upper_cell, out=cell)
            np.trunc(cell, out=cell)
            np.subtract(frac, cell, out=frac)
            np.maximum(frac, 0.0, out=frac)
            np.minimum(frac, 1.0, out=frac)
            base = cell[0] * self.shape[1]
            base += cell[1]
            base *= self.shape[2]
            base += cell[2]
            return base.astype(np.int64), frac
        for axis in range(3):
            np.subtract(p[:, axis], self.origin[axis], out=frac[axis])
        frac *= 1.0 / self.cell
        cell = np.empty(n_pts)
        base = np.zeros(n_pts)
        for axis, n in enumerate(self.shape):
            g = frac[axis]
            # np.maximum/np.minimum: np.clip's wrappers cost more than its work on the walk's
            # small arrays (the same numbers).
            np.maximum(g, 0, out=cell)
            np.minimum(cell, n - 2, out=cell)
            np.trunc(cell, out=cell)
            np.subtract(g, cell, out=g)
            np.maximum(g, 0.0, out=g)
            np.minimum(g, 1.0, out=g)
            base *= n
            base += cell
        return base.astype(np.int64), frac

    def clear_of(self, points, clearance):
        """True where a point is certainly at least `clearance` outside: one look-up per point
        of the lowest value its cell can hold, in the points' own precision (float32 points:
        a cell found off by a rounding is a neighbour, whose bound differs by less than the
        1e-6 of a cell added to the clearance). False means 'look closer' (`value`). Points
        beyond the grid fall in its border cells, which are all clear (the grid's padding)."""
        return self.cell_lower[self._cells(points)] >= self._threshold(clearance)

    def _threshold(self, clearance):
        """What a cell's lower bound must reach for `clearance` (see clear_of)."""
        return clearance + 1e-6 * self.cell

    def _cells(self, points):
        """Flat index (N,) of the cell each point falls in (clear_of), in int32 (the grid has
        some 2 M nodes), on coordinate rows: the three as (3, N) up to _LOCATE_ROWS points
        (fewer calls), one column at a time beyond (a whole (N, 3) array less a (3,) origin
        runs numpy's loops 3 items long, several times slower)."""
        p = np.asarray(points)
        dt = p.dtype if p.dtype in (np.float32, np.float64) else np.float64
        origin = self.origin.astype(dt)
        inv = dt.type(1.0 / self.cell)
        n = len(p)
        itype = np.int32 if len(self.phi) < 2 ** 31 else np.int64
        if n <= _LOCATE_ROWS:
            # The three axes through each call together (as in _locate), the same numbers.
            col = np.empty((3, n), dt)
            np.subtract(p.T, origin[:, None], out=col, dtype=dt)
            col *= inv
            np.maximum(col, 0, out=col)
            np.minimum(col, self._upper_cell.astype(dt), out=col)
            i = col.astype(itype)   # truncation = floor, col >= 0
            idx = i[0] * itype(self.shape[1])
            idx += i[1]
            idx *= itype(self.shape[2])
            idx += i[2]
            return idx
        idx, i, col = np.empty(n, itype), np.empty(n, itype), np.empty(n, dt)
        for axis, m in enumerate(self.shape):
            np.subtract(p[:, axis], origin[axis], out=col, dtype=dt)
            col *= inv
            # One clip, not a maximum and a minimum: half the passes (the same numbers).
            np.clip(col, 0, m - 2, out=col)
            if axis:
                idx *= m
                np.copyto(i, col, casting="unsafe")   # truncation = floor, col >= 0
                idx += i
            else:
                np.copyto(idx, col, casting="unsafe")
        return idx

    def lower_within(self, reach):
        """Per cell (at clear_of's index) the least lower bound of the cells within `reach`
        cells of it along each axis: a point whose cell's value here clears it has every
        point within `reach` - 1 cells of it (a segment's middle) clear too, with one look-up
        for both. Made on first use and kept (8 MB)."""
        made = self.__dict__.setdefault("_lower_within", {})
        if reach not in made:
            shape = self.shape
            cells = self.cell_lower.reshape(shape)[:shape[0] - 1, :shape[1] - 1, :shape[2] - 1]
            low = np.array(cells)
            for axis in range(3):
                step = low.copy()
                for shift in range(1, reach + 1):
                    lo, hi = [slice(None)] * 3, [slice(None)] * 3
                    lo[axis], hi[axis] = slice(0, -shift), slice(shift, None)
                    np.minimum(step[tuple(lo)], low[tuple(hi)], out=step[tuple(lo)])
                    np.minimum(step[tuple(hi)], low[tuple(lo)], out=step[tuple(hi)])
                low = step
            out = np.zeros(self.cell_lower.shape, np.float32)
            out.reshape(shape)[:shape[0] - 1, :shape[1] - 1, :shape[2] - 1] = low
            made[reach] = out
        return made[reach]

    def value(self, points, gradient=False):
        """The sampled signed distance less its error bound (N,) float64: the true distance is
        at least this within the band. With gradient: also the interpolant's gradient (N,3)."""
        p = np.asarray(points, dtype=np.float64)
        if len(p) <= _LOCATE_ROWS:
            return self._value(p, gradient)
        # Blocks of at most _LOCATE_ROWS points (of equal size): larger (8, N) temporaries
        # outgrow the allocator's reused blocks and pay page faults (3 times slower at 8,000).
        val, grad = np.empty(len(p)), np.empty((len(p), 3)) if gradient else None
        step = -(-len(p) // -(-len(p) // _LOCATE_ROWS))
        for lo in range(0, len(p), step):
            part = self._value(p[lo:lo + step], gradient)
            if gradient:
                val[lo:lo + step], grad[lo:lo + step] = part
            else:
                val[lo:lo + step] = part
        return (val, grad) if gradient else val

    def _value(self, p, gradient):
        """value of at most _LOCATE_ROWS points p (float64)."""
        base, f = self._locate(p)
        fx, fy, fz = f
        # The 8 corners (dx, dy, dz) in rows 4dx+2dy+dz, gathered in one take of (8, N)
        # indices: contiguous rows, and the interpolation along z (then y) runs on the four
        # (two) pairs of rows at once: the same numbers as pair by pair, in fewer calls.
        idx = np.add.outer(self._corner_offsets, base)
        c = self.phi.take(idx).astype(np.float64)
        lo = c[0::2]
        dz = c[1::2] - lo               # c1-c0, c3-c2, c5-c4, c7-c6
        cz = lo + fz * dz               # c00, c01, c10, c11
        dy = cz[1::2] - cz[0::2]        # c01-c00, c11-c10
        cy = cz[0::2] + fy * dy         # c0, c1
        gx = cy[1] - cy[0]
        val = cy[0] + fx * gx
        val -= self.cell_error.take(base)
        if not gradient:
            return val
        gy = (1 - fx) * dy[0] + fx * dy[1]
        d0 = (1 - fy) * dz[0] + fy * dz[1]
        d1 = (1 - fy) * dz[2] + fy * dz[3]
        gz = (1 - fx) * d0 + fx * d1
        return val, np.stack([gx, gy, gz], 1) * (1.0 / self.cell)

    def outward(self, points):
        """Unit outward directions (N,3): the sampled distance's gradient, or away from the
        mesh's centre where that is flat (deep inside or far away)."""
        _, g = self.value(points, gradient=True)
        length = np.sqrt(_dot(g, g))
        flat = length < 0.1
        g /= np.where(flat, 1.0, length)[:, None]
        fl = _indices(flat)
        if fl.size:
            radial = points[fl] - 0.5 * (self.vertices.min(axis=0) + self.vertices.max(axis=0))
            r = np.sqrt(_dot(radial, radial))
            g[fl] = np.where(r[:, None] > 0, radial / np.where(r > 0, r, 1.0)[:, None], np.array([0.0, 0.0, 1.0]))
        return g


def _neighbourhood_max(a):
    """The largest value of each cell and its 6 face neighbours: a sharp feature between
    two cells' centres shows in one of them, not always in the cell a point falls in
    (measured on the USC head's eyes and ears: the cell's own error alone let points sit up
    to 0.36 mm closer than it said; with the neighbours, 0.03 mm)."""
    out = a.copy()
    for axis in range(3):
        lo, hi = [slice(None)] * 3, [slice(None)] * 3
        lo[axis], hi[axis] = slice(0, -1), slice(1, None)
        np.maximum(out[tuple(lo)], a[tuple(hi)], out=out[tuple(lo)])
        np.maximum(out[tuple(hi)], a[tuple(lo)], out=out[tuple(hi)])
    return out.ravel()


class _TriangleGeometry:
    """Per-triangle constants for many point-triangle distances (float32: relative
    coordinates inside the grid's box)."""

    def __init__(self, a, b, c):
        f = np.float32
        self.a = a.astype(f)
        self.ab, self.ac, self.bc = (b - a).astype(f), (c - a).astype(f), (c - b).astype(f)
        n = np.cross(b - a, c - a)
        self.n = (n / np.linalg.norm(n, axis=1, keepdims=True)).astype(f)
        d00 = np.einsum("td,td->t", b - a, b - a)
        d01 = np.einsum("td,td->t", b - a, c - a)
        d11 = np.einsum("td,td->t", c - a, c - a)
        inv = 1.0 / (d00 * d11 - d01 * d01)
        self.m = np.stack([d11 * inv, -d01 * inv, d00 * inv], 1).astype(f)
        self.len2 = np.stack([d00, d11, np.einsum("td,td->t", c - b, c - b)], 1).astype(f)

    def distance2_boxes(self, tris, p):
        """Squared distances (n, m) of triangles tris (n,) to points p (n, m, 3), each
        triangle's constants broadcast over its m points."""
        a, ab, ac, bc = (x[tris][:, None, :] for x in (self.a, self.ab, self.ac, self.bc))
        m = self.m[tris][:, None, :]
        n = self.n[tris][:, None, :]
        l2 = self.len2[tris][:, None, :]
        ap = p - a
        d20, d21 = _dot(ap, ab), _dot(ap, ac)
        v = m[..., 0] * d20 + m[..., 1] * d21
        w = m[..., 1] * d20 + m[..., 2] * d21
        plane = _dot(ap, n)
        inner = (v >= 0) & (w >= 0) & (v + w <= 1)
        edges = np.minimum(_segment2(ap, ab, d20, l2[..., 0]), _segment2(ap, ac, d21, l2[..., 1]))
        bp = ap - ab
        edges = np.minimum(edges, _segment2(bp, bc, _dot(bp, bc), l2[..., 2]))
        return np.where(inner, plane * plane, edges)


def _segment2(ap, ab, dot_ap_ab, len2):
    """Squared distance of points (relative to a) to the segments a→a+ab."""
    t = np.clip(dot_ap_ab / np.maximum(len2, np.float32(1e-30)), 0.0, 1.0).astype(ap.dtype)
    d = ap - t[..., None] * ab
    return _dot(d, d)


def _indices(mask):
    """np.flatnonzero of a 1-D mask, without its wrappers (the walk calls it thousands of
    times on small arrays)."""
    return mask.nonzero()[0]


def _dot3(u, v):
    """_dot of component-major (3, ...) arrays."""
    out = u[0] * v[0]
    out += u[1] * v[1]
    out += u[2] * v[2]
    return out


def _dot(u, v):
    """Row-wise dot products of (..., 3) arrays, summed x + y + z in that order, as
    (u * v).sum(axis=-1) does, at a third of its cost (numpy reduces 3-long rows slowly)."""
    return u[..., 0] * v[..., 0] + u[..., 1] * v[..., 1] + u[..., 2] * v[..., 2]


# --- colliders made once ------------------------------------------------------------------------

_CACHE = OrderedDict()
_CACHE_SIZE = 4
_CACHE_LOCK = threading.Lock()
_BUILDING = {}      # mesh digest -> (clearance, threading.Event set when that build ends)


def _mesh_key(vertices, triangles):
    """(vertices float64, triangles, digest) of a mesh, as collider_for keys it."""
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    t = np.ascontiguousarray(triangles)
    if t.dtype.kind in "iu":
        t = t.astype(np.int64)
    digest = hashlib.blake2b(v.tobytes() + b"|" + t.tobytes() + str(v.shape).encode(), digest_size=16).digest()
    return v, t, digest


def _cached(digest, clearance, name):
    """The cached collider of this mesh for at least `clearance`, named `name`, or None
    (with _CACHE_LOCK held)."""
    for key, hit in reversed(_CACHE.items()):
        if key[0] == digest and hit.clearance >= clearance:
            _CACHE.move_to_end(key)
            return hit if hit.name == str(name) else _renamed(hit, name)
    return None


def collider_for(vertices, triangles, name="collider", clearance=0.0):
    """A Collider for the mesh, made once per process for the same vertices and triangles
    and a clearance at least this large (building one takes about a second; a Generate that
    reruns on the same head reuses it). Where another thread is building it
    (prebuild_collider), waits for that build rather than making a second one; where that
    build failed, builds it here, so its error is raised here."""
    v, t, digest = _mesh_key(vertices, triangles)
    while True:
        hit, claim = _claim(digest, clearance, name)
        if hit is not None:
            return hit
        if claim[0]:
            return _build_claimed(v, t, name, clearance, digest, claim[1])
        claim[1].wait()


def _claim(digest, clearance, name):
    """(the cached collider, None), or (None, (True, event)): this caller builds it and sets
    event when done, or (None, (False, event)): another thread is building it."""
    with _CACHE_LOCK:
        hit = _cached(digest, clearance, name)
        if hit is not None:
            return hit, None
        pending = _BUILDING.get(digest)
        if pending is not None and pending[0] >= clearance:
            return None, (False, pending[1])
        done = threading.Event()
        _BUILDING[digest] = (clearance, done)
        return None, (True, done)


def _build_claimed(v, t, name, clearance, digest, done):
    try:
        made = Collider(v, t, name, clearance)
        with _CACHE_LOCK:
            _CACHE[(digest, clearance)] = made
            while len(_CACHE) > _CACHE_SIZE:
                _CACHE.popitem(last=False)
        return made
    finally:
        with _CACHE_LOCK:
            if _BUILDING.get(digest, (None, None))[1] is done:
                del _BUILDING[digest]
        done.set()


def prebuild_collider(vertices, triangles, name="collider", clearance=0.0, then=None):
    """Starts building collider_for(vertices, triangles, name, clearance) on a thread of its
    own and returns the thread (None where it is made or being made already): a caller who
    knows a collider will be wanted soon (Blender's Add Head: the preset loaded next places
    its keys with it) gets it built meanwhile (numpy leaves the interpreter free most of
    the time), and a collider_for of the same mesh waits for that build rather than making
    a second. An error of the build is not raised there: the collider_for that wants the
    collider builds it again and raises it. then: None or a callable given the collider
    on that thread once it is built (generate.prepare_workers); its errors are dropped,
    as it only prepares what a later run would otherwise do itself."""
    v, t, digest = _mesh_key(vertices, triangles)
    hit, claim = _claim(digest, clearance, name)
    if hit is not None or not claim[0]:
        return None

    def build():
        try:
            made = _build_claimed(v, t, name, clearance, digest, claim[1])
            if then is not None:
                then(made)
        except Exception:   # noqa: BLE001 -- raised again, with its message, where it is wanted
            pass
    thread = threading.Thread(target=build, name="groom-collider", daemon=True)
    thread.start()
    return thread


def _renamed(collider, name):
    """The same collider under another name (the arrays are shared, never changed)."""
    out = object.__new__(Collider)
    out.__dict__.update(collider.__dict__)
    out.name = str(name)
    return out


def with_clearance(collider, clearance):
    """`collider`, or the same mesh sampled with a band wide enough for `clearance`."""
    if collider.clearance >= clearance:
        return collider
    return collider_for(collider.vertices, collider.triangles, collider.name, 1.5 * clearance)


def default_collider():
    """The bundled head (scalp.default_head) as a Collider: what the bundled scalp lies on."""
    from .scalp import default_head
    head = default_head()
    return collider_for(head.vertices, head.triangles, "the bundled head")


def as_collider(mesh, name=None):
    """A Collider from a Collider (as it is), a groom.Scalp (a closed head mesh or the scalp
    itself) or a (vertices, triangles) pair."""
    if isinstance(mesh, Collider):
        return mesh
    if isinstance(mesh, Scalp):
        return collider_for(mesh.vertices, mesh.triangles, name or "collider")
    if isinstance(mesh, tuple) and len(mesh) == 2:
        return collider_for(mesh[0], mesh[1], name or "collider")
    raise InputError(f"collider: expected a groom.Collider, a groom.Scalp or (vertices, triangles), "
                     f"got {type(mesh).__name__}")


# --- checks before growing ----------------------------------------------------------------------

def check_scalp(collider, scalp):
    """InputError when the scalp is not on this collider: more than half of its area lies
    farther than `band` from the collider's surface (another object, moved or scaled)."""
    w = np.zeros(len(scalp.vertices))
    for i in range(3):
        np.add.at(w, scalp.triangles[:, i], scalp.face_areas)
    used = w > 0
    if not used.any():
        return
    d = collider.value(scalp.vertices[used]) + collider.cell_error[collider._locate(scalp.vertices[used])[0]]
    far = np.abs(d) >= collider.band * 0.999
    share = float(w[used][far].sum() / w[used].sum())
    if share > _FAR_SCALP_SHARE:
        where = "outside" if np.median(d[far]) > 0 else "inside"
        raise InputError(f"collider {collider.name!r}: {share:.0%} of the scalp lies more than "
                         f"{collider.band * 1e3:.1f} mm {where} it; a collider must be the head the scalp lies on "
                         "(is it another object, or moved or scaled away from the scalp?)")


@dataclass(frozen=True)
class KeyInside:
    """A key strand that passes through the collider: its index, how deep (scene units; at
    least `band` where it says deeper) and the span of its length inside (fractions)."""
    key: int
    depth: float
    span: tuple


def keys_inside(collider, tables, roots, radii):
    """[KeyInside] for keys whose sampled curve (tables: [(offsets (M,3), length)], roots
    (K,3)) goes deeper inside the collider than its radius or _KEY_DEPTH of the collider's
    size (a key drawn resting on the head dips in by its drawing's rounding), away from the
    root (a root the scalp puts inside the collider is the scalp's business: see
    resolve_strands)."""
    found = []
    for i, ((table, length), root, radius) in enumerate(zip(tables, roots, radii)):  # a few keys
        pts = root + table
        if not length > 0:
            continue
        v = collider.value(pts)
        from_root = np.linalg.norm(table, axis=1)
        allowed = np.minimum(-max(float(radius), _KEY_DEPTH * collider.size), v[0] + RAMP_SLOPE * from_root)
        inside = v < allowed
        inside[0] = False
        if inside.any():
            s = np.linspace(0.0, 1.0, len(pts))[inside]
            # The sampled distance is clamped past the band: the exact one says how deep.
            depth = -float(collider.signed_distance(pts[inside]).min())
            found.append(KeyInside(i, max(depth, 0.0), (float(s.min()), float(s.max()))))
    return found


def describe_keys_inside(name, found):
    """One sentence for an artist about keys inside the collider called `name`, or None."""
    if not found:
        return None
    parts = [f"key {k.key} ({k.depth * 1e3:.1f} mm deep, {k.span[0]:.0%}–{k.span[1]:.0%} of its length)" for k in found]
    return (f"collider {name!r}: " + ", ".join(parts) + " pass" + ("es" if len(found) == 1 else "")
            + " through it; the key is left as drawn (the hair it guides is moved out): move it out "
              "of the head if that is not what you meant")


# --- moving strands out -------------------------------------------------------------------------

@dataclass
class CollisionStats:
    """What resolve_strands did: strands / points tested, strands and points moved, the
    largest push (scene units) and points left closer than their clearance (0 unless the
    collider traps a segment: a narrow cleft). points_inside_before: points the first pass
    found deeper than their radius; it looks no further into a strand than its first few
    suspect points once one offends, so a lower bound (measure with signed_distance for
    the share inside)."""
    strands: int = 0
    points: int = 0
    strands_moved: int = 0
    points_moved: int = 0
    points_inside_before: int = 0
    largest_move: float = 0.0
    unresolved: int = 0
    # Seconds spent resolving, summed over the blocks (thread time: blocks grown side by side
    # overlap, so this can exceed the wall time it took). Not part of what a run did.
    seconds: float = field(default=0.0, compare=False)

    def add_walk(self, walked):
        """walk_into's (points moved, points unresolved, largest move) added to these."""
        self.points_moved += walked[0]
        self.unresolved += walked[1]
        self.largest_move = max(self.largest_move, walked[2])

    def add(self, other):
        for name in ("strands", "points", "strands_moved", "points_moved", "points_inside_before", "unresolved",
                     "seconds"):
            setattr(self, name, getattr(self, name) + getattr(other, name))
        self.largest_move = max(self.largest_move, other.largest_move)


def resolve_strands(collider, points, counts, radius, margin, threads=None, dtype=np.float32, in_place=False):
    """Strands moved out of the collider (see the module's notes): returns (points (P,3) of
    `dtype`, moved (S,) bool, CollisionStats). points (P,3), counts (S,), radius (P,) per
    point; margin in scene units; in_place: move `points` themselves (no copy of them). The
    strands are looked at in ranges on `threads` threads (first_pass), and those that must
    move are walked in parts (walk_into); each strand's numbers depend only on itself, never
    on its range or part (so the two steps may also run for shares of the strands in
    separate processes, groom.generate)."""
    counts = np.asarray(counts, np.int64)
    points, radius = np.asarray(points), np.asarray(radius)
    offsets = np.zeros(len(counts), np.int64)
    np.cumsum(counts[:-1], out=offsets[1:])
    out = points if in_place else np.array(points, dtype=dtype, copy=True)
    moved = np.zeros(len(counts), bool)
    stats = CollisionStats(strands=len(counts), points=int(counts.sum()))
    if not len(counts):
        return out, moved, stats
    strands, k0, root_value, stats.points_inside_before = first_pass(
        collider, points, offsets, counts, radius, margin, ranges(len(counts), threads), threads)
    if not strands.size:
        return out, moved, stats
    moved[strands], walked = walk_into(collider, out, points, offsets, counts, radius, margin, strands, k0,
                                       root_value, threads)
    stats.add_walk(walked)
    stats.strands_moved = int(moved.sum())
    return out, moved, stats


def first_pass(collider, points, offsets, counts, radius, margin, parts, threads=None):
    """The strands among the ranges `parts` [(lo, hi), ...] that must move: (their indices,
    the first point of each that is too close, their roots' sampled distance, points found
    deeper than their radius: CollisionStats.points_inside_before), the ranges looked at on
    `threads` threads."""
    found = run_jobs([partial(_offending, collider, points, offsets, counts, radius, margin, lo, hi)
                      for lo, hi in parts], threads)
    if not found:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), 0
    return (np.concatenate([f[0] for f in found]), np.concatenate([f[1] for f in found]),
            np.concatenate([f[2] for f in found]), sum(f[3] for f in found))


def walk_into(collider, out, points, offsets, counts, radius, margin, strands, k0, root_value, threads=None):
    """Walks `strands` (from first_pass) out of the collider, reading `points` and writing the
    points that move into `out` (which may be `points`: a strand reads only its own points):
    (moved (len(strands),) bool, (points moved, points unresolved, largest move)). One part
    per thread (parts of at least _MIN_WALK_PART), or parts of _WALK_PART strands when there
    are more (the walk goes point by point, and each part pays its steps' overhead once; the
    bound keeps its arrays to some 100 MB). Each part writes its strands' rows when it is
    done, so no part's arrays outlive it."""
    n_parts = max(min(-(-len(strands) // _MIN_WALK_PART), threads or cpu_threads()), -(-len(strands) // _WALK_PART))
    parts = [p for p in np.array_split(np.arange(len(strands)), n_parts) if len(p)]
    walked = run_jobs([partial(_walk_strands, collider, out, points, offsets, counts, radius, margin, strands[p],
                               k0[p], root_value[p]) for p in parts], threads)
    moved = np.zeros(len(strands), bool)
    points_moved, unresolved, largest = 0, 0, 0.0
    for part, (part_moved, part_points, part_unresolved, part_largest) in zip(parts, walked):
        moved[part] = part_moved
        points_moved += part_points
        unresolved += part_unresolved
        largest = max(largest, part_largest)
    return moved, (points_moved, unresolved, largest)


def _offending(collider, points, offsets, counts, radius, margin, lo, hi):
    """For strands lo..hi: (the strands that must move (global indices), the first point of
    each that is too close, their roots' sampled distance, points found deeper than their
    radius among those looked at closely: the first pass stops at a strand's first offence,
    so this counts the points inside up to there, not all of them)."""
    off, cnt = offsets[lo:hi], counts[lo:hi]
    first, stop = int(off[0]), int(off[-1] + cnt[-1])
    pts, rad = points[first:stop], radius[first:stop]
    off = off - first
    target = rad + np.float32(margin)
    none = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), 0)
    # A cheap look-up first, of the points and of the segments' middles (a long segment's
    # chord can dip into a convex head): most points are far from the head.
    look = ~_clear_with_middles(collider, pts, _half_segments(collider, pts, off), target,
                                lambda i: 0.5 * (_take(pts, i) + _take(pts, i - 1)))
    look[off] = False  # roots never move
    look = _indices(look)
    if not look.size:
        return none
    # A closer look at those, with the clearance near the root. `look` is in order, so are
    # the strands it falls in.
    strand_of = np.searchsorted(off, look, side="right") - 1
    new = np.empty(len(look), bool)
    new[0] = True
    np.not_equal(strand_of[1:], strand_of[:-1], out=new[1:])
    starts = _indices(new)
    suspect = strand_of[starts]
    which = np.cumsum(new) - 1
    roots = _take(pts, off[suspect]).astype(np.float64)
    root_value = collider.value(roots)
    at = look - off[suspect][which]     # the points' indices in their strands
    first_bad = np.full(len(suspect), np.iinfo(np.int64).max)
    inside = 0
    # Only each strand's first offence matters: its first _CHECK_FIRST suspect points are
    # looked at first, the others only for strands not yet found offending (most points
    # looked at closely lie inside the head: their strand is found in the first round).
    rank = np.arange(len(look)) - starts[which]
    first_round = rank < _CHECK_FIRST
    for rnd in range(2):
        sel = _indices(first_round if rnd == 0 else ~first_round & (first_bad[which] == np.iinfo(np.int64).max))
        if not sel.size:
            continue
        i, w = look[sel], which[sel]
        p = _take(pts, i).astype(np.float64)
        bad, at_end = _offends(collider, p, lambda j: 0.5 * (_take(p, j) + _take(pts, i[j] - 1)),
                               target[i].astype(np.float64), root_value[w], _take(roots, w))
        inside += int((at_end < -rad[i]).sum())
        _lower_to_first(first_bad, w[bad], at[sel][bad])
    hit = first_bad < np.iinfo(np.int64).max
    return lo + suspect[hit], first_bad[hit], root_value[hit], inside


# The reach of lower_within that clear_with_middles looks at: it holds the middles of
# segments up to 6 cells long (98 % of the shipped presets' on the bundled head); a larger
# one clears fewer points near the head.
_REACH = 3


def _half_segments(collider, pts, off):
    """Per point (N,) half the extent of the segment ending there along its longest axis, in
    cells (0 at the strands' roots, off): how far its middle lies from it."""
    half = np.zeros(len(pts), np.float32 if pts.dtype == np.float32 else np.float64)
    d = np.empty(max(len(pts) - 1, 0), half.dtype)
    for axis in range(3):
        np.subtract(pts[1:, axis], pts[:-1, axis], out=d)
        np.abs(d, out=d)
        np.maximum(half[1:], d, out=half[1:])
    half *= half.dtype.type(0.5 / collider.cell)
    half[off] = 0.0
    return half


def _clear_with_middles(collider, p, half, clearance, middles):
    """clear_of(p, clearance) & clear_of(middles(all), clearance) with one look-up per point
    where it can: a point whose cells within _REACH all clear it has its segment's middle
    clear too when that lies nearer than _REACH cells (half, from _half_segments; the cells
    of two points less than R cells apart differ by at most R along each axis, whatever the
    rounding of each). Only the others look at their own cell and their middle's (middles:
    a callable giving the middles of the points at the indices it is given)."""
    thr = collider._threshold(clearance)
    cells = collider._cells(p)
    # take: 1-D gathers by take cost less than by indexing.
    ok = collider.lower_within(_REACH).take(cells) >= thr
    ok &= half < _REACH - 0.01
    rest = _indices(~ok)
    if rest.size:
        lower = collider.cell_lower
        rest = rest[lower.take(cells.take(rest)) >= thr.take(rest)]   # the others are not clear (ok is False)
        ok[rest] = lower.take(collider._cells(middles(rest))) >= thr.take(rest)
    return ok


def _walk_strands(collider, out, points, offsets, counts, radius, margin, strands, k0, root_value):
    """Walks `strands` and writes the points that move into `out`: (which strands moved,
    points moved, unresolved points, largest move)."""
    cnt = counts[strands]
    rows = _flat_points(offsets[strands], cnt)
    original = _take(points, rows).astype(np.float64)
    target = radius[rows].astype(np.float64) + margin
    new, unresolved = _walk(collider, original, target, cnt, k0, root_value)
    del target
    step = original     # each point's move, in place of where it was
    step -= new
    move = np.sqrt(_dot(step, step))
    del original, step
    changed = move > 0
    ch = _indices(changed)
    out[rows[ch]] = _take(new, ch)
    return (np.logical_or.reduceat(changed, np.cumsum(cnt) - cnt), int(ch.size), unresolved,
            float(move.max()))


def _flat_points(off, cnt):
    """Flat indices of all points of strands starting at off with cnt points, in order."""
    starts = np.cumsum(cnt) - cnt
    return (off - starts).repeat(cnt) + np.arange(int(cnt.sum()))


def _clearance(target, root_value, p, root):
    """The clearance of points p: their target, or near a root inside the collider, the
    root's depth plus RAMP_SLOPE times the distance from the root."""
    r = p - root
    d = np.sqrt(_dot(r, r))
    return np.minimum(target, root_value + RAMP_SLOPE * d)


def _shortfall(collider, end, mid, target, root_value, root):
    """How far the end (or twice how far the middle) of a segment falls short of its
    clearance; <= 0 where it is clear (_offends: only whether it is)."""
    both = np.concatenate([end, mid]).reshape(2, len(end), 3)
    # The ends' and middles' clearances together (rows 0 and 1), the same numbers.
    lack = _clearance(target, root_value, both, root)
    lack -= collider.value(both.reshape(-1, 3)).reshape(2, -1)
    return np.maximum(lack[0], 2.0 * lack[1])


def _offends(collider, end, middles, target, root_value, root):
    """(_shortfall(...) > 0, the ends' sampled distances) of segments with ends `end`, their
    middles looked up only where the end is clear (middles: a callable giving the middles
    of the segments at the indices it is given): most segments looked at closely end inside
    the head, and an end too close says enough."""
    at_end = collider.value(end)
    bad = _clearance(target, root_value, end, root) - at_end > 0
    ok = _indices(~bad)
    if ok.size:
        mid = middles(ok)
        bad[ok] = _clearance(target[ok], root_value[ok], mid, _take(root, ok)) - collider.value(mid) > 0
    return bad, at_end


# Points _strand_measures takes at a time.
_MEASURE_POINTS = 16384


def _strand_measures(collider, pts, off, cnt):
    """_half_segments and _turn_limits of strands (pts strand after strand, off, cnt), made
    in blocks of whole strands of some _MEASURE_POINTS points: each strand's numbers are its
    own, and the blocks' temporaries stay in cache instead of passing over the whole part's
    points some twenty times (a third of the time)."""
    half = np.empty(len(pts))
    cos, sin = np.empty(len(cnt)), np.empty(len(cnt))
    ends = off + cnt
    cuts = np.unique(np.searchsorted(ends, np.arange(_MEASURE_POINTS, int(ends[-1]), _MEASURE_POINTS)))
    for s0, s1 in zip(np.concatenate([[0], cuts + 1]).tolist(), np.concatenate([cuts + 1, [len(cnt)]]).tolist()):
        if s0 >= s1:
            continue
        p0, p1 = int(off[s0]), int(ends[s1 - 1])
        block, o = pts[p0:p1], off[s0:s1] - p0
        half[p0:p1] = _half_segments(collider, block, o)
        cos[s0:s1], sin[s0:s1] = _turn_limits(block, o, cnt[s0:s1])
    return half, cos, sin


def _turn_limits(pts, off, cnt):
    """Per strand (cos, sin) of the largest turn a segment may make from the one before:
    the strand's sharpest original bend, at least 20°. pts holds the strands one after
    another (off, cnt)."""
    # One coordinate column at a time: einsum over (N, 3) rows runs its loops 3 items long.
    n = len(pts)
    seg = np.empty((3, max(n - 1, 0)))
    for axis in range(3):
        np.subtract(pts[1:, axis], pts[:-1, axis], out=seg[axis])
    l2 = _dot3(seg, seg)
    dots = _dot3(seg[:, :-1], seg[:, 1:])
    both = l2[:-1] * l2[1:]
    joint = np.ones(n)
    # joint[k]: the bend at point k, between the segments ending and starting there.
    ok = both > 0
    np.sqrt(both, out=both)
    np.divide(dots, both, out=joint[1:-1], where=ok)
    joint[off] = 1.0            # a root is no joint (the segment before it is another strand's)
    joint[off + cnt - 1] = 1.0  # nor is a tip
    cos = np.minimum(np.minimum.reduceat(joint, off), _MIN_TURN_COS)
    return cos, np.sqrt(np.maximum(0.0, 1.0 - cos * cos))


def _walk(collider, pts, target, cnt, k0, root_value):
    """The root-to-tip walk (see the module's notes) of strands whose points `pts` (float64,
    strand after strand, `cnt` each) and `target` clearances are given, from their first
    offending point k0. Returns (their points, same layout; points that could not be
    cleared)."""
    n = len(cnt)
    off = np.cumsum(cnt) - cnt
    result = pts.copy()
    half, cos_lim, sin_lim = _strand_measures(collider, pts, off, cnt)
    # The strands still walking, in order, each step all of them: their numbers packed in
    # rows (one take drops the finished ones) instead of gathered from and scattered back to
    # per-strand arrays by index every step. state: the last point placed, the direction of
    # the segment ending there, the root, the turn limits' cos and sin, the root's value.
    state = np.empty((n, _STATE))
    state[:, _ROOT] = _take(pts, off)
    state[:, _COS], state[:, _SIN] = cos_lim, sin_lim
    state[:, _RV] = root_value
    state[:, _PREV] = _take(pts, off + k0 - 1)
    u_prev = np.zeros((n, 3))
    have = k0 >= 2
    u_prev[have] = _unit(pts[off[have] + k0[have] - 1] - pts[off[have] + k0[have] - 2])
    state[:, _UPREV] = u_prev
    ints = np.stack([off, cnt, k0])     # first point, points, the point to place next
    # aligned: the strand so far is its original, translated; check: aligned after a step,
    # is the translated rest clear?
    flags = np.zeros((2, n), bool)
    flags[0] = True
    state, ints, flags = _still_walking(state, ints, flags)
    unresolved = 0
    while len(ints[0]):
        off, cnt, k = ints
        prev, rv, roots = state[:, _PREV], state[:, _RV], state[:, _ROOT]
        al = _indices(flags[1])
        if al.size:
            o, c, ka, p_al = off[al], cnt[al], k[al], _take(prev, al)
            jump = _first_offence(collider, pts, half, target, o, c, ka, p_al, rv[al], _take(roots, al))
            delta = p_al - _take(pts, o + ka - 1)
            _translate(result, pts, o, ka, jump, delta)
            k[al] = jump
            going = jump < c
            go = al[going]
            last = o[going] + jump[going] - 1
            _put(prev, go, _take(pts, last) + delta[going])
            _put(state[:, _UPREV], go, _unit(_take(pts, last) - _take(pts, last - 1)))
            flags[1] = False
            if not going.all():
                state, ints, flags = _still_walking(state, ints, flags)
                if not len(ints[0]):
                    break
                off, cnt, k = ints
                prev, rv, roots = state[:, _PREV], state[:, _RV], state[:, _ROOT]
        at = off + k
        d = _take(pts, at) - _take(pts, at - 1)
        length = np.sqrt(_dot(d, d))
        u = d / np.where(length > 0, length, 1.0)[:, None]
        up = state[:, _UPREV]
        c = _dot(u, up)
        # Back toward the strand's own direction, by no more than its sharpest bend.
        cos_lim = state[:, _COS]
        limited = ~flags[0] & (c < cos_lim) & (length > 0)
        u_new = u   # u is not needed after the limited turns are written
        if limited.any():
            li = _indices(limited)
            up_li = _take(up, li)
            w = _perpendicular_toward(up_li, _take(u, li), c[li])
            _put(u_new, li, cos_lim[li, None] * up_li + state[li, _SIN, None] * w)
        p0 = prev
        need = target.take(at)
        end = p0 + length[:, None] * u_new

        def mid(i):
            """The middles of segments i (only those looked at closely need them)."""
            return _take(p0, i) + 0.5 * length[i, None] * _take(u_new, i)
        # Only segments the cells' lower bounds do not clear get the closer look (the bound
        # clears a point for its target, so for the smaller clearance near a root too).
        short = np.full(len(at), -1.0)
        near = _indices(~_clear_with_middles(collider, end, length * (0.5 / collider.cell), need, mid))
        if near.size:
            short[near] = _shortfall(collider, _take(end, near), mid(near), need[near], rv[near], _take(roots, near))
        push = (short > 0) & (length > 0)
        if push.any():
            pi = _indices(push)
            p0_pi, len_pi = _take(p0, pi), length[pi]
            u_pi, left = _push_out(collider, p0_pi, _take(u_new, pi), len_pi, need[pi], rv[pi], _take(roots, pi),
                                   short[pi])
            _put(u_new, pi, u_pi)
            unresolved += left
            _put(end, pi, p0_pi + len_pi[:, None] * u_pi)
        placed = end   # the segments' ends as they now point
        _put(result, at, placed)
        state[:, _UPREV] = np.where((length > 0)[:, None], u_new, up)
        state[:, _PREV] = placed
        np.logical_not(push, out=flags[0])
        flags[0] &= ~limited
        flags[1] = flags[0]
        k += 1
        if (k >= cnt).any():
            state, ints, flags = _still_walking(state, ints, flags)
    return result, unresolved


# Columns of _walk's per-strand state.
_PREV, _UPREV, _ROOT = slice(0, 3), slice(3, 6), slice(6, 9)
_COS, _SIN, _RV = 9, 10, 11
_STATE = 12


def _still_walking(state, ints, flags):
    """The rows of the walk's state, ints (first point, points, next point) and flags of the
    strands with points left to place."""
    keep = _indices(ints[2] < ints[1])
    if len(keep) == len(ints[1]):
        return state, ints, flags
    return state.take(keep, axis=0), ints.take(keep, axis=1), flags.take(keep, axis=1)


def _put(a, i, v):
    """a[i] = v for rows of a C-contiguous (N, k) array `a` (or a column slice of one): as
    one put of whole rows (viewed as single items), three times faster than numpy's fancy
    indexing, which copies short rows item by item."""
    if not a.flags.c_contiguous:
        a[i] = v
        return
    row = np.dtype((np.void, a.itemsize * a.shape[1]))
    a.view(row).reshape(-1).put(i, np.ascontiguousarray(v, a.dtype).view(row).reshape(-1))


def _take(a, i):
    """a[i] for an index array i: rows of an (N, 3) array gathered by take, three times
    faster than indexing them (numpy's fancy indexing copies 3-long rows one at a time)."""
    return a.take(i, axis=0)


def _unit(v):
    n = np.sqrt(_dot(v, v))
    return v / np.where(n > 0, n, 1.0)[:, None]


def _perpendicular_toward(a, b, cos_ab):
    """Unit vectors perpendicular to a, in the plane of a and b, on b's side (some
    perpendicular where b is parallel to a)."""
    w = b - cos_ab[:, None] * a
    n = np.sqrt(_dot(w, w))
    bad = n < 1e-12
    if bad.any():
        e = np.eye(3)[np.argmin(np.abs(a[bad]), axis=1)]
        w[bad] = e - (e * a[bad]).sum(axis=1)[:, None] * a[bad]
        n[bad] = np.sqrt((w[bad] ** 2).sum(axis=1))
    return w / n[:, None]


def _push_out(collider, p0, u, length, target, root_value, root, short):
    """Directions that clear segments of `length` from p0. First u is turned toward the
    outward direction g at p0 (keeping u's side of g) by the least angle found: the cosine
    to g is raised by each try's shortfall over the length (the end rises by length per unit
    of it) until clear, at most to g itself. Where that is not enough (a crease, as behind
    an ear, where the way out is not g), the worse of the segment's end and middle is moved
    out along its own outward direction and the segment aimed through it, a few times.
    Returns (directions, how many are still short)."""
    g = collider.outward(p0)
    cos_ug = _dot(u, g)
    w = _perpendicular_toward(g, u, cos_ug)
    s = cos_ug.copy()
    out = u.copy()
    todo = np.arange(len(p0))
    for _ in range(_PUSH_ITERATIONS):
        s[todo] = np.minimum(s[todo] + (1.2 * short[todo] + _OVERSHOOT * collider.cell) / length[todo], 1.0)
        st = s[todo, None]
        out[todo] = st * _take(g, todo) + np.sqrt(np.maximum(0.0, 1.0 - st * st)) * _take(w, todo)
        t = todo
        p, o = _take(p0, t), _take(out, t)
        o *= length[t, None]    # the segment (0.5 times it is exact: its middle as before)
        short[t] = _shortfall(collider, p + o, p + 0.5 * o,
                              target[t], root_value[t], _take(root, t))
        todo = t[(short[t] > 0) & (s[t] < 1.0)]
        if not todo.size:
            break
    todo = _indices(short > 0)
    for _ in range(_PUSH_ITERATIONS):
        if not todo.size:
            break
        t = todo
        half = 0.5 * length[t, None]
        p, o = _take(p0, t), _take(out, t)
        o *= half
        end, mid = p + 2.0 * o, p + o
        v = collider.value(np.concatenate([end, mid]))
        n = len(t)
        lack_end = _clearance(target[t], root_value[t], end, _take(root, t)) - v[:n]
        lack_mid = _clearance(target[t], root_value[t], mid, _take(root, t)) - v[n:]
        by_mid = 2.0 * lack_mid > lack_end
        at = np.where(by_mid[:, None], mid, end)
        lack = np.where(by_mid, lack_mid, lack_end)
        moved_to = at + (1.2 * np.maximum(lack, 0.0) + _OVERSHOOT * collider.cell)[:, None] * collider.outward(at)
        out[t] = _unit(moved_to - _take(p0, t))
        p, o = _take(p0, t), _take(out, t)
        o *= half
        short[t] = _shortfall(collider, p + 2.0 * o, p + o, target[t],
                              root_value[t], _take(root, t))
        todo = t[short[t] > 0]
    if todo.size:
        # Still short (a strand wedged between an ear and the skull): of a fixed set of
        # directions, the one nearest u that clears the segment, else the one that falls
        # least short.
        t = todo
        dirs = _SEARCH_DIRECTIONS
        n, m = len(t), len(dirs)
        rep = np.repeat(t, m)
        cand = np.tile(dirs, (n, 1))
        p = _take(p0, rep)
        sh = _shortfall(collider, p + length[rep, None] * cand, p + 0.5 * length[rep, None] * cand,
                        target[rep], root_value[rep], _take(root, rep)).reshape(n, m)
        score = np.where(sh <= 0, 2.0 + _take(u, t) @ dirs.T, -sh)
        best = np.argmax(score, axis=1)
        out[t] = dirs[best]
        short[t] = sh[np.arange(n), best]
    return out, int((short > 0).sum())


def _first_offence(collider, pts, half, target, off, cnt, k, prev, root_value, roots):
    """For strands whose rest (points k..) would be their original translated to put point
    k-1 at prev: the first point of the next _CHECK_AHEAD of the rest that it or its
    segment's middle would bring too close (the end of those where none: the walk steps on
    and looks again). Looking at the whole rest each time a strand came free looked at
    twice the points the walk goes through. The first _CHECK_FIRST points are looked at
    first, the others only for strands clear so far (a quarter of the strands offend within
    them on the shipped presets): each point's answer is its own, so the first offence
    found is the same. half: _half_segments of pts."""
    delta = prev - _take(pts, off + k - 1)
    stop = k + np.minimum(cnt - k, _CHECK_AHEAD)
    first = stop.copy()
    sel = np.arange(len(off))
    start = k
    for ahead in (_CHECK_FIRST, _CHECK_AHEAD - _CHECK_FIRST):
        end = np.minimum(start + ahead, stop[sel])
        found = _offence(collider, pts, half, target, off[sel], start, end, _take(delta, sel), root_value[sel],
                         _take(roots, sel))
        first[sel] = found
        more = (found == end) & (end < stop[sel])
        sel, start = sel[more], end[more]
        if not sel.size:
            break
    return first


def _offence(collider, pts, half, target, off, start, end, delta, root_value, roots):
    """_first_offence over points start..end-1 of strands (per strand; end where none)."""
    rest = end - start
    idx = _flat_points(off + start, rest)
    s_of = np.arange(len(off)).repeat(rest)
    d = _take(delta, s_of)
    p = _take(pts, idx) + d

    def middles(i):
        return 0.5 * (_take(pts, idx[i]) + _take(pts, idx[i] - 1)) + _take(d, i)
    look = _indices(~_clear_with_middles(collider, p, half.take(idx), target.take(idx), middles))
    first = end.copy()
    if look.size:
        sl = s_of[look]
        bad, _ = _offends(collider, _take(p, look), lambda i: middles(look[i]), target[idx[look]], root_value[sl],
                          _take(roots, sl))
        _lower_to_first(first, sl[bad], (idx[look] - off[sl])[bad])
    return first


def _lower_to_first(out, strands, values):
    """np.minimum.at(out, strands, values) where `strands` does not decrease and `values`
    rises within each strand (points in order): each strand's first value is its least,
    so one look per strand instead of ufunc.at's slow loop."""
    if not strands.size:
        return
    new = np.empty(len(strands), bool)
    new[0] = True
    np.not_equal(strands[1:], strands[:-1], out=new[1:])
    s, v = strands[new], values[new]
    out[s] = np.minimum(out[s], v)


def _translate(result, pts, off, k, end, delta):
    """Points k..end-1 of strands = their original + delta."""
    n_rest = end - k
    if n_rest.sum():
        rows = _flat_points(off + k, n_rest)
        moved = _take(pts, rows)
        moved += _take(delta, np.arange(len(delta)).repeat(n_rest))
        _put(result, rows, moved)


# StrandCollision.check_keys's answers for recent key sets (by the collider's id, which a
# weak reference to it confirms).
_KEY_CHECKS = OrderedDict()
_KEY_CHECKS_KEPT = 8


@dataclass(frozen=True)
class CollisionReport:
    """What collision did to a groom (GroomResult.collision): the collider's name, how many
    strands it moved, the keys that pass through it ([KeyInside]) and the stats of the last
    pass (a full generation, or the strands an update recomputed)."""
    collider: str
    strands_moved: int
    keys_inside: tuple
    last: CollisionStats

    def warning(self):
        """A sentence naming the keys inside the collider, or None."""
        return describe_keys_inside(self.collider, self.keys_inside)


class StrandCollision:
    """Collision for a Generator: the collider sampled for the hair's clearance, the scalp
    checked against it, the keys inside it, and which strands it moved (kept per strand, so an
    incremental update reports the whole groom)."""

    def __init__(self, collider, scalp, params, n_strands):
        self.collider = as_collider(collider)
        self.margin = params.collision_margin
        check_scalp(self.collider, scalp)
        self.moved = np.zeros(n_strands, bool)
        self.keys_inside = ()
        self.last = CollisionStats()

    def check_keys(self, keys, params):
        """Make sure the band fits the thickest hair, and find the keys inside."""
        from .keys import arc_length_tables
        radii = np.array([params.radius if k.root_radius is None else k.root_radius for k in keys])
        self.collider = with_clearance(self.collider, float(radii.max()) + self.margin)
        # Generate again with the same keys on the same collider: the same answer, kept.
        tag = (id(self.collider), radii.tobytes()) + tuple(
            (k.kind, k.points.shape, k.points.tobytes(), np.asarray(k.root).tobytes()) for k in keys)
        hit = _KEY_CHECKS.get(tag)
        if hit is not None and hit[0]() is self.collider:
            _KEY_CHECKS.move_to_end(tag)
            self.keys_inside = hit[1]
            return
        tables = arc_length_tables(keys, _KEY_CHECK_SAMPLES)
        self.keys_inside = tuple(keys_inside(self.collider, tables, np.array([k.root for k in keys]), radii))
        _KEY_CHECKS[tag] = (weakref.ref(self.collider), self.keys_inside)
        while len(_KEY_CHECKS) > _KEY_CHECKS_KEPT:
            _KEY_CHECKS.popitem(last=False)

    def apply(self, points, counts, radius, sel=None, threads=None):
        """(points (float32) of strands `sel` (None: all) moved out of the collider, the
        CollisionStats of this call). Calls for disjoint strands may run side by side:
        each writes only its own strands' `moved` (the caller keeps `last`)."""
        t0 = time.perf_counter()
        new, moved, stats = resolve_strands(self.collider, points, counts, radius, self.margin, threads,
                                            in_place=True)
        if sel is None:
            self.moved = moved
        else:
            self.moved[sel] = moved
        stats.seconds = time.perf_counter() - t0
        return new, stats

    def report(self):
        return CollisionReport(self.collider.name, int(self.moved.sum()), self.keys_inside, self.last)

# SPDX-License-Identifier: GPL-3.0-or-later
"""The scalp: a triangle mesh the roots grow from (SPEC §1).

`Scalp` validates its arrays where they enter; everything downstream trusts them.
Normals: the thesis uses the triangle's own normal inside a triangle (`normal_mode="face"`);
the default interpolates area-weighted vertex normals barycentrically, which is continuous
across triangle edges (`normal_mode="interpolated"`).
"""
import os

import numpy as np

from hairio import InputError, check_finite
from hairio.obj import parse_obj

# Below this (relative to the mesh size squared) a triangle counts as having no area:
# its own normal is noise, so it borrows its vertices' normals instead.
_DEGENERATE_AREA = 1e-14


def _unit(v, fallback):
    """Normalise rows of v; rows too short to have a direction get `fallback` rows."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    ok = n[..., 0] > 1e-300
    out = np.where(ok[..., None], v / np.where(n > 1e-300, n, 1.0), fallback)
    return out, ok


class Scalp:
    """Triangle mesh: vertices (V,3) float64, triangles (T,3) int64, optional per-vertex
    density weight (V,) >= 0, optional UV map (V,2), optional per-vertex group id (V,) int
    (a parting: a root takes the group of its triangle's nearest vertex)."""

    def __init__(self, vertices, triangles, density=None, uv=None, groups=None):
        v = np.asarray(vertices)
        if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0:
            raise InputError(f"scalp vertices: expected shape (V, 3) with V >= 1, got {v.shape}")
        if v.dtype.kind not in "fiu":
            raise InputError(f"scalp vertices: expected numbers, got dtype {v.dtype}")
        self.vertices = check_finite("scalp vertices", v.astype(np.float64))
        t = np.asarray(triangles)
        if t.ndim != 2 or t.shape[1] != 3 or len(t) == 0:
            raise InputError(f"scalp triangles: expected shape (T, 3) with at least one triangle, got {t.shape}; "
                             "a scalp needs faces, not only vertices")
        if t.dtype.kind not in "iu":
            if t.dtype.kind == "f" and np.all(np.isfinite(t)) and np.all(t == np.round(t)):
                t = t.astype(np.int64)
            else:
                raise InputError(f"scalp triangles: expected integer vertex indices, got dtype {t.dtype}")
        t = t.astype(np.int64)
        if t.min() < 0 or t.max() >= len(self.vertices):
            raise InputError(f"scalp triangles: vertex indices must lie in [0, {len(self.vertices) - 1}], "
                             f"got range [{t.min()}, {t.max()}]")
        self.triangles = t
        self.density = None
        if density is not None:
            d = check_finite("scalp density", np.asarray(density, dtype=np.float64))
            if d.shape != (len(self.vertices),):
                raise InputError(f"scalp density: expected shape ({len(self.vertices)},), got {d.shape}")
            if d.min() < 0:
                raise InputError("scalp density: negative weights; density must be >= 0")
            self.density = d
        self.uv = None
        if uv is not None:
            uv = check_finite("scalp uv", np.asarray(uv, dtype=np.float64))
            if uv.shape != (len(self.vertices), 2):
                raise InputError(f"scalp uv: expected shape ({len(self.vertices)}, 2), got {uv.shape}")
            self.uv = uv
        self.groups = None
        if groups is not None:
            g = np.asarray(groups)
            if g.shape != (len(self.vertices),) or g.dtype.kind not in "iu":
                raise InputError(f"scalp groups: expected integer array of shape ({len(self.vertices)},)")
            self.groups = g.astype(np.int32)
        self._compute_normals()
        if self.degenerate.all():
            size = float(np.ptp(self.vertices, axis=0).max())
            why = ("all its vertices coincide" if size == 0 else
                   f"corners on one line or point, or too small next to the mesh's extent {size:.3g}: a stray vertex?")
            raise InputError(f"scalp: every one of its {len(t)} triangle(s) has no area ({why}); "
                             "a scalp needs faces with area to grow hair on")

    def _compute_normals(self):
        p = self.vertices[self.triangles]
        # Work relative to the mesh centre: a head offset by 1e4 keeps its cross products exact.
        centre = 0.5 * (self.vertices.min(axis=0) + self.vertices.max(axis=0))
        p = p - centre
        cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        area2 = np.linalg.norm(cross, axis=1)
        self.face_areas = 0.5 * area2
        size = float(np.ptp(self.vertices, axis=0).max()) or 1.0
        self.degenerate = self.face_areas <= _DEGENERATE_AREA * size * size
        # Area-weighted vertex normals: the raw cross product already carries twice the area.
        acc = np.zeros_like(self.vertices)
        for c in range(3):
            np.add.at(acc, self.triangles[:, c], np.where(self.degenerate[:, None], 0.0, cross))
        up = np.array([0.0, 0.0, 1.0])
        vn, ok = _unit(acc, up)
        # A vertex touching only degenerate faces points away from the mesh centre (or up).
        if not ok.all():
            radial, _ = _unit(self.vertices - self.vertices.mean(axis=0), up)
            vn[~ok] = radial[~ok]
        self.vertex_normals = vn
        fn, fok = _unit(cross, up)
        if not fok.all() or self.degenerate.any():
            borrowed, _ = _unit(vn[self.triangles].sum(axis=1), up)
            fn = np.where(self.degenerate[:, None] | ~fok[:, None], borrowed, fn)
        self.face_normals = fn

    @property
    def num_triangles(self):
        return len(self.triangles)

    @property
    def total_area(self):
        return float(self.face_areas.sum())

    def points_at(self, tri, bary):
        """Positions at triangle ids (N,) with barycentrics (N,3)."""
        return np.ascontiguousarray(self.corner_blend(self.vertices, tri, bary).T)

    def corner_blend(self, values, tri, bary):
        """Per-vertex `values` (V, d) blended barycentrically at surface points, component-major
        (d, N): one contiguous row per component, the layout whole-array code over many
        roots reads fastest. bary may be (N,3) or its three columns."""
        corners = [self.triangles[:, c].take(tri) for c in range(3)]
        b = [np.ascontiguousarray(bary[:, c]) for c in range(3)] if isinstance(bary, np.ndarray) else bary
        out = np.empty((values.shape[1], len(corners[0])))
        for d, column in enumerate(values.T):
            out[d] = b[0] * column.take(corners[0]) + b[1] * column.take(corners[1]) + b[2] * column.take(corners[2])
        return out

    def normals_at(self, tri, bary, mode="interpolated"):
        """Unit normals at surface points: 'interpolated' (vertex normals blended, default)
        or 'face' (the triangle's own normal, the thesis)."""
        return np.ascontiguousarray(self.normals_blend(tri, bary, mode).T)

    def normals_blend(self, tri, bary, mode="interpolated"):
        """normals_at component-major, (3, N)."""
        if mode == "face":
            return self.face_normals.T.take(tri, axis=1)
        if mode != "interpolated":
            raise InputError(f"normal_mode: expected 'interpolated' or 'face', got {mode!r}")
        n = self.corner_blend(self.vertex_normals, tri, bary)
        length = np.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
        ok = length > 1e-300
        n /= np.where(ok, length, 1.0)
        if not ok.all():
            # Opposing vertex normals (a fold) can cancel; the face normal is then the honest answer.
            n[:, ~ok] = self.face_normals[np.asarray(tri)[~ok]].T
        return n

    def uv_at(self, tri, bary):
        if self.uv is None:
            return None
        return np.ascontiguousarray(self.corner_blend(self.uv, tri, bary).T)

    def groups_at(self, tri, bary):
        """Group id of each surface point: that of the triangle's vertex with the largest weight."""
        if self.groups is None:
            return np.zeros(len(tri), np.int32)
        corner = np.argmax(bary, axis=1)
        return self.groups[self.triangles[tri, corner]]

    def closest_points(self, points):
        """Nearest surface point of each query (Q,3): returns (tri (Q,), bary (Q,3), point (Q,3)).

        Meant for a few key roots. The nearest corner of any triangle bounds the distance to
        the surface from above, so only triangles whose bounding sphere comes that close can
        hold the nearest point: those few are solved exactly, and the result is the one a
        search of every triangle gives (ties to the lower triangle index)."""
        q = check_finite("query points", np.asarray(points, dtype=np.float64).reshape(-1, 3))
        a, b, c, centre, radius, corners, size = self._search_data()
        qi, ti = [], []
        step = max(1, (1 << 14) // max(len(a), len(corners)))
        for lo in range(0, len(q), step):  # a few queries at a time: small (queries x triangles) arrays
            p = q[lo:lo + step, :, None]
            near = np.sqrt(_distance2(p, corners).min(axis=1))
            reach = np.sqrt(_distance2(p, centre)) - radius
            # The margin covers rounding of these bounds; excluded triangles are truly farther.
            i, j = np.nonzero(reach <= near[:, None] * (1.0 + 1e-9) + 1e-12 * size)
            qi.append(i + lo)
            ti.append(j)
        qi, ti = np.concatenate(qi), np.concatenate(ti)
        on = _closest_on_triangles(q[qi], a[ti], b[ti], c[ti])
        pts = on[:, :1] * a[ti] + on[:, 1:2] * b[ti] + on[:, 2:] * c[ti]
        d2 = _dot(pts - q[qi], pts - q[qi])
        # Per query the smallest distance, then the lowest triangle index (pairs come in
        # (query, triangle) order, lexsort is stable).
        order = np.lexsort((d2, qi))
        first = order[np.flatnonzero(np.r_[True, np.diff(qi[order]) != 0])]
        tri = ti[first]
        bary = on[first]
        return tri, bary, self.points_at(tri, bary)


    def _search_data(self):
        """Per-triangle corners and bounding spheres for closest_points, made once: the mesh
        does not change after it is validated."""
        if getattr(self, "_search", None) is None:
            a, b, c = (self.vertices[self.triangles[:, i]] for i in range(3))
            centre = (a + b + c) / 3.0
            radius = np.sqrt(np.maximum(np.maximum(_dot(a - centre, a - centre), _dot(b - centre, b - centre)),
                                        _dot(c - centre, c - centre)))
            corners = self.vertices[np.unique(self.triangles)]
            # Centres and corners one coordinate row each, for the queries x points distances.
            self._search = (a, b, c, np.ascontiguousarray(centre.T), radius, np.ascontiguousarray(corners.T),
                            float(np.abs(self.vertices).max()))
        return self._search


def _distance2(p, points):
    """Squared distances (Q, N) of queries p (Q, 3, 1) to points given as coordinate rows (3, N)."""
    return (p[:, 0] - points[0]) ** 2 + (p[:, 1] - points[1]) ** 2 + (p[:, 2] - points[2]) ** 2


def _dot(u, v):
    """Dot products over the last axis (3)."""
    return u[..., 0] * v[..., 0] + u[..., 1] * v[..., 1] + u[..., 2] * v[..., 2]


def _closest_on_triangles(p, a, b, c):
    """Barycentrics (N, 3) of the point of each triangle (a, b, c: (N,3) corners) nearest to
    its query p (N,3) (Ericson, Real-Time Collision Detection §5.1.5), vectorised;
    degenerate triangles fall to an edge or vertex."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = _dot(ab, ap), _dot(ac, ap)
    bp = p - b
    d3, d4 = _dot(ab, bp), _dot(ac, bp)
    cp = p - c
    d5, d6 = _dot(ab, cp), _dot(ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    out = np.zeros(d1.shape + (3,))
    done = np.zeros(d1.shape, bool)

    def put(mask, bary):
        nonlocal done
        m = mask & ~done
        out[m] = bary[m] if np.ndim(bary) > 1 else bary
        done |= m

    with np.errstate(divide="ignore", invalid="ignore"):
        put((d1 <= 0) & (d2 <= 0), np.array([1.0, 0, 0]))
        put((d3 >= 0) & (d4 <= d3), np.array([0, 1.0, 0]))
        put((d6 >= 0) & (d5 <= d6), np.array([0, 0, 1.0]))
        # An edge region needs an edge: a zero-length one (two identical corners) divides
        # 0 by 0 there, and the other edges already cover the segment that is left.
        v = np.clip(d1 / (d1 - d3), 0, 1)
        put((vc <= 0) & (d1 >= 0) & (d3 <= 0) & (d1 - d3 > 0), np.stack([1 - v, v, 0 * v], -1))
        w = np.clip(d2 / (d2 - d6), 0, 1)
        put((vb <= 0) & (d2 >= 0) & (d6 <= 0) & (d2 - d6 > 0), np.stack([1 - w, 0 * w, w], -1))
        w = np.clip((d4 - d3) / ((d4 - d3) + (d5 - d6)), 0, 1)
        put((va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0) & ((d4 - d3) + (d5 - d6) > 0),
            np.stack([0 * w, 1 - w, w], -1))
        denom = va + vb + vc
        ok = np.abs(denom) > 0
        inner = np.stack([va, vb, vc], -1) / np.where(ok, denom, 1.0)[..., None]
        inner = np.where(ok[..., None] & np.isfinite(inner), inner, np.array([1.0, 0, 0]))
        put(np.ones(d1.shape, bool), inner)
    return out


def default_scalp(rings=13):
    """A bundled head-shaped scalp made in code: Blender units (metres), Z up, -Y front.

    A cap over the top, back and sides of an ellipsoidal head (half-axes 0.08 m left-right,
    0.1 m front-back, 0.1 m up) centred at the origin. It is a disc of `rings` concentric
    rings (6k vertices on ring k, 6·rings² triangles: 1014 for 13) mapped onto the head by an
    azimuthal projection from the crown, so the crown is an ordinary vertex, not a pole of
    slivers. The hairline is lower at the back than at the front. UV = the disc, in [0, 1]².
    """
    if rings < 1:
        raise InputError("default_scalp rings: must be >= 1")
    rho = [np.zeros(1)]
    az = [np.zeros(1)]
    for k in range(1, rings + 1):
        n = 6 * k
        rho.append(np.full(n, k / rings))
        az.append(2 * np.pi * np.arange(n) / n)
    rho, az = np.concatenate(rho), np.concatenate(az)
    tris = []
    start = [0]
    for k in range(1, rings + 1):
        start.append(start[-1] + (1 if k == 1 else 6 * (k - 1)))
    for k in range(1, rings + 1):
        inner_n = 1 if k == 1 else 6 * (k - 1)
        outer_n = 6 * k
        i0, o0 = start[k - 1], start[k]
        if inner_n == 1:
            for j in range(outer_n):
                tris.append((i0, o0 + j, o0 + (j + 1) % outer_n))
            continue
        # Walk both rings by angle, always advancing the ring whose next vertex comes first.
        i = j = 0
        while i < inner_n or j < outer_n:
            next_i = (i + 1) / inner_n
            next_j = (j + 1) / outer_n
            a, b = i0 + i % inner_n, o0 + j % outer_n
            if j < outer_n and (i >= inner_n or next_j <= next_i):
                tris.append((a, b, o0 + (j + 1) % outer_n))
                j += 1
            else:
                tris.append((a, b, i0 + (i + 1) % inner_n))
                i += 1
    tris = np.array(tris, np.int64)
    # Hairline: polar angle from the crown, 55° at the front (-Y), 115° at the back (+Y).
    # Azimuth 0 = +X; the front (-Y) is at -90°.
    polar_max = np.radians(85.0 + 30.0 * np.sin(az))
    polar = rho * polar_max
    d = np.stack([np.sin(polar) * np.cos(az), np.sin(polar) * np.sin(az), np.cos(polar)], 1)
    verts = d * np.array([0.08, 0.1, 0.1])
    uv = 0.5 + 0.5 * np.stack([rho * np.cos(az), rho * np.sin(az)], 1)
    # Counter-clockwise seen from outside: flip any triangle whose normal points inward.
    p = verts[tris]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    inward = np.einsum("td,td->t", n, p.mean(axis=1)) < 0
    tris[inward] = tris[inward][:, ::-1]
    return Scalp(verts, tris, uv=uv)


def default_head(frequency=12):
    """The bundled head: a closed mesh the bundled scalp (default_scalp) lies on, as a Scalp
    (vertices, triangles, normals; no UVs). Same space: metres, Z up, -Y front.

    The cranium is default_scalp's ellipsoid (half-axes 0.08, 0.1, 0.1 m about the origin);
    below the middle of the head and in front of it the jaw is longer (the chin 2 cm lower)
    and narrower, so the head has a face side. Where the scalp lies the surface is the bare
    ellipsoid, so every scalp vertex is on the head (outside it by at most the sagitta of
    the head's triangles, ~0.1 mm). A geodesic sphere of `frequency` subdivisions per
    icosahedron edge (20·frequency² triangles: 2880 for 12, none of them slivers) mapped
    onto that shape; triangles counter-clockwise seen from outside. No neck."""
    if frequency < 1:
        raise InputError("default_head frequency: must be >= 1")
    directions, tris = _geodesic_sphere(int(frequency))
    p = directions * np.array([0.08, 0.1, 0.1])
    x, y, z = p.T
    # Weights of the face side (in front of y = 0.02) and of the lower head (z < 0): their
    # product is zero wherever the scalp is (its vertices below z = 0 all lie behind
    # y = 0.023), so the scalp keeps the bare ellipsoid.
    front = _smoothstep(0.02, -0.05, y)
    low = _smoothstep(0.0, -0.1, z)
    below = np.minimum(z, 0.0)
    # z' = z - 0.35·front·z²/0.1 and x' = x·(1 - 0.25·front·low) keep dz'/dz > 0 and
    # dx'/dx > 0 with y unchanged, so the map is one-to-one: the surface stays closed and
    # unfolded, its orientation kept.
    p = np.stack([x * (1.0 - 0.25 * front * low), y, z - 0.35 * front * below * below / 0.1], 1)
    return Scalp(p, tris)


def _smoothstep(edge0, edge1, v):
    t = np.clip((v - edge0) / (edge1 - edge0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _geodesic_sphere(n):
    """Unit vertices and outward counter-clockwise triangles of an icosahedron whose edges
    are cut in n, projected onto the sphere."""
    g = (1.0 + 5.0 ** 0.5) / 2.0
    ico = np.array([(-1, g, 0), (1, g, 0), (-1, -g, 0), (1, -g, 0), (0, -1, g), (0, 1, g), (0, -1, -g),
                    (0, 1, -g), (g, 0, -1), (g, 0, 1), (-g, 0, -1), (-g, 0, 1)], np.float64)
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
             (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5),
             (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    # Lattice points (i, j), i + j <= n, of one face, and its small triangles in lattice indices.
    ij = [(i, j) for i in range(n + 1) for j in range(n + 1 - i)]
    index = {q: k for k, q in enumerate(ij)}
    small = []
    for i, j in ij:
        if i + j < n:
            small.append((index[i, j], index[i + 1, j], index[i, j + 1]))
        if i + j < n - 1:
            small.append((index[i + 1, j], index[i + 1, j + 1], index[i, j + 1]))
    ij, small = np.array(ij, np.float64) / n, np.array(small, np.int64)
    points, tris = [], []
    for f, (a, b, c) in enumerate(faces):
        points.append(ico[a] + ij[:, :1] * (ico[b] - ico[a]) + ij[:, 1:] * (ico[c] - ico[a]))
        tris.append(small + f * len(ij))
    points, tris = np.concatenate(points), np.concatenate(tris)
    # Faces share their edge points; merge them (the lattice spacing is far above the rounding).
    _, first, inverse = np.unique(np.round(points * (8 * n), 3), axis=0, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    tris = inverse[tris]
    points = points[first]
    points /= np.linalg.norm(points, axis=1, keepdims=True)
    return points, tris


def load_obj(path):
    """Read a Wavefront .obj as a Scalp (hairio.obj parses it: `v`, `vt` and `f`, polygons
    fan-triangulated, every index form). UVs are kept per vertex when every face corner
    gives one and they are finite; a vertex with NaN/Inf coordinates is refused."""
    path = os.fspath(path)
    mesh = parse_obj(path, "scalp mesh")
    verts, tris = mesh.vertices, mesh.triangles
    if not np.isfinite(verts).all():
        bad = int(np.argmax(~np.isfinite(verts).all(axis=1)))
        raise InputError(f"scalp mesh {path!r}: vertex {bad} has NaN/Inf coordinates; repair the mesh")
    uv, uvs, tuv = None, mesh.uvs, mesh.triangle_uvs
    if len(uvs) and tuv is not None and tuv.max() < len(uvs) and np.isfinite(uvs).all():
        # Per-vertex UV: the last corner using a vertex wins (seams keep one side).
        uv = np.zeros((len(verts), 2))
        uv[tris.ravel()] = uvs[tuv.ravel()]
    try:
        return Scalp(verts, tris, uv=uv)
    except InputError as e:
        raise InputError(f"scalp mesh {path!r}: {str(e).removeprefix('scalp: ')}") from None

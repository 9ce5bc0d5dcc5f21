# SPDX-License-Identifier: GPL-3.0-or-later
"""Float64 reference written from the geometry alone (SPEC §6, §8), to guard against a
mistake the GPU tracer and its mirror (reference.py) share.

Every strand is the union of its cut cylinders, each a convex solid: the points within r of
the axis line through P_i, P_{i+1} that lie on the inner side of both cut planes (plane 1
through P_i square to its own axis; plane 2 through P_{i+1} square to the next axis, or to
its own at a strand's end and past layout.SHARP_BEND_DEG). A ray meets a convex solid in one
interval [t_in, t_out]; it enters a strand at t_in of one of its cylinders unless another
cylinder of the same strand already holds the ray there (t_in' < t_in <= t_out'). The
image is those entries, nearest first: layers are entries into strands (each strand one
tube, as the tracer treats them), shading is SPEC §7's (the normal of the surface entered:
the side, or a cut plane), shadow rays count the entries between the point and the light.

Nothing here comes from the tracer's hit test, entry flags or grid: no shared-plane rule,
no crescent test, no cells. Every ray meets every cylinder it can reach: ray_bundles pairs
them (conservatively: it only leaves out cylinders no ray of the set comes near). It shares
with the tracer only the strand points after the repeat rule (cylinders.plan_cylinders),
the sample positions of each pixel and the settings.

Not modelled: the minimum pixel width, which widens each cylinder per ray (a rendering
device, not geometry); `solid_render` refuses it.
"""
from dataclasses import dataclass

import numpy as np

from hairio import InputError

from . import layout
from .cylinders import plan_cylinders
from .ray_bundles import candidate_pairs
from .reference import finish_pixels, light_sample, light_seeds, pixel_samples
from .settings import RenderSettings
from .shading import Surface, shading_model

BIG = 1e30
PAIRS_PER_STEP = 4_000_000      # ray x cylinder pairs held in memory at once


@dataclass(frozen=True, eq=False)
class CutCylinders:
    """Per cylinder, float64: a, b (N,3) the axis ends P_i, P_{i+1}; u (N,3) unit axis
    (plane 1's normal); n2 (N,3) unit normal of plane 2; radius, alpha (N,); color (N,3);
    strand (N,); far (N,3): the solid lies within its radius of the segment a–far."""
    a: np.ndarray
    b: np.ndarray
    u: np.ndarray
    n2: np.ndarray
    radius: np.ndarray
    color: np.ndarray
    alpha: np.ndarray
    strand: np.ndarray
    far: np.ndarray

    def __len__(self):
        return len(self.a)


def cut_cylinders(strands):
    """hairio.Strands -> CutCylinders (SPEC §6), in float64 from the float32 points."""
    plan = plan_cylinders(strands)
    pts = np.asarray(plan.points, np.float64)
    i = np.asarray(plan.top_point, np.int64)
    a, b = pts[i], pts[i + 1]
    axis = b - a
    length = np.linalg.norm(axis, axis=1)
    u = axis / length[:, None]
    # Cylinder k + 1 continues cylinder k when it starts at k's tip point.
    follows = np.zeros(len(i), bool)
    follows[:-1] = i[1:] == i[:-1] + 1
    n2 = u.copy()
    n2[:-1][follows[:-1]] = u[1:][follows[:-1]]
    cos = np.einsum("ij,ij->i", u, n2)
    sharp = cos < layout.cos_sharp()
    n2[sharp] = u[sharp]
    cos[sharp] = 1.0
    rad = np.asarray(plan.radius, np.float64)
    r = 0.5 * (rad[i] + rad[i + 1])     # the mean of the cylinder's two points' radii
    # Plane 2 tilts by the bend angle θ: the solid reaches r·tan θ past b along the axis.
    tan = np.sqrt(np.maximum(0.0, 1.0 - cos * cos)) / np.maximum(cos, 1e-12)
    return CutCylinders(a=a, b=b, u=u, n2=n2, radius=r, color=np.asarray(plan.color, np.float64)[i],
                        alpha=np.asarray(plan.alpha, np.float64)[i], strand=np.asarray(plan.strand, np.int64)[i],
                        far=b + (r * tan)[:, None] * u)


def _dot(x, y):
    return np.einsum("ij,ij->i", x, y)


def solid_intervals(cyl, ids, o, d):
    """Where the rays o[k] + t·d[k] (unit d) lie inside solid ids[k]: (t_in, t_out, surface
    entered: 0 side, 1 plane 1, 2 plane 2); t_in > t_out where the ray misses."""
    a, b, u, n2, r = cyl.a[ids], cyl.b[ids], cyl.u[ids], cyl.n2[ids], cyl.radius[ids]
    # Inside the infinite cylinder: |m⊥ + t·d⊥|² <= r², solved around the ray's point nearest
    # the axis middle, where the quadratic's terms are the cylinder's size, not the camera's distance.
    t0 = _dot(0.5 * (a + b) - o, d)
    m = o + t0[:, None] * d - a
    mp = m - _dot(m, u)[:, None] * u
    dp = d - _dot(d, u)[:, None] * u
    qa, qb, qc = _dot(dp, dp), _dot(mp, dp), _dot(mp, mp) - r * r
    along = qa < 1e-24                      # parallel to the axis: inside everywhere or nowhere
    disc = qb * qb - qa * qc
    root = np.sqrt(np.maximum(disc, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        lo = np.where(along, -BIG, t0 + (-qb - root) / qa)
        hi = np.where(along, BIG, t0 + (-qb + root) / qa)
    empty = np.where(along, qc > 0.0, disc < 0.0)
    surf = np.zeros(len(ids), np.int64)
    # The half-spaces (p - a)·u >= 0 and (p - b)·n2 <= 0, with p = o + t·d. Cylinders that
    # share a plane compute its crossing from the same point and normal, so the exit from one
    # and the entry into the next are the same number.
    for point, normal, keep_below, which in ((a, u, False, 1), (b, n2, True, 2)):
        dn = _dot(d, normal)
        s = _dot(point - o, normal)
        with np.errstate(divide="ignore", invalid="ignore"):
            tp = s / dn
        enters = (dn < 0.0) if keep_below else (dn > 0.0)
        leaves = (dn > 0.0) if keep_below else (dn < 0.0)
        later = enters & (tp > lo)
        lo = np.where(later, tp, lo)
        surf[later] = which
        hi = np.where(leaves, np.minimum(hi, tp), hi)
        empty |= (dn == 0.0) & ((s < 0.0) if keep_below else (s > 0.0))
    lo = np.where(empty, BIG, lo)
    hi = np.where(empty, -BIG, hi)
    return lo, hi, surf


def _pairs(cyl, o, d, tmin, target=None):
    """(ray, cylinder, t_in, t_out, surface) of every ray that passes through a solid beyond
    tmin[ray]; `target` where all the rays end, if they do."""
    ray, cid = candidate_pairs(o, d, cyl.a, cyl.far, cyl.radius, target)
    out = ([], [], [], [], [])
    for s in range(0, len(ray), PAIRS_PER_STEP):
        pr, pc = ray[s:s + PAIRS_PER_STEP], cid[s:s + PAIRS_PER_STEP]
        lo, hi, surf = solid_intervals(cyl, pc, o[pr], d[pr])
        keep = (lo <= hi) & (hi > tmin[pr])
        for acc, x in zip(out, (pr, pc, lo, hi, surf)):
            acc.append(x[keep])
    if not out[0]:
        return [np.zeros(0, np.int64)] * 2 + [np.zeros(0)] * 2 + [np.zeros(0, np.int64)]
    return [np.concatenate(x) for x in out]


def strand_entries(cyl, o, d, tmin, target=None):
    """Entries into strands of the rays beyond tmin, sorted by ray, then distance, then
    cylinder: (ray, cylinder, t, surface). An entry at t_in of a cylinder is no entry where
    an interval of another cylinder of the same strand already holds the ray. `target`:
    where all the rays end (a point light), if they do."""
    ray, cid, lo, hi, surf = _pairs(cyl, o, d, tmin, target)
    strand = cyl.strand[cid]
    order = np.lexsort((cid, lo, strand, ray))
    ray, cid, lo, hi, surf, strand = (x[order] for x in (ray, cid, lo, hi, surf, strand))
    n = len(ray)
    head = np.ones(n, bool)
    head[1:] = (ray[1:] != ray[:-1]) | (strand[1:] != strand[:-1])
    start = np.maximum.accumulate(np.where(head, np.arange(n), 0)) if n else np.zeros(0, np.int64)
    rank = np.arange(n) - start
    # Farthest exit of the intervals before each one within its (ray, strand) run.
    before = np.full(n, -BIG)
    for k in range(1, int(rank.max()) + 1 if n else 0):
        at = np.flatnonzero(rank == k)
        before[at] = np.maximum(before[at - 1], hi[at - 1])
    # The tie at a shared plane is exact (see solid_intervals); the margin only absorbs
    # rounding of a crossing computed from two sides.
    covered = before >= lo - 1e-12 * np.maximum(np.abs(lo), 1.0)
    keep = ~covered & (lo > tmin[ray])
    ray, cid, lo, surf = ray[keep], cid[keep], lo[keep], surf[keep]
    order = np.lexsort((cid, lo, ray))
    return ray[order], cid[order], lo[order], surf[order]


def _normals(cyl, ids, surf, p, d):
    """Normal of the surface entered (SPEC §7), facing the ray."""
    q = p - cyl.a[ids]
    u = cyl.u[ids]
    n = q - _dot(q, u)[:, None] * u
    n = np.where((surf == 1)[:, None], -u, n)
    n = np.where((surf == 2)[:, None], cyl.n2[ids], n)
    length = np.linalg.norm(n, axis=1)
    n = np.where((length > 0)[:, None], n / np.maximum(length, 1e-300)[:, None], -d)
    return np.where((_dot(n, d) > 0)[:, None], -n, n)


def _light_through(cyl, p, L, dist, own_radius, settings, target=None):
    """Transmittance from p toward the light along L (unit) up to dist: hard (any entry
    blocks) or the product of 1 - alpha over the strands entered; `target` the point
    light's position."""
    tmin = 1e-3 * own_radius
    ray, cid, t, _ = strand_entries(cyl, p, L, tmin, target)
    hit = t < dist[ray]
    ray, cid = ray[hit], cid[hit]
    lit = np.ones(len(p))
    if settings.shadow_mode == "hard":
        lit[ray] = 0.0
        return lit
    logs = np.zeros(len(p))
    with np.errstate(divide="ignore"):
        np.add.at(logs, ray, np.log1p(-cyl.alpha[cid]))
    lit = np.exp(logs)
    lit[lit < settings.transmittance_eps] = 0.0
    return lit


def _shade(cyl, ids, surf, o, d, t, settings, seeds, k):
    model = shading_model(settings.shading)
    p = o + t[:, None] * d
    col = cyl.color[ids]
    n = _normals(cyl, ids, surf, p, d) if model.needs_normal else None
    s = Surface(p=p, T=cyl.u[ids], N=n, V=d, color=col)
    out = settings.ambient * col
    for l, light in enumerate(settings.lights):
        lcol = light.packed()[1]
        # The point on the light the shader draws for this shading (its centre without extent).
        L, dist = light.towards(p, light_sample(seeds, k, l, len(settings.lights)))
        lit = np.ones(len(p))
        if settings.shadows and light.shadows:
            lit = _light_through(cyl, p, L, dist, cyl.radius[ids], settings, light.target())
        lit = lit * light.scale(L, dist)        # fall-off, a spot's cone, an area light's cosine
        out = out + lit[:, None] * np.asarray(lcol) * model.reference(s, L, settings)
    return out


def solid_render(strands, camera, settings=None, pixels=None):
    """(H, W, 4) float64 premultiplied linear RGBA, row 0 = top, traced against the solids
    themselves; `pixels` (P,2) int x, y: only those pixels, (P, 4)."""
    settings = settings or RenderSettings()
    settings.check()
    if settings.min_pixel_width:
        raise InputError("settings.min_pixel_width: the solid reference traces the strands as they are; "
                         "compare widened images with tracer.reference_render")
    cyl = cut_cylinders(strands)
    n = settings.spp_n
    pos = pixel_samples(camera, n, pixels)
    seeds = light_seeds(camera, n, pixels)
    o, d = camera.rays(pos[:, 0], pos[:, 1])
    C = np.zeros((len(o), 3))
    T = np.ones(len(o))
    if len(cyl):
        ray, cid, t, surf = strand_entries(cyl, o, d, np.zeros(len(o)))
        first = np.searchsorted(ray, ray, side="left")
        rank = np.arange(len(ray)) - first
        layers = 1 if cyl.alpha.min() >= 1.0 else settings.layers
        for k in range(layers):
            sel = np.flatnonzero(rank == k)
            if k:
                sel = sel[T[ray[sel]] >= settings.transmittance_eps]
            if not len(sel):
                break
            r_k, ids = ray[sel], cid[sel]
            col = _shade(cyl, ids, surf[sel], o[r_k], d[r_k], t[sel], settings, seeds[r_k], k)
            alpha = cyl.alpha[ids]
            C[r_k] += (T[r_k] * alpha)[:, None] * col
            T[r_k] *= 1 - alpha
    bg = np.asarray(settings.premultiplied_background(), np.float64)
    rgba = np.concatenate([C + T[:, None] * bg[:3], (1 - T + T * bg[3])[:, None]], axis=1)
    return finish_pixels(rgba, camera, n, pixels)

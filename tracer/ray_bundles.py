# SPDX-License-Identifier: GPL-3.0-or-later
"""Which rays may meet which cylinders: the float64 references' stand-in for testing every
ray against every cylinder.

The references have no spatial structure of their own, and for whole images of real scenes
all pairs are too many (65,536 rays and 570,000 cylinders: 3.7e10). So rays are sorted along
a Morton curve through the points where they cross the scene and cut into bundles of
neighbours; a bundle tests each cylinder's capsule (its axis, extended as far as the solid
reaches, inflated by its radius) once, with a conservative test that keeps every capsule
some ray of the bundle may pass within (`reachable`); halves of the bundle then test only
those, down to LEAF rays (or SPLIT_PAIRS pairs), whose pairs go to the reference's own hit test. Nothing a ray
could hit is dropped, so the images are the all-pairs ones.
"""
import numpy as np

BUNDLE = 4096      # rays per top-level bundle
LEAF = 2           # rays per bundle whose pairs go to the hit test
# A bundle with fewer pairs than this goes to the hit test whole: splitting it costs more
# numpy calls than the pairs it could save.
SPLIT_PAIRS = 4000
PAIRS_PER_RUN = 2_000_000   # (ray, capsule) pairs held at once


def _morton(q):
    """Interleaved bits of three 10-bit integer columns (N,3) -> (N,) int64."""
    key = np.zeros(len(q), np.int64)
    for bit in range(10):
        for axis in range(3):
            key |= ((q[:, axis] >> bit) & 1).astype(np.int64) << (3 * bit + axis)
    return key


def bundles(o, d, reach_depth, size=BUNDLE):
    """Index arrays, each of about `size` rays (o, d: (R,3)) that pass near one another at
    distance `reach_depth` along them (the depth of the scene): rays sorted along a Morton
    curve through their points o + reach_depth·d, then cut into runs."""
    n = len(o)
    if n <= size:
        return [np.arange(n)]
    x = o + float(reach_depth) * d
    lo, hi = x.min(axis=0), x.max(axis=0)
    q = np.clip(((x - lo) / np.maximum(hi - lo, 1e-300) * 1023.0).astype(np.int64), 0, 1023)
    order = np.argsort(_morton(q), kind="stable")
    return [order[a:a + size] for a in range(0, n, size)]


def reachable(o, d, a, b, radius):
    """Indices of the capsules (segments a–b (N,3), radius (N,)) that some ray
    o[i] + t·d[i], t >= 0, of the bundle may pass within radius of.

    Conservative: the origins lie within δ of their mean o_c and the directions within α of
    their mean d_0. A ray that passes within ρ of a point x has a copy from o_c (same
    direction) that passes within ρ + δ, so x lies in the cone around d_0 of half-angle α
    widened by ρ' = ρ + δ: lateral distance l(x) <= z(x)·tan α + ρ'/cos α (z along d_0),
    z(x) >= -ρ'. Over a segment, min l - tan α · max z bounds l - z·tan α from below, and
    min l is the 2-D distance from the axis to the segment's shadow on the lateral plane."""
    oc = o.mean(axis=0)
    delta = float(np.sqrt(np.max(np.einsum("ij,ij->i", o - oc, o - oc))))
    dm = d.mean(axis=0)
    norm = float(np.linalg.norm(dm))
    if norm < 1e-9:
        return np.arange(len(a))
    d0 = dm / norm
    alpha = float(np.arccos(np.clip(np.min(d @ d0), -1.0, 1.0)))
    if alpha > 1.0:
        return np.arange(len(a))
    # Frame (e1, e2, d0): lateral coordinates and depth of both ends.
    e1 = np.cross(d0, [1.0, 0.0, 0.0] if abs(d0[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    frame = np.stack([e1, np.cross(d0, e1), d0], axis=1)
    pa = (a - oc) @ frame
    pb = (b - oc) @ frame
    rho = radius + delta
    zmax = np.maximum(pa[:, 2], pb[:, 2])
    ab = pb[:, :2] - pa[:, :2]
    len2 = ab[:, 0] * ab[:, 0] + ab[:, 1] * ab[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = -(pa[:, 0] * ab[:, 0] + pa[:, 1] * ab[:, 1]) / len2
    s = np.clip(np.where(len2 > 0, s, 0.0), 0.0, 1.0)
    lx, ly = pa[:, 0] + s * ab[:, 0], pa[:, 1] + s * ab[:, 1]
    lateral = np.sqrt(lx * lx + ly * ly)
    keep = (lateral - np.tan(alpha) * zmax <= rho / np.cos(alpha) * (1 + 1e-9) + 1e-300) & (zmax >= -rho)
    return np.flatnonzero(keep)


def _near_pairs(o, d, a, b, radius, rays, cand):
    """The pairs rays × cand whose ray passes within radius of the segment (exact up to
    rounding, which it errs on the side of keeping)."""
    r = np.repeat(rays, len(cand))
    c = np.tile(cand, len(rays))
    oo, dd = o[r], d[r]
    w = a[c] - oo
    u = b[c] - a[c]
    # Closest points of the ray line and the segment (u·u > 0; a zero-length axis is a point).
    uu = np.einsum("ij,ij->i", u, u)
    ud = np.einsum("ij,ij->i", u, dd)
    uw = np.einsum("ij,ij->i", u, w)
    wd = np.einsum("ij,ij->i", w, dd)
    den = uu - ud * ud
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(den > 1e-12 * uu, (ud * wd - uw) / den, 0.0)
    s = np.clip(np.nan_to_num(s), 0.0, 1.0)
    x = w + s[:, None] * u                        # segment point - ray origin
    t = np.maximum(np.einsum("ij,ij->i", x, dd), 0.0)
    off = x - t[:, None] * dd
    dist2 = np.einsum("ij,ij->i", off, off)
    rho = radius[c]
    # The closest point pair above is exact for the line; a margin of one radius more keeps
    # every pair its rounding or the clamp at t = 0 might misjudge.
    keep = dist2 <= (2.0 * rho) ** 2 + 1e-300
    return r[keep], c[keep]


def _bundle_pairs(o, d, a, b, radius):
    """candidate_pairs of any rays, by halving bundles (see the module)."""
    n = len(o)
    out_r, out_c = [], []
    if not n or not len(a):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    depth = float(np.linalg.norm(0.5 * (a + b).mean(axis=0) - o.mean(axis=0)))
    # Each bundle carries its candidates' ends and radii, so a half gathers from its
    # parent's few rows rather than from the whole scene.
    whole = (np.arange(len(a)), a, b, np.asarray(radius, np.float64))
    stack = [(rays, whole) for rays in bundles(o, d, depth, BUNDLE)[::-1]]
    while stack:
        rays, (cand, ca, cb, cr) = stack.pop()
        k = reachable(o[rays], d[rays], ca, cb, cr)
        if not len(k):
            continue
        sub = (cand[k], ca[k], cb[k], cr[k])
        if len(rays) > LEAF and len(rays) * len(k) > SPLIT_PAIRS:
            half = -(-len(rays) // 2)
            stack += [(rays[half:], sub), (rays[:half], sub)]
            continue
        r, c = _near_pairs(o, d, sub[1], sub[2], sub[3], rays, np.arange(len(k)))
        out_r.append(r)
        out_c.append(sub[0][c])
    if not out_r:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    r, c = np.concatenate(out_r), np.concatenate(out_c)
    order = np.argsort(r, kind="stable")
    return r[order], c[order]


def _frame(axis):
    """Columns e1, e2, axis: an orthonormal frame around the unit `axis`."""
    e1 = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    return np.stack([e1, np.cross(axis, e1), axis], axis=1)


def _segment_distance2(q, a, b):
    """Squared 2-D distances from points q (P,2) to segments a–b (P,2)."""
    ab = b - a
    aq = q - a
    len2 = np.einsum("ij,ij->i", ab, ab)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(len2 > 0, np.einsum("ij,ij->i", aq, ab) / len2, 0.0)
    off = aq - np.clip(s, 0.0, 1.0)[:, None] * ab
    return np.einsum("ij,ij->i", off, off)


def _projected_pairs(q, a2, b2, r2, anywhere):
    """Pairs (ray, capsule) of rays at points q (R,2) of a plane and capsules whose shadows
    on it are the segments a2–b2 (N,2) widened by r2 (N,), those within reach of their ray;
    capsules flagged `anywhere` are paired with every ray. Binned in square tiles of about
    a few rays each, so a ray meets only the capsules whose shadow reaches its tile."""
    n = len(q)
    lo, hi = q.min(axis=0), q.max(axis=0)
    area = float(np.prod(np.maximum(hi - lo, 1e-300)))
    h = max(np.sqrt(area / max(1.0, n / 4.0)), float(np.max(hi - lo)) / 2048.0, 1e-300)
    dims = np.maximum(1, np.ceil((hi - lo) / h).astype(np.int64) + 1)
    ray_tile = np.minimum(((q - lo) / h).astype(np.int64), dims - 1)
    ray_tile = ray_tile[:, 0] + dims[0] * ray_tile[:, 1]
    blo = np.floor((np.minimum(a2, b2) - r2[:, None] - lo) / h)
    bhi = np.floor((np.maximum(a2, b2) + r2[:, None] - lo) / h)
    inside = np.all(bhi >= 0, axis=1) & np.all(blo <= dims - 1, axis=1) & ~anywhere
    blo = np.clip(blo, 0, dims - 1).astype(np.int64)
    bhi = np.clip(bhi, 0, dims - 1).astype(np.int64)
    span = np.where(inside, (bhi[:, 0] - blo[:, 0] + 1) * (bhi[:, 1] - blo[:, 1] + 1), 0)
    # A shadow over very many tiles (a long cylinder close to the rays' origin) goes with
    # every ray instead of into every tile.
    wide = span > 4096
    anywhere = anywhere | wide
    span[wide] = 0
    cap = np.repeat(np.arange(len(a2)), span)
    local = np.arange(len(cap)) - np.repeat(np.cumsum(span) - span, span)
    width = (bhi[:, 0] - blo[:, 0] + 1)[cap]
    tile = (blo[cap, 0] + local % width) + dims[0] * (blo[cap, 1] + local // width)
    order = np.argsort(tile, kind="stable")
    cap, tile = cap[order], tile[order]
    ntile = int(dims[0] * dims[1])
    count = np.bincount(tile, minlength=ntile)
    start = np.cumsum(count) - count
    per_ray = count[ray_tile]
    extra = np.flatnonzero(anywhere)
    out_r, out_c = [], []
    # Rays in runs of about PAIRS_PER_RUN pairs, so memory stays bounded however deep the hair.
    ends = np.cumsum(per_ray + len(extra))
    first = 0
    while first < n:
        last = max(int(np.searchsorted(ends, (ends[first - 1] if first else 0) + PAIRS_PER_RUN, side="right")),
                   first + 1)
        rays = np.arange(first, last)
        pr = per_ray[first:last]
        r = np.repeat(rays, pr)
        k = (np.arange(len(r)) - np.repeat(np.cumsum(pr) - pr, pr)) + np.repeat(start[ray_tile[first:last]], pr)
        c = cap[k]
        if len(extra):
            r = np.concatenate([r, np.repeat(rays, len(extra))])
            c = np.concatenate([c, np.tile(extra, len(rays))])
        near = _segment_distance2(q[r], a2[c], b2[c]) <= (r2[c] * (1 + 1e-9)) ** 2 + 1e-300
        near |= anywhere[c]
        out_r.append(r[near])
        out_c.append(c[near])
        first = last
    return np.concatenate(out_r), np.concatenate(out_c)


def candidate_pairs(o, d, a, b, radius, target=None):
    """(ray, capsule) index pairs, ray-major, of the rays o[i] + t·d[i] (unit d, t >= 0)
    that may pass within radius[j] of the segment a[j]–b[j]: every pair that does, and few
    that do not. `target`: a point every ray heads for and stops at (shadow rays toward a
    point light).

    Rays from one point (a pinhole camera) or to one point (`target`) are seen from that
    point, rays of one direction (an orthographic camera, a sun's shadow rays) along it; the
    capsules' shadows on that view are binned with the rays. Other rays go in bundles."""
    n = len(o)
    if not n or not len(a):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    radius = np.asarray(radius, np.float64)
    if target is not None or not np.ptp(o, axis=0).any():
        centre = o[0] if target is None else np.asarray(target, np.float64)
        dirs = d if target is None else -d
        axis = dirs.mean(axis=0)
        axis /= max(float(np.linalg.norm(axis)), 1e-300)
        f = _frame(axis)
        pd = dirs @ f
        spread = float(np.arccos(np.clip(pd[:, 2].min(), -1.0, 1.0)))
        if spread < np.radians(50):
            pa, pb = (a - centre) @ f, (b - centre) @ f
            zmin = np.minimum(pa[:, 2], pb[:, 2])
            # Seen from the centre, a capsule in front of it (every point at depth > 0) casts
            # the segment between its ends' projections, widened by the angle its radius
            # spans (asin(ρ / depth)) times the projection's stretch at that angle from the
            # axis (1 / cos²); others go with every ray.
            front = zmin > radius * (1 + 1e-6)
            with np.errstate(divide="ignore", invalid="ignore"):
                beta = np.arcsin(np.clip(radius / zmin, 0.0, 1.0))
                a2 = pa[:, :2] / pa[:, 2:3]
                b2 = pb[:, :2] / pb[:, 2:3]
            wide_angle = spread + beta
            ok = front & (wide_angle < np.radians(75))
            r2 = np.where(ok, beta / np.cos(np.minimum(wide_angle, 1.3)) ** 2 * (1 + 1e-6), 0.0)
            a2, b2 = np.where(ok[:, None], a2, 0.0), np.where(ok[:, None], b2, 0.0)
            return _projected_pairs(pd[:, :2] / pd[:, 2:3], a2, b2, r2, ~ok)
    if not np.ptp(d, axis=0).any():
        f = _frame(d[0] / np.linalg.norm(d[0]))
        return _projected_pairs(o @ f[:, :2], a @ f[:, :2], b @ f[:, :2], radius * (1 + 1e-9),
                                np.zeros(len(a), bool))
    return _bundle_pairs(o, d, a, b, radius)

# SPDX-License-Identifier: GPL-3.0-or-later
"""The shape in float64: ray vs cut cylinder and the normal of the surface entered, the
mirror of tracer/shaders/shapes_cylinder.glsl, vectorised over (ray, cylinder) pairs."""
import numpy as np

BIG = 1e30


class CylinderSet:
    """The cylinders in float64 plus what the hit test derives from them."""

    def __init__(self, cylinders):
        c = cylinders
        self.top = c.top.astype(np.float64)
        self.tip = c.tip.astype(np.float64)
        self.n2 = c.n2.astype(np.float64)
        self.radius = c.radius.astype(np.float64)
        self.alpha = c.alpha.astype(np.float64)
        self.color = c.color.astype(np.float64)
        self.flags = c.flags.astype(np.int64)
        self.ext = c.extension.astype(np.float64)
        # The solid lies within the radius of the axis from top to `far`, the tip moved on
        # by the extension (how far plane 2 reaches past it).
        axis = self.tip - self.top
        self.far = self.tip + axis * (self.ext / np.linalg.norm(axis, axis=1))[:, None]

    def __len__(self):
        return len(self.top)


def intersect(cyl, ids, o, d, widen_per_t=0.0, widen_const=0.0, min_px=False, cap=1.0):
    """The shader's hit_cylinder_ab for pairs (o[k], d[k], ids[k]): entry distance t (inf on a
    miss), entry surface (0 side, 1 plane 1, 2 plane 2) and alpha scale."""
    A, B, n2 = cyl.top[ids], cyl.tip[ids], cyl.n2[ids]
    ax = B - A
    dot = lambda x, y: np.einsum("ij,ij->i", x, y)  # noqa: E731
    tc = dot(A + 0.5 * ax - o, d)
    w = o + tc[:, None] * d - A
    r = cyl.radius[ids].copy()
    ascale = np.ones(len(ids))
    want = None
    if min_px:
        want = widen_const + widen_per_t * np.abs(tc)
        rw = np.clip(want, r, r * cap)
        ascale = r / np.maximum(rw, 1e-30)
        r = rw
    L2 = dot(ax, ax)
    dn, wn = dot(d, ax), dot(w, ax)
    dp = d - ax * (dn / L2)[:, None]
    wp = w - ax * (wn / L2)[:, None]
    a, b, c = dot(dp, dp), dot(dp, wp), dot(wp, wp) - r * r
    par = a < 1e-12
    disc = b * b - a * c
    miss = np.where(par, c > 0, disc < 0)
    s = np.sqrt(np.maximum(disc, 0))
    with np.errstate(divide="ignore", invalid="ignore"):
        tin = np.where(par, -BIG, (-b - s) / a)
        tout = np.where(par, BIG, (-b + s) / a)
        surf = np.zeros(len(ids), np.int64)
        t1 = -wn / dn
        e1 = (dn > 0) & (t1 > tin)
        tin = np.where(e1, t1, tin)
        surf[e1] = 1
        tout = np.where(dn < 0, np.minimum(tout, t1), tout)
        miss |= (dn == 0) & (wn < 0)
        d2, w2 = dot(d, n2), dot(ax - w, n2)
        t2 = w2 / d2
        e2 = (d2 < 0) & (t2 > tin)
        tin = np.where(e2, t2, tin)
        surf[e2] = 2
        tout = np.where(d2 > 0, np.minimum(tout, t2), tout)
        miss |= (d2 == 0) & (w2 < 0)
    miss |= tin > tout
    # An entry through a shared plane is no surface where the neighbour's section (points
    # within its radius of its axis: the next cylinder's axis is n2, the previous one's runs
    # into A) covers it; elsewhere it is one of the exposed crescents of SPEC §6.
    flags = cyl.flags[ids]
    shared = ((surf == 1) & ((flags & 1) == 0)) | ((surf == 2) & ((flags & 2) == 0))
    nb = ids + np.where(shared, np.where(surf == 2, 1, -1), 0)
    with np.errstate(invalid="ignore"):
        q = w + np.where(shared, tin, 0.0)[:, None] * d - np.where((surf == 2)[:, None], ax, 0.0)
    na = np.where((surf == 2)[:, None], n2, A - cyl.top[nb])
    rn = cyl.radius[nb]
    if want is not None:
        rn = np.clip(want, rn, rn * cap)
    qa, aa = dot(q, na), dot(na, na)
    miss |= shared & (dot(q, q) * aa - qa * qa < rn * rn * aa)
    t = np.where(miss, np.inf, tc + tin)
    return t, surf, ascale


def cylinder_normal(cyl, ids, surf, p, d, T):
    """The shader's cylinder_normal: the normal of the surface entered (SPEC §7), facing the
    ray; T the unit tangents."""
    dot = lambda x, y: np.einsum("ij,ij->i", x, y)  # noqa: E731
    q = p - cyl.tip[ids]
    N = q - T * dot(q, T)[:, None]
    N = np.where((surf == 1)[:, None], -T, N)
    N = np.where((surf == 2)[:, None], cyl.n2[ids], N)
    nl = np.linalg.norm(N, axis=1)
    N = np.where((nl > 0)[:, None], N / np.maximum(nl, 1e-300)[:, None], -d)
    return np.where((dot(N, d) > 0)[:, None], -N, N)

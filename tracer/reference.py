# SPDX-License-Identifier: GPL-3.0-or-later
"""Float64 CPU reference tracer of exactly the GPU tracer's model (shaders/trace.glsl):
the same cylinders and cut planes, the same entry rule, shading, layers, shadows, sample
positions and minimum pixel width. Brute force over cylinders, vectorised over ray/cylinder
pairs that survive a bounding-sphere test; meant for small images (tests, error figures).
"""
import numpy as np

from .cylinders import strands_to_cylinders
from .ray_bundles import candidate_pairs
from .settings import RenderSettings

BIG = 1e30


def _hash32(x):
    x = x.astype(np.uint32)
    x ^= x >> np.uint32(16)
    x *= np.uint32(0x7FEB352D)
    x ^= x >> np.uint32(15)
    x *= np.uint32(0x846CA68B)
    x ^= x >> np.uint32(16)
    return x


def sample_positions(width, height, spp_n):
    """Continuous pixel coordinates (x from the left, y from the top) of every sample,
    shape (H, W, spp_n², 2): pixel centres for one sample, otherwise one jittered sample per
    stratum, jittered by the shader's hash of (sample, row, column)."""
    py, px, s = np.meshgrid(np.arange(height), np.arange(width), np.arange(spp_n * spp_n), indexing="ij")
    if spp_n == 1:
        jx = np.full(px.shape, 0.5)
        jy = np.full(px.shape, 0.5)
    else:
        h = _hash32(_hash32(_hash32(s.astype(np.uint32)) ^ py.astype(np.uint32)) ^ px.astype(np.uint32))
        rx = (h >> np.uint32(8)).astype(np.float64) / 16777216.0
        ry = (_hash32(h ^ np.uint32(0x68BC21EB)) >> np.uint32(8)).astype(np.float64) / 16777216.0
        jx = ((s % spp_n) + rx) / spp_n
        jy = ((s // spp_n) + ry) / spp_n
    return np.stack([px + jx, py + jy], axis=-1)


class _Cyl:
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


def _candidates(cyl, o, d, rmax, target=None):
    """Pairs (ray, cylinder) that may meet (all that do: ray_bundles); `rmax` the radius
    each cylinder may be widened to; `target` where all the rays end (a point light)."""
    return candidate_pairs(o, d, cyl.top, cyl.far, rmax, target)


def intersect(cyl, ids, o, d, widen_per_t=0.0, widen_const=0.0, min_px=False, cap=1.0):
    """The shader's hit_cylinder for pairs (o[k], d[k], ids[k]): entry distance t (inf on a
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


def _shadow(cyl, p, L, tmax, own, tmin, settings, target=None):
    """Transmittance toward the light for every point (the shader's shadow_ray); `target`
    the point light's position."""
    trans = np.ones(len(p))
    rr, cc = _candidates(cyl, p, L, cyl.radius, target)
    keep = cc != own[rr]
    rr, cc = rr[keep], cc[keep]
    if not len(rr):
        return trans
    t, _, _ = intersect(cyl, cc, p[rr], L[rr])
    hit = (t > tmin[rr]) & (t < tmax[rr])
    if settings.shadow_mode == "hard":
        trans[np.unique(rr[hit])] = 0.0
        return trans
    logs = np.zeros(len(p))
    with np.errstate(divide="ignore"):
        np.add.at(logs, rr[hit], np.log1p(-cyl.alpha[cc[hit]]))
    trans = np.exp(logs)
    trans[trans < settings.transmittance_eps] = 0.0
    return trans


def _shade(cyl, ids, surf, o, d, t, settings):
    A, B = cyl.top[ids], cyl.tip[ids]
    col = cyl.color[ids]
    T = B - A
    T /= np.linalg.norm(T, axis=1)[:, None]
    p = o + t[:, None] * d
    dot = lambda x, y: np.einsum("ij,ij->i", x, y)  # noqa: E731
    if settings.shading == "phong":
        q = p - B
        N = q - T * dot(q, T)[:, None]
        N = np.where((surf == 1)[:, None], -T, N)
        N = np.where((surf == 2)[:, None], cyl.n2[ids], N)
        nl = np.linalg.norm(N, axis=1)
        N = np.where((nl > 0)[:, None], N / np.maximum(nl, 1e-300)[:, None], -d)
        N = np.where((dot(N, d) > 0)[:, None], -N, N)
    out = settings.ambient * col
    for light in settings.lights:
        vec, lcol = light.packed()
        if vec[3] > 0.5:
            L = np.asarray(vec[:3]) - p
            dist = np.linalg.norm(L, axis=1)
            L = L / np.maximum(dist, 1e-30)[:, None]
        else:
            L = np.broadcast_to(-np.asarray(vec[:3]), p.shape)
            dist = np.full(len(p), BIG)
        lit = np.ones(len(p))
        if settings.shadows:
            lit = _shadow(cyl, p, np.ascontiguousarray(L), dist, ids, 1e-3 * cyl.radius[ids], settings,
                          vec[:3] if vec[3] > 0.5 else None)
        if settings.shading == "kajiya-kay":
            tl, tv = dot(T, L), dot(T, d)
            sl = np.sqrt(np.maximum(0, 1 - tl * tl))
            sv = np.sqrt(np.maximum(0, 1 - tv * tv))
            diff = sl
            spec = np.maximum(0, tl * tv + sl * sv) ** settings.shininess
        else:
            diff = np.maximum(dot(N, L), 0)
            R = 2 * dot(N, L)[:, None] * N - L
            spec = np.where(diff > 0, np.maximum(dot(R, -d), 0) ** settings.shininess, 0)
        out = out + (lit * (lit > 0))[:, None] * np.asarray(lcol) * (
            settings.diffuse * diff[:, None] * col + settings.specular * spec[:, None])
    return out


def pixel_samples(camera, spp_n, pixels=None):
    """Sample positions (P·spp_n², 2) of the whole image (pixels None: P = W·H, row by row)
    or of the pixels (P,2) int columns x, y; the same samples as the GPU's for those pixels."""
    w, h = camera.size
    pos = sample_positions(w, h, spp_n)
    if pixels is None:
        return pos.reshape(-1, 2)
    px = np.asarray(pixels, np.int64)
    if px.ndim != 2 or px.shape[1] != 2 or (px < 0).any() or (px[:, 0] >= w).any() or (px[:, 1] >= h).any():
        raise ValueError(f"pixels: expected (P, 2) integer x, y inside {w}x{h}, got shape {px.shape}")
    return pos[px[:, 1], px[:, 0]].reshape(-1, 2)


def finish_pixels(rgba, camera, spp_n, pixels=None):
    """Per-sample RGBA (P·spp_n², 4) -> the image (H, W, 4), or (P, 4) for `pixels`."""
    w, h = camera.size
    shape = (h, w) if pixels is None else (len(pixels),)
    return rgba.reshape(shape + (spp_n * spp_n, 4)).mean(axis=-2)


def reference_render(strands, camera, settings=None, cylinders=None, pixels=None):
    """(H, W, 4) float64 premultiplied linear RGBA, row 0 = top; the GPU tracer's model.
    `pixels` (P,2) int x, y: only those pixels, (P, 4) (whole-image figures on a subset of
    rays when every ray costs too much)."""
    settings = settings or RenderSettings()
    settings.check()
    cyl = _Cyl(cylinders if cylinders is not None else strands_to_cylinders(strands))
    w, h = camera.size
    n = settings.spp_n
    pos = pixel_samples(camera, n, pixels)
    o, d = camera.rays(pos[:, 0], pos[:, 1])
    nray = len(o)
    C = np.zeros((nray, 3))
    T = np.ones(nray)
    if len(cyl):
        opaque = cyl.alpha.min() >= 1.0 and not settings.min_pixel_width
        K = 1 if opaque else settings.layers
        if camera.type == "ORTHO":
            widen_per_t, widen_const = 0.0, 0.5 * camera.pixel_size
        else:
            u = (pos[:, 0] - w / 2 + camera.shift_px[0]) * camera.pixel_size
            v = (h / 2 - pos[:, 1] + camera.shift_px[1]) * camera.pixel_size
            widen_per_t = 0.5 * camera.pixel_size / np.sqrt(u * u + v * v + 1)
            widen_const = 0.0
        rmax = cyl.radius * (settings.min_pixel_width_cap if settings.min_pixel_width else 1.0)
        rr, cc = _candidates(cyl, o, d, rmax)
        wpt = widen_per_t[rr] if np.ndim(widen_per_t) else widen_per_t
        t, surf, asc = intersect(cyl, cc, o[rr], d[rr], wpt, widen_const,
                                 settings.min_pixel_width, settings.min_pixel_width_cap)
        ok = np.isfinite(t) & (t > 0)
        rr, cc, t, surf, asc = rr[ok], cc[ok], t[ok], surf[ok], asc[ok]
        order = np.lexsort((t, rr))
        rr, cc, t, surf, asc = rr[order], cc[order], t[order], surf[order], asc[order]
        first = np.searchsorted(rr, rr, side="left")
        rank = np.arange(len(rr)) - first
        for k in range(K):
            sel = rank == k
            r_k = rr[sel]
            live = T[r_k] >= settings.transmittance_eps if k else np.ones(len(r_k), bool)
            r_k = r_k[live]
            if not len(r_k):
                break
            ids, s_k, t_k, a_k = cc[sel][live], surf[sel][live], t[sel][live], asc[sel][live]
            col = _shade(cyl, ids, s_k, o[r_k], d[r_k], t_k, settings)
            alpha = cyl.alpha[ids] * a_k
            C[r_k] += (T[r_k] * alpha)[:, None] * col
            T[r_k] *= 1 - alpha
    bg = np.asarray(settings.premultiplied_background(), np.float64)
    rgba = np.concatenate([C + T[:, None] * bg[:3], (1 - T + T * bg[3])[:, None]], axis=1)
    return finish_pixels(rgba, camera, n, pixels)

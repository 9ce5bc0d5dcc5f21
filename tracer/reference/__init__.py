# SPDX-License-Identifier: GPL-3.0-or-later
"""Float64 CPU reference tracer of exactly the GPU tracer's model (tracer/shaders): the same
cylinders and cut planes, the same entry rule, shading, layers, shadows, sample positions
and minimum pixel width. Brute force over cylinders, vectorised over ray/cylinder pairs
that survive a bounding-sphere test; meant for small images (tests, error figures).

Split as the shaders are: shapes (shapes_cylinder.glsl), traversal (what accel.glsl asks
of an accelerator), triangles (meshes: shapes_triangle.glsl, accel_mesh_grid.glsl), shading
(the float64 functions of tracer/shading's registry), samples and this module
(trace_main.glsl: rays, layers, lights, the meshes' diffuse shading).
"""
import numpy as np

from ..cylinders import strands_to_cylinders
from ..meshes import mesh_set
from ..settings import RenderSettings
from ..shading import Surface, shading_model
from .samples import finish_pixels, light_sample, light_seeds, pixel_samples, sample_positions  # noqa: F401  (the API)
from .shapes import BIG, CylinderSet, cylinder_normal, intersect
from .traversal import candidates, transmittance
from .triangles import TriangleSet, mesh_blocked, mesh_nearest


def _lights(settings, p, seeds, k):
    """Per light: unit directions from every point p toward its point drawn for the pixel's
    k-th shading (the shader's light_sample: `seeds` per point, Light.towards), distances, its
    colour (per point, (N, 3), for a light that falls off with distance: Light.scale), the
    point every shadow ray heads for (a light without extent; None: a directional light or
    points of their own), and whether shadow rays go toward it (the settings' and its own)."""
    for l, light in enumerate(settings.lights):
        u = light_sample(seeds, k, l, len(settings.lights))
        L, dist = light.towards(p, u)
        lcol = light.packed()[1]
        shadowed = settings.shadows and light.shadows
        yield L, dist, np.asarray(lcol) * light.scale(L, dist)[:, None], light.target(), shadowed


def _hair_transmittance(cyl, p, L, dist, own, tmin, settings, target):
    if not len(cyl):
        return np.ones(len(p))
    return transmittance(cyl, p, np.ascontiguousarray(L), dist, own, tmin, settings, target)


MESH_SHADING = 255      # trace_main.glsl's index of the mesh's shading for light_sample


def shade_mesh(cyl, tris, tri, o, d, t, n, settings, seeds):
    """The shader's shade_mesh: base colour times ambient plus every light's colour times
    max(N·L, 0) times the model's mesh_brdf (tracer/shading), in the shadow of hair and meshes (shadow rays leave tris.offset off the
    surface and ignore the triangle they leave)."""
    col = tris.color[tri]
    brdf = shading_model(settings.shading).mesh_brdf
    q = o + t[:, None] * d + n * tris.offset
    out = settings.ambient * col
    for L, dist, lcol, target, shadowed in _lights(settings, q, seeds, MESH_SHADING):
        lit = np.ones(len(q))
        if shadowed:
            lit = _hair_transmittance(cyl, q, L, dist, np.full(len(q), -1), np.zeros(len(q)), settings, target)
            lit[mesh_blocked(tris, q, L, dist, tri)] = 0.0
        nl = np.maximum(np.einsum("ij,ij->i", n, L), 0.0)
        out = out + (lit * (lit > 0))[:, None] * lcol * nl[:, None] * (brdf * col)
    return out


def shade(cyl, ids, surf, o, d, t, settings, seeds, k, tris=None):
    """The shader's shade: ambient plus every light's shade_light of the settings' model,
    each light's part times its transmittance (0 behind a mesh of `tris`)."""
    model = shading_model(settings.shading)
    A, B = cyl.top[ids], cyl.tip[ids]
    col = cyl.color[ids]
    T = B - A
    T /= np.linalg.norm(T, axis=1)[:, None]
    p = o + t[:, None] * d
    N = cylinder_normal(cyl, ids, surf, p, d, T) if model.needs_normal else None
    s = Surface(p=p, T=T, N=N, V=d, color=col)
    out = settings.ambient * col
    for L, dist, lcol, target, shadowed in _lights(settings, p, seeds, k):
        lit = np.ones(len(p))
        if shadowed:
            lit = transmittance(cyl, p, np.ascontiguousarray(L), dist, ids, 1e-3 * cyl.radius[ids], settings, target)
            if tris is not None:
                lit[mesh_blocked(tris, p, L, dist)] = 0.0
        out = out + (lit * (lit > 0))[:, None] * lcol * model.reference(s, L, settings)
    return out


def reference_render(strands, camera, settings=None, cylinders=None, pixels=None, meshes=None):
    """(H, W, 4) float64 premultiplied linear RGBA, row 0 = top; the GPU tracer's model.
    `pixels` (P,2) int x, y: only those pixels, (P, 4) (whole-image figures on a subset of
    rays when every ray costs too much). `meshes`: as Renderer.set_meshes takes them."""
    settings = settings or RenderSettings()
    settings.check()
    checked = mesh_set(meshes)
    tris = None if checked is None else TriangleSet(checked)
    cyl = CylinderSet(cylinders if cylinders is not None else strands_to_cylinders(strands))
    w, h = camera.size
    n = settings.spp_n
    pos = pixel_samples(camera, n, pixels)
    seeds = light_seeds(camera, n, pixels)
    o, d = camera.rays(pos[:, 0], pos[:, 1])
    nray = len(o)
    C = np.zeros((nray, 3))
    T = np.ones(nray)
    tmesh = np.full(nray, BIG)
    if tris is not None:        # the nearest mesh hides every hair behind it
        tmesh, mtri, mnormal = mesh_nearest(tris, o, d, BIG)
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
        rr, cc = candidates(cyl, o, d, rmax)
        wpt = widen_per_t[rr] if np.ndim(widen_per_t) else widen_per_t
        t, surf, asc = intersect(cyl, cc, o[rr], d[rr], wpt, widen_const,
                                 settings.min_pixel_width, settings.min_pixel_width_cap)
        ok = np.isfinite(t) & (t > 0) & (t < tmesh[rr])
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
            col = shade(cyl, ids, s_k, o[r_k], d[r_k], t_k, settings, seeds[r_k], k, tris)
            alpha = cyl.alpha[ids] * a_k
            C[r_k] += (T[r_k] * alpha)[:, None] * col
            T[r_k] *= 1 - alpha
    if tris is not None:        # opaque: what is left of each ray ends on the mesh
        r_m = np.flatnonzero(mtri >= 0)
        C[r_m] += T[r_m, None] * shade_mesh(cyl, tris, mtri[r_m], o[r_m], d[r_m], tmesh[r_m], mnormal[r_m], settings,
                                            seeds[r_m])
        T[r_m] = 0.0
    bg = np.asarray(settings.premultiplied_background(), np.float64)
    rgba = np.concatenate([C + T[:, None] * bg[:3], (1 - T + T * bg[3])[:, None]], axis=1)
    return finish_pixels(rgba, camera, n, pixels)

# SPDX-License-Identifier: GPL-3.0-or-later
"""Traversal in float64, the part the GPU leaves to its accelerator (tracer/shaders/accel.glsl):
which cylinders a ray can meet (every one a ray comes near, tracer/ray_bundles.py: brute
force, no grid) and the transmittance of shadow rays."""
import numpy as np

from ..ray_bundles import candidate_pairs
from .shapes import intersect


def candidates(cyl, o, d, rmax, target=None):
    """Pairs (ray, cylinder) that may meet (all that do: ray_bundles); `rmax` the radius
    each cylinder may be widened to; `target` where all the rays end (a point light)."""
    return candidate_pairs(o, d, cyl.top, cyl.far, rmax, target)


def transmittance(cyl, p, L, tmax, own, tmin, settings, target=None):
    """Transmittance toward the light for every point (the shader's shadow_ray); `target`
    the point light's position."""
    trans = np.ones(len(p))
    rr, cc = candidates(cyl, p, L, cyl.radius, target)
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

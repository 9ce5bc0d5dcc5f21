# SPDX-License-Identifier: GPL-3.0-or-later
"""Strands as continual cylinders (SPEC §6): how many, how thick, what colour, how opaque.

A strand of n+1 points is n cylinders. The thesis uses a fixed count (typically 25) and notes
straight hair needs only 3–4; `error_bound_cylinders` gives each strand the fewest
cylinders whose polyline provably stays within a tolerance of the exact curve, and
`geometric_error` measures the result the way SPEC §6 defines it.
"""
import numpy as np

from . import rng


def error_bound_cylinders(frac, guides, weights, accel, tolerance, max_cylinders):
    """Fewest cylinders c (uniform in σ) with the polyline provably within `tolerance`:
    for a curve with |C''| <= A over a parameter step h, the chord is within A·h²/8, and
    |C_j''| <= Σ w_x |D_x''| (B_j is a rotation), so c = ceil(f·sqrt(A/(8·tol)))."""
    samples = accel.shape[1]
    last = np.minimum(np.ceil(frac * (samples - 1)).astype(np.int64), samples - 1)
    a = (weights[:, 0] * accel[guides[:, 0], last] + weights[:, 1] * accel[guides[:, 1], last]
         + weights[:, 2] * accel[guides[:, 2], last])
    c = np.ceil(frac * np.sqrt(a / (8.0 * tolerance)))
    return np.clip(c, 1, max_cylinders).astype(np.int64)



def strand_attributes(seed, ids, counts, base_radius, base_color, params):
    """Per-point radius, colour and alpha (SPEC §6) for strands with `counts` points.

    Position along a strand is s = k / (count - 1), so the profile is the same whatever the
    resolution. Colour: base + U(-1,1)·variation per strand and per point, clamped to [0,1]."""
    n_pts = int(counts.sum())
    strand = np.repeat(np.arange(len(counts)), counts)
    offsets = np.zeros(len(counts), np.int64)
    np.cumsum(counts[:-1], out=offsets[1:])
    k = np.arange(n_pts) - offsets[strand]
    s = k / (counts[strand] - 1)
    r = base_radius[strand]
    if params.radius_mode == "linear":
        radius = r * (1.0 - s)
    elif params.radius_mode == "constant":
        radius = r.copy()
    else:
        span = max(1.0 - params.taper_start, 1e-12)
        radius = r * np.clip((1.0 - s) / span, 0.0, 1.0)
    var = np.asarray(params.color_variation)
    color = base_color.copy()
    if var.any():
        u = np.stack([rng.uniform(seed, ids, rng.CH_COLOR + c) for c in range(3)], 1)
        color = color + (2.0 * u - 1.0) * var
    color = color[strand]
    var_p = np.asarray(params.color_variation_point)
    if var_p.any():
        sid = ids[strand]
        u = np.stack([rng.uniform(seed, sid, rng.CH_COLOR_POINT + 3 * k + c) for c in range(3)], 1)
        color = color + (2.0 * u - 1.0) * var_p
    np.clip(color, 0.0, 1.0, out=color)
    if params.alpha_start >= 1.0 or params.alpha_tip == 1.0:
        alpha = np.ones(n_pts)
    else:
        t = np.clip((s - params.alpha_start) / (1.0 - params.alpha_start), 0.0, 1.0)
        alpha = 1.0 + (params.alpha_tip - 1.0) * t
    return radius, color, alpha


def _segment_distances(points, a, b):
    """Distance from each point (N,3) to the nearest of the segments a[i]–b[i] (M,3)."""
    ab = b - a
    len2 = np.einsum("md,md->m", ab, ab)
    ap = points[:, None, :] - a[None, :, :]
    t = np.einsum("nmd,md->nm", ap, ab) / np.where(len2 > 0, len2, 1.0)
    t = np.clip(np.where(len2 > 0, t, 0.0), 0.0, 1.0)
    diff = ap - t[..., None] * ab[None]
    return np.sqrt(np.einsum("nmd,nmd->nm", diff, diff)).min(axis=1)


def geometric_error(exact_dense, polyline):
    """(max, 99th percentile) distance from the exact curve, densely sampled (SPEC §6: at 64×
    the polyline's resolution), to the polyline. Accepts one strand ((n,3), (m,3)) or a batch
    of strands with equal counts ((S,n,3), (S,m,3)); the statistics are over all samples."""
    exact = np.asarray(exact_dense, dtype=np.float64)
    poly = np.asarray(polyline, dtype=np.float64)
    if exact.ndim == 2:
        exact, poly = exact[None], poly[None]
    dists = np.concatenate([_segment_distances(e, p[:-1], p[1:]) if len(p) > 1
                            else np.linalg.norm(e - p[0], axis=1) for e, p in zip(exact, poly)])
    return float(dists.max()), float(np.percentile(dists, 99))


def strand_geometric_errors(exact_dense, polyline):
    """Per-strand maximum distance, batch form of geometric_error: (S,) float64."""
    exact = np.asarray(exact_dense, dtype=np.float64)
    poly = np.asarray(polyline, dtype=np.float64)
    return np.array([_segment_distances(e, p[:-1], p[1:]).max() for e, p in zip(exact, poly)])

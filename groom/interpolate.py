# SPDX-License-Identifier: GPL-3.0-or-later
"""Ordinary strands from key strands (SPEC §5).

Every key is resampled by arc length into a table of KEY_SAMPLES root-relative offsets
D_x(σ), σ in [0, 1] the fraction of its length. Strand j is the curve

    C_j(σ) = R_j + M_j · Σ_x w_x · (F_j F_x^T) · D_x(σ),   σ in [0, f_j]

(M_j the tidiness rotation, F the root frames, f_j the length fraction). With the
intelligence flag the table holds F_x^T D_x (the key's shape in its own root frame) and the
strand applies B_j = F_j·Rloc_j; without it the table holds world offsets and
B_j = F_j·Rloc_j·F_j^T (translate only, apart from tidiness), Rloc_j the tidiness angles
about the root's own axes. Length is set by TRIMMING: the strand stops at the fraction f_j
of its keys' arc length, so curls keep their size.

The weights w_x come from wisps.guide_weights; the default neighbour mode was chosen by
measurement (measure.py holds the numbers). Each strand is evaluated at its own curve
parameters σ (equal steps at fixed resolution, cylinders.adaptive_sigma otherwise), in
whole-array chunks of strands, never a loop over strands. Every operation is element-wise
per strand, so evaluating a subset of strands gives bit-identical results to evaluating
them all (incremental regeneration relies on it).
"""
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from . import rng
from .frames import rotation_xyz

# Arc-length samples per key table (1024 steps): the lerp between samples is off the exact
# curve by at most |D''|·h²/8 with h = 1/1024, about 1e-7 of the length for a curl of 20 turns.
KEY_SAMPLES = 1025
# Curvature bins per key for the adaptive resolution (SAMPLES - 1 must be a multiple).
CURVATURE_BINS = 128
# The sampled curvature can miss a peak between samples; bound it with a margin.
_CURVATURE_SAFETY = 1.05


def key_table(key, frame, intelligence, samples=KEY_SAMPLES, bins=CURVATURE_BINS):
    """(table (samples,3) float64, bound (bins,) float64): offsets of the key from its root
    at equal arc-length steps (in the key's root frame when `intelligence`, else world axes),
    and for each of `bins` equal ranges of σ an upper bound of |d²D/dσ²| there (the largest
    sampled curvature·length² over the bin's samples and one beyond each end, times a margin)."""
    table, length = key.arc_length_table(samples)
    if intelligence:
        table = table @ frame  # rows: F_x^T D
    steps = samples - 1
    # |D''(σ)| = κ·L² for a curve parametrised by arc-length fraction. κ from the circle through
    # three neighbouring samples (Menger curvature), which is blind to the small uneven spacing
    # of the samples that a plain second difference would read as bending.
    second = np.zeros(samples)
    if samples >= 3:
        u, v = table[1:-1] - table[:-2], table[2:] - table[1:-1]
        lu, lv, lw = (np.linalg.norm(x, axis=1) for x in (u, v, u + v))
        denom = lu * lv * lw
        cross = np.linalg.norm(np.cross(u, v), axis=1)
        kappa = np.where(denom > 0, 2.0 * cross / np.where(denom > 0, denom, 1.0), 0.0)
        second[1:-1] = kappa * length * length
        second[0], second[-1] = second[1], second[-2]
    per = steps // bins
    padded = np.concatenate([[second[0]], second, [second[-1]]])
    # bin b covers samples b·per .. (b+1)·per; padded index = sample + 1, widened by one each side
    idx = np.arange(bins)[:, None] * per + np.arange(per + 3)[None, :]
    bound = padded[idx].max(axis=1) * _CURVATURE_SAFETY
    return table, bound


def length_fractions(seed, ids, lo, hi):
    """Per-strand trim fraction, uniform in [lo, hi]."""
    return lo + (hi - lo) * rng.uniform(seed, ids, rng.CH_LENGTH)


def tidiness_angles(seed, ids, tidiness, theta_max):
    """Angles (S,3) about the root's main tangent, second tangent and normal, each uniform in
    ±(1 - tidiness)·theta_max; exactly 0 at tidiness 1."""
    amp = (1.0 - tidiness) * theta_max
    u = np.stack([rng.uniform(seed, ids, c) for c in (rng.CH_TIDY_X, rng.CH_TIDY_Y, rng.CH_TIDY_Z)], 1)
    return (2.0 * u - 1.0) * amp


def strand_transforms(frames, angles, intelligence):
    """B_j (S,3,3) applied to the blended table offsets (see module docstring)."""
    if not np.any(angles):  # tidiness 1: no rotation at all
        return frames.copy() if intelligence else np.broadcast_to(np.eye(3), frames.shape).copy()
    rot = rotation_xyz(angles)
    b = _matmul3(frames, rot)
    if not intelligence:
        b = _matmul3(b, np.transpose(frames, (0, 2, 1)))
    return b


def _matmul3(a, b):
    """Batched 3x3 products written out, so each result depends only on its own inputs.

    The nine entries are first laid out entry-major (one contiguous row per entry): the
    strided reads of an (S,3,3) array made this 2.7x slower at 100k strands."""
    shape = np.broadcast_shapes(a.shape, b.shape)
    a = np.broadcast_to(a, shape).reshape(-1, 9).T.copy()
    b = np.broadcast_to(b, shape).reshape(-1, 9).T.copy()
    out = np.empty_like(a)
    for i in range(3):
        for j in range(3):
            out[3 * i + j] = a[3 * i] * b[j] + a[3 * i + 1] * b[3 + j] + a[3 * i + 2] * b[6 + j]
    return np.ascontiguousarray(out.T).reshape(shape)


def uniform_sigma(frac, cylinders):
    """Flat σ (P,) of strands with cylinders[j] equal steps over [0, f_j], and counts (S,)."""
    cylinders = np.asarray(cylinders, np.int64)
    counts = cylinders + 1
    if len(counts) and (counts == counts[0]).all():
        # One count for all (fixed resolution): a broadcast, no per-point gathers.
        c = int(cylinders[0])
        return (frac[:, None] * (np.arange(c + 1) / c)).ravel(), counts
    strand = np.repeat(np.arange(len(counts)), counts)
    offsets = np.zeros(len(counts), np.int64)
    np.cumsum(counts[:-1], out=offsets[1:])
    k = np.arange(int(counts.sum())) - offsets[strand]
    return frac[strand] * (k / cylinders[strand]), counts


def evaluate_strands(roots, transforms, guides, weights, counts, sigma, tables, chunk_points=1 << 16,
                     threads=None):
    """Points of strands at flat curve parameters σ (P,) (counts (S,) points per strand, in
    order): C_j(σ) = R_j + B_j Σ_g w_jg D_g(σ).

    roots (S,3) f64, transforms (S,3,3), guides (S,3), weights (S,3), tables (K, M, 3).
    Returns points (P,3) float32 (the precision Strands keeps). The blend runs in float32
    (offsets from the root: relative precision 6e-8 of the strand length wherever the head
    is) in chunks of whole strands of
    about `chunk_points` points that stay in cache; the root is added in float64. Chunks
    write disjoint rows and numpy releases the GIL in its loops, so they run on `threads`
    threads (default: one per CPU); a chunk's numbers do not depend on the thread."""
    n_keys, samples, _ = tables.shape
    # Component-major 1-D tables (value and step to the next sample, for the lerp): 1-D
    # gathers into contiguous arrays are about twice as fast as gathering 6-wide rows.
    step = np.concatenate([np.diff(tables, axis=1), np.zeros((n_keys, 1, 3))], axis=1)
    value_c = [np.ascontiguousarray(tables[..., c].ravel(), np.float32) for c in range(3)]
    step_c = [np.ascontiguousarray(step[..., c].ravel(), np.float32) for c in range(3)]
    w_c = [np.ascontiguousarray(weights[:, k], np.float32) for k in range(3)]
    b_c = [np.ascontiguousarray(transforms[:, i // 3, i % 3], np.float32) for i in range(9)]
    root_c = [np.ascontiguousarray(roots[:, c]) for c in range(3)]
    g_c = [np.ascontiguousarray(guides[:, k], np.int64) * samples for k in range(3)]
    counts = np.asarray(counts, np.int64)
    ends = np.cumsum(counts)
    out = np.empty((int(ends[-1]) if len(ends) else 0, 3), np.float32)
    bounds = []
    first = 0
    while first < len(counts):  # chunks of whole strands, ~64k points each, for the cache
        start = int(ends[first - 1]) if first else 0
        last = max(int(np.searchsorted(ends, start + chunk_points, side="right")), first + 1)
        bounds.append((first, last, start, int(ends[last - 1])))
        first = last

    def chunk(bound):
        first, last, start, stop = bound
        n_pts = counts[first:last]
        if n_pts[0] == n_pts[-1] and (n_pts == n_pts[0]).all():
            # Equal counts (fixed resolution): per-strand data broadcasts, nothing is gathered
            # per point.
            shape = (last - first, int(n_pts[0]))
            sl = slice(first, last)

            def per_strand(x):
                return x[sl, None]
        else:
            shape = (stop - start,)
            strand = np.repeat(np.arange(first, last), n_pts)

            def per_strand(x):
                return x[strand]
        pos = sigma[start:stop].reshape(shape) * (samples - 1)
        i0 = np.minimum(pos.astype(np.int64), samples - 2)
        fr = (pos - i0).astype(np.float32)
        acc = [None, None, None]
        for k in range(3):  # the three guides
            idx = per_strand(g_c[k]) + i0
            wk = per_strand(w_c[k])
            wf = wk * fr
            for c in range(3):
                term = wk * value_c[c].take(idx) + wf * step_c[c].take(idx)
                acc[c] = term if acc[c] is None else acc[c] + term
        dst = out[start:stop].reshape(shape + (3,))
        for a in range(3):
            # B_j · acc in float32 (offsets), plus the root in float64, stored as float32.
            dst[..., a] = (per_strand(b_c[3 * a]) * acc[0] + per_strand(b_c[3 * a + 1]) * acc[1]
                           + per_strand(b_c[3 * a + 2]) * acc[2]) + per_strand(root_c[a])

    threads = threads or os.cpu_count() or 1
    if threads > 1 and len(bounds) > 1:
        with ThreadPoolExecutor(max_workers=min(threads, len(bounds))) as pool:
            list(pool.map(chunk, bounds))
    else:
        for bound in bounds:
            chunk(bound)
    return out

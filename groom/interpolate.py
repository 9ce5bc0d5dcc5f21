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

Default neighbour mode, by measurement (measure.seam_jump on the default scalp, 'wavy'
preset keys, tidiness 1, equal lengths, 20,000 root pairs 0.5 mm apart): see
params.GroomParams.neighbour_mode and the numbers recorded in measure.py.

Each strand is evaluated at its own number of points; strands are grouped by that number
and each group is whole-array numpy (a loop over a handful of resolutions, never strands).
Every operation is element-wise per strand, so evaluating a subset of strands gives
bit-identical results to evaluating them all (incremental regeneration relies on it).
"""
import numpy as np

from . import rng
from .frames import rotation_xyz

# Arc-length samples per key table: the lerp between samples is off the exact curve by at
# most |D''|·h²/8 with h = 1/1023, about 1e-7 of the length for a curl of 20 turns.
KEY_SAMPLES = 1024
# The second-difference estimate of |D''| misses peaks between samples; bound it generously.
_CURVATURE_SAFETY = 1.05


def key_table(key, frame, intelligence, samples=KEY_SAMPLES):
    """(table (samples,3) float64, accel (samples,) float64): offsets of the key from its root at
    equal arc-length steps (in the key's root frame when `intelligence`, else world axes),
    and the running maximum over σ' <= σ of |d²D/dσ²| used to bound polyline error."""
    table, _ = key.arc_length_table(samples)
    if intelligence:
        table = table @ frame  # rows: F_x^T D
    h = 1.0 / (samples - 1)
    second = np.zeros(samples)
    if samples >= 3:
        second[1:-1] = np.linalg.norm(table[2:] - 2 * table[1:-1] + table[:-2], axis=1) / (h * h)
        second[0], second[-1] = second[1], second[-2]
    accel = np.maximum.accumulate(second) * _CURVATURE_SAFETY
    return table, accel


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
    rot = rotation_xyz(angles)
    b = _matmul3(frames, rot)
    if not intelligence:
        b = _matmul3(b, np.transpose(frames, (0, 2, 1)))
    return b


def _matmul3(a, b):
    """Batched 3x3 products written out, so each result depends only on its own inputs."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    for i in range(3):
        for j in range(3):
            out[..., i, j] = a[..., i, 0] * b[..., 0, j] + a[..., i, 1] * b[..., 1, j] + a[..., i, 2] * b[..., 2, j]
    return out


def evaluate_strands(roots, transforms, guides, weights, frac, cylinders, tables, chunk_points=1 << 16):
    """Points of each strand at cylinders[j] + 1 values of σ equally spaced in [0, f_j].

    roots (S,3) f64, transforms (S,3,3), guides (S,3), weights (S,3), frac (S,),
    cylinders (S,) int, tables (K, M, 3). Returns (points (P,3) float64, counts (S,) int64),
    strands in input order. The blend runs in float32 (offsets from the root: relative
    precision 6e-8 of the strand length wherever the head is) in chunks of about
    `chunk_points` points that stay in cache; the root is added in float64."""
    n_keys, samples, _ = tables.shape
    # One gather per guide fetches a sample and the step to the next one (lerp needs both).
    step = np.concatenate([np.diff(tables, axis=1), np.zeros((n_keys, 1, 3))], axis=1)
    packed = np.concatenate([tables, step], axis=2).reshape(-1, 6).astype(np.float32)
    w32 = weights.astype(np.float32)
    b32 = transforms.astype(np.float32)
    counts = np.asarray(cylinders, np.int64) + 1
    offsets = np.zeros(len(counts), np.int64)
    np.cumsum(counts[:-1], out=offsets[1:])
    out = np.empty((int(counts.sum()), 3))
    for c in np.unique(cylinders):  # a handful of distinct resolutions, not strands
        c = int(c)
        all_sel = np.flatnonzero(cylinders == c)
        per = max(1, chunk_points // (c + 1))
        kc = (np.arange(c + 1, dtype=np.float64) / c)
        for lo in range(0, len(all_sel), per):  # chunks of ~64k points, for the cache
            sel = all_sel[lo:lo + per]
            pos = (frac[sel, None] * kc) * (samples - 1)
            i0 = np.minimum(pos.astype(np.int64), samples - 2)
            fr = (pos - i0).astype(np.float32)[..., None]
            acc = None
            for g in range(3):  # the three guides
                row = np.take(packed, guides[sel, g, None] * samples + i0, axis=0)
                term = w32[sel, g, None, None] * (row[..., :3] + fr * row[..., 3:])
                acc = term if acc is None else acc + term
            b = b32[sel]
            pts = np.empty(acc.shape, np.float64)
            for a in range(3):
                pts[..., a] = (b[:, None, a, 0] * acc[..., 0] + b[:, None, a, 1] * acc[..., 1]
                               + b[:, None, a, 2] * acc[..., 2])
            pts += roots[sel, None, :]
            start = offsets[sel[0]]
            if sel[-1] - sel[0] == len(sel) - 1:  # a contiguous run of strands: one slice
                out[start:start + pts.shape[0] * (c + 1)] = pts.reshape(-1, 3)
            else:
                rows = offsets[sel, None] + np.arange(c + 1)
                out[rows.ravel()] = pts.reshape(-1, 3)
    return out, counts

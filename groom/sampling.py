# SPDX-License-Identifier: GPL-3.0-or-later
"""Root sampling (SPEC §2): exactly m roots, spread over the scalp by area (and density).

Triangle i gets its share (A_i·d_i / sum)·m rounded by largest remainder, so the counts sum
to m exactly and the split is deterministic. Inside a triangle a root is placed with
barycentrics (a·b, a·(1-b), 1-a), i.e. R = a(b·T_x + (1-b)·T_y) + (1-a)·T_z:

- `uniform` (default): a = sqrt(u), the square-root warp, uniform over the triangle;
- `seed`: a = u, the thesis's formula, whose density grows like 1/a toward T_z.

Root i's random numbers come from the counter-based stream (seed, i), so root i is the same
root whoever asks for it.
"""
from dataclasses import dataclass
from functools import partial

import numpy as np

from hairio import InputError

from . import rng
from .parallel import ranges, run_jobs

SAMPLING_MODES = ("uniform", "seed")


@dataclass(frozen=True, eq=False)
class RootSamples:
    """points (m,3) float64, tri (m,) int64, bary (m,3) float64, ids (m,) int64 (stable
    per-root ids: the sample index, used to seed each strand's random stream)."""
    points: np.ndarray
    tri: np.ndarray
    bary: np.ndarray
    ids: np.ndarray


def triangle_weights(scalp):
    """Area times mean vertex density per triangle (density 1 when the scalp has none)."""
    w = scalp.face_areas.copy()
    if scalp.density is not None:
        w *= scalp.density[scalp.triangles].mean(axis=1)
    return w


def allocate_counts(weights, m):
    """Integer counts proportional to weights, summing to exactly m (largest remainder;
    ties go to the lower index, so the result is deterministic)."""
    w = np.asarray(weights, dtype=np.float64)
    total = w.sum()
    if not (total > 0 and np.isfinite(total)):
        raise InputError("scalp: total (density-weighted) area is zero; nothing to grow hair on")
    share = w / total * m
    counts = np.floor(share).astype(np.int64)
    rest = m - int(counts.sum())
    if rest > 0:
        order = np.argsort(-(share - counts), kind="stable")
        counts[order[:rest]] += 1
    return counts


def sample_roots(scalp, m, seed=0, mode="uniform", lo=0, hi=None):
    """Exactly m roots on the scalp. Returns RootSamples sorted by triangle. lo, hi: only
    roots lo..hi of those m, the very same numbers (each root's triangle follows from the
    counts, its place from its own random stream), for a head grown a block at a time."""
    if isinstance(m, bool) or not isinstance(m, (int, np.integer)) or m < 1:
        raise InputError(f"count: expected an integer >= 1, got {m!r}")
    if mode not in SAMPLING_MODES:
        raise InputError(f"sampling_mode: expected one of {SAMPLING_MODES}, got {mode!r}")
    counts = allocate_counts(triangle_weights(scalp), int(m))
    hi = int(m) if hi is None else int(hi)
    ids = np.arange(int(lo), hi, dtype=np.int64)
    if lo == 0 and hi == int(m):
        tri = np.repeat(np.arange(scalp.num_triangles, dtype=np.int64), counts)
    else:   # the triangle root i falls in: the same as the repeat's entry i
        tri = np.searchsorted(np.cumsum(counts), ids, side="right").astype(np.int64)
    n = len(ids)
    points, bary = np.empty((n, 3)), np.empty((n, 3))

    def place(lo, hi):
        u = rng.uniform(seed, ids[lo:hi], rng.CH_TRIANGLE_A)
        b = rng.uniform(seed, ids[lo:hi], rng.CH_TRIANGLE_B)
        a = np.sqrt(u) if mode == "uniform" else u
        corners = [a * b, a * (1.0 - b), 1.0 - a]
        bary[lo:hi] = np.stack(corners, axis=1)
        points[lo:hi] = scalp.corner_blend(scalp.vertices, tri[lo:hi], corners).T
    run_jobs([partial(place, lo, hi) for lo, hi in ranges(n)])
    return RootSamples(points, tri, bary, ids)

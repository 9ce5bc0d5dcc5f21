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
import threading
import weakref
from collections import OrderedDict

import numpy as np

from . import rng
from .frames import rotation_entries
from .keys import arc_length_tables
from . import parallel

# Arc-length samples per key table (1024 steps): the lerp between samples is off the exact
# curve by at most |D''|·h²/8 with h = 1/1024 (on the bundled curly keys the points lay up to
# 7.8 µm off it, 16 % of a one-radius tolerance). Fixed resolution uses these; the adaptive
# resolution uses as many as its tolerance needs (table_samples).
KEY_SAMPLES = 1025
# Curvature bins per key for the adaptive resolution (SAMPLES - 1 must be a multiple).
CURVATURE_BINS = 128
# The sampled curvature can miss a peak between samples; bound it with a margin.
_CURVATURE_SAFETY = 1.05
# The adaptive resolution takes its curvature bound on tables this fine (64 samples a bin).
# The bundled presets' tightest turns are a few tenths of a millimetre long: on 1025 samples
# their bound came out 2 to 100 times below what 65,537 samples see, on these 2 to 14 times,
# where the segments the bound allows span several samples, and a turn between two samples
# then moves the chord by less than the bound says (measured against the exact curve:
# tests/groom/test_adaptive_tolerance.py).
FINE_SAMPLES = CURVATURE_BINS * 64 + 1
# The most samples a blend table may get (2 MB a key), and the exact curve of measurements
# (groom.measure.strand_errors): the lerp between them is off by 1/4096 of that of 1025.
MAX_TABLE_SAMPLES = CURVATURE_BINS * 512 + 1
EXACT_SAMPLES = MAX_TABLE_SAMPLES
# At adaptive resolution the lerp between table samples may stray by at most this share of
# the tolerance at the keys' tightest bend (elsewhere by less): the segments there can then
# still be most of what the tolerance allows (cylinders.adaptive_sigma counts the lerp in).
LERP_SHARE = 0.25


def key_offsets(keys, frames, intelligence, samples=KEY_SAMPLES):
    """[(table (samples,3) float64, read-only, length)] per key: offsets of the key from its
    root at equal arc-length steps (in the key's root frame when `intelligence`, else world
    axes), all that fixed resolution needs (adaptive resolution adds `curvature_bound`); the
    keys are resampled in one batch. The tables of the last few key sets are kept (by the
    keys' points, kind and frames): pressing Generate again on unchanged keys, or growing
    another count of strands from them, does not resample them again (a tenth of the time
    of 100,000 strands, and all of it on one thread)."""
    frames = [np.asarray(f, np.float64) for f in frames]
    cache = samples <= FINE_SAMPLES
    if cache:
        tag = (samples, bool(intelligence)) + tuple(
            (k.kind, k.points.shape, k.points.tobytes(), f.tobytes()) for k, f in zip(keys, frames))
        hit = _TABLES.get(tag)
        if hit is not None:
            _TABLES.move_to_end(tag)
            return list(hit)
    out = []
    for (table, length), frame in zip(arc_length_tables(keys, samples), frames):
        table = table @ frame if intelligence else table  # rows: F_x^T D
        table.flags.writeable = False
        out.append((table, length))
    if cache:
        _TABLES[tag] = tuple(out)
        while len(_TABLES) > _TABLES_KEPT:
            _TABLES.popitem(last=False)
    return out


# key_offsets' tables of recent key sets (at most FINE_SAMPLES each: some 5 MB for 24 keys).
_TABLES = OrderedDict()
_TABLES_KEPT = 4


def curvature_bound(table, length, bins=CURVATURE_BINS):
    """For each of `bins` equal ranges of σ an upper bound of |d²D/dσ²| there (the largest
    sampled curvature·length² over the bin's samples and one beyond each end, times a margin).
    Kept for the read-only tables key_offsets keeps (Generate again on the same keys)."""
    if table.flags.writeable:
        return _curvature_bound(table, length, bins)
    tag = (id(table), float(length), int(bins))
    hit = _BOUNDS.get(tag)
    if hit is not None and hit[0]() is table:
        _BOUNDS.move_to_end(tag)
        return hit[1].copy()
    bound = _curvature_bound(table, length, bins)
    _BOUNDS[tag] = (weakref.ref(table), bound.copy())   # a table gone frees its id: the ref says so
    while len(_BOUNDS) > _BOUNDS_KEPT:
        _BOUNDS.popitem(last=False)
    return bound


# curvature_bound's results for recent read-only tables (1 KB each).
_BOUNDS = OrderedDict()
_BOUNDS_KEPT = 1024


def _curvature_bound(table, length, bins):
    samples = len(table)
    steps = samples - 1
    # |D''(σ)| = κ·L² for a curve parametrised by arc-length fraction. κ from the circle through
    # three neighbouring samples (Menger curvature), which is blind to the small uneven spacing
    # of the samples that a plain second difference would read as bending.
    second = np.zeros(samples)
    if samples >= 3:
        u, v = table[1:-1] - table[:-2], table[2:] - table[1:-1]
        lu, lv, lw = (_row_norms(x) for x in (u, v, u + v))
        denom = lu * lv * lw
        cross = _row_norms(np.cross(u, v))
        kappa = np.where(denom > 0, 2.0 * cross / np.where(denom > 0, denom, 1.0), 0.0)
        second[1:-1] = kappa * length * length
        second[0], second[-1] = second[1], second[-2]
    per = steps // bins
    padded = np.concatenate([[second[0]], second, [second[-1]]])
    # bin b covers samples b·per .. (b+1)·per; padded index = sample + 1, widened by one each side
    idx = np.arange(bins)[:, None] * per + np.arange(per + 3)[None, :]
    return padded[idx].max(axis=1) * _CURVATURE_SAFETY


def _row_norms(x):
    """np.linalg.norm(x, axis=1) of an (n, 3) array, the same sum in the same order, without
    numpy's slow reduction over rows 3 long (a third of the time of a Generate of 1,000
    strands went to it)."""
    x0, x1, x2 = x[:, 0], x[:, 1], x[:, 2]
    return np.sqrt(x0 * x0 + x1 * x1 + x2 * x2)


def lerp_errors(bounds, samples):
    """(K,) how far the lerp between `samples` equally spaced table samples strays at most
    from each key's curve, from its curvature bound (K, bins): max |D''|·h²/8, h = 1/(samples - 1)."""
    return np.asarray(bounds, np.float64).max(axis=1) / (8.0 * (samples - 1) ** 2)


def table_samples(bounds, tolerance):
    """Samples of the blend's key tables at adaptive resolution: KEY_SAMPLES, or twice as
    many steps at a time (so the tables nest) until the lerp takes at most LERP_SHARE of
    `tolerance`, the smallest a strand has; at most MAX_TABLE_SAMPLES."""
    worst = float(np.max(bounds)) if np.size(bounds) else 0.0
    m = KEY_SAMPLES
    while m < MAX_TABLE_SAMPLES and worst / (8.0 * (m - 1) ** 2) > LERP_SHARE * tolerance:
        m = 2 * m - 1
    return m


def nested_table(table, samples):
    """The rows of a table of (samples - 1)·k + 1 equally spaced samples that a table of
    `samples` samples has (every k-th)."""
    step = (len(table) - 1) // (samples - 1)
    if step < 1 or (samples - 1) * step != len(table) - 1:
        raise ValueError(f"nested_table: {samples} samples do not nest in {len(table)}")
    return table[::step]


# The columns of key_rows' rows that hold numbers (the sample, then the step to the next).
_ROW_COLUMNS = (0, 1, 2, 4, 5, 6)


def key_rows(table):
    """The rows the strand blend gathers, (samples, 8) float32: sample i as
    (x, y, z, 0, dx, dy, dz, 0), d the step to sample i+1 (0 after the last). One 32-byte row
    per guide and point is a single fixed-size copy in numpy's take, where six separate
    component gathers cost about five times as much."""
    rows = np.zeros((len(table), 8), np.float32)
    rows[:, :3] = table
    rows[:-1, 4:7] = np.diff(table, axis=0)
    return rows


def length_fractions(seed, ids, lo, hi):
    """Per-strand trim fraction, uniform in [lo, hi]."""
    return lo + (hi - lo) * rng.uniform(seed, ids, rng.CH_LENGTH)


def tidiness_angles(seed, ids, tidiness, theta_max):
    """Angles (3, S) about the root's main tangent, second tangent and normal, each uniform
    in ±(1 - tidiness)·theta_max; exactly 0 at tidiness 1."""
    amp = (1.0 - tidiness) * theta_max
    u = np.stack([rng.uniform(seed, ids, c) for c in (rng.CH_TIDY_X, rng.CH_TIDY_Y, rng.CH_TIDY_Z)])
    return (2.0 * u - 1.0) * amp


def strand_transforms(axes, angles, intelligence):
    """B_j (see module docstring) entry-major, (9, S) float32: row 3a + c holds entry (a, c)
    of every strand's matrix, the layout the blend reads. axes: frames.frame_axes of the
    roots; angles (3, S) from tidiness_angles. Computed in float64, stored in the float32
    the blend works in."""
    # frame[3i + j] = entry (i, j) = component i of axis j
    frame = [axes[j][i] for i in range(3) for j in range(3)]
    if not np.any(angles):  # tidiness 1: no rotation at all
        if intelligence:
            return np.array(frame, np.float32)
        return np.eye(3, dtype=np.float32).reshape(9, 1).repeat(axes[0].shape[1], axis=1)
    out = _matmul3(frame, rotation_entries(angles))
    if not intelligence:
        out = _matmul3(out, [frame[3 * j + i] for i in range(3) for j in range(3)])  # · F^T
    return np.array(out, np.float32)


def _matmul3(a, b):
    """Products of 3x3 matrices given entry-major (lists of 9 arrays, entry 3i + j), written
    out so each result depends only on its own inputs."""
    return [a[3 * i] * b[j] + a[3 * i + 1] * b[3 + j] + a[3 * i + 2] * b[6 + j]
            for i in range(3) for j in range(3)]


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


def evaluate_strands(roots, transforms, guides, weights, counts, rows, sigma=None, frac=None,
                     chunk_points=1 << 15, threads=None, also=(), clump=None, out=None):
    """Points of strands at curve parameters σ: C_j(σ) = R_j + B_j Σ_g w_jg D_g(σ).

    All per-strand inputs are component-major, one contiguous row per component: roots
    (3, S) f64, transforms (9, S) f32 (strand_transforms), guides (3, S) key indices, weights
    (3, S) f32; rows (K, M, 8) f32 from key_rows; counts (S,) points per strand. σ is either
    `sigma`, flat (P,), or, when every strand has the same count n, None with `frac` (S,):
    σ = f_j·k/(n - 1), made a chunk at a time (the same numbers as uniform_sigma).

    Returns points (P,3) float32 (the precision Strands keeps). The blend runs in float32
    (offsets from the root: relative precision 6e-8 of the strand length wherever the head
    is); the root is added in float64. Per point: one 32-byte row gathered per guide, the
    weighted sum of the rows, then the lerp σ·(M-1) between the sample and the next (linear,
    so it commutes with the blend), then B_j. Chunks of whole strands of about
    `chunk_points` points write disjoint rows; numpy releases the GIL in its loops, so they
    run on `threads` threads (default: one per CPU), after the jobs `also` (other work the
    caller wants done meanwhile; their results are returned too). A strand's numbers depend
    only on its own inputs, never on its chunk or thread. Returns (points, [results of also]).

    clump: None or (scale, exponent, towards (3, S) f32) pulls each point a fraction
    c = scale·σ^exponent of the way to its wisp key (guide 0) carried to that key's root,
    R_key + B_j D_0(σ) (shaping.py): the blend becomes (1-c)·Σ_g w_g D_g + c·D_0 and the
    point moves by c·towards, towards = R_key - R_j; per-point weights, no extra gathers.

    out: None, or the (P, 3) float32 C-contiguous array to write the points into (a block's
    rows of the whole result: no copy of them afterwards).
    """
    n_keys, samples, _ = rows.shape
    table = rows.reshape(n_keys * samples, 8)
    first_row = [np.asarray(g, np.int64) * samples for g in guides]
    counts = np.asarray(counts, np.int64)
    ends = np.cumsum(counts)
    n_points = int(ends[-1]) if len(ends) else 0
    if out is None:
        out = np.empty((n_points, 3), np.float32)
    elif out.shape != (n_points, 3) or out.dtype != np.float32 or not out.flags.c_contiguous:
        raise ValueError(f"evaluate_strands: out must be a C-contiguous ({n_points}, 3) float32 array")
    equal = len(counts) > 0 and bool((counts == counts[0]).all())
    if sigma is None and not equal:
        raise ValueError("evaluate_strands: sigma is needed unless every strand has the same count")
    if equal:
        n = int(counts[0])
        grid = np.arange(n) / (n - 1)
        # Equal chunks, as many as a multiple of the threads, so no thread waits at the end.
        workers = threads or parallel.cpu_threads()
        parts = workers * max(1, -(-len(out) // (workers * chunk_points)))
        edges = [len(counts) * i // parts for i in range(parts + 1)]
        bounds = [(lo, hi) for lo, hi in zip(edges[:-1], edges[1:]) if hi > lo]
    else:
        bounds, first = [], 0
        while first < len(counts):  # chunks of whole strands of about chunk_points points
            start = int(ends[first - 1]) if first else 0
            last = max(int(np.searchsorted(ends, start + chunk_points, side="right")), first + 1)
            bounds.append((first, last))
            first = last

    def chunk(bound):
        first, last = bound
        start = int(ends[first - 1]) if first else 0
        stop = int(ends[last - 1])
        if equal:
            # Per-strand values broadcast along each strand's row of points; nothing is
            # gathered per point.
            shape = (last - first, n)
            sl = slice(first, last)

            def per_strand(x):
                return x[sl, None]
            src = None if sigma is None else sigma[start:stop].reshape(shape)
        else:
            shape = (stop - start,)
            n_of = counts[first:last]

            def per_strand(x):
                # Each strand's value repeated over its points: a copy per strand, some five
                # times faster than gathering it per point.
                return np.repeat(x[first:last], n_of)
            src = sigma[start:stop]
        # Every temporary lives in this thread's scratch arrays (out=): fresh arrays of this
        # size would have the allocator map and fault in new pages on every chunk.
        buf = _scratch(shape)
        pos, i0, fr, idx, acc, row, d, term = (buf[name] for name in ("pos", "i0", "fr", "idx", "acc", "row", "d",
                                                                     "term"))
        if src is None:
            np.multiply(frac[sl, None], grid, out=pos)  # σ, as uniform_sigma makes it
            src = pos
        pull = None
        if clump is not None:
            scale, exponent, towards = clump
            pull, keep = buf["pull"], buf["keep"]
            np.copyto(pull, src if exponent == 1.0 else np.power(src, exponent), casting="same_kind")
            pull *= np.float32(scale)
            np.subtract(np.float32(1.0), pull, out=keep)
        np.multiply(src, samples - 1, out=pos)
        np.copyto(i0, pos, casting="unsafe")  # truncation = floor, σ >= 0
        np.minimum(i0, samples - 2, out=i0)
        np.subtract(pos, i0, out=pos)
        np.copyto(fr, pos, casting="same_kind")
        for k in range(3):  # the three guides
            np.add(per_strand(first_row[k]), i0, out=idx)
            # mode="clip" (the indices are valid anyway) lets take write into `out` unbuffered.
            table.take(idx, axis=0, out=acc if k == 0 else row, mode="clip")
            wk = per_strand(weights[k])
            if pull is not None:
                wk = np.multiply(wk, keep, out=buf["wk"])
                if k == 0:
                    wk += pull
            scaled = acc if k == 0 else row
            if wk.shape == shape:
                # A weight a point: the six columns in use one at a time (a row of 8 times one
                # broadcast value is a loop of 8 per point in numpy, twice the time).
                for col in _ROW_COLUMNS:
                    scaled[..., col] *= wk
            else:
                scaled *= wk[..., None]
            if k:
                acc += row
        # Offsets in the keys' frame: sample + fraction · step, per component.
        for c in range(3):
            np.multiply(fr, acc[..., 4 + c], out=d[c])
            d[c] += acc[..., c]
        dst = out[start:stop].reshape(shape + (3,))
        for a in range(3):
            # B_j · d in float32 (offsets), plus the root in float64, stored as float32.
            e = buf["e"]
            np.multiply(per_strand(transforms[3 * a]), d[0], out=e)
            np.multiply(per_strand(transforms[3 * a + 1]), d[1], out=term)
            e += term
            np.multiply(per_strand(transforms[3 * a + 2]), d[2], out=term)
            e += term
            if pull is not None:
                np.multiply(pull, per_strand(towards[a]), out=term)
                e += term
            np.add(e, per_strand(roots[a]), out=dst[..., a], casting="same_kind")

    also = list(also)
    done = parallel.run_jobs(also + [lambda b=b: chunk(b) for b in bounds], threads)
    return out, done[:len(also)]


_SCRATCH = threading.local()


def _scratch(shape):
    """This thread's work arrays for a chunk of `shape` points, kept between chunks and calls
    (a few MB per thread at the default chunk size)."""
    size = int(np.prod(shape))
    have = getattr(_SCRATCH, "arrays", None)
    if have is None or len(have["pos"]) < size:
        have = _SCRATCH.arrays = {
            "pos": np.empty(size), "i0": np.empty(size, np.int64), "idx": np.empty(size, np.int64),
            "fr": np.empty(size, np.float32), "term": np.empty(size, np.float32), "e": np.empty(size, np.float32),
            "pull": np.empty(size, np.float32), "keep": np.empty(size, np.float32), "wk": np.empty(size, np.float32),
            "acc": np.empty((size, 8), np.float32), "row": np.empty((size, 8), np.float32),
            "d": np.empty((3, size), np.float32)}
    out = {name: a[:size].reshape(shape + a.shape[1:]) for name, a in have.items() if name != "d"}
    out["d"] = have["d"][:, :size].reshape((3,) + shape)
    return out

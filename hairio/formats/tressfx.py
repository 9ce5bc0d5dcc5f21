# SPDX-License-Identifier: GPL-3.0-or-later
"""AMD TressFX binary hair (.tfx, version 4), little-endian.

Header, 160 bytes (TressFXTFXFileHeader in AMD's TressFXFileFormat.h):
    float32 version (4.0)
    uint32  numHairStrands, numVerticesPerStrand (4, 8, 16, 32 or 64)
    uint32  byte offsets from the file start, 8-byte aligned, 0 = absent:
            positions   float32[S*N][4]  xyz + inverse mass (w = 0 pins the vertex)
            strand UV   float32[S][2]
            vertex UV   float32[S*N][2]
            thickness   float32[S]
            vertex color float32[S*N][4]
    uint32  reserved[32]

Every strand has exactly N vertices. The writer resamples each strand to N vertices on the
strand, equal chords apart (`resample_strands`), as TressFX's simulation holds neighbouring
vertices at their rest distance, and reports how far that moves it (`resampling_error`).

What AMD's reference loader (TressFXAsset::LoadHairData, TressFX 4.x) does with a file, and
so what the writer respects:
- it rounds the strand count up to the simulation thread group (64):
  (S - S % 64) + 64, a whole extra group even when S already is a multiple of 64, and fills
  the new strands with copies of the last one (`loaded_strand_count`). Copies render on top
  of the last strand, so nothing shows; `pad_strands=True` writes whole groups into the file
  for engines whose loaders assert S % 64 == 0 instead of padding. The reader leaves such
  padding copies out (`padding_strands`), so a padded file reads back as the strands written.
- it reads the strand UVs at offsetStrandUV unconditionally (0 would read the header), so
  the writer always writes them: from the scalp's UV map when the caller has one (`root_uv`),
  else `spherical_root_uv` (documented there).
- follow hairs are not in the file, and no TressFX version reads them from one (TressFX 3's
  header has a guideHairStrandOffset its loader never reads): GenerateFollowHairs(
  numFollowHairsPerGuideHair, tipSeparationFactor, maxRadiusAroundGuideHair) makes them at
  load time, each its guide moved by a random root offset, so the engine draws
  loaded_strand_count(S) * (1 + follow) strands. Our render strands are already every strand,
  so their file is loaded with numFollowHairsPerGuideHair = 0. For an engine that simulates
  guides and makes followers, `export_tfx` writes a guide file beside it: key strands given
  as guides, or (`follow_hairs`) guides taken from our wisps with the three load parameters
  that make the followers grow where each wisp's strands grow (`follow_hair_guides`), in a
  JSON file beside the guides.
- N must divide 64 (4..64) and the loader asserts N > 2.
- AMD's Maya exporter pins the first two vertices (w = 0) and optionally the tip, and flips
  V for DirectX; `pinned`, `pin_tip` and `flip_v` do the same here.
Thickness (per strand) follows the .hair convention: a width, 2 * root radius. The AMD loader
ignores it and the vertex colors, other engines read them.
"""
import json
import math
import os
from dataclasses import dataclass

import numpy as np

from ..atomic import atomic_write
from ..validate import InputError, check_finite, check_shape
from ._common import check_strands, need, read_bytes, strands_without_short
from .axes import convert_strands

HEADER = np.dtype([
    ("version", "<f4"), ("num_strands", "<u4"), ("vertices_per_strand", "<u4"),
    ("offset_positions", "<u4"), ("offset_strand_uv", "<u4"), ("offset_vertex_uv", "<u4"),
    ("offset_thickness", "<u4"), ("offset_vertex_color", "<u4"), ("reserved", "<u4", (32,)),
])
assert HEADER.itemsize == 160

VERTICES_PER_STRAND = (4, 8, 16, 32, 64)
THREAD_GROUP_SIZE = 64


@dataclass(frozen=True, eq=False)
class TfxFile:
    """The arrays of a .tfx file as stored (absent ones are None)."""
    version: float
    positions: np.ndarray               # (S, N, 4) xyz + inverse mass
    strand_uv: np.ndarray = None        # (S, 2)
    vertex_uv: np.ndarray = None        # (S, N, 2)
    thickness: np.ndarray = None        # (S,)
    vertex_color: np.ndarray = None     # (S, N, 4)


def loaded_strand_count(num_strands, follow_per_guide=0):
    """How many strands AMD's reference loader simulates and draws for a file of
    `num_strands` strands: padded to the next thread group (always adding one), times
    1 + follow hairs per guide."""
    n = int(num_strands)
    return ((n - n % THREAD_GROUP_SIZE) + THREAD_GROUP_SIZE) * (1 + int(follow_per_guide))


def load_tfx(path):
    """The raw arrays of a .tfx v4 file (`TfxFile`). Each array's size is worked out in
    Python integers (a header's strand and vertex counts multiply past int64) and checked
    against the file's length before it is read."""
    data = read_bytes(path, ".tfx")
    need(data, HEADER.itemsize, path, ".tfx")
    h = np.frombuffer(data, HEADER, count=1)[0]
    version = float(h["version"])
    if not (4.0 <= version < 5.0):
        raise InputError(f"{path}: .tfx version {version:g}; only the version 4 binary layout is read "
                         f"(re-export with a TressFX 4 exporter)")
    n_s, n_v = int(h["num_strands"]), int(h["vertices_per_strand"])
    if n_v < 2:
        raise InputError(f"{path}: {n_v} vertices per strand; a strand needs at least 2")
    if h["offset_positions"] == 0:
        raise InputError(f"{path}: .tfx file without vertex positions (offset 0)")

    def take(field, shape, name):
        offset = int(h[field])
        if offset == 0:
            return None
        if offset < HEADER.itemsize:
            raise InputError(f"{path}: the {name} start at byte {offset}, inside the {HEADER.itemsize}-byte "
                             "header; the file is damaged, re-export it")
        count = math.prod(shape)
        need(data, offset + 4 * count, path, f".tfx ({name} of {n_s:,} strands x {n_v:,} vertices)")
        return np.frombuffer(data, "<f4", count=count, offset=offset).reshape(shape)

    return TfxFile(
        version=version,
        positions=take("offset_positions", (n_s, n_v, 4), "positions"),
        strand_uv=take("offset_strand_uv", (n_s, 2), "strand UVs"),
        vertex_uv=take("offset_vertex_uv", (n_s, n_v, 2), "vertex UVs"),
        thickness=take("offset_thickness", (n_s,), "thickness"),
        vertex_color=take("offset_vertex_color", (n_s, n_v, 4), "vertex colors"),
    )


def padding_strands(t):
    """How many strands at the end of the TfxFile `t` are padding: copies of the strand before
    them (every array equal) that round the count up to a multiple of the thread group (64),
    as `pad_strands` and other exporters write them for loaders that want whole groups.
    Copies draw on top of their original, so they are no hair of their own."""
    n_s = len(t.positions)
    if n_s < 2 or n_s % THREAD_GROUP_SIZE:
        return 0
    tail = slice(max(n_s - THREAD_GROUP_SIZE, 0), n_s)
    same = np.ones(tail.stop - tail.start, bool)
    for array in (t.positions, t.strand_uv, t.vertex_uv, t.thickness, t.vertex_color):
        if array is not None:
            block = array[tail].reshape(len(same), -1)
            same &= (block == block[-1]).all(axis=1)
    # The run of copies ends at the last strand; its first member is the original.
    run = len(same) - np.flatnonzero(~same)[-1] - 1 if not same.all() else len(same)
    return int(min(run - 1, THREAD_GROUP_SIZE - 1))


def read_tfx(path):
    """Strands from a .tfx v4 file: points = xyz; radius = thickness / 2 when stored;
    color and alpha from the vertex colors when stored. Padding strands (`padding_strands`)
    are left out."""
    t = load_tfx(path)
    n_s = len(t.positions) - padding_strands(t)
    n_v = t.positions.shape[1]
    points = t.positions[:n_s, :, :3].reshape(-1, 3)
    radius = color = alpha = None
    if t.thickness is not None:
        radius = np.repeat(t.thickness[:n_s] * np.float32(0.5), n_v)
    if t.vertex_color is not None:
        color = np.clip(t.vertex_color[:n_s, :, :3].reshape(-1, 3), 0, None)
        alpha = np.clip(t.vertex_color[:n_s, :, 3].reshape(-1), 0, 1)
    return strands_without_short(points, np.full(n_s, n_v, np.int64), source=path, radius=radius, color=color,
                                 alpha=alpha)


def _arc_table(strands):
    """(pts float64, g, roots, tips): g is the cumulative arc length over all points, with
    the joins between strands counted as 0, so g is non-decreasing and one searchsorted
    finds a point of any strand."""
    pts = strands.points.astype(np.float64)
    counts = strands.counts.astype(np.int64)
    roots = strands.offsets
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    # Segments that join a strand's tip to the next strand's root are not hair.
    seg[roots[1:] - 1] = 0.0
    g = np.zeros(len(pts))
    np.cumsum(seg, out=g[1:])
    return pts, g, roots, roots + counts - 1


def _locate(g, roots, tips, arc):
    """For arc lengths `arc` (A, n) along strands `roots`/`tips` (A,): the point index `a`
    where each one's segment starts and the fraction `f` along it, both (A*n,)."""
    n = arc.shape[1]
    target = (g[roots][:, None] + arc).ravel()
    a = np.searchsorted(g, target, side="right") - 1
    a = np.clip(a, np.repeat(roots, n), np.repeat(tips - 1, n))
    span = g[a + 1] - g[a]
    with np.errstate(invalid="ignore", divide="ignore"):
        f = np.where(span > 0, (target - g[a]) / span, 0.0)
    return a, np.clip(f, 0.0, 1.0)


def _points_at(pts, g, roots, tips, arc, seg=None):
    """Points (A, n, 3) at arc lengths `arc` (A, n) along strands `roots`/`tips`; `seg`:
    np.diff(pts, axis=0), when the caller has it."""
    a, f = _locate(g, roots, tips, arc)
    seg = np.diff(pts, axis=0) if seg is None else seg
    q = np.take(pts, a, axis=0)
    q += np.take(seg, a, axis=0) * f[:, None]
    return q.reshape(arc.shape + (3,))


# Equal chords within this fraction of their mean, inside the 1 % a simulation's rest
# lengths are asked to share; strands the scaling leaves apart are marched
# (`_march_equal_chords`), and those still apart (a marched vertex leaping a tight curl)
# solved by damped Gauss-Newton (`_polish_equal_chords`). Each keeps its best try.
CHORD_TOLERANCE = 5e-3
CHORD_ITERATIONS = 80
CHORD_POLISH_ITERATIONS = 40
CHORD_SHAKES = 16


def chord_parameters(strands, n):
    """Arc lengths (S, n) from each root of `n` vertices per strand whose chords (straight
    distances between consecutive vertices) are equal, root and tip kept exactly.

    TressFX simulates a strand as particles held at their rest distances, so its exporters
    place vertices a constant distance apart; equal steps of arc length would not do that
    where the strand bends (a chord across a curl is shorter than its arc). Starting from
    equal arc steps, each step is scaled by mean chord / its chord and the steps rescaled to
    the strand's length: where a step's chord-to-arc ratio is locally constant this lands on
    equal chords at once, so a few iterations suffice; only strands not yet equal within
    CHORD_TOLERANCE iterate again, with damped steps after a quarter of the iterations; those
    still apart are marched (`_march_equal_chords`), those still apart then polished
    (`_polish_equal_chords`), and each strand keeps its best try. The later stages see only
    the strands left apart (about 0.5 % of the curly preset's)."""
    pts, g, roots, tips = _arc_table(strands)
    # Chords are compared to 0.5 %: float32 points (relative error 1e-7 of a coordinate) do,
    # at half the memory traffic of the gathers that are this loop's cost.
    pts = pts.astype(np.float32)
    seg = np.diff(pts, axis=0)
    length = g[tips] - g[roots]
    arc = length[:, None] * np.linspace(0.0, 1.0, n)[None, :]
    best = arc.copy()
    best_apart = np.full(len(arc), np.inf)
    todo = np.flatnonzero(length > 0)
    for it in range(CHORD_ITERATIONS + 1):
        if not len(todo):
            break
        q = _points_at(pts, g, roots[todo], tips[todo], arc[todo], seg)
        chord = np.linalg.norm(np.diff(q, axis=1), axis=2).astype(np.float64)
        mean = chord.mean(axis=1, keepdims=True)
        apart = np.abs(chord / mean - 1.0).max(axis=1)
        better = apart < best_apart[todo]
        best[todo[better]] = arc[todo[better]]
        best_apart[todo[better]] = apart[better]
        keep = apart > CHORD_TOLERANCE
        todo, chord, mean = todo[keep], chord[keep], mean[keep]
        if not len(todo) or it == CHORD_ITERATIONS:
            break
        # A fold or a sharp bend can make the full step overshoot back and forth; later
        # iterations take half of it (in the logarithm), which settles most of them.
        power = 1.0 if it < CHORD_ITERATIONS // 4 else 0.5
        step = np.diff(arc[todo], axis=1) * (mean / np.maximum(chord, 1e-300)) ** power
        step *= (length[todo] / step.sum(axis=1))[:, None]
        arc[todo, 1:] = np.cumsum(step, axis=1)
        arc[todo, -1] = length[todo]
    rest = np.flatnonzero(np.isfinite(best_apart) & (best_apart > CHORD_TOLERANCE))
    if not len(rest):
        return best
    marched, apart, arc_lo, arc_hi = _march_equal_chords(pts, g, roots[rest], tips[rest], n, brackets=True)
    better = apart < best_apart[rest]
    best[rest[better]] = marched[better]
    best_apart[rest[better]] = apart[better]
    if n <= 2:
        return best
    # Polish the best try; where it settles in a local minimum (a vertex held at a fold of
    # the curl, moving it either way shortens its chord), start again from blends of the
    # two bracketing marches, which put the leaping vertex inside the gap it leapt.
    # The few still apart after that start from the best try shaken: each interior vertex
    # moved by up to a quarter of a mean step (a fixed seed, so files are reproducible).
    shake = np.random.default_rng(0).uniform(-0.25, 0.25, (CHORD_SHAKES, n))
    shake[:, [0, -1]] = 0.0
    for start in (None, 0.5, 0.25, 0.75, 0.125, 0.875, 0.375, 0.625) + tuple(shake):
        left = best_apart[rest] > CHORD_TOLERANCE
        rest, arc_lo, arc_hi = rest[left], arc_lo[left], arc_hi[left]
        if not len(rest):
            break
        if start is None:
            arc0 = best[rest]
        elif np.ndim(start) == 0:
            arc0 = (1 - start) * arc_lo + start * arc_hi
        else:
            arc0 = np.clip(best[rest] + start * (best[rest, -1:] / (n - 1)), 0.0, best[rest, -1:])
            arc0 = np.maximum.accumulate(arc0, axis=1)
        polished, apart = _polish_equal_chords(pts, g, roots[rest], tips[rest], arc0)
        better = apart < best_apart[rest]
        best[rest[better]] = polished[better]
        best_apart[rest[better]] = apart[better]
    return best


def _polish_equal_chords(pts, g, roots, tips, arc, iterations=CHORD_POLISH_ITERATIONS):
    """Equal chords by damped Gauss-Newton (Levenberg-Marquardt) from the best try `arc`
    (A, n), for the strands that scaling and marching left apart: where a tight curl makes
    the marched vertex jump (the first point at chord c from the one before moves from one
    turn of the curl to the next as c grows), the solution lies between two marches, on a
    vertex that is not the first at that distance, and no choice of c alone reaches it.

    Unknowns: the interior vertices' arc lengths s_1..s_{n-2} and the common chord c;
    equations |P(s_{i+1}) - P(s_i)| - c = 0 for the n - 1 chords (s_0 = 0 and s_{n-1} =
    length stay, so root and tip are kept exactly). The Jacobian is bidiagonal (chord
    direction . tangent at each end) plus a column of -1. A step is taken only when it
    keeps the vertices in order along the strand and lowers the sum of squared chord
    deviations; else the damping grows. Each strand keeps its best try (by the largest chord
    deviation) and leaves once within CHORD_TOLERANCE. Returns arc (A, n)."""
    A, n = arc.shape
    arc = np.array(arc, np.float64)
    length = arc[:, -1].copy()
    lam = np.full(A, 1e-3)
    rows_i = np.arange(n - 1)

    def evaluate(index, s):
        a, f = _locate(g, roots[index], tips[index], s)
        p0 = np.take(pts, a, axis=0).astype(np.float64)
        d = np.take(pts, a + 1, axis=0).astype(np.float64) - p0
        q = (p0 + d * f[:, None]).reshape(s.shape + (3,))
        dl = np.linalg.norm(d, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            tangent = np.where(dl[:, None] > 0, d / dl[:, None], 0.0).reshape(s.shape + (3,))
        chord_v = np.diff(q, axis=1)
        chord = np.linalg.norm(chord_v, axis=2)
        return tangent, chord_v, chord

    def deviation(chord):
        mean = chord.mean(axis=1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.abs(chord / mean - 1.0).max(axis=1)

    tangent, chord_v, chord = evaluate(np.arange(A), arc)
    c = chord.mean(axis=1)
    apart = deviation(chord)
    best, best_apart = arc.copy(), apart.copy()
    cost = ((chord - c[:, None]) ** 2).sum(axis=1)
    todo = np.flatnonzero(apart > CHORD_TOLERANCE)
    for _ in range(iterations):
        if not len(todo):
            break
        t, cv, ch, cc = tangent[todo], chord_v[todo], chord[todo], c[todo]
        with np.errstate(invalid="ignore", divide="ignore"):
            u = np.where(ch[..., None] > 0, cv / ch[..., None], 0.0)
        # d chord_i / d s_{i+1} = u_i . T(s_{i+1}); d chord_i / d s_i = -u_i . T(s_i).
        ahead = np.einsum("aik,aik->ai", u, t[:, 1:])
        behind = -np.einsum("aik,aik->ai", u, t[:, :-1])
        J = np.zeros((len(todo), n - 1, n - 1))
        J[:, rows_i[:-1], rows_i[:-1]] = ahead[:, :-1]        # chord i, unknown s_{i+1}
        J[:, rows_i[1:], rows_i[:-1]] = behind[:, 1:]          # chord i, unknown s_i
        J[:, :, -1] = -1.0                                      # the common chord c
        F = ch - cc[:, None]
        JtJ = np.einsum("aki,akj->aij", J, J)
        rhs = -np.einsum("aki,ak->ai", J, F)
        diag = np.einsum("aii->ai", JtJ)
        H = JtJ.copy()
        H[:, rows_i, rows_i] += lam[todo, None] * (diag + 1e-12)
        # H is positive definite unless a strand's Jacobian is zero; 1e-12 keeps it solvable.
        step = np.linalg.solve(H, rhs[..., None])[..., 0]
        trial = arc[todo].copy()
        trial[:, 1:-1] += step[:, :-1]
        trial_c = cc + step[:, -1]
        ordered = (np.diff(trial, axis=1) > 0).all(axis=1) & (trial_c > 0) & np.isfinite(step).all(axis=1)
        trial[~ordered] = arc[todo[~ordered]]
        tt, tcv, tch = evaluate(todo, trial)
        tcost = ((tch - trial_c[:, None]) ** 2).sum(axis=1)
        good = ordered & (tcost < cost[todo])
        k = todo[good]
        arc[k], tangent[k], chord_v[k], chord[k] = trial[good], tt[good], tcv[good], tch[good]
        c[k], cost[k] = trial_c[good], tcost[good]
        lam[k] = np.maximum(lam[k] / 3.0, 1e-9)
        lam[todo[~good]] *= 4.0
        apart = deviation(chord[todo])
        better = apart < best_apart[todo]
        best[todo[better]] = arc[todo[better]]
        best_apart[todo[better]] = apart[better]
        todo = todo[(apart > CHORD_TOLERANCE) & (lam[todo] < 1e8)]
    best[:, -1] = length
    return best, best_apart


def _march_equal_chords(pts, g, roots, tips, n, iterations=16, brackets=False):
    """Equal chords by construction, for the strands the scaling left apart (sharp bends
    that a vertex crossing them changes the chord of at once): from the root, each vertex is
    the first point along the strand at distance c from the one before; c is solved so the
    tip lies c from vertex n - 2 (regula falsi, Illinois' variant, kept bracketed: at c -> 0
    the tip is farther than c; at c = length / (n - 1) every chord used at least c of arc,
    so it is nearer). Returns (arc (A, n), largest chord deviation (A,)), and with `brackets`
    also the marches at the two ends of the final bracket (A, n) each: where f jumps across
    zero (a vertex leaping a curl) the equal chords lie between them."""
    pts = np.asarray(pts, np.float64)
    m = int((tips - roots).max()) + 1
    idx = np.minimum(roots[:, None] + np.arange(m)[None, :], tips[:, None])     # padded with the tip
    P, G = pts[idx], g[idx] - g[roots][:, None]
    rows = np.arange(len(roots))
    after = np.arange(m)[None, :]

    def march(c):
        """(arc (A, n), f = |tip - vertex n-2| - c) for chord lengths c (A,)."""
        arc = np.zeros((len(c), n))
        q, k = P[:, 0].copy(), np.zeros(len(c), np.int64)
        fell = np.zeros(len(c), bool)
        for v in range(1, n - 1):
            ahead = (after > k[:, None]) & (np.linalg.norm(P - q[:, None, :], axis=2) >= c[:, None])
            fell |= ~ahead.any(axis=1)
            i = np.maximum(np.argmax(ahead, axis=1), 1)
            a, ab = P[rows, i - 1], P[rows, i] - P[rows, i - 1]
            aq = a - q
            qa = np.einsum("ij,ij->i", ab, ab)
            qb = 2 * np.einsum("ij,ij->i", ab, aq)
            qc = np.einsum("ij,ij->i", aq, aq) - c * c
            with np.errstate(invalid="ignore", divide="ignore"):
                t = np.where(qa > 0, (-qb + np.sqrt(np.maximum(qb * qb - 4 * qa * qc, 0))) / (2 * qa), 0.0)
            t = np.clip(t, 0.0, 1.0)
            q, k = a + t[:, None] * ab, i - 1
            arc[:, v] = G[rows, i - 1] + t * (G[rows, i] - G[rows, i - 1])
        arc[:, -1] = G[:, -1]
        f = np.where(fell, -c, np.linalg.norm(P[:, -1] - q, axis=1) - c)
        return arc, f

    lo, hi = np.zeros(len(roots)), G[:, -1] / (n - 1)
    f_lo, f_hi = G[:, -1].copy(), march(hi)[1]      # c -> 0: the tip is the whole chord away
    side = np.zeros(len(roots), np.int64)
    for _ in range(iterations):
        with np.errstate(invalid="ignore", divide="ignore"):
            c = np.where(f_lo != f_hi, (lo * f_hi - hi * f_lo) / (f_hi - f_lo), 0.5 * (lo + hi))
        c = np.clip(np.nan_to_num(c, nan=0.0), lo + 1e-3 * (hi - lo), hi - 1e-3 * (hi - lo))
        _, f = march(c)
        pos = f > 0
        # Illinois: halve the value kept at the end that stays, so the bracket shrinks from both sides.
        f_hi = np.where(pos & (side == 1), 0.5 * f_hi, f_hi)
        f_lo = np.where(~pos & (side == -1), 0.5 * f_lo, f_lo)
        lo, f_lo = np.where(pos, c, lo), np.where(pos, f, f_lo)
        hi, f_hi = np.where(pos, hi, c), np.where(pos, f_hi, f)
        side = np.where(pos, 1, -1)
    arc_lo, arc_hi = march(lo)[0], march(hi)[0]
    arc = np.where((np.abs(f_lo) < np.abs(f_hi))[:, None], arc_lo, arc_hi)
    q = _points_at(pts, g, roots, tips, arc)
    chord = np.linalg.norm(np.diff(q, axis=1), axis=2)
    apart = np.abs(chord / chord.mean(axis=1, keepdims=True) - 1.0).max(axis=1)
    if brackets:
        return arc, apart, arc_lo, arc_hi
    return arc, apart


def resample_strands(strands, vertices_per_strand):
    """`strands` with every strand resampled to `vertices_per_strand` points on the strand,
    equal chords apart (`chord_parameters`; root and tip kept exactly). Radius, color and
    alpha are interpolated at the same places; float64 inside, float32 out."""
    s = check_strands(strands)
    n = int(vertices_per_strand)
    if n < 2:
        raise InputError(f"vertices_per_strand: {n}; need at least 2")
    if s.num_strands == 0:
        return s
    pts, g, roots, tips = _arc_table(s)
    a, f = _locate(g, roots, tips, chord_parameters(s, n))
    b = a + 1

    def lerp(v, dtype):
        # Points in float64 (their error is what we report); radius and colors in float32.
        v0 = np.take(v, a, axis=0).astype(dtype, copy=False)
        dv = np.take(v, b, axis=0).astype(dtype, copy=False) - v0
        ff = f.astype(dtype).reshape((-1,) + (1,) * (v.ndim - 1))
        return v0 + dv * ff

    return type(s).from_arrays(lerp(s.points, np.float64), np.full(s.num_strands, n, np.int32),
                               lerp(s.radius, np.float32), lerp(s.color, np.float32),
                               np.clip(lerp(s.alpha, np.float32), 0, 1), s.wisp)


def resampling_error(strands, vertices_per_strand):
    """How far resampling to `vertices_per_strand` moves each strand.

    The resampled vertices lie on the original polyline, so the error is how far the
    original points lie from the resampled one: each original point at arc length s is
    measured to the resampled segment that covers s (the correspondence resampling
    defines). Each stretch of the original between two resampled vertices then stays in a
    tube of that radius around their chord, so the max is also a bound on the distance
    from any point of either strand to the other (both ways). The resampled points are
    the float32 ones the file stores. Returns dict(max=, mean=, per_strand=(S,) max), in
    scene units."""
    s = check_strands(strands)
    n = int(vertices_per_strand)
    if s.num_strands == 0:
        return {"max": 0.0, "mean": 0.0, "per_strand": np.zeros(0)}
    r = resample_strands(s, n)
    q = r.points.astype(np.float64).reshape(-1, 3)
    pts, g, roots, tips = _arc_table(s)
    # Every resampled vertex's place on the global arc; the segment covering an original
    # point is the last vertex at or before it, within the point's own strand.
    at = (g[roots][:, None] + chord_parameters(s, n)).ravel()
    counts = s.counts.astype(np.int64)
    first = np.repeat(np.arange(s.num_strands) * n, counts)
    j = np.clip(np.searchsorted(at, g, side="right") - 1, first, first + n - 2)
    a, b = q[j], q[j + 1]
    ab = b - a
    den = np.einsum("ij,ij->i", ab, ab)
    with np.errstate(invalid="ignore", divide="ignore"):
        u = np.where(den > 0, np.einsum("ij,ij->i", pts - a, ab) / den, 0.0)
    u = np.clip(u, 0.0, 1.0)
    d = np.linalg.norm(pts - (a + u[:, None] * ab), axis=1)
    per_strand = np.maximum.reduceat(d, s.offsets)
    return {"max": float(d.max()), "mean": float(d.mean()), "per_strand": per_strand}


def resampling_errors(strands, vertex_counts=VERTICES_PER_STRAND):
    """{vertices per strand: max resampling error} for each count (the benchmark's table)."""
    return {int(n): resampling_error(strands, n)["max"] for n in vertex_counts}


def _unit(v, name):
    v = np.asarray(v, np.float64)
    norm = np.linalg.norm(v)
    if v.shape != (3,) or not np.isfinite(norm) or norm == 0:
        raise InputError(f"{name}: expected a non-zero 3-vector, got {v!r}")
    return v / norm


def spherical_root_uv(roots, up=(0.0, 0.0, 1.0), front=(0.0, -1.0, 0.0)):
    """Strand UVs for scalps without a UV map: a spherical projection of each root around
    the roots' centroid. u = azimuth around `up`, 0.5 at `front` and the seam (0 / 1) straight
    behind, where the back of the head hides it; v = elevation, 0 at the bottom pole, 1 at the
    top. Defaults are Blender's axes (Z up, -Y front)."""
    roots = np.asarray(roots, np.float64)
    e_up = _unit(up, "up")
    e_front = _unit(np.asarray(front, np.float64) - np.dot(front, e_up) * e_up, "front (perpendicular to up)")
    e_side = np.cross(e_up, e_front)
    if len(roots) == 0:
        return np.zeros((0, 2), np.float32)
    d = roots - roots.mean(axis=0)
    r = np.linalg.norm(d, axis=1)
    u = 0.5 + np.arctan2(d @ e_side, d @ e_front) / (2 * np.pi)
    with np.errstate(invalid="ignore", divide="ignore"):
        v = 0.5 + np.arcsin(np.clip(np.where(r > 0, (d @ e_up) / r, 0.0), -1, 1)) / np.pi
    return np.stack([u, v], axis=1).astype(np.float32)


def _align8(n):
    return (n + 7) // 8 * 8


def encode_tfx(strands, vertices_per_strand=32, pinned=2, pin_tip=False, root_uv=None,
               up=(0.0, 0.0, 1.0), front=(0.0, -1.0, 0.0), flip_v=True, thickness=True,
               colors=True, pad_strands=False, shuffle_seed=None):
    """The bytes of a .tfx v4 file for `strands`, as a list of blocks to write in order.

    vertices_per_strand: 4, 8, 16, 32 or 64 (TressFX's simulation needs N | 64).
    pinned: root vertices with inverse mass 0 (immovable); the rest get 1.
    pin_tip: also pin the last vertex (AMD's "both ends immovable").
    root_uv: (S, 2) strand UVs from the scalp's UV map; None = `spherical_root_uv` with
    `up`/`front`. flip_v: v -> 1 - v, the DirectX convention AMD's exporter defaults to.
    thickness / colors: also write per-strand thickness (2 * root radius) / vertex colors.
    pad_strands: round the strand count up to a multiple of 64 with copies of the last strand.
    shuffle_seed: shuffle the strand order (TressFX's LOD drops the last strands first, so a
    random order thins the hair evenly); None keeps the order.
    """
    s = check_strands(strands)
    n = int(vertices_per_strand) if np.ndim(vertices_per_strand) == 0 else -1
    if n not in VERTICES_PER_STRAND:
        raise InputError(f"vertices_per_strand: {vertices_per_strand!r}; TressFX needs one of "
                         f"{', '.join(map(str, VERTICES_PER_STRAND))}")
    pinned = int(pinned)
    if not 0 <= pinned <= n:
        raise InputError(f"pinned: {pinned} root vertices pinned; must be in 0..{n}")
    if s.num_strands == 0:
        raise InputError("strands: no strands to write; TressFX files need at least one strand")
    if root_uv is None:
        uv = spherical_root_uv(s.points[s.offsets], up, front)
    else:
        uv = check_finite("root_uv", check_shape("root_uv", np.asarray(root_uv), (s.num_strands, 2)))
        uv = uv.astype(np.float32)
    if flip_v:
        uv = np.stack([uv[:, 0], np.float32(1) - uv[:, 1]], axis=1)
    r = resample_strands(s, n)
    pos = np.empty((s.num_strands, n, 4), "<f4")
    pos[..., :3] = r.points.reshape(-1, n, 3)
    pos[..., 3] = 1.0
    pos[:, :pinned, 3] = 0.0
    if pin_tip:
        pos[:, -1, 3] = 0.0
    width = (s.radius[s.offsets] * np.float32(2)).astype("<f4")
    rgba = np.empty((s.num_strands, n, 4), "<f4")
    rgba[..., :3] = r.color.reshape(-1, n, 3)
    rgba[..., 3] = r.alpha.reshape(-1, n)
    order = None
    if shuffle_seed is not None:
        order = np.random.default_rng(int(shuffle_seed)).permutation(s.num_strands)
    if pad_strands and s.num_strands % THREAD_GROUP_SIZE:
        extra = THREAD_GROUP_SIZE - s.num_strands % THREAD_GROUP_SIZE
        base = order if order is not None else np.arange(s.num_strands)
        order = np.concatenate([base, np.full(extra, base[-1])])
    if order is not None:
        pos, uv, width, rgba = pos[order], uv[order], width[order], rgba[order]
    arrays = [("offset_positions", pos), ("offset_strand_uv", uv.astype("<f4"))]
    if thickness:
        arrays.append(("offset_thickness", width))
    if colors:
        arrays.append(("offset_vertex_color", rgba))
    h = np.zeros(1, HEADER)
    h["version"], h["num_strands"], h["vertices_per_strand"] = 4.0, len(pos), n
    blocks, at = [None], HEADER.itemsize
    for field, array in arrays:
        start = _align8(at)
        if start > at:
            blocks.append(b"\0" * (start - at))
        h[field] = start
        blocks.append(np.ascontiguousarray(array).tobytes())
        at = start + array.nbytes
    if at >= 1 << 32:
        raise InputError(f"strands: the .tfx file would be {at} bytes; its 32-bit offsets stop at 4 GiB; "
                         f"export fewer strands or fewer vertices per strand")
    blocks[0] = h.tobytes()
    return blocks


def write_tfx(path, strands, **opts):
    """Write `strands` as .tfx v4, atomically (options: `encode_tfx`); returns the number of
    strands in the file (more than `strands` has with pad_strands)."""
    blocks = encode_tfx(strands, **opts)
    with atomic_write(path) as f:
        for b in blocks:
            f.write(b)
    return int(np.frombuffer(blocks[0], HEADER, count=1)[0]["num_strands"])


def guides_path_for(path):
    """Where the guides go by default: NAME_guides.tfx beside NAME.tfx."""
    stem, ext = os.path.splitext(os.fspath(path))
    return stem + "_guides" + (ext or ".tfx")


def write_tfx_pair(path, strands, guides, guides_path=None, guide_root_uv=None, **opts):
    """Render strands to `path` and guide strands to `guides_path` (default
    `guides_path_for(path)`), each a complete .tfx with the same options, as TressFX loads
    separate hair objects (load the render file with numFollowHairsPerGuideHair = 0).
    Both are encoded before either file is opened, and a failure leaves neither.
    Returns (path, guides_path)."""
    guides_path = guides_path_for(path) if guides_path is None else os.fspath(guides_path)
    guide_opts = dict(opts, root_uv=guide_root_uv)
    strand_blocks = encode_tfx(strands, **opts)
    guide_blocks = encode_tfx(guides, **guide_opts)
    with atomic_write(guides_path) as fg, atomic_write(path) as fs:
        for b in guide_blocks:
            fg.write(b)
        for b in strand_blocks:
            fs.write(b)
    return os.fspath(path), guides_path


def _morton(points):
    """A Z-order code (30 bits) of each point in the points' bounding cube: points near in
    space are mostly near in code order, so runs of the order are compact patches."""
    p = np.asarray(points, np.float64)
    lo = p.min(axis=0)
    size = max(float((p.max(axis=0) - lo).max()), 1e-300)
    q = np.minimum(((p - lo) / size * 1024).astype(np.uint64), 1023)
    code = np.zeros(len(p), np.uint64)
    for bit in range(10):
        for axis in range(3):
            code |= ((q[:, axis] >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit + axis)
    return code


def follow_hair_guides(strands, follow_hairs):
    """Guide strands for TressFX's follow hairs, taken from our own wisps.

    TressFX keeps no follow hairs in its file: its loader makes numFollowHairsPerGuideHair
    of them around each guide at load time (TressFXAsset::GenerateFollowHairs), each the
    guide moved by a random root offset (each of two components in +-maxRadiusAroundGuideHair,
    across the guide's first segment) that grows along the strand to 1 + tipSeparationFactor
    times at the tip (about). What a file can decide is where the guides are and the three numbers.
    So every wisp is cut into patches of `follow_hairs` + 1 strands with nearby roots (runs
    of a Z-order of the roots within the wisp); each patch's guide is its strand nearest the
    patch's root centroid, so the generated followers grow where that wisp's strands grow,
    as many as it has; the radius is the median over patches of the farthest root from its
    guide, the tip factor the median ratio of the tips' to the roots' distance from the guide.

    Returns (guide strand indices (G,) int64, {"numFollowHairsPerGuideHair",
    "maxRadiusAroundGuideHair", "tipSeparationFactor"}) in the strands' units."""
    s = check_strands(strands)
    follow = int(follow_hairs)
    if follow < 1:
        raise InputError(f"follow_hairs: {follow_hairs!r}; give at least 1 follow hair per guide")
    if s.num_strands == 0:
        raise InputError("strands: no strands to take guides from")
    roots = s.points[s.offsets].astype(np.float64)
    tips = s.points[s.offsets + s.counts - 1].astype(np.float64)
    order = np.lexsort((_morton(roots), s.wisp))
    wisp = s.wisp[order]
    first = np.flatnonzero(np.r_[True, wisp[1:] != wisp[:-1]])
    rank = np.arange(len(order)) - np.repeat(first, np.diff(np.r_[first, len(order)]))
    # A patch starts at each wisp's start and every follow + 1 strands within it.
    starts = np.flatnonzero(rank % (follow + 1) == 0)
    patch = np.cumsum(rank % (follow + 1) == 0) - 1
    sizes = np.diff(np.r_[starts, len(order)])
    centroid = np.add.reduceat(roots[order], starts) / sizes[:, None]
    d = np.linalg.norm(roots[order] - centroid[patch], axis=1)
    nearest = np.lexsort((d, patch))
    guide_pos = nearest[np.r_[0, np.cumsum(sizes)[:-1]]]      # first of each patch in (patch, d) order
    guides = order[guide_pos]
    g = guides[patch]
    root_off = np.linalg.norm(roots[order] - roots[g], axis=1)
    tip_off = np.linalg.norm(tips[order] - tips[g], axis=1)
    member = root_off > 0
    radius = float(np.median(np.maximum.reduceat(root_off, starts))) if len(starts) else 0.0
    ratio = float(np.median(tip_off[member] / root_off[member])) if member.any() else 1.0
    return guides, {"numFollowHairsPerGuideHair": follow, "maxRadiusAroundGuideHair": radius,
                    "tipSeparationFactor": max(ratio - 1.0, 0.0)}


def _subset(s, index):
    """The strands `index` of `s`, in that order (arrays only)."""
    counts = s.counts[index].astype(np.int64)
    within = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    take = np.repeat(s.offsets[index], counts) + within
    return type(s).from_arrays(s.points[take], counts, s.radius[take], s.color[take], s.alpha[take],
                               s.wisp[index])


def export_tfx(path, strands, axis="none", scale=1.0, root_uv=None, vertices_per_strand=32, pinned=2,
               pin_tip=False, flip_v=True, pad_strands=False, shuffle_seed=None, guides=None,
               guides_out=None, follow_hairs=None):
    """Write `strands` as .tfx turned to `axis` and multiplied by `scale`; returns the files.

    root_uv: (S, 2) strand UVs (else the strands' own, else `spherical_root_uv` of the roots
    in our frame, before the axis turn). Other options as `encode_tfx`. Guide files, for a
    TressFX that simulates guides and makes follow hairs (never both):
    - guides: key strands (a Strands) written to `guides_out` (default NAME_guides.tfx);
    - follow_hairs: F; guides taken from the strands' wisps (`follow_hair_guides`) to
      `guides_out`, with NAME_guides.tfx.json holding the loader's numFollowHairsPerGuideHair,
      maxRadiusAroundGuideHair and tipSeparationFactor for them.
    The render file is always all of the strands (load it with numFollowHairsPerGuideHair 0)."""
    s = check_strands(strands)
    if guides is not None and follow_hairs is not None:
        raise InputError("--guides, --follow-hairs: give one: key strands as the guides, or guides taken "
                         "from the wisps for TressFX's follow hairs")
    uv = root_uv if root_uv is not None else s.root_uv
    if uv is None:
        # The projection needs the head's own up/front, so it runs before any axis change.
        uv = spherical_root_uv(s.points[s.offsets])
    opts = dict(vertices_per_strand=vertices_per_strand, pinned=pinned, pin_tip=pin_tip, flip_v=flip_v,
                pad_strands=pad_strands, shuffle_seed=shuffle_seed)
    s = convert_strands(s, axis, scale)
    guides_path = guides_out or guides_path_for(path)
    if guides is not None:
        key_uv = spherical_root_uv(check_strands(guides).points[guides.offsets])
        keys = convert_strands(guides, axis, scale)
        return list(write_tfx_pair(path, s, keys, guides_path, guide_root_uv=key_uv, root_uv=uv, **opts))
    if follow_hairs is None:
        write_tfx(path, s, root_uv=uv, **opts)
        return [os.fspath(path)]
    index, load = follow_hair_guides(s, follow_hairs)
    uv = check_finite("root_uv", check_shape("root_uv", np.asarray(uv, np.float32), (s.num_strands, 2)))
    meta = {"format": "keystrand-hair TressFX guides", "guides_file": os.path.basename(guides_path),
            "strands_file": os.path.basename(os.fspath(path)), **load, "guides": int(len(index)),
            "strands": int(s.num_strands),
            "note": "load guides_file with these numFollowHairsPerGuideHair, maxRadiusAroundGuideHair and "
                    "tipSeparationFactor (TressFX's GenerateFollowHairs), or strands_file with "
                    "numFollowHairsPerGuideHair 0"}
    guide_opts = dict(opts, pad_strands=False, shuffle_seed=None)
    guide_blocks = encode_tfx(_subset(s, index), root_uv=uv[index], **guide_opts)
    strand_blocks = encode_tfx(s, root_uv=uv, **opts)
    text = json.dumps(meta, indent=2) + "\n"
    with atomic_write(guides_path + ".json", "w") as fj, atomic_write(guides_path) as fg, \
            atomic_write(path) as fs:
        for b in guide_blocks:
            fg.write(b)
        for b in strand_blocks:
            fs.write(b)
        fj.write(text)
    return [os.fspath(path), guides_path, guides_path + ".json"]

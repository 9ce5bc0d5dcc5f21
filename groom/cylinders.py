# SPDX-License-Identifier: GPL-3.0-or-later
"""Strands as continual cylinders (SPEC §6): how many, how thick, what colour, how opaque.

A strand of n+1 points is n cylinders. The thesis uses a fixed count (typically 25) and notes
straight hair needs only 3–4; `adaptive_sigma` gives each strand few cylinders, placed where
it bends, whose polyline provably stays within a tolerance of the exact curve, and
`geometric_error` measures the result the way SPEC §6 defines it.
"""
import threading
from dataclasses import dataclass
from functools import partial

import numpy as np

from . import parallel, rng


@dataclass(frozen=True, eq=False)
class AdaptiveResolution:
    """adaptive_sigma's answer: sigma (P,) flat curve parameters and counts (S,) points per
    strand; met (S,) the tolerance each strand's polyline is bound to (its own, unless the
    cylinder cap stopped it); needed (S,) a lower bound of the cylinders its own tolerance
    takes (for the message when the cap stops it)."""
    sigma: np.ndarray
    counts: np.ndarray
    met: np.ndarray
    needed: np.ndarray


# Strands per range of the adaptive resolution's sweep: its bins x strands arrays (three of
# float32, 8 MB at this size) stay modest, and each of its many small steps per bin has
# enough strands that the threads are not held up by the interpreter between them. (One
# range per thread up to 65,536 strands saved 45 ms of CPU at 100,000 strands but left
# 300 MB more on the heap at 1,000,000: docs/DECISIONS.md.)
_CHUNK = 16384

# A strand the cap stops gets the cap's cylinders placed for a looser tolerance, raised by
# this factor until they suffice (so it is within 25 % of the best the cap allows).
_RELAX = 1.25


def adaptive_sigma(frac, guides, weights, bins, tolerance, max_cylinders, chunk=_CHUNK, table_step=0.0,
                   threads=None, clump=None):
    """Per-strand adaptive resolution: curve parameters σ of the fewest points whose polyline
    provably stays within `tolerance` (S,) of the exact strand, for the curvature bound below.

    The bound: over a parameter step h, a curve with |C''| <= A stays within A·h²/8 of its
    chord, and |C_j''(σ)| <= Σ_g w_g |D_g''(σ)| (B_j is a rotation), bounded per bin of σ by
    `bins` (K, NB) from interpolate.curvature_bound. Points are placed greedily from the root:
    each segment is the longest whose h² times the largest bound over the bins it touches
    stays <= 8·tol. Greedy covering is optimal for such a monotone constraint, so straight
    stretches get one long cylinder and bends get short ones. The placement sweeps the bins
    from the root for all strands of a range at once (_greedy_range), so the work is about
    (strands x bins) whatever the resolution, in ranges of `chunk` strands on `threads`
    worker threads.

    The points themselves come from key tables of `table_step` (in σ) between samples, whose
    lerp strays from the curve by up to A·table_step²/8 (A the strand's largest bound), so
    the segments get 8·tol - A·table_step² (interpolate.table_samples makes the tables fine
    enough that this keeps most of the tolerance): the polyline then stays within tol of the
    exact curve, not only of the tables'.

    A strand that needs more than `max_cylinders` gets max_cylinders placed the same way for
    the least tolerance (in steps of _RELAX from what the count's lower bound suggests) they
    meet, and `met` says which; only a strand that fits no tolerance so (none does after 60
    steps) falls back to equal steps, met = inf.

    With clump (interpolate.evaluate_strands's `clump` argument, (scale, exponent,
    towards)), the strand is (1-c)·its blend + c·its wisp key (guide 0) carried over, so
    its bound per bin is the blend's plus c·(the key's - the blend's) where the key bends
    more, plus |c''| times its root's distance to the key's root (shaping.py; what is the
    same for every strand is already in `bins`, shaping.shaping_bound).

    Returns an AdaptiveResolution. Each strand's numbers depend only on its own inputs
    (incremental regeneration relies on it)."""
    tolerance = np.asarray(tolerance, np.float64)
    mix = None
    if clump is not None:
        from .shaping import clump_bins
        scale, exponent, towards = clump
        c, _, c2 = clump_bins(scale, exponent, bins.shape[1])
        gap = np.sqrt((np.asarray(towards, np.float64) ** 2).sum(axis=0))
        mix = (c, c2 if c2.any() else None, gap)
    sigma, counts, capped, needed = _greedy_sigma(frac, guides, weights, bins, tolerance, max_cylinders, chunk,
                                                  table_step, threads, mix)
    met = tolerance.copy()
    todo = np.flatnonzero(capped & (frac > 0))
    if todo.size:
        # The lower bound of the count scales as 1/sqrt(tol): start where it says the cap fits.
        trial = tolerance[todo] * np.maximum(_RELAX, (needed[todo] / max_cylinders) ** 2)
        done_idx, done_sig, done_counts = [], [], []
        for _ in range(60):
            sub = None if mix is None else (mix[0], mix[1], mix[2][todo])
            sig2, cnt2, cap2, _ = _greedy_sigma(frac[todo], guides[todo], weights[todo], bins, trial, max_cylinders,
                                                chunk, table_step, threads, sub)
            ends = np.cumsum(cnt2)
            fits = np.flatnonzero(~cap2)
            if fits.size:
                rows = np.repeat(ends[fits] - cnt2[fits], cnt2[fits]) + (
                    np.arange(int(cnt2[fits].sum())) - np.repeat(np.cumsum(cnt2[fits]) - cnt2[fits], cnt2[fits]))
                done_idx.append(todo[fits])
                done_sig.append(sig2[rows])
                done_counts.append(cnt2[fits])
                met[todo[fits]] = trial[fits]
            todo, trial = todo[cap2], trial[cap2] * _RELAX
            if not todo.size:
                break
        met[todo] = np.inf
        if done_idx:
            sigma, counts = _replace_strands(sigma, counts, np.concatenate(done_idx), np.concatenate(done_sig),
                                             np.concatenate(done_counts))
    return AdaptiveResolution(sigma, counts, met, needed)


def _replace_strands(sigma, counts, sel, new_sigma, new_counts):
    """Flat per-point values of strands with strands `sel` (their new values `new_sigma`, in
    the order of sel, `new_counts` points each) replaced."""
    out_counts = counts.copy()
    out_counts[sel] = new_counts
    old_start = np.cumsum(counts) - counts
    base = old_start.copy()
    new_start = np.cumsum(new_counts) - new_counts
    base[sel] = len(sigma) + new_start
    first = np.cumsum(out_counts) - out_counts
    src = np.repeat(base - first, out_counts) + np.arange(int(out_counts.sum()))
    return np.concatenate([sigma, new_sigma])[src], out_counts


def _greedy_sigma(frac, guides, weights, bins, tolerance, max_cylinders, chunk=_CHUNK, table_step=0.0, threads=None,
                  mix=None):
    """The greedy placement of adaptive_sigma: (sigma flat, counts, capped (S,) bool: the
    cap stopped the strand, which got max_cylinders equal steps, needed (S,) the count's
    lower bound). mix: None or clump's (c (NB,), |c''| (NB,) or None, root gap (S,)).
    Ranges of `chunk` strands on `threads` threads (parallel.run_jobs); a strand's numbers
    do not depend on its range."""
    bins_t = np.ascontiguousarray(np.asarray(bins, np.float32).T)   # (NB, K): a bin's row is contiguous

    scratch = {}

    def part(lo, hi):
        m = None if mix is None else (mix[0], mix[1], mix[2][lo:hi])
        return _greedy_range(frac[lo:hi], guides[lo:hi], weights[lo:hi], bins_t, tolerance[lo:hi], max_cylinders,
                             table_step, m, scratch)
    parts = parallel.run_jobs([partial(part, lo, hi) for lo, hi in parallel.ranges(len(frac), size=chunk)], threads)
    if not parts:
        return np.zeros(0), np.zeros(0, np.int64), np.zeros(0, bool), np.zeros(0)
    return tuple(np.concatenate([p[i] for p in parts]) for i in range(4))


def _running(op, x, out):
    """out[b] = op(out[b-1], x[b]) down the rows of x (NB, S): np.maximum.accumulate and
    np.cumsum along axis 0, a row at a time (numpy's own walk the columns with a stride of a
    row, some twenty times slower)."""
    out[0] = x[0]
    for b in range(1, len(x)):
        op(out[b - 1], x[b], out=out[b])
    return out


def _greedy_range(f, g, w, bins_t, tolerance, max_cylinders, table_step, mix=None, scratch=None):
    """_greedy_sigma on one range of strands, sweeping the bins from the root.

    Per strand the sweep carries the open segment's start c and the longest step its bins
    allow so far, hm = sqrt(budget / max A) (the running minimum of each bin's own step
    H = sqrt(budget / A)). A bin the segment can cross (c + hm reaches its far edge, the
    tip in the strand's last bin) only lowers hm; otherwise the segment ends inside it, at
    c + hm, or at the bin's near edge when even that is out of reach (the bins before
    allowed it), and the bin is then covered by steps of its own H. So a segment is always
    the longest whose h² times the largest bound over the bins it touches fits the budget,
    as in the greedy search bin by bin, but the work per bin is a few whole-array
    operations over the strands, not a search per segment (a tenth of the time at 100,000
    strands). A strand leaves the sweep after its last bin, or when the cap stops it.
    scratch: where its work arrays are kept between ranges (_sweep_scratch)."""
    nb = bins_t.shape[0]
    s = len(f)
    lanes = np.arange(s)
    step2 = float(table_step) ** 2
    # A (NB, S): the blend of the guides' bounds, bin-major (one contiguous row per bin), in
    # float32 (half the memory traffic of the work over strands x bins; a bound off by a few
    # parts in 10^7 is nothing beside its 5 % margin, interpolate._CURVATURE_SAFETY).
    f32 = np.float32
    width = max_cylinders + 2           # root, max_cylinders - 1 inner points, tip; one spill column
    key, a, term, grid = _sweep_scratch(scratch, nb, s, width)
    np.take(bins_t, g[:, 0], axis=1, out=key, mode="clip")
    np.multiply(key, w[:, 0].astype(f32), out=a)
    for k in (1, 2):
        np.take(bins_t, g[:, k], axis=1, out=term, mode="clip")    # clip: not buffered
        term *= w[:, k].astype(f32)
        a += term
    if mix is not None:
        # Clump: + c·(the wisp key's bound - the blend's) where the key bends more, and
        # |c''| times the root gap (adaptive_sigma).
        c, c2, gap = mix
        np.subtract(key, a, out=key)
        np.maximum(key, f32(0.0), out=key)
        key *= c.astype(f32)[:, None]
        a += key
        if c2 is not None:
            a += (c2[:, None] * gap[None, :]).astype(f32)
    last_bin = np.clip(np.ceil(f * nb).astype(np.int64) - 1, 0, nb - 1)
    # Bins past the tip do not count: the largest bound up to the last bin.
    _running(np.maximum, a, key)
    # The tables' lerp moves each point by up to (the strand's largest bound)·step²/8.
    budget = np.maximum(8.0 * tolerance - key[last_bin, lanes] * step2, 1e-300)
    # Lower bound on the count: a segment that fits has ∫ sqrt(A / 8tol) <= 1 over it, so a
    # strand with more than max_cylinders of that integral cannot fit: cap it right away.
    np.sqrt(a, out=key)
    _running(np.add, key, term)
    whole = np.where(last_bin > 0, term[np.maximum(last_bin - 1, 0), lanes], 0.0)
    need = (whole / nb + key[last_bin, lanes] * (f - last_bin / nb)) / np.sqrt(budget)
    h_bin = term
    with np.errstate(divide="ignore", over="ignore"):
        # A straight bin's step is unbounded; a finite stand-in keeps 0·h a number.
        np.divide(budget.astype(f32), a, out=h_bin)
    np.sqrt(h_bin, out=h_bin)
    np.minimum(h_bin, f32(1e30), out=h_bin)
    del key
    # Strands by last bin: they leave the sweep there.
    order = np.argsort(last_bin, kind="stable")
    leave = np.searchsorted(last_bin[order], np.arange(nb + 1))
    active = (f > 0) & (need <= max_cylinders)
    c = np.where(active, 0.0, np.inf)   # a strand out of the sweep: no segment of it ever ends
    hm = np.full(s, np.inf, f32)        # float32: it only ever holds values of h_bin (or inf)
    count = np.zeros(s, np.int64)       # inner points placed so far
    # A row's points: the root, then each segment's end; what lies past them is never read.
    grid[:, 0] = 0.0
    flat = grid.ravel()
    reach, hi = np.empty(s), np.empty(s)
    # Bins where every strand's step reaches across a whole bin: a segment ending in one
    # never needs another step within it (first >= b / nb, first + h >= (b + 1) / nb >= hi,
    # in float64 as in the test below), so the test for more steps is skipped there.
    wide = (np.arange(nb) / nb + h_bin.min(axis=1)) >= (np.arange(nb) + 1.0) / nb if s else np.ones(nb, bool)
    # Up to the shortest strand's tip, a bin's far edge hi = min(f, (b + 1) / nb) is the
    # edge itself for every strand in the sweep (the others' reach is inf).
    shortest = float(f[active].min()) if active.any() else 0.0
    for b in range(nb):
        np.minimum(hm, h_bin[b], out=hm)
        np.add(c, hm, out=reach)
        edge = (b + 1.0) / nb
        if edge <= shortest:
            hi_of = None
            ends = np.flatnonzero(reach < edge)
        else:
            np.minimum(f, edge, out=hi)
            hi_of = hi.take
            ends = np.flatnonzero(reach < hi)   # inf (out of the sweep) is never below
        if ends.size:
            h = h_bin[b, ends]
            first = np.maximum(reach[ends], b / nb)
            at = count[ends] + 1
            flat[ends * width + np.minimum(at, width - 1)] = first
            hm[ends] = h
            # Steps of h from `first` until one reaches hi: the least k with first + k·h + h >= hi.
            more = () if wide[b] else np.flatnonzero(first + h < (edge if hi_of is None else hi_of(ends)))
            if len(more):
                fm, hh = first[more], h[more]
                hm_ = np.full(len(more), edge) if hi_of is None else hi_of(ends[more])
                k = np.maximum(np.ceil((hm_ - fm) / hh) - 1.0, 1.0)
                k = np.where(fm + k * hh + hh >= hm_, k, k + 1.0)
                k = np.where((k > 1) & (fm + (k - 1.0) * hh + hh >= hm_), k - 1.0, k)
                km = np.minimum(k, max_cylinders).astype(np.int64)
                i = np.arange(int(km.sum())) - np.repeat(np.cumsum(km) - km, km) + 1
                rows = np.repeat(ends[more], km)
                flat[rows * width + np.minimum(np.repeat(at[more], km) + i, width - 1)] = (
                    np.repeat(fm, km) + i * np.repeat(hh, km))
                at[more] += km
                first[more] = fm + km * hh
            count[ends] = at
            c[ends] = first
        gone = order[leave[b]:leave[b + 1]]
        c[gone] = np.inf     # past its tip
    capped = (f > 0) & (~active | (count + 1 > max_cylinders))
    done = np.flatnonzero((f > 0) & ~capped)
    grid[done, count[done] + 1] = f[done]
    grid = grid[:, :max_cylinders + 1]
    # Each row's points are a prefix of it: the root, the inner points, the tip.
    points = np.where(capped, max_cylinders + 1, count + 2)
    _merge_sliver_tips(grid, ~capped & (f > 0), a, nb, last_bin, budget, points)
    if capped.any():
        kk = np.arange(max_cylinders + 1)
        grid[capped] = f[capped, None] * (kk / max_cylinders)
    zero = f <= 0
    if zero.any():  # a strand of no length: one cylinder of no length
        grid[zero, 1] = 0.0
        points[zero] = 2
    # The rows' prefixes one after another: a gather by flat index (a boolean mask of the
    # whole grid takes twice the time).
    stops = np.cumsum(points)
    total = int(stops[-1]) if s else 0
    src = np.repeat(lanes * width - (stops - points), points)
    src += np.arange(total)
    return flat.take(src), points, capped, need


def strand_attributes(seed, ids, counts, along, base_radius, base_color, params, out=None):
    """Per-point radius, colour and alpha (SPEC §6), float32, for strands with `counts` points
    at fractions `along` of their length (0 at the root, 1 at the tip), so a profile is the
    same whatever the resolution: `along` is flat (P,), or (n,) shared by every strand when
    all counts are n (fixed resolution: the profiles are then made once and copied).
    `along` may also be (sigma (P,), frac (S,)), the fractions σ / f_j made a range at a time.
    Radius: r(1 - s) ('linear', the thesis's r(1 - i/res)), r ('constant'), or constant up to
    taper_start then linear to 0 ('taper_from'). Colour: base + U(-1,1)·variation per strand
    and per point, clamped to [0, 1]. Alpha: 1 up to alpha_start, then linear to alpha_tip.
    out: None or (radius (P,), colour (P, 3), alpha (P,)) float32 arrays to write into (the
    rows of a block of the whole result; alpha None where it is 1 everywhere, alpha_is_one:
    nothing is written for it); the arrays written are returned either way."""
    if out is not None:
        made = strand_attributes(seed, ids, counts, along, base_radius, base_color, params) if (
            not isinstance(along, tuple) or np.any(params.color_variation_point)) else None
        if made is None:
            color = strand_colors(seed, ids, base_color, params)
            return _flat_attributes(along, counts, base_radius, color, params, out=out)
        for whole, part in zip(out, made):
            if whole is not None:
                whole[...] = part
        return out
    n_pts = int(counts.sum())
    color = strand_colors(seed, ids, base_color, params)
    var_p = np.asarray(params.color_variation_point)
    if isinstance(along, tuple):    # (sigma (P,), frac (S,)): along = σ / f_j, made per range
        if not var_p.any():
            return _flat_attributes(along, counts, base_radius, color, params)
        along = along[0] / np.repeat(along[1], counts)
    s = along.astype(np.float32)
    if along.shape != (n_pts,) and not var_p.any():
        out = (np.empty(n_pts, np.float32), np.empty((n_pts, 3), np.float32), np.empty(n_pts, np.float32))
        fill_strand_rows(*out, base_radius, color, radius_profile(s, params), alpha_profile(s, params))
        return out
    if along.shape != (n_pts,):
        s = np.tile(s, len(counts))
    if not var_p.any():
        return _flat_attributes(s, counts, base_radius, color, params)
    radius = np.repeat(base_radius.astype(np.float32), counts) * radius_profile(s, params)
    color = np.repeat(color, counts, axis=0)
    strand = np.repeat(np.arange(len(counts)), counts)
    offsets = np.zeros(len(counts), np.int64)
    np.cumsum(counts[:-1], out=offsets[1:])
    k = np.arange(n_pts) - offsets[strand]
    sid = ids[strand]
    u = np.stack([rng.uniform(seed, sid, rng.CH_COLOR_POINT + 3 * k + c) for c in range(3)], 1)
    color += ((2.0 * u - 1.0) * var_p).astype(np.float32)
    np.clip(color, 0.0, 1.0, out=color)
    alpha = alpha_profile(s, params)
    return radius, color, np.ones(n_pts, np.float32) if alpha is None else alpha


def _flat_attributes(s, counts, base_radius, color, params, threads=None, out=None):
    """strand_attributes without per-point colour variation, for strands of any counts at
    fractions s (P,) float32, or (sigma (P,), frac (S,)) whose quotient they are: ranges of
    strands on the worker threads, each writing its own rows (a colour channel at a time:
    np.repeat of 12-byte rows is slow). out: None or the arrays to write into (colour None:
    not written, the colour kept a strand at a time, hairio.Strands.strand_color)."""
    ends = np.cumsum(counts)
    n_pts = int(ends[-1]) if len(ends) else 0
    if out is None:
        out = (np.empty(n_pts, np.float32), np.empty((n_pts, 3), np.float32), np.empty(n_pts, np.float32))
    radius, rgb, alpha = out
    base = base_radius.astype(np.float32)
    clamped = None if rgb is None else np.clip(color, 0.0, 1.0)

    def fill(lo, hi):
        start, stop = (int(ends[lo - 1]) if lo else 0), int(ends[hi - 1])
        n = counts[lo:hi]
        if isinstance(s, tuple):
            # The quotient in float64, stored straight into float32 (no float64 temporary).
            part = np.empty(stop - start, np.float32)
            np.divide(s[0][start:stop], np.repeat(s[1][lo:hi], n), out=part, casting="same_kind")
        else:
            part = s[start:stop]
        np.multiply(np.repeat(base[lo:hi], n), radius_profile(part, params), out=radius[start:stop])
        if rgb is not None:
            for c in range(3):
                rgb[start:stop, c] = np.repeat(clamped[lo:hi, c], n)
        if alpha is not None:
            a = alpha_profile(part, params)
            alpha[start:stop] = 1.0 if a is None else a
    if len(counts):
        parallel.run_jobs([partial(fill, lo, hi) for lo, hi in parallel.ranges(len(counts))], threads)
    return out


def radius_alpha_rows(s, counts, base_radius, params, radius, alpha):
    """The radius and alpha of strands_attributes into `radius` (P,) and `alpha` (P,) (None:
    not written, an opaque groom's), without the colour (kept a strand at a time); s as
    _flat_attributes takes it."""
    _flat_attributes(s, counts, base_radius, None, params, out=(radius, None, alpha))


def strand_colors(seed, ids, base_color, params):
    """Colour per strand, (S,3) float32: base + U(-1,1)·color_variation (not yet clamped)."""
    var = np.asarray(params.color_variation)
    color = base_color
    if var.any():
        u = np.stack([rng.uniform(seed, ids, rng.CH_COLOR + c) for c in range(3)], 1)
        color = color + (2.0 * u - 1.0) * var
    return color.astype(np.float32)


def radius_profile(s, params):
    """Radius per unit root radius at fractions s (float32) of the strand length."""
    if params.radius_mode == "linear":
        return np.float32(1.0) - s
    if params.radius_mode == "constant":
        return np.ones_like(s)
    span = np.float32(max(1.0 - params.taper_start, 1e-12))
    return np.clip((np.float32(1.0) - s) / span, 0.0, 1.0)


def alpha_is_one(params):
    """Whether the strands of `params` are opaque throughout (alpha 1 at every point)."""
    return params.alpha_start >= 1.0 or params.alpha_tip == 1.0


def ones(n):
    """(n,) float32 ones that take no memory a point: a read-only view of one value, the alpha
    of an opaque groom (4 bytes a point, 250 MB at 1,000,000 strands of 62 points, that say
    nothing). Code that needs the values laid out (a file, a GPU buffer) lays them out."""
    return np.broadcast_to(np.float32(1.0), (int(n),))


def alpha_profile(s, params):
    """Alpha at fractions s (float32) of the strand length; None where it is 1 everywhere."""
    if alpha_is_one(params):
        return None
    t = np.clip((s - params.alpha_start) / (1.0 - params.alpha_start), 0.0, 1.0)
    return (1.0 + (params.alpha_tip - 1.0) * t).astype(np.float32)


def fill_strand_rows(radius, color, alpha, base_radius, strand_color, radius_prof, alpha_prof):
    """Write radius (S·n,), color (S·n,3), alpha (S·n,) of S strands of n points that share
    the profiles radius_prof, alpha_prof (n,) (alpha_prof None: 1; alpha None: not written,
    as for an opaque groom's result, cylinders.ones; color None: not written, the colour
    kept a strand at a time): each strand's radius
    scales the profile, its colour (clamped here) is copied to its points. Whole rows per
    strand, written in place (one strided pass per colour channel: np.repeat copies 12-byte
    rows one at a time and takes about twice as long)."""
    n = len(radius_prof)
    rows = (len(base_radius), n)
    np.multiply(base_radius.astype(np.float32)[:, None], radius_prof, out=radius.reshape(rows))
    if color is not None:
        clamped = np.clip(strand_color, 0.0, 1.0)
        per_point = color.reshape(rows + (3,))
        for c in range(3):
            per_point[:, :, c] = clamped[:, c, None]
    if alpha is not None:
        alpha.reshape(rows)[...] = 1.0 if alpha_prof is None else alpha_prof


SLIVER = 1e-3   # of a bin: a last segment shorter than this is merged when the bound allows


def _sweep_scratch(scratch, nb, s, width):
    """The calling thread's work arrays for _greedy_range over s strands, three (nb, s)
    float32 and the (s, width) float64 grid, from `scratch` (a dict by thread the caller
    keeps for its ranges; None: fresh arrays). Fresh arrays of this size come as new pages,
    each faulted in, for every range: kept for the ranges of one _greedy_sigma, 5 % of a
    range's time at 12,500 strands; dropped with it, so no thread holds them afterwards."""
    have = None if scratch is None else scratch.get(threading.get_ident())
    if have is None or have[0].size < nb * s or have[3].size < s * width:
        have = (np.empty(nb * s, np.float32), np.empty(nb * s, np.float32), np.empty(nb * s, np.float32),
                np.empty(s * width))
        if scratch is not None:
            scratch[threading.get_ident()] = have
    return tuple(x[:nb * s].reshape(nb, s) for x in have[:3]) + (have[3][:s * width].reshape(s, width),)


def _merge_sliver_tips(grid, rows, a, nb, last_bin, budget, points):
    """In place: where a strand's trim fraction falls just past a bin edge, the greedy search
    stops at the edge and leaves a sliver of a last segment, whose end repeats its start to
    within float32 (renderers then drop or special-case it). The last two segments [a, b],
    [b, c] become one when the bound holds over [a, c] (the largest curvature bound `a` (NB, S)
    from a's bin to the last bin, times (c - a)² within `budget`); otherwise b moves to the middle
    of [a, c]: [a, b'] is a part of the accepted [a, b], and [b', c] has a quarter of
    (c - a)², which fits whenever [a, c] misses by less than 4x (the greedy segment before a
    sliver nearly always reaches the bound exactly, so it misses by a hair). points (S,):
    each row's points (a prefix of it), one fewer where two segments become one."""
    r = np.flatnonzero(rows & (points >= 3))
    if not r.size:
        return
    k = points[r] - 1
    sliver = (grid[r, k] - grid[r, k - 1]) < SLIVER / nb
    r, k = r[sliver], k[sliver]
    if not r.size:
        return
    last, prev2 = grid[r, k], grid[r, k - 2]
    b0 = np.minimum(np.floor(prev2 * nb).astype(np.int64), last_bin[r])
    span = (np.arange(nb)[:, None] >= b0[None, :]) & (np.arange(nb)[:, None] <= last_bin[r][None, :])
    suffix = np.where(span, a[:, r], 0.0).max(axis=0)
    miss = suffix * (last - prev2) ** 2 / budget[r]
    merge = miss <= 1.0
    grid[r[merge], k[merge] - 1] = last[merge]
    points[r[merge]] -= 1
    split = (miss > 1.0) & (miss <= 4.0)
    grid[r[split], k[split] - 1] = 0.5 * (prev2[split] + last[split])


def _all_segment_distances(points, a, b):
    """Distance from each point (N,3) to the nearest of the segments a[i]–b[i] (M,3), every
    pair tested."""
    ab = b - a
    len2 = np.einsum("md,md->m", ab, ab)
    ap = points[:, None, :] - a[None, :, :]
    t = np.einsum("nmd,md->nm", ap, ab) / np.where(len2 > 0, len2, 1.0)
    t = np.clip(np.where(len2 > 0, t, 0.0), 0.0, 1.0)
    diff = ap - t[..., None] * ab[None]
    return np.sqrt(np.einsum("nmd,nmd->nm", diff, diff)).min(axis=1)


_BLOCK = 256    # dense points per block of _segment_distances


def _segment_distances(points, a, b):
    """Distance from each point (N,3) to the nearest of the segments a[i]–b[i] (M,3), exactly.

    All pairs cost N·M (a strand of 300 cylinders sampled 64 times denser: 5.8 M), so points
    go in blocks of neighbours: a block's distances to the segment whose middle is nearest
    its centre bound its answer from above, and only segments that could come nearer than
    that (their middle within the bound + the block's and the segment's half-sizes of its
    centre) are tested."""
    n, m = len(points), len(a)
    if n * m <= 50_000:
        return _all_segment_distances(points, a, b)
    mid = 0.5 * (a + b)
    half = 0.5 * np.linalg.norm(b - a, axis=1)
    out = np.empty(n)
    for lo in range(0, n, _BLOCK):
        block = points[lo:lo + _BLOCK]
        centre = block.mean(axis=0)
        spread = float(np.sqrt(np.max(np.einsum("nd,nd->n", block - centre, block - centre))))
        to_mid = np.sqrt(np.einsum("md,md->m", mid - centre, mid - centre))
        k = int(np.argmin(to_mid))
        bound = float(_all_segment_distances(block, a[k:k + 1], b[k:k + 1]).max())
        near = np.flatnonzero(to_mid - half - spread <= bound * (1 + 1e-9))
        out[lo:lo + _BLOCK] = _all_segment_distances(block, a[near], b[near])
    return out


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

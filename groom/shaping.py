# SPDX-License-Identifier: GPL-3.0-or-later
"""Wisps that read as wisps: clump, frizz and curl (not in the thesis; Blender's hair nodes
Clump, Frizz and Curl do the same jobs).

Each is a function of a strand's curve parameter σ (the fraction of its keys' length, as in
interpolate.py) and of the strand's own random numbers, so the dense samples a measurement
takes and the strand's points lie on one curve, and a strand's shape never depends on which
others are computed with it (incremental regeneration stays bit-identical).

- clump: C'(σ) = C(σ) + c(σ)·(T(σ) - C(σ)), c(σ) = clump·σ^clump_shape, where T is the
  wisp's key carried to the key's own root by the strand's own transform B_j:
  T(σ) = R_key + B_j D_main(σ). Loose at the root (c = 0: the root stays), tight at the tip;
  strands of one wisp gather toward their key, strands of two wisps part between them. It
  is done inside the blend (interpolate.evaluate_strands, `clump_arguments`): a shift of
  the weights toward the wisp key and a move by c·(R_key - R_j), no extra work per point.
- frizz: + frizz·a_j·σ²·(u1 sin(2πν1σ + φ1) + u2 sin(2πν2σ + φ2))/2, two random unit
  directions u, 2-4 periods ν along the length, amplitude a_j in [0.3, 1]: stray, wandering
  tips and a straight root.
- curl: + r(σ)(cos ψ e1 + sin ψ e2), a helix about the wisp key's direction t(σ) (e1 ⟂ t and
  a random direction of the strand, e2 = t × e1), ψ = 2π·σ·L/curl_period + φ (L the wisp
  key's length), radius curl·[0.7, 1] growing over the first tenth of the length.

`shaping_bound` adds what these do to the curvature bound the adaptive resolution uses, so
the strands keep the resolution's tolerance.
"""
import numpy as np

from . import parallel, rng

# Random channels of the shaping (see rng.py: fixed numbers, new uses never shift old ones).
CH_FRIZZ = 16    # 16..25: two directions (2 each), two frequencies, two phases, amplitude
CH_CURL = 32     # 32..35: phase, radius, reference direction (2)
_FRIZZ_PERIODS = (2.0, 4.0)
_CURL_RAMP = 0.1


def active(params):
    """Whether frizz or curl is asked for (clump is part of the blend)."""
    return params.frizz > 0 or params.curl > 0


def clump_arguments(params, main, roots, key_roots):
    """The `clump` argument of interpolate.evaluate_strands for strands whose wisp keys are
    `main` (S,) and roots (3, S): None without clump."""
    if not params.clump > 0:
        return None
    towards = (key_roots[main].T - roots).astype(np.float32)
    return params.clump, params.clump_shape, towards


def clump_bins(clump, exponent, nb):
    """Per bin of σ (NB,): the pull c = clump·σ^exponent and |c'|, |c''|, each at the bin's
    far end: their largest over the bin for c, and for c' (c'') at an exponent of at least
    1 (2). Below that a derivative grows without bound toward the root and this understates
    it near there (a known limit: the presets use exponent 1, where c'' = 0)."""
    s = (np.arange(nb) + 1.0) / nb
    k = float(exponent)
    c = clump * s ** k
    c1 = clump * k * s ** max(k - 1.0, 0.0)
    c2 = clump * k * abs(k - 1.0) * s ** max(k - 2.0, 0.0)
    return c, c1, c2


def shaping_bound(bins, rows, params):
    """The curvature bins of interpolate.curvature_bound (K, NB) plus what clump, frizz and
    curl add to |C''(σ)| (bounds, per bin of σ; each taken at the bin's far end)."""
    if not (active(params) or params.clump > 0):
        return bins
    nb = bins.shape[1]
    s = (np.arange(nb) + 1.0) / nb
    # Key lengths from their tables (the steps are 1/(M-1) of the length apart).
    lengths = np.sqrt((rows[:, :-1, 4:7].astype(np.float64) ** 2).sum(axis=2)).sum(axis=1)
    longest = float(lengths.max()) if lengths.size else 0.0
    extra = np.zeros(nb)
    if params.clump > 0:
        # Clump blends the strand with its wisp key: C'' = (1-c)·C'' + c·T'' - 2c'(C' - T')
        # - c''(C - T), with |C' - T'| <= 2L and |C - T| <= 2L + |R_key - R_j|. The first
        # two terms are a blend of the strand's own bound and its wisp key's, which the
        # adaptive resolution adds per strand (clump_bins: the bins hold neither alone, and
        # where the wisp key bends more than the blend of the strand's keys, the blend's
        # bound alone fell short by up to 14 %); the root distance's share too. Here: the
        # rest, the same for every key.
        _, c1, c2 = clump_bins(params.clump, params.clump_shape, nb)
        extra += 4.0 * c1 * longest + 2.0 * c2 * longest
    if params.frizz > 0:
        w = 2.0 * np.pi * _FRIZZ_PERIODS[1]
        extra += params.frizz * (s * s * w * w + 4.0 * s * w + 2.0)
    if params.curl > 0:
        w = 2.0 * np.pi * longest / params.curl_period
        extra += params.curl * (w * w + 2.0 * w / _CURL_RAMP + 6.0 / _CURL_RAMP ** 2)
    return bins + extra[None, :]


def shape_strands(points, counts, sigma, frac, transforms, main, ids, rows, params, threads=None,
                  chunk_points=1 << 15):
    """Frizz and curl applied in place to `points` (P,3) float32 of strands with
    `counts` points at curve parameters `sigma` (flat, P) or, when None, equal steps over
    [0, frac_j] (fixed resolution). transforms (9,S) f32 and rows (K,M,8)
    as interpolate.evaluate_strands takes them; main (S,) the wisp key of each strand, ids
    (S,) its random stream. Chunks of whole strands on `threads` threads."""
    if not active(params) or not len(counts):
        return points
    counts = np.asarray(counts, np.int64)
    ends = np.cumsum(counts)
    bounds, first = [], 0
    while first < len(counts):
        start = int(ends[first - 1]) if first else 0
        last = max(int(np.searchsorted(ends, start + chunk_points, side="right")), first + 1)
        bounds.append((first, last))
        first = last
    per = _per_strand(params, ids, rows, main)
    jobs = [lambda b=b: _shape_chunk(points, counts, ends, sigma, frac, transforms, main, rows, params, per, b)
            for b in bounds]
    parallel.run_jobs(jobs, threads)
    return points


def _per_strand(params, ids, rows, main):
    """Each strand's random numbers for frizz and curl, (name -> (S,) or (3, S))."""
    seed, out = params.seed, {}
    if params.frizz > 0:
        u = [rng.uniform(seed, ids, CH_FRIZZ + c) for c in range(7)]
        lo, hi = _FRIZZ_PERIODS
        out["dir1"] = _unit_from(u[0], u[1])
        out["dir2"] = _unit_from(u[2], u[3])
        out["nu1"] = 2.0 * np.pi * (lo + (hi - lo) * u[4])
        out["nu2"] = 2.0 * np.pi * (lo + (hi - lo) * rng.uniform(seed, ids, CH_FRIZZ + 7))
        out["phi1"] = 2.0 * np.pi * u[5]
        out["phi2"] = 2.0 * np.pi * rng.uniform(seed, ids, CH_FRIZZ + 8)
        out["frizz"] = params.frizz * (0.3 + 0.7 * u[6])
    if params.curl > 0:
        lengths = np.sqrt((rows[:, :-1, 4:7].astype(np.float64) ** 2).sum(axis=2)).sum(axis=1)
        out["turns"] = 2.0 * np.pi * lengths[main] / params.curl_period
        out["psi0"] = 2.0 * np.pi * rng.uniform(seed, ids, CH_CURL)
        out["radius"] = params.curl * (0.7 + 0.3 * rng.uniform(seed, ids, CH_CURL + 1))
        out["ref"] = _unit_from(rng.uniform(seed, ids, CH_CURL + 2), rng.uniform(seed, ids, CH_CURL + 3))
    return out


def _unit_from(u, v):
    """Unit vectors (3, S) uniform on the sphere from two uniforms."""
    z = 2.0 * u - 1.0
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    a = 2.0 * np.pi * v
    return np.stack([r * np.cos(a), r * np.sin(a), z])


def _shape_chunk(points, counts, ends, sigma, frac, transforms, main, rows, params, per, bound):
    first, last = bound
    start = int(ends[first - 1]) if first else 0
    stop = int(ends[last - 1])
    strand = np.repeat(np.arange(first, last), counts[first:last])
    if sigma is None:
        k = np.arange(stop - start) - np.repeat(np.cumsum(counts[first:last]) - counts[first:last], counts[first:last])
        s = frac[strand] * (k / (counts[strand] - 1))
    else:
        s = sigma[start:stop]
    p = points[start:stop].astype(np.float64)
    n_keys, samples, _ = rows.shape
    if params.curl > 0:
        pos = s * (samples - 1)
        i0 = np.minimum(pos.astype(np.int64), samples - 2)
        row = rows.reshape(n_keys * samples, 8)[main[strand] * samples + i0].astype(np.float64)
        b = transforms[:, strand].astype(np.float64)

        def turn(v):  # B_j v, per point
            return np.stack([b[3 * a] * v[:, 0] + b[3 * a + 1] * v[:, 1] + b[3 * a + 2] * v[:, 2] for a in range(3)], 1)
    out = p.copy()
    if params.frizz > 0:
        f = per
        amp = (f["frizz"][strand] * s * s * 0.5)[:, None]
        out += amp * (f["dir1"][:, strand].T * np.sin(f["nu1"][strand] * s + f["phi1"][strand])[:, None]
                      + f["dir2"][:, strand].T * np.sin(f["nu2"][strand] * s + f["phi2"][strand])[:, None])
    if params.curl > 0:
        t = turn(row[:, 4:7])
        t /= np.maximum(np.sqrt((t * t).sum(axis=1)), 1e-300)[:, None]
        ref = per["ref"][:, strand].T
        e1 = np.cross(t, ref)
        n1 = np.sqrt((e1 * e1).sum(axis=1))
        # A reference along the key: any other direction will do.
        flat = n1 < 1e-6
        if flat.any():
            e1[flat] = np.cross(t[flat], np.roll(ref[flat], 1, axis=1))
            n1[flat] = np.sqrt((e1[flat] ** 2).sum(axis=1))
        e1 /= np.maximum(n1, 1e-300)[:, None]
        e2 = np.cross(t, e1)
        psi = per["turns"][strand] * s + per["psi0"][strand]
        x = np.clip(s / _CURL_RAMP, 0.0, 1.0)
        r = per["radius"][strand] * x * x * (3.0 - 2.0 * x)
        out += r[:, None] * (np.cos(psi)[:, None] * e1 + np.sin(psi)[:, None] * e2)
    points[start:stop] = out

# SPDX-License-Identifier: GPL-3.0-or-later
"""Measurements behind the model's choices (benchmarks call these; tests do not time them).

- `seam_jump` / `seam_jumps_by_mode`: how much neighbouring strands differ across a wisp
  border, per neighbour mode (SPEC §5). Measured on the default scalp with the first 10
  keys of the 'wavy' preset, N = 50, tidiness 1, equal lengths, 32 points per strand,
  20,000 root pairs 0.5 mm apart; largest offset difference between the two strands of a
  pair, in metres (2 shared CPU cores, numpy 1.26):

      mode                 across a border   within a wisp
      key  (reading a)     0.195             0.0001
      root (reading b)     0.190             0.0023
      interpolate          0.0175            0.0144

  Readings (a) and (b) both jump by the length of the hair at a border (the main key's
  (101-N) factor moves from one key to the other); (b) is the smoother of the two by a
  little. 'interpolate' (Blender's weighting, sharpened by N) has no seam: across a border
  strands differ no more than inside a wisp. It is the default (params.GroomParams).
- `adaptive_vs_fixed`: cylinders per strand of the adaptive resolution against the thesis's
  fixed 25, at the same maximum geometric error (same 300 strands, 10 keys):
  curly 18.6, wavy 17.6, long_straight 8.2 (against 25).
- `strand_errors`: per-strand geometric error against the exact curve sampled 64x denser.
"""
import numpy as np

from .cylinders import strand_geometric_errors
from .generate import Generator
from .params import NEIGHBOUR_MODES
from .sampling import RootSamples, sample_roots


def _pair_samples(scalp, pairs, spacing, seed):
    """`pairs` roots and, for each, a partner about `spacing` away in the same triangle."""
    base = sample_roots(scalp, pairs, seed)
    rs = np.random.default_rng(seed + 1)
    tri = base.tri
    v = scalp.vertices[scalp.triangles[tri]]
    # A random direction in the triangle's plane, as a barycentric step of world length `spacing`.
    e1, e2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    ang = rs.uniform(0, 2 * np.pi, pairs)
    g11, g12, g22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    # step = x·e1 + y·e2 with |step| = spacing along a random direction of (x, y) metric-normalised
    x, y = np.cos(ang), np.sin(ang)
    norm = np.sqrt(np.maximum(x * x * g11 + 2 * x * y * g12 + y * y * g22, 1e-300))
    x, y = x * spacing / norm, y * spacing / norm
    bary2 = base.bary + np.stack([-x - y, x, y], 1)
    inside = (bary2 >= 0).all(axis=1)
    bary2 = np.where(inside[:, None], bary2, base.bary)
    keep = np.flatnonzero(inside)
    tri2 = np.concatenate([tri[keep], tri[keep]])
    bary_all = np.concatenate([base.bary[keep], bary2[keep]])
    n = len(keep)
    # Both strands of a pair share an id, so random streams cannot make them differ.
    ids = np.concatenate([base.ids[keep], base.ids[keep]])
    return RootSamples(scalp.points_at(tri2, bary_all), tri2, bary_all, ids), n


def seam_jump(scalp, keys, params, pairs=20000, spacing=5e-4, seed=1):
    """Largest position jump between neighbouring strands across a wisp border.

    Pairs of roots `spacing` apart are grown with tidiness 1, equal lengths and fixed
    resolution; a pair's jump is max_k |(P_a,k - R_a) - (P_b,k - R_b)|. Returns a dict:
    across_max / across_p99 over pairs whose main keys differ, within_max over the others,
    pairs_across (how many pairs straddle a border)."""
    p = params.replace(tidiness=1.0, min_length=params.max_length, resolution_mode="fixed")
    samples, n = _pair_samples(scalp, pairs, spacing, seed)
    res = Generator(scalp, list(keys), p, samples=samples).generate()
    pts = res.strands.points.astype(np.float64).reshape(2 * n, p.points_per_strand, 3)
    off = pts - res.roots[:, None, :]
    jump = np.abs(off[:n] - off[n:]).max(axis=(1, 2))
    across = res.guides[:n, 0] != res.guides[n:, 0]
    return {"mode": p.neighbour_mode, "pairs_across": int(across.sum()),
            "across_max": float(jump[across].max()) if across.any() else 0.0,
            "across_p99": float(np.percentile(jump[across], 99)) if across.any() else 0.0,
            "within_max": float(jump[~across].max()) if (~across).any() else 0.0}


def seam_jumps_by_mode(scalp, keys, params, **kw):
    """seam_jump for every neighbour mode: {mode: dict}."""
    return {m: seam_jump(scalp, keys, params.replace(neighbour_mode=m), **kw) for m in NEIGHBOUR_MODES}


def strand_errors(gen, sel=None, oversample=64):
    """Per-strand geometric error of a Generator's current strands: max distance from the
    exact curve sampled at `oversample` x the strand's resolution (SPEC §6) to its polyline.
    The exact curve is the blend of the keys' tables of EXACT_SAMPLES samples, not of the
    tables the strands were made from (whose lerp is part of the error)."""
    res = gen.result
    s = res.strands
    sel = np.arange(s.num_strands) if sel is None else np.asarray(sel)
    counts = s.counts[sel].astype(np.int64)
    dense, _ = gen.evaluate(sel, (counts - 1) * oversample, exact=True)
    offs = s.offsets
    errs = np.empty(len(sel))
    dense_off = np.concatenate([[0], np.cumsum(oversample * (counts - 1) + 1)])
    for c in np.unique(counts):  # group strands of one resolution into one batch
        idx = np.flatnonzero(counts == c)
        poly = np.stack([s.points[offs[sel[i]]:offs[sel[i]] + c] for i in idx]).astype(np.float64)
        ex = np.stack([dense[dense_off[i]:dense_off[i + 1]] for i in idx])
        errs[idx] = strand_geometric_errors(ex, poly)
    return errs


def adaptive_vs_fixed(scalp, keys, params, fixed_cylinders=25, strands=1000, max_cylinders=64):
    """Cylinders per strand: adaptive resolution against a fixed count, at equal maximum error.

    Grows `strands` strands with `fixed_cylinders` cylinders, measures their largest geometric
    error E, then grows the same strands adaptively with tolerance E. Returns a dict with
    fixed_max_error, adaptive_max_error, adaptive_mean_cylinders, adaptive_max_cylinders."""
    base = params.replace(count=strands)
    fixed = Generator(scalp, list(keys), base.replace(resolution_mode="fixed",
                                                       points_per_strand=fixed_cylinders + 1))
    fixed.generate()
    e_fixed = float(strand_errors(fixed).max())
    adaptive = Generator(scalp, list(keys), base.replace(resolution_mode="adaptive", tolerance=max(e_fixed, 1e-12),
                                                          tolerance_units="scene",
                                                          points_per_strand=max_cylinders + 1))
    res = adaptive.generate()
    cyl = res.strands.counts - 1
    return {"fixed_cylinders": fixed_cylinders, "fixed_max_error": e_fixed,
            "adaptive_max_error": float(strand_errors(adaptive).max()),
            "adaptive_mean_cylinders": float(cyl.mean()), "adaptive_max_cylinders": int(cyl.max()),
            "strands": strands}


def main():
    """Print the measurements for the bundled presets on the default scalp."""
    from . import default_scalp, load_preset
    scalp = default_scalp()
    for name in ("wavy", "long_straight", "curly", "short_intelligent"):
        preset = load_preset(name)
        keys = preset.keys_on(scalp)[:10]
        print(name, "seam jump (m):")
        for mode, r in seam_jumps_by_mode(scalp, keys, preset.params).items():
            print(f"  {mode:12s} across max {r['across_max']:.5f} p99 {r['across_p99']:.5f} "
                  f"within max {r['within_max']:.5f} ({r['pairs_across']} pairs across)")
        print(name, "adaptive vs fixed 25:", adaptive_vs_fixed(scalp, keys, preset.params))


if __name__ == "__main__":
    main()

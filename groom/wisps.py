# SPDX-License-Identifier: GPL-3.0-or-later
"""Wisps (SPEC §4) and the keys that guide each ordinary strand (SPEC §5).

A strand belongs to the wisp of the key whose ROOT is nearest ("semi-Voronoi"; wisp sizes
differ). With group ids (a parting), a strand only looks at keys of its own group.
Each strand gets three guide keys (main, n1, n2) and their weights; see `guide_weights`.
"""
import numpy as np

from hairio import InputError

from .params import NEIGHBOUR_MODES


def nearest_keys(roots, key_roots, k, root_groups=None, key_groups=None):
    """The k nearest key roots of every root: (index (S,k) int64, distance (S,k) float64),
    nearest first; ties go to the lower key index. Keys of another group are never chosen;
    where a group has fewer than k keys the rest is index -1, distance inf."""
    idx, dist = _nearest_keys(roots, key_roots, k, root_groups, key_groups)
    return np.ascontiguousarray(idx.T), np.ascontiguousarray(dist.T)


def _nearest_keys(roots, key_roots, k, root_groups=None, key_groups=None):
    """nearest_keys, key-major: (index (k,S), distance (k,S)).
    Chunked over roots so memory stays near 4M distances whatever the key count."""
    roots = np.asarray(roots, dtype=np.float64)
    key_roots = np.asarray(key_roots, dtype=np.float64)
    n_keys = len(key_roots)
    k_eff = min(k, n_keys)
    idx = np.full((k, len(roots)), -1, np.int64)
    dist = np.full((k, len(roots)), np.inf)
    chunk = max(1, (1 << 22) // max(n_keys, 1))
    for lo in range(0, len(roots), chunk):  # chunks of ~4M distances, not strands
        r = roots[lo:lo + chunk]
        cols = np.arange(len(r))
        # Squared distances order the keys as well; only the chosen few get a square root.
        if n_keys <= 32:
            # Few keys: key-major (keys x roots), one contiguous row per key, sorted down the
            # columns; equal distances keep the lower key index first (a stable sort).
            rx, ry, rz = (np.ascontiguousarray(r[:, c]) for c in range(3))
            d = np.empty((n_keys, len(r)))
            for j, (kx, ky, kz) in enumerate(key_roots):
                d[j] = (rx - kx) ** 2
                d[j] += (ry - ky) ** 2
                d[j] += (rz - kz) ** 2
            if root_groups is not None:
                d[key_groups[:, None] != root_groups[None, lo:lo + chunk]] = np.inf
            sel = _smallest_rows(d, k_eff)
            flat = sel * len(r) + cols
        else:
            # One coordinate at a time keeps the temporaries (roots x keys), not (roots x keys x 3).
            d = (r[:, 0, None] - key_roots[None, :, 0]) ** 2
            d += (r[:, 1, None] - key_roots[None, :, 1]) ** 2
            d += (r[:, 2, None] - key_roots[None, :, 2]) ** 2
            if root_groups is not None:
                d[root_groups[lo:lo + chunk, None] != key_groups[None, :]] = np.inf
            if k_eff < n_keys:
                part = np.argpartition(d, k_eff - 1, axis=1)[:, :k_eff]
                # argpartition is not stable; re-sort the chosen few by (distance, index).
                part.sort(axis=1)
                pd = np.take_along_axis(d, part, axis=1)
                order = np.argsort(pd, axis=1, kind="stable")
                sel = np.take_along_axis(part, order, axis=1).T
            else:
                sel = np.argsort(d, axis=1, kind="stable").T
            flat = cols * n_keys + sel
        idx[:k_eff, lo:lo + chunk] = sel
        dist[:k_eff, lo:lo + chunk] = np.sqrt(d.take(flat))
    missing = np.isinf(dist)  # another group's keys only
    if missing.any():
        idx[missing] = -1
    return idx, dist


def _smallest_rows(d, k):
    """np.argsort(d, axis=0, kind="stable")[:k] of distances d (keys, roots), >= 0 or inf:
    the k nearest keys of each root, a tie to the lower key index, at half the cost of the
    sort. Root-major int64 bits (a non-negative double's bits order as it does), each key
    taken marked above any of them (inf included) and the next found by argmin, which keeps
    the first of equal values."""
    bits = np.array(d.T, order="C").view(np.int64)     # a copy: d itself is read afterwards
    cols = np.arange(len(bits))
    sel = np.empty((k, len(bits)), np.int64)
    for i in range(k):
        j = bits.argmin(axis=1)
        sel[i] = j
        bits[cols, j] = np.iinfo(np.int64).max
    return sel


def root_groups_for(scalp, tri, bary, points, params):
    """Group id per root: the scalp's vertex groups when it has them, else the parting plane
    of the parameters, else 0."""
    if scalp.groups is not None:
        return scalp.groups_at(tri, bary)
    if params.parting is not None:
        p = np.asarray(params.parting["point"])
        n = np.asarray(params.parting["normal"])
        parted = (points - p) @ n > 0
        if "end" in params.parting:
            # Only in front of the end point: the parting stops there (at the crown).
            front = np.asarray(params.front, dtype=np.float64)
            parted &= (points - np.asarray(params.parting["end"])) @ front >= 0
        return parted.astype(np.int32)
    return np.zeros(len(points), np.int32)


def check_groups(root_groups, key_groups):
    if (key_groups == key_groups[0]).all() and (root_groups == key_groups[0]).all():
        return  # one group (the usual case): nothing to sort
    missing = np.setdiff1d(np.unique(root_groups), np.unique(key_groups))
    if missing.size:
        raise InputError(f"key strands: roots fall in group(s) {missing.tolist()} but no key strand has that "
                         f"group (key groups: {sorted(set(key_groups.tolist()))}); add a key to each group")


def _ratio(num, den):
    """num/den for distances with num <= den; 0/0 = 1 (two keys at one point are equally near)."""
    zero = den <= 0
    if not zero.any():
        return num / den
    return np.where(zero, 1.0, num / np.where(zero, 1.0, den))


def interpolate_sharpness(n_influence):
    """Exponent γ = 1 + (100 - N)/20 applied to the 'interpolate' weights (1 at N = 100,
    6 at N = 0)."""
    return 1.0 + (100.0 - float(n_influence)) / 20.0


def guide_weights(roots, key_roots, mode="interpolate", n_influence=50.0, root_groups=None, key_groups=None):
    """Guides (S,3) int32 (main, n1, n2 key index) and weights (S,3) float64 summing to 1.

    'root' (reading (b) of SPEC §5): n1, n2 = 2nd and 3rd nearest keys to the strand's root.
    'key'  (reading (a)): n1, n2 = the two keys nearest the MAIN key's root, fixed per wisp.
    Both then use the thesis's N-influence: a = (101-N)/d0, b = 1/d1, c = 1/d2, normalised.
    'interpolate': Blender's Interpolate Curves weighting over the 3 nearest keys with the
    4th nearest at d_max: w = (d_max - d)/d ∝ 1/d - 1/d_max (d_max = inf when there is no
    4th key), continuous across wisp borders. N-influence enters continuously as an exponent,
    w^γ with γ = interpolate_sharpness(N) (γ = 1 at N = 100: Blender's weights exactly;
    larger γ for smaller N keeps strands closer to their nearest key without a seam).

    The weights are computed multiplied through by d0, so d0 = 0 gives exactly (1, 0, 0)
    with no division by zero. A missing neighbour (fewer than 3 keys in the group) repeats
    the main index with weight 0.
    """
    g, w = guide_weights_by_guide(roots, key_roots, mode, n_influence, root_groups, key_groups)
    return np.stack(g, axis=1).astype(np.int32), np.stack(w, axis=1)


def guide_weights_by_guide(roots, key_roots, mode="interpolate", n_influence=50.0, root_groups=None,
                           key_groups=None, check=True):
    """guide_weights guide-major: ([main, n1, n2] each (S,) int64, [w0, w1, w2] each (S,)
    float64), the layout whole-array code reads fastest (one contiguous row per guide).
    check=False skips check_groups (a caller that checked all roots at once)."""
    if mode not in NEIGHBOUR_MODES:
        raise InputError(f"neighbour_mode: expected one of {NEIGHBOUR_MODES}, got {mode!r}")
    roots = np.asarray(roots, dtype=np.float64)
    key_roots = np.asarray(key_roots, dtype=np.float64)
    if key_groups is None:
        key_groups = np.zeros(len(key_roots), np.int32)
    if root_groups is None:
        root_groups = np.zeros(len(roots), np.int32)
    if check:
        check_groups(root_groups, key_groups)
    # One group everywhere: nothing to mask.
    grouped = bool((key_groups != key_groups[0]).any())
    want = 4 if mode == "interpolate" else 3
    idx, dist = _nearest_keys(roots, key_roots, want, root_groups if grouped else None,
                              key_groups if grouped else None)
    if mode == "key":
        # Neighbours of each key among the keys of its own group (excluding itself).
        kidx, _ = _nearest_keys(key_roots, key_roots, 3, key_groups, key_groups)
        main = idx[0]
        nb = kidx[1:3, main]
        idx = np.concatenate([idx[:1], nb])
        dnb = []
        for j in range(2):
            k = key_roots[np.where(nb[j] >= 0, nb[j], 0)]
            d = np.sqrt((roots[:, 0] - k[:, 0]) ** 2 + (roots[:, 1] - k[:, 1]) ** 2 + (roots[:, 2] - k[:, 2]) ** 2)
            dnb.append(np.where(nb[j] >= 0, d, np.inf))
        dist = np.stack([dist[0]] + dnb)
    d0 = dist[0]

    all_present = bool((idx >= 0).all())

    def near_ratio(j):
        """d0/dj for a present key j, else 0."""
        if all_present:
            return _ratio(d0, dist[j])
        present = idx[j] >= 0
        return np.where(present, _ratio(d0, np.where(present, dist[j], 1.0)), 0.0)

    def where_present(j, x):
        return x if all_present else np.where(idx[j] >= 0, x, 0.0)

    if mode == "interpolate":
        inv_max = near_ratio(3)
        w = [1.0 - inv_max] + [where_present(j, near_ratio(j) - inv_max) for j in (1, 2)]
        gamma = interpolate_sharpness(n_influence)
        w = [np.maximum(x, 0.0) ** gamma for x in w]
        total = w[0] + w[1] + w[2]
        # All of main and neighbours as far as the 4th key: nothing singles one out; the main wins.
        flat = total <= 0
        if flat.any():
            w[0][flat], w[1][flat], w[2][flat] = 1.0, 0.0, 0.0
            total[flat] = 1.0
    else:
        w = [np.full_like(d0, 101.0 - n_influence), near_ratio(1), near_ratio(2)]
        total = w[0] + w[1] + w[2]
    w = [x / total for x in w]
    g = [idx[0]] + [idx[j] if all_present else np.where(idx[j] >= 0, idx[j], idx[0]) for j in (1, 2)]
    return g, w

# SPDX-License-Identifier: GPL-3.0-or-later
"""Error measures of SPEC §6 and §8: geometric distance to the exact curve, image error."""
import numpy as np

COVERAGE_ALPHA = 0.5   # a pixel "is hair" when its alpha reaches this
MIN_HAIR_PIXELS = 10_000   # an image error is measured over at least this many hair pixels


def image_error(image, reference, coverage_alpha=COVERAGE_ALPHA):
    """Error of `image` against `reference` (both (..., 4) linear RGBA: whole images, or the
    same pixels of both). Hair pixels are the union of both coverage masks (alpha >=
    coverage_alpha), so a pixel either image misses counts:

      iou          coverage agreement over the union (|A∩B| / |A∪B|); 0 when the union is
                   empty, so an empty image never scores well
      rmse_hair    RMSE over the hair pixels' RGBA (nan without any)
      max_abs      largest difference anywhere
      hair_pixels  how many pixels the union holds
      bad_pixels   hair pixels off by more than 2e-3 in some channel
      nonfinite    pixels of `image` that are not finite (counted, never hidden by a mean)
      coverage     the fraction of `image` that is hair

    and the old measures, which count background pixels too (an empty image scored high on
    a mostly empty view): rmse over every pixel, coverage_agree = fraction of pixels whose
    masks agree."""
    a = np.asarray(image, np.float64)
    b = np.asarray(reference, np.float64)
    if a.shape != b.shape:
        raise ValueError(f"image shape {a.shape} differs from reference {b.shape}")
    finite = np.isfinite(a).all(axis=-1)
    diff = np.where(finite[..., None], a - b, 0.0)
    mask_a = a[..., 3] >= coverage_alpha
    mask_b = b[..., 3] >= coverage_alpha
    union = mask_a | mask_b
    n_union = int(union.sum())
    worst = np.abs(diff).max(axis=-1) if diff.size else np.zeros(union.shape)
    return {
        "iou": float((mask_a & mask_b).sum() / n_union) if n_union else 0.0,
        "rmse_hair": float(np.sqrt(np.mean(diff[union] ** 2))) if n_union else float("nan"),
        "max_abs": float(worst.max()) if diff.size else 0.0,
        "hair_pixels": n_union,
        "bad_pixels": int((worst[union] > 2e-3).sum()),
        "nonfinite": int((~finite).sum()),
        "coverage": float(mask_a.mean()),
        "rmse": float(np.sqrt(np.mean(diff ** 2))),
        "coverage_agree": float(np.mean(mask_a == mask_b)),
    }


def hair_rmse(image, reference):
    """RMSE of linear RGBA over the pixels where either image has any hair (alpha > 0): dust
    and haze both count; nan where neither has any."""
    a, b = np.asarray(image, np.float64), np.asarray(reference, np.float64)
    mask = (a[..., 3] > 0) | (b[..., 3] > 0)
    return float(np.sqrt(np.mean((a - b)[mask] ** 2))) if mask.any() else float("nan")


def whole_image_error(image, reference_of, max_rays=None, seed=0, coverage_alpha=COVERAGE_ALPHA):
    """image_error of a whole image (H,W,4) against a reference that `reference_of(pixels)`
    traces: pixels None for every pixel (returns (H,W,4)), else (P,2) int columns x, y
    (returns (P,4)). With `max_rays` below the pixel count the reference traces a uniform
    random subset of the image's pixel centres (rays, not a window), the same for every
    call with one seed. Adds `rays`: how many pixels were compared."""
    h, w = image.shape[:2]
    if max_rays is None or max_rays >= w * h:
        e = image_error(image, reference_of(None), coverage_alpha)
        e["rays"] = w * h
        return e
    flat = np.sort(np.random.default_rng(seed).choice(w * h, int(max_rays), replace=False))
    pixels = np.stack([flat % w, flat // w], axis=1)
    e = image_error(np.asarray(image)[pixels[:, 1], pixels[:, 0]], reference_of(pixels), coverage_alpha)
    e["rays"] = int(max_rays)
    return e


def _pad(points, counts, fill_last=True):
    """(S, n_max, 3) array of each strand's points, short strands padded with their last point
    (a repeated point adds a zero-length segment, which changes no distance)."""
    counts = np.asarray(counts, np.int64)
    n_max = int(counts.max()) if len(counts) else 0
    offsets = np.concatenate([[0], np.cumsum(counts)[:-1]])
    j = np.minimum(np.arange(n_max)[None, :], counts[:, None] - 1)
    return np.asarray(points, np.float64)[offsets[:, None] + j]


def curve_to_polyline_distance(dense_points, dense_counts, poly_points, poly_counts, chunk=None):
    """Distance from every point of each strand's dense (exact) sampling to that strand's
    polyline. Returns (per-strand max (S,), all distances flat) so callers can take the
    maximum and the 99th percentile. Whole-array numpy, chunked over strands to bound memory."""
    dense = _pad(dense_points, dense_counts)
    poly = _pad(poly_points, poly_counts)
    if len(dense) != len(poly):
        raise ValueError("dense and polyline strand counts differ")
    dense_counts = np.asarray(dense_counts)
    s, m = dense.shape[:2]
    n = poly.shape[1]
    if chunk is None:
        chunk = max(1, int(2e7 // max(1, m * max(n - 1, 1) * 3)))
    per_strand = np.empty(s)
    flat = []
    for lo in range(0, s, chunk):
        d = dense[lo:lo + chunk]                       # (c, m, 3)
        a = poly[lo:lo + chunk, :-1]                   # (c, n-1, 3)
        ab = poly[lo:lo + chunk, 1:] - a
        ap = d[:, :, None, :] - a[:, None, :, :]       # (c, m, n-1, 3)
        len2 = np.einsum("csk,csk->cs", ab, ab)[:, None, :]
        t = np.einsum("cmsk,csk->cms", ap, ab) / np.where(len2 > 0, len2, 1.0)
        t = np.clip(t, 0.0, 1.0)
        closest = ap - t[..., None] * ab[:, None, :, :]
        dist = np.sqrt(np.einsum("cmsk,cmsk->cms", closest, closest)).min(axis=2)   # (c, m)
        valid = np.arange(m)[None, :] < dense_counts[lo:lo + chunk, None]
        dist = np.where(valid, dist, 0.0)
        per_strand[lo:lo + chunk] = dist.max(axis=1)
        flat.append(dist[valid])
    return per_strand, (np.concatenate(flat) if flat else np.zeros(0))


def strand_lengths(points, counts):
    """Arc length of each strand."""
    points = np.asarray(points, np.float64)
    counts = np.asarray(counts, np.int64)
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    ends = np.cumsum(counts)
    # segments that join one strand's tip to the next root do not count
    keep = np.ones(len(seg), bool)
    keep[ends[:-1] - 1] = False
    strand_of_seg = np.repeat(np.arange(len(counts)), counts)[:-1]
    return np.bincount(strand_of_seg[keep], weights=seg[keep], minlength=len(counts))


def pareto_front(xs, ys):
    """Indices of the points no other point beats in both x and y (smaller is better)."""
    order = np.lexsort((np.asarray(ys), np.asarray(xs)))
    front, best = [], np.inf
    for i in order:
        if ys[i] < best:
            front.append(int(i))
            best = ys[i]
    return front

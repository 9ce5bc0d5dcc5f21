# SPDX-License-Identifier: GPL-3.0-or-later
"""The error of a preview image against a reference render, over the hair and over a mesh
(the head) separately, and how well the hair's coverage agrees (section contact_sheet).

The regions are the reference's: a pixel is "hair" where the reference's hair covers at
least half of it, "head" where the head (what is covered but not by hair) covers at least
half of it. So a preview that draws nothing, or draws black, is measured over the same
pixels as a good one and scores the reference's whole mean as its error (relative error 1),
instead of escaping through an empty mask.

Over a region of n pixels, with d the difference preview − reference per pixel and linear
RGB channel: MAE = mean |d|, RMSE = sqrt(mean d^2), rel = MAE / the reference's mean
value there, ratio = the preview's mean there / the reference's (1: as bright on the whole,
whatever the per-pixel noise). A non-finite preview pixel makes MAE and RMSE infinite.

Coverage IoU compares fractional masks (the fraction of each pixel the hair covers, in
0..1): sum(min(a, b)) / sum(max(a, b)), 1 when they agree, 0 when one is empty.
"""
import numpy as np

HALF = 0.5             # a pixel belongs to a region its surface covers at least half of
MIN_PIXELS = 100       # fewer reference pixels than this: nothing to measure against


def regions(hair, cover, threshold=HALF):
    """(hair, head) boolean masks from the reference's coverage: `hair` the fraction of
    each pixel the hair covers, `cover` the fraction hair or mesh cover."""
    hair = np.asarray(hair, np.float64)
    cover = np.asarray(cover, np.float64)
    return hair >= threshold, (cover - hair) >= threshold


def region_error(image, reference, mask, name="region"):
    """{mae, rmse, mean, rel, pixels} of `image` against `reference` ((H, W, 3) linear RGB,
    or more channels: the first three are used) over the pixels of `mask`."""
    mask = np.asarray(mask, bool)
    n = int(mask.sum())
    if n < MIN_PIXELS:
        raise ValueError(f"{name}: the reference covers only {n} pixels (fewer than {MIN_PIXELS}); "
                         "frame the view so it shows more of it")
    a = np.asarray(image, np.float64)[..., :3][mask]
    b = np.asarray(reference, np.float64)[..., :3][mask]
    mean = float(b.mean())
    if not np.isfinite(a).all():
        mae = rmse = float("inf")
    else:
        d = a - b
        mae, rmse = float(np.abs(d).mean()), float(np.sqrt((d * d).mean()))
    ratio = float(a.mean()) / mean if mean > 0 else float("inf")
    return {"mae": mae, "rmse": rmse, "mean": mean, "rel": mae / mean if mean > 0 else float("inf"),
            "ratio": ratio, "pixels": n}


def coverage_iou(a, b):
    """Fractional-mask IoU: sum(min) / sum(max); 0 where both are empty."""
    a = np.clip(np.nan_to_num(np.asarray(a, np.float64), nan=0.0), 0.0, 1.0)
    b = np.clip(np.nan_to_num(np.asarray(b, np.float64), nan=0.0), 0.0, 1.0)
    union = float(np.maximum(a, b).sum())
    return float(np.minimum(a, b).sum()) / union if union > 0 else 0.0


def compare(image, image_hair, reference, reference_hair, reference_cover):
    """{"hair": region_error, "head": region_error, "iou": hair coverage IoU} of a preview
    (`image` RGB(A), `image_hair` its hair coverage) against the reference."""
    hair, head = regions(reference_hair, reference_cover)
    return {"hair": region_error(image, reference, hair, "hair"),
            "head": region_error(image, reference, head, "head"),
            "iou": coverage_iou(image_hair, reference_hair)}

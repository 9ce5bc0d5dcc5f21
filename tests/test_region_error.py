# SPDX-License-Identifier: GPL-3.0-or-later
"""The contact sheet's error measure (benchmarks/region_error.py): a preview that draws
nothing, or black, or NaN must score badly over the reference's own hair and head pixels,
and a close one well."""
import numpy as np
import pytest

from benchmarks.region_error import compare, coverage_iou, region_error


def _reference():
    """A 64x64 reference: a head disc (cover 1) with a band of hair across its top half."""
    rng = np.random.default_rng(3)
    y, x = np.mgrid[0:64, 0:64]
    cover = (((x - 32) ** 2 + (y - 32) ** 2) < 28 ** 2).astype(float)
    hair = cover * (y < 30)
    rgb = np.where(hair[..., None] > 0, rng.uniform(0.05, 0.4, (64, 64, 3)), 0.3 * cover[..., None])
    return rgb, hair, cover


def test_a_black_or_empty_preview_scores_the_reference_mean_as_its_error():
    rgb, hair, cover = _reference()
    for image, image_hair in ((np.zeros((64, 64, 4)), np.zeros((64, 64))),      # nothing drawn
                              (np.zeros((64, 64, 4)), hair)):                    # the hair, black
        e = compare(image, image_hair, rgb, hair, cover)
        assert e["hair"]["rel"] == pytest.approx(1.0) and e["head"]["rel"] == pytest.approx(1.0)
        assert e["hair"]["mae"] == pytest.approx(rgb[hair > 0].mean())
        assert e["hair"]["pixels"] == int((hair > 0).sum()) and e["hair"]["ratio"] == 0.0
    assert compare(np.zeros((64, 64, 4)), np.zeros((64, 64)), rgb, hair, cover)["iou"] == 0.0


def test_a_close_preview_scores_well_and_its_errors_are_those_of_each_region():
    rgb, hair, cover = _reference()
    image = rgb.copy()
    image[hair > 0] += 0.01                  # the hair a little bright, the head exact
    e = compare(image, hair, rgb, hair, cover)
    assert e["hair"]["mae"] == pytest.approx(0.01) and e["hair"]["rmse"] == pytest.approx(0.01)
    assert e["head"]["mae"] == 0.0 and e["head"]["ratio"] == 1.0 and e["iou"] == 1.0
    assert e["hair"]["ratio"] == pytest.approx(1.0 + 0.01 / rgb[hair > 0].mean())


def test_a_nan_preview_fails_and_a_reference_without_the_region_is_refused():
    rgb, hair, cover = _reference()
    image = rgb.copy()
    image[10, 32] = np.nan
    assert compare(image, hair, rgb, hair, cover)["hair"]["mae"] == float("inf")
    with pytest.raises(ValueError, match="hair"):
        compare(rgb, hair, rgb, np.zeros_like(hair), cover)


def test_coverage_iou_of_fractional_masks():
    a = np.array([1.0, 0.5, 0.0, 0.0])
    b = np.array([1.0, 0.25, 0.5, 0.0])
    assert coverage_iou(a, b) == pytest.approx((1.0 + 0.25) / (1.0 + 0.5 + 0.5))
    assert coverage_iou(np.zeros(4), np.zeros(4)) == 0.0
    assert region_error(np.ones((10, 10, 3)), np.ones((10, 10, 3)) * 2, np.ones((10, 10), bool))["rel"] == 0.5

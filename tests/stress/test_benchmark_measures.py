# SPDX-License-Identifier: GPL-3.0-or-later
"""The measuring sticks of the benchmark report: if these are wrong, every figure is."""
import time

import numpy as np
import pytest

from benchmarks.harness import MIN_RUNS, TooSlow, measure
from benchmarks.metrics import curve_to_polyline_distance, image_error


def test_distance_to_a_chorded_arc_is_its_sagitta():
    """A quarter circle of radius R cut into n equal chords is off by R(1 - cos(Δ/2)), Δ = (π/2)/n."""
    R, n = 2.0, 6
    dense_t = np.linspace(0, np.pi / 2, 64 * n + 1)
    poly_t = np.linspace(0, np.pi / 2, n + 1)
    arc = lambda t: np.stack([R * np.cos(t), R * np.sin(t), np.zeros_like(t)], 1)  # noqa: E731
    worst, dists = curve_to_polyline_distance(arc(dense_t), [len(dense_t)], arc(poly_t), [n + 1])
    assert worst[0] == pytest.approx(R * (1 - np.cos(np.pi / 4 / n)), rel=1e-9)
    assert dists.min() == pytest.approx(0, abs=1e-12)   # chord ends lie on the arc


def test_distance_handles_strands_of_different_lengths_independently():
    a = np.array([[0, 0, 0], [1, 0, 0.0]])
    b = np.array([[5, 0, 0], [5, 1, 0], [5, 2, 0.0]])
    dense = np.vstack([a, b + [0.5, 0, 0]])          # second strand shifted by 0.5
    worst, _ = curve_to_polyline_distance(dense, [2, 3], np.vstack([a, b]), [2, 3])
    assert worst == pytest.approx([0.0, 0.5])


def test_image_error_counts_coverage_and_nonfinite_pixels():
    ref = np.zeros((4, 4, 4))
    ref[:2, :, 3] = 1.0
    img = ref.copy()
    assert image_error(img, ref)["rmse"] == 0 and image_error(img, ref)["coverage_agree"] == 1
    img[0, 0, 3] = 0.0
    img[3, 3, 0] = np.nan
    e = image_error(img, ref)
    assert e["coverage_agree"] == pytest.approx(15 / 16)
    assert e["nonfinite"] == 1
    assert e["max_abs"] == pytest.approx(1.0)


def test_an_empty_image_scores_iou_zero_against_hair():
    ref = np.zeros((100, 100, 4))
    ref[40:44, :, 3] = 1.0                  # 4 % of the view is hair
    empty = np.zeros_like(ref)
    e = image_error(empty, ref)
    assert e["iou"] == 0.0 and e["hair_pixels"] == 400
    assert e["rmse_hair"] == pytest.approx(0.5)       # alpha off by 1 in one channel of four
    assert e["coverage_agree"] == pytest.approx(0.96)  # the old measure: background counted
    assert image_error(empty, empty)["iou"] == 0.0     # nothing to agree about scores nothing


def test_iou_is_agreement_over_the_union_of_both_masks():
    ref = np.zeros((10, 10, 4))
    ref[:4, :, 3] = 1.0                     # 40 pixels
    img = np.zeros_like(ref)
    img[2:6, :, 3] = 1.0                    # 40 pixels, 20 shared
    assert image_error(img, ref)["iou"] == pytest.approx(20 / 60)


def test_whole_image_error_on_a_ray_subset_sees_the_whole_view():
    from benchmarks.metrics import whole_image_error
    ref = np.zeros((64, 64, 4))
    ref[:, 48:, 3] = 1.0                    # hair only at the right edge
    img = np.zeros_like(ref)
    calls = []

    def reference_of(pixels):
        calls.append(pixels)
        return ref if pixels is None else ref[pixels[:, 1], pixels[:, 0]]
    e = whole_image_error(img, reference_of, max_rays=1000)
    assert e["rays"] == 1000 and calls[0][:, 0].max() >= 48    # not a window in one corner
    assert e["iou"] == 0.0 and e["hair_pixels"] > 150
    assert whole_image_error(ref, reference_of)["iou"] == 1.0


def test_measure_takes_at_least_five_runs_after_a_warm_up():
    calls = []
    t, _ = measure(lambda: calls.append(1), runs=2)
    assert len(t.runs) == MIN_RUNS and len(t.warmups) == 1 and len(calls) == MIN_RUNS + 1


def test_measure_refuses_runs_that_cannot_fit_the_budget():
    with pytest.raises(TooSlow):
        measure(lambda: time.sleep(0.02), budget=0.05)


def test_window_camera_sees_exactly_the_full_image_pixels():
    """The float64 comparisons trace windows of the real image: same rays, pixel for pixel."""
    from tracer import Camera
    from benchmarks.scenes import crop_camera
    cam = Camera.from_blender(np.array([[1, 0, 0, 0.1], [0, 0, -1, -1.0], [0, 1, 0, 0.2], [0, 0, 0, 1]]),
                              (96, 64), lens=35.0, shift_x=0.1, shift_y=-0.05)
    win = crop_camera(cam, 40, 17, 8, 5)
    ys, xs = np.mgrid[0:5, 0:8] + 0.5
    o1, d1 = win.rays(xs, ys)
    o2, d2 = cam.rays(xs + 40, ys + 17)
    assert np.allclose(o1, o2) and np.allclose(d1, d2, atol=1e-12)

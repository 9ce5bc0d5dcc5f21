# SPDX-License-Identifier: GPL-3.0-or-later
"""The pixel centres' listing (tracer.beams.centre_span): where a column's centre line crosses
the points within P of a projected axis, against the distance of each point of the line to
the segment, for segments of every slope, level and vertical ones and points among them."""
import numpy as np
import pytest

from tracer.beams import centre_span


def _segment_distance(a, ys, A0, B0, dA, dB):
    L2 = dA * dA + dB * dB
    s = np.clip(((a - A0) * dA + (ys - B0) * dB) / L2, 0.0, 1.0) if L2 > 0 else np.zeros_like(ys)
    return np.hypot(A0 + s * dA - a, B0 + s * dB - ys)


@pytest.mark.parametrize("kind", ["any", "level", "point", "steep"])
def test_a_columns_span_holds_the_points_within_reach_and_no_others(kind):
    rng = np.random.default_rng({"any": 1, "level": 2, "point": 3, "steep": 4}[kind])
    ys = np.linspace(-12.0, 22.0, 3401)
    crossed = 0
    for _ in range(300):
        A0, B0 = rng.uniform(-3, 10, 2)
        dA = rng.uniform(-6, 6)
        dB = {"any": rng.uniform(-1, 1) * abs(dA), "level": 0.0, "point": 0.0, "steep": dA}[kind]
        if kind == "point":
            dA = 0.0
        P = rng.uniform(0.001, 2.0)
        cols = np.arange(-5, 15) + 0.5
        n = len(cols)
        lo, hi = centre_span(cols, np.full(n, A0), np.full(n, dA), np.full(n, B0), np.full(n, dB), np.full(n, P))
        for a, l, h in zip(cols, lo, hi):
            d = _segment_distance(a, ys, A0, B0, dA, dB)
            inside = (ys >= l) & (ys <= h)
            clear = np.abs(d - P) > 1e-9          # not on the boundary, where rounding decides
            np.testing.assert_array_equal(inside[clear], (d <= P)[clear])
            crossed += bool(inside.any())
    assert crossed > 100

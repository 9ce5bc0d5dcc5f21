# SPDX-License-Identifier: GPL-3.0-or-later
"""Counter-based random numbers: one seed, an independent stream per strand.

A number is a pure function of (seed, stream id, channel): hashing with the SplitMix64
finaliser instead of drawing from a sequential generator means strand 7's tidiness angles
are the same whether 10 strands or 100,000 are generated, or only strand 7's wisp is
regenerated. Whole arrays at once; no per-strand generator objects.
"""
import numpy as np

# Channels: fixed small integers naming what a number is for, so adding a new use never
# shifts the numbers of an old one.
CH_TRIANGLE_A, CH_TRIANGLE_B = 0, 1
CH_LENGTH = 2
CH_TIDY_X, CH_TIDY_Y, CH_TIDY_Z = 3, 4, 5
CH_COLOR = 8          # 8, 9, 10: per-strand colour, one per channel
CH_COLOR_POINT = 64   # 64 + 3k + c: colour of point k, channel c

_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


def _mix(x):
    x = (x ^ (x >> np.uint64(30))) * _M1
    x = (x ^ (x >> np.uint64(27))) * _M2
    return x ^ (x >> np.uint64(31))


def uniform(seed, ids, channel):
    """Uniform floats in [0, 1) of shape broadcast(ids, channel), float64."""
    with np.errstate(over="ignore"):
        s = _mix(np.uint64(int(seed) & 0xFFFFFFFFFFFFFFFF) + _GOLDEN)
        ids = np.asarray(ids).astype(np.uint64)
        ch = np.asarray(channel).astype(np.uint64)
        x = _mix(s ^ (ids * _GOLDEN))
        x = _mix(x + (ch + np.uint64(1)) * _M2)
    return (x >> np.uint64(11)).astype(np.float64) * (1.0 / 9007199254740992.0)

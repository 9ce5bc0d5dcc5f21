# SPDX-License-Identifier: GPL-3.0-or-later
"""Strand scenes built in code for the hairio tests (imported by name: conftest modules
of different test folders share the module name `conftest`)."""
import numpy as np

from hairio import Strands


def make_wavy(num_strands=50, points=(8, 24), seed=0, curl=3.0):
    """Wavy strands of varying point counts hanging from a half sphere (Z up), with tapered
    radius, per-point color and an alpha falling toward the tip: every per-point array varies."""
    rng = np.random.default_rng(seed)
    lo, hi = points
    counts = rng.integers(lo, hi + 1, num_strands).astype(np.int32)
    strand = np.repeat(np.arange(num_strands), counts)
    first = np.repeat(np.cumsum(counts) - counts, counts)
    k = np.arange(counts.sum()) - first
    t = k / (counts[strand] - 1)
    theta = rng.uniform(0, 2 * np.pi, num_strands)
    phi = rng.uniform(0, 0.45 * np.pi, num_strands)
    root = 0.1 * np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], 1)
    length = rng.uniform(0.1, 0.3, num_strands)
    phase = rng.uniform(0, 2 * np.pi, num_strands)
    ang = 2 * np.pi * curl * t + phase[strand]
    amp = 0.01 * t
    pts = root[strand] + np.stack([
        root[strand, 0] * 0.5 * t + amp * np.cos(ang),
        root[strand, 1] * 0.5 * t + amp * np.sin(ang),
        -length[strand] * t], 1)
    radius = 1e-4 * (1 - 0.9 * t)
    color = np.clip(np.stack([0.3 + 0.2 * t, 0.2 + 0.05 * np.sin(ang), 0.1 + 0 * t], 1), 0, 1)
    alpha = np.clip(1 - 0.7 * t ** 2, 0, 1)
    wisp = rng.integers(0, 5, num_strands)
    return Strands.from_arrays(pts, counts, radius, color, alpha, wisp)

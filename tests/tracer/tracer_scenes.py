# SPDX-License-Identifier: GPL-3.0-or-later
"""Small scenes built in code for the tracer tests."""
import numpy as np

from hairio import Strands


def make_strands(polylines, radius=0.02, color=(0.8, 0.5, 0.2), alpha=1.0):
    """Strands from a list of (n,3) polylines; radius/alpha scalars or per-point arrays."""
    pts = np.concatenate([np.asarray(p, float) for p in polylines])
    counts = np.array([len(p) for p in polylines], np.int32)
    n = len(pts)
    rad = np.broadcast_to(np.asarray(radius, float), (n,)) if np.ndim(radius) == 0 else np.asarray(radius)
    al = np.broadcast_to(np.asarray(alpha, float), (n,)) if np.ndim(alpha) == 0 else np.asarray(alpha)
    col = np.broadcast_to(np.asarray(color, float), (n, 3))
    return Strands.from_arrays(pts, counts, radius=rad, color=col, alpha=al)


def curls(n_strands=12, n_points=10, seed=0, radius=0.015, alpha=1.0):
    """A small tuft of wavy strands with bends, in a unit-ish box."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, n_points)
    lines = []
    for k in range(n_strands):
        x0, y0 = rng.uniform(-0.3, 0.3, 2)
        f, ph = rng.uniform(4, 9), rng.uniform(0, 6.3)
        lines.append(np.stack([x0 + 0.08 * np.sin(f * t + ph), y0 + 0.08 * np.cos(f * t + ph), t], 1))
    return make_strands(lines, radius=radius, alpha=alpha,
                        color=(0.7, 0.45, 0.25))

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


def dense_tuft(n_strands=8000, seed=3):
    """Faint straight-ish strands (alpha 0.05) packed into a box of half side 0.25 at the
    origin: seen from 1.6 away through 32² pixels, hundreds of cylinders a pixel (the
    pixel sampler's loop-cap scene)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, 24)[:, None]
    lines = []
    for _ in range(n_strands):
        a, b = rng.uniform(-0.25, 0.25, 3), rng.uniform(-0.25, 0.25, 3)
        lines.append(a + t * (b - a) + 0.02 * np.sin(9 * t + rng.uniform(0, 6)))
    return make_strands(lines, radius=0.0008, alpha=0.05)


def uv_sphere(centre, radius, rings=12, segments=24):
    """A closed sphere: (vertices, triangles)."""
    theta = np.linspace(0, np.pi, rings + 1)[1:-1]
    phi = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    ring = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
    verts = np.concatenate([[[0, 0, 1]], ring, [[0, 0, -1]]]) * radius + np.asarray(centre, float)
    idx = 1 + np.arange((rings - 1) * segments).reshape(rings - 1, segments)
    nxt = np.roll(idx, -1, axis=1)
    tris = [np.stack([np.zeros(segments, int), idx[0], nxt[0]], 1),
            np.stack([np.full(segments, len(verts) - 1), nxt[-1], idx[-1]], 1)]
    tris += [np.stack([idx[:-1], idx[1:], nxt[1:]], -1).reshape(-1, 3),
             np.stack([idx[:-1], nxt[1:], nxt[:-1]], -1).reshape(-1, 3)]
    return verts, np.concatenate(tris)


def plane(z, half, centre=(0.0, 0.0)):
    """A square at height z: (vertices, triangles)."""
    cx, cy = centre
    v = np.array([[cx - half, cy - half, z], [cx + half, cy - half, z], [cx + half, cy + half, z],
                  [cx - half, cy + half, z]])
    return v, np.array([[0, 1, 2], [0, 2, 3]])

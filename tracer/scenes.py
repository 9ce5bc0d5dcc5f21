# SPDX-License-Identifier: GPL-3.0-or-later
"""Synthetic strands for tests and benchmarks, made in whole-array numpy."""
import numpy as np

from hairio import Strands


def wavy_cap(num_strands=100_000, points=16, length=0.25, head_radius=0.1, radius=6e-5,
             alpha_tip=0.4, seed=0):
    """Wavy strands growing from a spherical cap (the upper half of a head-sized sphere),
    falling under a little gravity; alpha falls from 1 to `alpha_tip` along the last third,
    radius tapers to 20 % at the tip."""
    rng = np.random.default_rng(seed)
    z = rng.uniform(0.1, 1.0, num_strands)
    phi = rng.uniform(0, 2 * np.pi, num_strands)
    s = np.sqrt(1 - z * z)
    normal = np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)
    root = normal * head_radius
    u = np.linspace(0, 1, points)
    seg = length * rng.uniform(0.7, 1.0, num_strands)
    down = np.array([0, 0, -1.0])
    # Direction bends from the normal toward "down" along the strand.
    w = (u ** 1.5)[None, :, None]
    direction = (1 - w) * normal[:, None, :] + w * (down + 0.6 * normal)[:, None, :] * 1.0
    direction /= np.linalg.norm(direction, axis=2, keepdims=True)
    steps = direction * (seg[:, None, None] / (points - 1))
    pts = root[:, None, :] + np.concatenate([np.zeros((num_strands, 1, 3)), np.cumsum(steps[:, :-1], axis=1)], axis=1)
    freq = rng.uniform(8, 16, num_strands)[:, None]
    phase = rng.uniform(0, 2 * np.pi, num_strands)[:, None]
    amp = 0.01 * u[None, :]
    side = np.cross(normal, down + 1e-3)
    side /= np.linalg.norm(side, axis=1, keepdims=True)
    pts += (amp * np.sin(freq * u[None, :] * np.pi + phase))[:, :, None] * side[:, None, :]
    counts = np.full(num_strands, points, np.int32)
    rad = np.broadcast_to(radius * (1 - 0.8 * u), (num_strands, points)).ravel()
    alpha = np.broadcast_to(np.clip(1 - (1 - alpha_tip) * (u - 2 / 3) * 3, alpha_tip, 1), (num_strands, points)).ravel()
    base = np.array([0.35, 0.2, 0.1]) + rng.uniform(-0.05, 0.05, (num_strands, 3))
    color = np.repeat(np.clip(base, 0, 1), points, axis=0)
    return Strands.from_arrays(pts.reshape(-1, 3), counts, radius=rad, color=color, alpha=alpha)

# SPDX-License-Identifier: GPL-3.0-or-later
import numpy as np
import pytest

from groom import GroomParams, KeyStrand, default_scalp


@pytest.fixture(scope="session")
def scalp():
    return default_scalp()


def _curl_key(root, normal=(0.0, 0.0, 1.0), length=0.08, group=0):
    """A curved Bézier key growing along `normal` and bending toward +x."""
    root = np.asarray(root, float)
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    side = np.cross(n, [0.0, 1.0, 0.0]) if abs(n[1]) < 0.9 else np.cross(n, [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    pts = [root, root + 0.3 * length * n, root + 0.5 * length * n + 0.3 * length * side,
           root + 0.4 * length * n + 0.7 * length * side]
    return KeyStrand(np.array(pts), group=group)


def _keys_around(scalp, count=6, group=None):
    """`count` keys on the default scalp, spread over the cap, each along its surface normal."""
    d = np.array([[0, 0, 1], [0.6, 0, 0.8], [-0.6, 0, 0.8], [0, 0.7, 0.7], [0.5, 0.5, 0.7],
                  [-0.5, 0.5, 0.7], [0, -0.5, 0.85], [0.9, 0.2, 0.3], [-0.9, 0.2, 0.3], [0, 0.9, 0.1]], float)
    d = d[:count] / np.linalg.norm(d[:count], axis=1, keepdims=True)
    tri, bary, pts = scalp.closest_points(d * 0.12)
    normals = scalp.normals_at(tri, bary)
    keys = []
    for i, (p, n) in enumerate(zip(pts, normals)):
        g = 0 if group is None else int(group(p))
        keys.append(_curl_key(p, n, length=0.05 + 0.01 * i, group=g))
    return keys


@pytest.fixture
def small_params():
    return GroomParams(count=2000, seed=3)


@pytest.fixture
def curl_key():
    return _curl_key


@pytest.fixture
def keys_around():
    return _keys_around

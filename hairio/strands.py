# SPDX-License-Identifier: GPL-3.0-or-later
"""The strand arrays of SPEC §0, validated once where they enter."""
from dataclasses import dataclass

import numpy as np

from .atomic import atomic_write
from .npyfile import read_npz
from .validate import InputError, as_array, check_shape, to_float32, to_int32

NPZ_NAMES = ("points", "counts", "radius", "color", "alpha", "wisp")


@dataclass(frozen=True, eq=False)
class Strands:
    """points (P,3) f32, counts (S,) i32, radius (P,) f32, color (P,3) f32 linear RGB,
    alpha (P,) f32, wisp (S,) i32. Point 0 of each strand is its root."""
    points: np.ndarray
    counts: np.ndarray
    radius: np.ndarray
    color: np.ndarray
    alpha: np.ndarray
    wisp: np.ndarray

    @classmethod
    def from_arrays(cls, points, counts, radius=None, color=None, alpha=None, wisp=None,
                    default_radius=1e-4, default_color=(0.3, 0.2, 0.1)):
        """Validate and convert; missing per-point arrays get defaults (radius, color, alpha 1).

        Every conversion is checked, so nothing is stored other than what was passed:
        floats beyond float32's range, counts beyond int32 and fractional or NaN wisp ids
        are refused (a cast would make them Inf, wrap them or round them)."""
        points = to_float32("points", check_shape("points", as_array("points", points), (None, 3)))
        counts = check_shape("counts", as_array("counts", counts), (None,))
        if counts.size and counts.dtype.kind not in "iu":
            raise InputError(f"counts: expected integers, got dtype {counts.dtype}")
        if counts.size and counts.min() < 2:
            bad = int(np.argmax(counts < 2))
            raise InputError(f"counts: strand {bad} has {counts[bad]} point(s); every strand needs at least 2")
        counts = to_int32("counts", counts, lo=2)
        total = int(counts.sum(dtype=np.int64))
        if total != len(points):
            raise InputError(f"counts: sum is {total} but points has {len(points)} rows; they must match")
        n_p, n_s = len(points), len(counts)
        radius = np.full(n_p, default_radius) if radius is None else radius
        color = np.broadcast_to(np.asarray(default_color, float), (n_p, 3)) if color is None else color
        alpha = np.ones(n_p, np.float32) if alpha is None else alpha
        wisp = np.zeros(n_s, np.int32) if wisp is None else wisp
        radius = to_float32("radius", check_shape("radius", as_array("radius", radius), (n_p,)))
        color = to_float32("color", check_shape("color", as_array("color", color), (n_p, 3)))
        alpha = to_float32("alpha", check_shape("alpha", as_array("alpha", alpha), (n_p,)))
        wisp = to_int32("wisp", check_shape("wisp", as_array("wisp", wisp), (n_s,)), allow_integral_floats=True)
        if n_p and radius.min() < 0:
            raise InputError("radius: negative values; radii must be >= 0")
        if n_p and (alpha.min() < 0 or alpha.max() > 1):
            raise InputError("alpha: values outside [0, 1]; clamp them first")
        return cls(points, counts, radius, np.ascontiguousarray(color), alpha, wisp)

    @classmethod
    def empty(cls):
        return cls.from_arrays(np.zeros((0, 3)), np.zeros(0, np.int32))

    @property
    def num_strands(self):
        return len(self.counts)

    @property
    def num_points(self):
        return len(self.points)

    @property
    def num_segments(self):
        return self.num_points - self.num_strands

    @property
    def offsets(self):
        """Index of each strand's root in the point arrays."""
        out = np.zeros(len(self.counts), np.int64)
        np.cumsum(self.counts[:-1], out=out[1:])
        return out

    def strand_points(self, i):
        o = int(self.offsets[i])
        return self.points[o:o + int(self.counts[i])]

    def bounds(self):
        """(lo, hi) of the points, each (3,); zeros for an empty set."""
        if not self.num_points:
            return np.zeros(3, np.float32), np.zeros(3, np.float32)
        return self.points.min(axis=0), self.points.max(axis=0)

    def arrays(self):
        return {name: getattr(self, name) for name in NPZ_NAMES}

    def save_npz(self, path):
        with atomic_write(path) as f:
            np.savez(f, **self.arrays())

    @classmethod
    def load_npz(cls, path):
        """Strands from a .npz of the SPEC §0 arrays (`save_npz`); every size in the archive
        is checked before memory is taken (hairio.npyfile)."""
        arrays = read_npz(path, NPZ_NAMES, required=("points", "counts"))
        try:
            return cls.from_arrays(**arrays)
        except InputError as e:
            raise InputError(f"{path}: {e}") from None

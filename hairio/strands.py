# SPDX-License-Identifier: GPL-3.0-or-later
"""The strand arrays of SPEC §0, validated once where they enter."""
from dataclasses import dataclass, replace

import numpy as np

from .atomic import atomic_write
from .npyfile import read_npz
from .validate import InputError, as_array, check_finite, check_shape, to_float32, to_int32

NPZ_NAMES = ("points", "counts", "radius", "color", "alpha", "wisp")
# Optional arrays a groom carries beside the strands (docs/ARCHITECTURE.md, "Guides"):
# its key strands, each strand's three guides and their weights, and the roots' UVs.
GUIDE_NPZ_NAMES = ("key_points", "key_counts", "key_radius", "key_color", "key_group",
                   "guides", "guide_weights", "root_uv")


@dataclass(frozen=True, eq=False)
class Guides:
    """How a groom's strands follow its key strands: keys (a Strands of K curves, point 0
    the root), group (K,) i32 the parting group of each key, index (S,3) i32 the main key
    and two neighbours of every strand, weights (S,3) f32 their interpolation weights
    (summing to 1; a missing neighbour repeats the main key with weight 0)."""
    keys: "Strands"
    group: np.ndarray
    index: np.ndarray
    weights: np.ndarray

    @classmethod
    def from_arrays(cls, keys, index, weights, group=None, num_strands=None):
        if not isinstance(keys, Strands):
            raise InputError(f"keys: expected hairio.Strands, got {type(keys).__name__}")
        n_k = keys.num_strands
        if n_k == 0:
            raise InputError("keys: no key strands; guides need at least one")
        group = np.zeros(n_k, np.int32) if group is None else group
        group = to_int32("key_group", check_shape("key_group", as_array("key_group", group), (n_k,)),
                         allow_integral_floats=True)
        index = to_int32("guides", check_shape("guides", as_array("guides", index), (num_strands, 3)),
                         allow_integral_floats=True)
        if index.size and (index.min() < 0 or index.max() >= n_k):
            raise InputError(f"guides: key indices must lie in [0, {n_k}) for {n_k} key strands, "
                             f"got [{int(index.min())}, {int(index.max())}]")
        weights = to_float32("guide_weights",
                             check_shape("guide_weights", as_array("guide_weights", weights), (len(index), 3)))
        if weights.size and weights.min() < 0:
            raise InputError("guide_weights: negative values; weights must be >= 0")
        return cls(keys, group, index, weights)

    def arrays(self):
        k = self.keys
        return {"key_points": k.points, "key_counts": k.counts, "key_radius": k.radius,
                "key_color": k.color, "key_group": self.group, "guides": self.index,
                "guide_weights": self.weights}


def _checked_extras(guides, root_uv, n_s):
    """(guides, root_uv (S, 2) float32 or None) of n_s strands, checked."""
    if guides is not None and not isinstance(guides, Guides):
        raise InputError(f"guides: expected hairio.Guides, got {type(guides).__name__}")
    if guides is not None and len(guides.index) != n_s:
        raise InputError(f"guides: {len(guides.index)} rows for {n_s} strands; one row per strand")
    if root_uv is not None:
        root_uv = check_finite("root_uv", to_float32(
            "root_uv", check_shape("root_uv", as_array("root_uv", root_uv), (n_s, 2))))
    return guides, root_uv


@dataclass(frozen=True, eq=False)
class Strands:
    """points (P,3) f32, counts (S,) i32, radius (P,) f32, color (P,3) f32 linear RGB,
    alpha (P,) f32, wisp (S,) i32. Point 0 of each strand is its root. Optional: guides
    (a Guides: the key strands and each strand's guides and weights) and root_uv (S,2) f32.
    An array may be a read-only view that takes no memory a point (groom gives an opaque
    groom's alpha as one 1.0 broadcast: groom.cylinders.ones); code that needs it laid out
    (a file, a GPU buffer) lays it out, as np.ascontiguousarray does.

    The colour of strands whose colour does not change along them may be held a strand at a
    time: strand_color (S,3) f32, with point_color None (Blender's CURVE domain beside its
    POINT domain). `color` is per point either way: made from strand_color on first use and
    kept (12 bytes a point that a groom of 1,000,000 strands of 62 points need not hold
    until something reads them: 714 MiB). Code that can use a colour a strand (a renderer's
    upload, Blender's attributes) reads strand_color where it is not None."""
    points: np.ndarray
    counts: np.ndarray
    radius: np.ndarray
    point_color: np.ndarray
    alpha: np.ndarray
    wisp: np.ndarray
    guides: "Guides" = None
    root_uv: np.ndarray = None
    strand_color: np.ndarray = None

    @property
    def color(self):
        """(P,3) f32 linear RGB per point (made from strand_color on first use, see above)."""
        c = self.point_color
        if c is None:
            c = repeat_rows(self.strand_color, self.counts)
            object.__setattr__(self, "point_color", c)
        return c

    @classmethod
    def from_arrays(cls, points, counts, radius=None, color=None, alpha=None, wisp=None,
                    default_radius=1e-4, default_color=(0.3, 0.2, 0.1), guides=None, root_uv=None,
                    strand_color=None):
        """Validate and convert; missing per-point arrays get defaults (radius, color, alpha 1).
        guides: a Guides or None; root_uv: (S, 2) or None; strand_color: (S, 3), the colour a
        strand at a time, in place of color (give one of them).

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
        if strand_color is not None:
            if color is not None:
                raise InputError("color and strand_color both given; give the colour per point or per strand")
            strand_color = to_float32("strand_color", check_shape("strand_color", as_array(
                "strand_color", strand_color), (n_s, 3)))
        elif color is None:
            color = np.broadcast_to(np.asarray(default_color, float), (n_p, 3))
        alpha = np.ones(n_p, np.float32) if alpha is None else alpha
        wisp = np.zeros(n_s, np.int32) if wisp is None else wisp
        radius = to_float32("radius", check_shape("radius", as_array("radius", radius), (n_p,)))
        if color is not None:
            color = np.ascontiguousarray(to_float32("color", check_shape("color", as_array("color", color), (n_p, 3))))
        alpha = to_float32("alpha", check_shape("alpha", as_array("alpha", alpha), (n_p,)))
        wisp = to_int32("wisp", check_shape("wisp", as_array("wisp", wisp), (n_s,)), allow_integral_floats=True)
        if n_p and radius.min() < 0:
            raise InputError("radius: negative values; radii must be >= 0")
        if n_p and (alpha.min() < 0 or alpha.max() > 1):
            raise InputError("alpha: values outside [0, 1]; clamp them first")
        guides, root_uv = _checked_extras(guides, root_uv, n_s)
        return cls(points, counts, radius, color, alpha, wisp, guides, root_uv,
                   None if strand_color is None else np.ascontiguousarray(strand_color))

    def with_guides(self, guides=None, root_uv=None):
        """A copy carrying `guides` (a Guides) and `root_uv` (S, 2), each checked; the strand
        arrays are this Strands' own, checked when it was made (at 100,000 strands of 62
        points checking them again took 0.1 s of each Generate)."""
        guides, root_uv = _checked_extras(guides, root_uv, len(self.counts))
        return replace(self, guides=guides, root_uv=root_uv)

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
        """The arrays a .npz holds: SPEC §0's, then the optional guide arrays present."""
        out = {name: getattr(self, name) for name in NPZ_NAMES}
        if self.guides is not None:
            out.update(self.guides.arrays())
        if self.root_uv is not None:
            out["root_uv"] = self.root_uv
        return out

    def save_npz(self, path):
        with atomic_write(path) as f:
            np.savez(f, **self.arrays())

    @classmethod
    def load_npz(cls, path):
        """Strands from a .npz of the SPEC §0 arrays (`save_npz`); every size in the archive
        is checked before memory is taken (hairio.npyfile)."""
        arrays = read_npz(path, NPZ_NAMES + GUIDE_NPZ_NAMES, required=("points", "counts"))
        try:
            return cls.from_arrays(**_guides_from(arrays))
        except InputError as e:
            raise InputError(f"{path}: {e}") from None


def repeat_rows(per_strand, counts):
    """(P, C) rows of `per_strand` (S, C), each repeated counts[i] times, as np.repeat(...,
    axis=0) but a column at a time (np.repeat moves a row of C floats as one item, at about
    twice the cost)."""
    counts = np.asarray(counts)
    out = np.empty((int(counts.sum(dtype=np.int64)),) + per_strand.shape[1:], per_strand.dtype)
    for c in range(per_strand.shape[1]):
        out[:, c] = np.repeat(per_strand[:, c], counts)
    return out


def _guides_from(arrays):
    """from_arrays' arguments from a .npz's arrays: the key_* and guide arrays become a Guides,
    all of them or none (a partial set is refused by name)."""
    guide_names = GUIDE_NPZ_NAMES[:-1]
    present = [n for n in guide_names if n in arrays]
    out = {n: arrays[n] for n in NPZ_NAMES + ("root_uv",) if n in arrays}
    if not present:
        return out
    needed = ("key_points", "key_counts", "guides", "guide_weights")
    missing = [n for n in needed if n not in arrays]
    if missing:
        raise InputError(f"guide arrays {present} without {missing}; save all of them or none")
    keys = Strands.from_arrays(arrays["key_points"], arrays["key_counts"], arrays.get("key_radius"),
                               arrays.get("key_color"))
    n_s = len(as_array("counts", arrays["counts"]))
    out["guides"] = Guides.from_arrays(keys, arrays["guides"], arrays["guide_weights"],
                                       arrays.get("key_group"), num_strands=n_s)
    return out

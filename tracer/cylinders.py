# SPDX-License-Identifier: GPL-3.0-or-later
"""Strands -> continual cylinders (SPEC §6), whole-array numpy.

Cylinder i of a strand has top P_i, tip P_{i+1}, radius r_i = (the radii of P_i and P_{i+1}) / 2,
colour and alpha of point i, and is the part of the infinite cylinder of radius r_i around its
axis that lies between

    plane 1: through P_i,     normal N1 = P_{i+1} - P_i       keep (p - P_i)·N1 >= 0
    plane 2: through P_{i+1}, normal N2 = P_{i+2} - P_{i+1}   keep (p - P_{i+1})·N2 <= 0

(the last cylinder of a strand uses its own axis for N2), so consecutive cylinders share a
plane and never overlap along the strand.

Choices the SPEC leaves open, made here:

* The radius: SPEC §6 gives cylinder i the radius of its top point, so a strand tapered point
  by point is a staircase of cylinders each as wide as the step's wider end, wider on the
  whole than the curve through the points that Cycles renders (a cone along each segment).
  With the mean of its two points' radii a cylinder covers, seen from the side, what that
  segment's cone covers. On few-point strands the difference shows: the `short_intelligent`
  preset (8 points a strand) covered 8.6 % more of the image than in Cycles and rendered 9 %
  darker (docs/DECISIONS.md, "A cylinder's radius: the mean of its two points'").

* Zero-length segments: a point that repeats its predecessor (closer than `MERGE_EPS`
  times the scene size) is dropped before cylinders are made, so every axis has a direction
  and the neighbours of the dropped point share a plane as if it never existed. A strand
  left with fewer than two distinct points makes no cylinder.
* Sharp bends: past 90° the shared plane would cut the cylinder into an unbounded piece
  ((p - P_{i+1})·N2 <= 0 then holds for points far beyond the tip). Where the angle between
  the two axes exceeds `layout.SHARP_BEND_DEG`, both cylinders end on a plane square to their own
  axis instead (a flat end cap, like a strand end), which stays bounded.
* Joint planes vs. end caps: the tracer treats a strand as one solid tube. A ray that enters
  a cylinder through a plane it shares with its neighbour, at a point the neighbour's section
  covers, was already inside the strand, so that entry is no new surface; elsewhere on that
  plane (the crescents between the incoming cylinder's ellipse and the outgoing one's circle,
  SPEC §6) it is, and so is entering through a strand end or a sharp-bend cap. A strand's
  cylinders are consecutive rows, so the neighbour across plane 1 is the previous row and
  across plane 2 the next. `flags` bit 0 = plane 1 is a cap, bit 1 = plane 2 is a cap.
* Past the tip, on the outer side of a bend, a cylinder reaches up to r·tan(angle) beyond
  P_{i+1}; `extension` records that length so the grid can bound it.
"""
from dataclasses import dataclass

import numpy as np

from hairio import InputError

from . import layout

MERGE_EPS = 1e-7


@dataclass(frozen=True, eq=False)
class Cylinders:
    """Per cylinder (N rows): top, tip (N,3); n2 (N,3) plane-2 normal (unit); radius, alpha (N,);
    color (N,3); strand (N,) index into the input strands; flags (N,) uint8 (caps, see module);
    extension (N,) reach past the tip along the axis."""
    top: np.ndarray
    tip: np.ndarray
    n2: np.ndarray
    radius: np.ndarray
    color: np.ndarray
    alpha: np.ndarray
    strand: np.ndarray
    flags: np.ndarray
    extension: np.ndarray

    def __len__(self):
        return len(self.top)

    @property
    def axis(self):
        return self.tip - self.top

    def bounds(self, pad_factor=1.0):
        """Per-cylinder boxes (lo, hi), each (N,3): the capsule from top to the extended tip,
        inflated by radius·pad_factor."""
        axis = self.tip - self.top
        length = np.sqrt(np.einsum("ij,ij->i", axis, axis))
        far = self.tip + axis * (self.extension / np.maximum(length, 1e-30))[:, None]
        r = (self.radius * pad_factor)[:, None]
        return np.minimum(self.top, far) - r, np.maximum(self.top, far) + r

    def select(self, index):
        return Cylinders(*(getattr(self, f)[index] for f in _FIELDS))


_FIELDS = ("top", "tip", "n2", "radius", "color", "alpha", "strand", "flags", "extension")


def column_bounds(points):
    """(lo, hi) float64 (3,) of (N,3) points, column by column: numpy's min(axis=0) walks
    (N,3) arrays three values at a time and is ~10x slower on millions of points."""
    lo = np.array([points[:, i].min() for i in range(3)], np.float64)
    hi = np.array([points[:, i].max() for i in range(3)], np.float64)
    return lo, hi


def repeat_distance(points, bounds=None):
    """Points closer than this to their predecessor repeat it (MERGE_EPS times the scene
    size, which is at least a thousandth of the farthest coordinate). `bounds`: the points'
    column_bounds when the caller has them already."""
    if len(points) < 2:
        return 0.0
    lo, hi = column_bounds(points) if bounds is None else bounds
    scale = max(float(np.max(hi - lo)), float(np.max(np.abs(np.concatenate([lo, hi])))) * 1e-3, 1e-30)
    return MERGE_EPS * scale


def _distinct_points(strands, strand_of_point):
    """Mask of points kept: drops points that repeat their predecessor within a strand."""
    pts = strands.points
    keep = np.ones(len(pts), bool)
    if len(pts) < 2:
        return keep
    step = pts[1:] - pts[:-1]
    keep[1:] = np.einsum("ij,ij->i", step, step) > repeat_distance(pts) ** 2
    keep[1:] |= strand_of_point[1:] != strand_of_point[:-1]    # a root never repeats anything
    return keep


# How many times its radius the float32 spacing at a strand's coordinates may be before the
# strand counts as unresolved. Past a few radii the strand zigzags by more than its width,
# but it still renders where it is (coarsely); far past it a small head's points round onto
# each other, its cylinders vanish, and the image comes out empty without a word (a 0.2 mm
# head of radius 1e-6 at 1e4 m: spacing 1e3 radii). 16 keeps scenes that render coarsely
# but visibly (0.1 mm hair 1e4 m out: spacing ~10 radii) and stops the collapse.
SPACING_PER_RADIUS_MAX = 16.0


def points_reach(points, bounds=None):
    """The largest |coordinate| of (N,3) points (0 for none), from their column_bounds when
    the caller has them (no pass over the points)."""
    if not len(points):
        return 0.0
    lo, hi = column_bounds(points) if bounds is None else bounds
    return float(np.abs(np.concatenate([lo, hi])).max())


def check_float32_precision(strands, reach=None):
    """InputError when float32 points (SPEC §0) cannot resolve the thinnest strand: when the
    float32 spacing at the strands' coordinates exceeds SPACING_PER_RADIUS_MAX times the
    smallest strand radius (a strand's largest radius), and the image would otherwise come
    out empty or wrong without a word (SPEC §9). `reach`: points_reach of the points when the
    caller has it."""
    if not strands.num_points:
        return
    # A strand's thickness is its largest radius: tapered tips go towards zero by design
    # and may fall below the spacing without harm (they are thinner than anything drawn).
    nonempty = strands.counts > 0
    thick = np.maximum.reduceat(strands.radius, strands.offsets[nonempty]) if nonempty.any() else strands.radius[:0]
    pos = thick[thick > 0]
    if not pos.size:
        return
    far = points_reach(strands.points) if reach is None else reach
    spacing = float(np.spacing(np.float32(far)))
    rmin = float(pos.min())
    if spacing > SPACING_PER_RADIUS_MAX * rmin:
        raise InputError(f"points: coordinates reach {far:.6g}, where float32 numbers lie {spacing:.3g} apart, "
                         f"more than {SPACING_PER_RADIUS_MAX:g} times the thinnest strand's radius {rmin:.3g}; "
                         "the strands cannot be resolved. "
                         "Recentre the strands near the origin, e.g. subtract their bounds' centre "
                         "(and move the camera and lights by the same amount)")


@dataclass(frozen=True, eq=False)
class CylinderPlan:
    """What the cylinders of a set of strands are made from, before any per-cylinder work:
    the points left after dropping repeats (points (P,3), radius, alpha (P,), color (P,3),
    strand (P,) index of each point's strand or None, counts (S,) points left per strand)
    and `top_point` (N,): cylinder k runs from point top_point[k] to the next point. The numpy build (strands_to_cylinders) and the
    GPU build (tracer/shaders/cylinders_build.glsl) both start from it."""
    points: np.ndarray
    radius: np.ndarray
    color: np.ndarray
    alpha: np.ndarray
    strand: np.ndarray
    counts: np.ndarray
    top_point: np.ndarray

    def __len__(self):
        return len(self.top_point)


def plan_cylinders(strands, drop_repeats=True, candidates=None, reach=None):
    """hairio.Strands -> CylinderPlan. InputError where float32 cannot resolve the strands
    (check_float32_precision). With drop_repeats False, points that repeat their
    predecessor are kept and `strand` is None: for a caller that checks for repeats itself
    (the GPU build does, while it makes the cylinders) and comes back for the full plan
    when there are any, with `candidates`: the points whose successors may repeat them (a
    superset; only these are checked, by the same rule). `reach`: points_reach of the
    strands' points when the caller has it."""
    check_float32_precision(strands, reach)
    counts = strands.counts.astype(np.int64)
    if not drop_repeats:
        return CylinderPlan(strands.points, strands.radius, strands.color, strands.alpha, None,
                            counts, _top_points(counts))
    if candidates is not None:
        # Few points to check and drop: no per-point pass, one copy of each array.
        c = np.asarray(candidates, np.int64)
        ends = np.cumsum(counts)
        owner = np.searchsorted(ends, c, side="right")
        c = c[(c + 1 < ends[np.minimum(owner, len(ends) - 1)]) & (owner < len(ends))]
        step = strands.points[c + 1] - strands.points[c]
        drop = c[np.einsum("ij,ij->i", step, step) <= repeat_distance(strands.points) ** 2] + 1
        counts = counts - np.bincount(np.searchsorted(ends, drop, side="right"), minlength=len(counts))
        return CylinderPlan(*(np.delete(a, drop, axis=0) for a in
                              (strands.points, strands.radius, strands.color, strands.alpha)),
                            None, counts, _top_points(counts))
    strand_of_point = np.repeat(np.arange(len(counts), dtype=np.int32), counts)
    keep = _distinct_points(strands, strand_of_point)
    if keep.all():      # the usual case: no copies
        pts, sid = strands.points, strand_of_point
        radius, color, alpha = strands.radius, strands.color, strands.alpha
    else:
        pts, sid = strands.points[keep], strand_of_point[keep]
        radius, color, alpha = strands.radius[keep], strands.color[keep], strands.alpha[keep]
    # Point j starts a cylinder when point j+1 belongs to the same strand.
    top_point = np.flatnonzero(sid[:-1] == sid[1:]).astype(np.int32) if len(pts) > 1 else np.zeros(0, np.int32)
    return CylinderPlan(pts, radius, color, alpha, sid, np.bincount(sid, minlength=len(counts)), top_point)


def _top_points(counts):
    """Every point but the last of its strand starts a cylinder (strands of `counts` points,
    none repeated)."""
    starts = np.ones(int(counts.sum()), bool)
    full = counts > 0
    starts[(np.cumsum(counts) - 1)[full]] = False
    return np.flatnonzero(starts).astype(np.int32)


def strands_to_cylinders(strands):
    """hairio.Strands -> Cylinders (float32 arrays for the GPU; the reference promotes them).
    Whole-array float32 work: the GPU consumes float32, and the reference promotes exactly
    these values, so both trace the same cylinders. InputError where float32 cannot resolve
    the strands (check_float32_precision)."""
    return cylinders_from_plan(plan_cylinders(strands))


def cylinders_from_plan(plan):
    """Cylinders of a CylinderPlan made with drop_repeats (its `strand` is needed)."""
    if not len(plan):
        return _empty()
    i = plan.top_point
    pts = plan.points
    top = pts[i]
    tip = pts[i + 1]
    strand = plan.strand[i]
    axis = tip - top
    length = np.sqrt(np.einsum("ij,ij->i", axis, axis))
    u1 = axis / length[:, None]
    # Cylinders of a strand are consecutive, so the next axis is the next row's own axis.
    has_next = np.zeros(len(top), bool)
    has_next[:-1] = strand[1:] == strand[:-1]
    u2 = u1.copy()
    u2[:-1][has_next[:-1]] = u1[1:][has_next[:-1]]
    cosang = np.einsum("ij,ij->i", u1, u2)
    cos_sharp = np.float64(layout.cos_sharp())
    sharp = has_next & (cosang < cos_sharp)
    u2[sharp] = u1[sharp]
    cosang[sharp] = 1.0
    # Plane 1 of cylinder k is plane 2 of cylinder k-1 unless k is a strand's first or the
    # joint is sharp; both of those make it a cap.
    first = np.ones(len(top), bool)
    first[1:] = ~has_next[:-1] | sharp[:-1]
    flags = (first * layout.CAP_PLANE1 | (~has_next | sharp) * layout.CAP_PLANE2).astype(np.uint8)
    r = segment_radius(plan.radius, i)
    cosang = np.clip(cosang, cos_sharp, 1.0)
    ext = r * np.sqrt(1.0 - cosang * cosang) / cosang
    return Cylinders(
        top=top, tip=tip, n2=u2.astype(np.float32), radius=r,
        color=plan.color[i], alpha=plan.alpha[i],
        strand=strand, flags=flags, extension=ext.astype(np.float32))


def segment_radius(radius, top):
    """The radius of the cylinders from points `top` to top + 1 (radius per point, float32):
    the mean of their two points' radii, in float32 as the GPU build takes it ((a + b)·0.5),
    so a tapered strand covers what the tapered curve through its points covers."""
    out = np.add(radius[top], radius[top + 1], dtype=np.float32)
    out *= np.float32(0.5)
    return out


def _empty():
    z3 = np.zeros((0, 3), np.float32)
    z = np.zeros(0, np.float32)
    return Cylinders(z3, z3, z3, z, z3, z, np.zeros(0, np.int32), np.zeros(0, np.uint8), z)

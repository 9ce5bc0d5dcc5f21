# SPDX-License-Identifier: GPL-3.0-or-later
"""The head frame: where the bundled head's space lies on any scalp mesh.

Presets are drawn on the bundled head (`default_scalp`: metres, Z up, -Y front, a cap on an
ellipsoid of half-axes 0.08 x 0.1 x 0.1 m centred at the origin), the *canonical* space. A
user's scalp is anywhere, any size, any way up. `fit_head_frame` finds its head: the axes
from the `up` and `front` the caller gives (the mesh alone cannot tell a face from a back),
the centre and the half-axes from the mesh, so `HeadFrame.to_scalp` carries a canonical
point to the matching place on that head.

The centre and half-axes come from a weighted least-squares fit of an ellipsoid aligned
with the head's axes to the mesh vertices, each weighted by its share of the surface area
(a dense face must not outvote the cranium). A bounding box would not do: a cap's box
centre lies wherever the cap happens to end (3 cm above the head's centre on the bundled
scalp, whose hairline is higher in front than behind), a whole head's far below, by the jaw.

What is fitted:
- a cap (the usual scalp: top, back and sides, down to the nape): one fit over all of it.
- a whole head (face, jaw, neck): the first fit is pulled down and stretched by the jaw and
  the neck, so it is fitted again over the part above its centre (the cranium and the
  brow). The second fit is kept when it explains that upper part clearly better than the
  first (RMS distance 1.6 times smaller; measured: the USC head 2.2, the bundled head
  exact, the real cap 1.4, heads cut below the nose 1.3 or less). The frame's centre then
  lies near the ears' height and its top at the crown, as on the bundled head, so key
  anchors land on the cranium; a whole head used as a scalp still grows hair wherever its
  surface is (paint a density weight to keep the face bare).
- a small cap (less than ~35° around the crown): its curvature says little about three
  separate half-axes, so the fit falls back to a sphere through it (three equal
  half-axes). Anchors lower than the cap reaches land on its edge; `Preset.place_keys`
  reports them.
- a mesh with no curvature to speak of (a flat patch, a few triangles): the bounding box.
On the bundled scalp (every vertex exactly on its ellipsoid) the first fit recovers the
canonical head to rounding, so the frame is the identity there; on the bundled head
(default_head) the second does.
"""
import numpy as np

from hairio import InputError

#: The bundled head (groom.default_scalp): its half-axes along (right, front, up), its axes.
CANONICAL_HALF_AXES = (0.08, 0.1, 0.1)
CANONICAL_UP = (0.0, 0.0, 1.0)
CANONICAL_FRONT = (0.0, -1.0, 0.0)

# Up and front closer than this (|cos|) are taken as parallel; frames.frame_axes uses the same.
_PARALLEL_COS = 0.999
# Normalised least-squares condition numbers above these mean the mesh does not pin the
# quantities down (measured: a whole head or a cap ~3; a 30° cap around the crown ~50, a
# 20° one ~110, where 0.2 mm of noise already moves the fitted centre by 4 cm).
_ELLIPSOID_MAX_CONDITION = 40.0
_SPHERE_MAX_CONDITION = 1e4
# A fitted head longer than this along one axis than another is not a head.
_MAX_AXIS_RATIO = 2.5
# The refit above the first fit's centre replaces it when the first fit's RMS distance to
# that upper part is this many times the refit's (see the module's notes).
_BENT_BY_BELOW = 1.6


def vector3(name, v):
    """`v` as a float64 3-vector; InputError naming `name` for anything else or a NaN/Inf."""
    try:
        a = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError):
        a = np.full(1, np.nan)
    if a.shape != (3,) or not np.isfinite(a).all():
        raise InputError(f"{name}: expected 3 finite numbers, got {v!r}")
    return a


def head_axes(up, front, names=("up", "front")):
    """Unit (up, front), front made perpendicular to up; InputError naming the argument
    (`names`, e.g. the command line's options) for anything that is not two finite,
    non-zero, non-parallel 3-vectors."""
    out = []
    for name, v in zip(names, (up, front)):
        a = vector3(name, v)
        length = float(np.linalg.norm(a))
        if not length > 1e-300:
            raise InputError(f"{name}: must not be the zero vector")
        out.append(a / length)
    u, f = out
    if abs(float(u @ f)) > _PARALLEL_COS:
        raise InputError(f"{names[1]}: must not be parallel to {names[0]}; give the direction the face looks")
    f = f - (f @ u) * u
    return u, f / np.linalg.norm(f)


class HeadFrame:
    """A head in a scalp's space: centre (3,), half_axes (3,) along (right, front, up), and
    the unit axes up, front and right = up × front, all in the scalp's own space.

    `right` is the viewer's right when facing the head (the head's own left): +X on the
    bundled head, whose face looks down -Y. (right, -front, up) is the scalp-space image of
    the canonical (X, Y, Z) and a rotation, never a mirror. `method` says how the frame was
    found: 'ellipsoid', 'sphere' or 'box' (see fit_head_frame)."""

    def __init__(self, centre, half_axes, up=CANONICAL_UP, front=CANONICAL_FRONT, method="given"):
        self.up, self.front = head_axes(up, front)
        self.right = np.cross(self.up, self.front)
        c = np.asarray(centre, dtype=np.float64)
        h = np.asarray(half_axes, dtype=np.float64)
        if c.shape != (3,) or not np.isfinite(c).all():
            raise InputError(f"head centre: expected 3 finite numbers, got {centre!r}")
        if h.shape != (3,) or not np.isfinite(h).all() or not (h > 0).all():
            raise InputError(f"head half-axes: expected 3 finite numbers > 0, got {half_axes!r}")
        self.centre, self.half_axes, self.method = c, h, method
        # Rows: the canonical X, Y, Z axes in the scalp's space.
        self._axes = np.stack([self.right, -self.front, self.up])
        self._stretch = h / np.asarray(CANONICAL_HALF_AXES)

    @property
    def size(self):
        """Mean half-axis (metres on a head in metres): the head's size for tolerances."""
        return float(self.half_axes.mean())

    @property
    def scale(self):
        """This head's size relative to the bundled head's."""
        return self.size / float(np.mean(CANONICAL_HALF_AXES))

    @property
    def rotation(self):
        """(3, 3): columns (right, -front, up), the canonical X, Y, Z axes in the scalp's
        space; `rotation @ v` turns a canonical vector without changing its length."""
        return self._axes.T.copy()

    def to_scalp(self, points_canonical):
        """Canonical points (3,) or (N, 3) -> the matching points of this head: the bundled
        head's ellipsoid goes onto this one (an affine map, so a point's place relative to
        the head, e.g. half-way up the back, is kept)."""
        p = np.asarray(points_canonical, dtype=np.float64)
        return self.centre + (p * self._stretch) @ self._axes

    def to_canonical(self, points):
        """The inverse of to_scalp: points of this head (3,) or (N, 3) -> canonical points."""
        p = np.asarray(points, dtype=np.float64)
        return ((p - self.centre) @ self._axes.T) / self._stretch

    def direction_to_scalp(self, d):
        """A canonical direction seen from the head's centre (3,) or (N, 3) -> the unit
        direction from this head's centre to the image of the point the canonical ray
        points at (the direction of a point, not of a normal: see normal_to_scalp)."""
        return _unit(np.asarray(d, dtype=np.float64) * self._stretch @ self._axes)

    def normal_to_scalp(self, n):
        """A canonical plane normal (3,) or (N, 3) -> the unit normal of the image plane
        (normals take the inverse stretch)."""
        return _unit(np.asarray(n, dtype=np.float64) / self._stretch @ self._axes)

    def normal_to_canonical(self, n):
        """The inverse of normal_to_scalp."""
        return _unit((np.asarray(n, dtype=np.float64) @ self._axes.T) * self._stretch)

    def __repr__(self):
        return (f"HeadFrame(centre={self.centre.round(6).tolist()}, half_axes={self.half_axes.round(6).tolist()}, "
                f"up={self.up.round(6).tolist()}, front={self.front.round(6).tolist()}, method={self.method!r})")


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def fit_head_frame(scalp, up=CANONICAL_UP, front=CANONICAL_FRONT):
    """The HeadFrame of `scalp` (a groom.Scalp); up and front in the scalp's own space
    (front is made perpendicular to up). See the module's notes for caps vs whole heads."""
    up, front = head_axes(up, front)
    axes = np.stack([np.cross(up, front), -front, up])
    points, weights = _surface_samples(scalp)
    origin = np.average(points, axis=0, weights=weights)
    local = (points - origin) @ axes.T
    # Unit-sized coordinates, so the condition numbers mean the same on any head.
    unit = float(np.sqrt(np.average(np.einsum("nd,nd->n", local, local), weights=weights)))
    if not unit > 1e-12 * max(1.0, float(np.abs(points).max())):
        raise InputError("scalp: all its vertices coincide; a head frame needs a surface")
    local = local / unit
    fitted = _fit_ellipsoid(local, weights)
    method = "ellipsoid"
    if fitted is not None:
        above = local[:, 2] >= fitted[0][2]
        cranium = _fit_ellipsoid(local[above], weights[above])
        if cranium is not None:
            first, second = (_rms_distance(local[above], weights[above], f) for f in (fitted, cranium))
            if first > _BENT_BY_BELOW * second + 1e-9:
                fitted = cranium
    else:
        fitted, method = _fit_sphere(local, weights), "sphere"
        if fitted is None:
            fitted, method = _fit_box(local), "box"
    centre, half_axes = fitted
    return HeadFrame(origin + (centre * unit) @ axes, half_axes * unit, up, front, method)


def _surface_samples(scalp):
    """Vertices used by a triangle, each weighted by a third of its triangles' area (equal
    weights when the mesh has no area at all)."""
    used = np.unique(scalp.triangles)
    w = np.zeros(len(scalp.vertices))
    for c in range(3):
        np.add.at(w, scalp.triangles[:, c], scalp.face_areas / 3.0)
    w = w[used]
    if not w.sum() > 0:
        w = np.ones(len(used))
    return scalp.vertices[used], w


def _weighted_lstsq(design, rhs, weights):
    """Weighted least squares; (solution, condition number) or None when rank-deficient."""
    sw = np.sqrt(weights / weights.sum())
    sol, _, rank, sv = np.linalg.lstsq(design * sw[:, None], rhs * sw, rcond=None)
    if rank < design.shape[1] or not sv[-1] > 0:
        return None
    return sol, float(sv[0] / sv[-1])


def _fit_ellipsoid(local, weights):
    """Axis-aligned ellipsoid A x² + B y² + C z² + D x + E y + F z = 1 through the samples:
    (centre, half-axes), or None where the samples do not determine it well."""
    if len(local) < 6:
        return None
    x, y, z = local.T
    solved = _weighted_lstsq(np.stack([x * x, y * y, z * z, x, y, z], 1), np.ones(len(local)), weights)
    if solved is None or solved[1] > _ELLIPSOID_MAX_CONDITION:
        return None
    quad, lin = solved[0][:3], solved[0][3:]
    if not (quad > 0).all():
        return None
    centre = -lin / (2.0 * quad)
    level = 1.0 + float(quad @ (centre * centre))
    half = np.sqrt(level / quad)
    if not np.isfinite(half).all() or half.max() > _MAX_AXIS_RATIO * half.min():
        return None
    return centre, half


def _rms_distance(local, weights, ellipsoid):
    """Weighted RMS of the samples' radial distances to an ellipsoid (centre, half-axes),
    relative to its size: a close stand-in for the true distance on a head."""
    centre, half = ellipsoid
    r = np.linalg.norm((local - centre) / half, axis=1) - 1.0
    return float(np.sqrt(np.average(r * r, weights=weights)))


def _fit_sphere(local, weights):
    """Sphere |p|² + D·p + G = 0 through the samples (the algebraic fit): (centre, three
    equal half-axes), or None."""
    if len(local) < 4:
        return None
    rhs = -np.einsum("nd,nd->n", local, local)
    solved = _weighted_lstsq(np.column_stack([local, np.ones(len(local))]), rhs, weights)
    if solved is None or solved[1] > _SPHERE_MAX_CONDITION:
        return None
    centre = -0.5 * solved[0][:3]
    r2 = float(centre @ centre - solved[0][3])
    if not r2 > 0:
        return None
    return centre, np.full(3, np.sqrt(r2))


def _fit_box(local):
    """The samples' bounding box: its centre, its largest half-extent on every axis."""
    lo, hi = local.min(axis=0), local.max(axis=0)
    return 0.5 * (lo + hi), np.full(3, 0.5 * float((hi - lo).max()))

# SPDX-License-Identifier: GPL-3.0-or-later
"""Beams: an acceleration structure for a family of rays that share an origin (the camera's)
or a direction (a sun's), or end near one point (a point, spot or area light's shadow rays:
light_frame), built in whole-array numpy (the compute passes, shaders/beams_build.glsl,
follow the same rules).

Every camera ray of a pixel stays inside the pyramid of that pixel, and every shadow ray
toward a sun stays inside a thin prism along the sun's direction. So the rays of such a
family are binned across their direction: a 2-D grid of bins (the camera's: whole pixels,
`bin_px` a side; a sun's: squares of the plane square to it), each listing every cylinder a
ray of the bin can meet, nearest first. A ray then looks up its bin once (no 3-D walk) and
tests the list in order until nothing farther can change its result: a camera ray once its
layers are settled nearer than the next entry, a shadow ray once the entries left lie
behind its origin. Thin diagonal hair is what a uniform grid lists worst (each cylinder in
every cell its box touches, most of which a ray crosses without meeting it); a bin lists a
cylinder only where its projected capsule reaches, and a ray tests the few nearest of them.

Lists are kept in order of depth by buckets: the scene's depth range is cut into
`layout.BEAM_SLICES` slices, each into 2^sub fine ones (at most as many bits as the scene's
ids leave: layout.beam_sub_bits). Each entry is one 32-bit word, the cylinder id and its
fine slice (`id | fine << (BEAM_ID_BITS - sub)`), and a bin's list holds its entries fine
slice by fine slice (in any order within one), so a walk knows without a second fetch that
every later entry lies at least that fine slice's depth away. The compute passes fill the
lists one of two ways (fill_plan, which also chooses sub): a fine slice a dispatch (sub is
then fine_bits' choice, no more fine slices than the lists' references pay for), or every
cylinder in one dispatch in id order and then each bin's entries sorted by fine slice. The
depth of an entry, its `key`:

    camera   the capsule's nearest distance from the camera (perspective: from its position,
             the distance to its axis less its radius; orthographic: from the camera's plane,
             its nearest depth less its radius): a camera ray meets it no nearer than that;
    sun      minus the capsule's greatest height toward the sun (max over its axis of p·w,
             plus its radius): a shadow ray leaving p reaches only heights above p·w, so
             entries whose key exceeds -p·w (lying wholly below p) cannot stop it.
    light    as a perspective camera's, from the light's position: a shadow ray from p toward
             a point of the light within its extent R of the position goes no farther from
             the position than max(|p - position|, R) (light_frame).

Listing (conservative): a ray of a bin passes within r of some point q of a cylinder's axis
(its capsule holds the cut cylinder, bent joints included: tracer/cylinders.py, `extension`),
and then its projection lies within rho of q's: for a perspective camera rho = r·sqrt(1 +
|x|²) / (depth(q)·pixel_size) pixels, where x is the ray's point on the image plane at unit
depth (|x| is largest at a corner of the bins) — the distance from q to the ray is at least
depth(q)·|x_q - x| / sqrt(1 + |x|²) —, for an orthographic camera r / pixel_size, for a sun r
plus the sideways drift of a sun with an angle over the scene's height. The projection of the
axis is a segment (perspective maps segments to segments when they lie in front of the
camera), so the listing is the 2-D version of the grid's slab listing: the segment cut into
the bins' columns along its longer side, each column listing the rows its part reaches within
rho. A capsule that reaches the camera's plane cannot be projected: the camera then gets no
beams (`BeamsUnfit`) and its rays walk the grid.

Pixel centres. A render of one independent sample a pixel sends each camera ray through its
pixel's centre, so a camera frame with `centres` lists in a 1-pixel bin only what that one
ray may meet: the columns and rows whose centre lies within rho of the projected axis
(centre_span), for thin hair a small share of the pixels its capsule's shadow touches (10,000
wavy strands at 512x512: 157 k entries against 4.3 M for whole pixels). Such lists serve no
other ray: a pass that moves the camera, or more samples, takes lists of whole bins.
"""
from dataclasses import dataclass

import numpy as np

from . import layout

CHUNK = 1 << 16         # cylinders per listing job (their temporaries stay in cache)


class BeamsUnfit(Exception):
    """Beams cannot serve this family of rays (a capsule reaching the camera's plane, one
    listed in too many bins, or more references than one buffer holds): its rays walk the
    grid instead. Not an input error: the scene renders either way."""


class TooManyRefs(BeamsUnfit):
    """More references than the budget: coarser bins may fit."""


@dataclass(frozen=True, eq=False)
class BeamFrame:
    """How a family's points map to bins. `kind`: "persp" or "ortho" (camera rays) or "sun"
    (shadow rays toward a directional light). A point q maps to X, Y, Z = axes·(q - origin),
    then to bin coordinates gx = X/Z + offset[0], gy = Y/Z + offset[1] ("persp") or
    gx = X + offset[0], gy = Y + offset[1]; Z is its depth (camera) or height toward the sun.
    `radius_scale`: bins per unit of radius (per unit of radius and depth for "persp"),
    `drift`: bins added to every radius (a sun's spread; a camera's shift_pad); the keys' slices start at `key0`,
    `key_step` apart; `dims`: bins along x and y; `bin_px` (cameras): pixels a bin side,
    `box`: the whole-image pixels (x0, y0, x1, y1) the bins cover; `centres` (cameras, 1-pixel
    bins): a bin lists only what the ray through its centre may meet; `extent` (a point, spot or
    area light's "persp" frame, light_frame): how far from `origin` its shadow rays may end,
    `spread` what every capsule's listing radius is widened for (the rays' drift from their
    origins' directions), `far_depth` the hair's farthest depth; `anchor` (suns and lights) a
    point amid the hair, whose frame coordinates the GPU takes from the host (float64) and adds
    to a point's offset from it: a light far away, or hair far from the world's origin, then
    loses no float32 precision to the origin's distance (anchored)."""
    kind: str
    origin: np.ndarray
    axes: np.ndarray
    offset: np.ndarray
    radius_scale: float
    drift: float
    key0: float
    key_step: float
    dims: tuple
    bin_px: int = 1
    box: tuple = (0, 0, 0, 0)
    near_limit: float = 0.0     # perspective: a capsule whose key is not above this reaches the camera's plane
    centre: tuple = (0.0, 0.0)  # cameras: the optical axis in pixels the bins were laid for
    centres: bool = False       # cameras: for the rays through the pixels' centres alone (module text)
    extent: float = 0.0         # lights ("persp"): how far from the origin their shadow rays may end
    spread: float = 0.0         # lights: how far those rays drift from their origin's direction (light_frame)
    far_depth: float = 0.0      # lights: the hair's farthest depth (origins beyond move along their ray to it)
    anchor: np.ndarray = None   # suns and lights: a point amid the hair the GPU measures from (anchored)
    cone: tuple = None          # spot lights: (axis x, y, z, half angle): what lies wholly outside is never listed

    @property
    def num_bins(self):
        return int(self.dims[0]) * int(self.dims[1])


@dataclass(frozen=True, eq=False)
class Beams:
    """A family's bins: the frame, how many entries they hold, the bits of its fine slices
    (`sub`, module text), and (numpy build) per bin its first entry and entry count (int32,
    bin id x + nx·y) and the entries (uint32 id | fine slice << id_bits, sorted within a
    bin). The compute passes leave those three None: their lists exist only on the GPU
    (tracer.scene_beams.read_beams brings them back). `reach` (built on the GPU with each
    entry's mark: a sun's, a camera's whole bins for independent samples; else None): the
    largest listing radius in bins (frame_reach), which a ray's point must lie within of a
    cylinder's projected axis for its full test, and the margin of the box the marks code
    the axis in (tracer/scene_beams.py; shaders/beams_build.glsl, beam_mark)."""
    frame: BeamFrame
    refs: int
    sub: int = 0
    start: np.ndarray = None
    count: np.ndarray = None
    entries: np.ndarray = None
    reach: float = None
    longest: int = 0            # the most entries a bin holds

    @property
    def id_bits(self):
        return layout.BEAM_ID_BITS - self.sub

    @property
    def fine_step(self):
        """The keys' span of one fine slice."""
        return self.frame.key_step / (1 << self.sub)

    def ids(self, entries):
        """The cylinder ids of `entries`."""
        return np.asarray(entries) & np.uint32((1 << self.id_bits) - 1)

    def starts(self, entries):
        """Where the fine slice of each of `entries` starts: no key of it lies below."""
        fine = np.asarray(entries) >> np.uint32(self.id_bits)
        return self.frame.key0 + fine.astype(np.float64) * self.fine_step


# --- frames ------------------------------------------------------------------------------
def _slices(lo, hi, pad):
    """(key0, key_step) of BEAM_SLICES slices over keys lo..hi widened by `pad`."""
    lo, hi = lo - pad, hi + pad
    return float(lo), float(max(hi - lo, 1e-30) / layout.BEAM_SLICES)


def box_corners(lo, hi):
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])],
                    np.float64)


def camera_frame(camera, box, scene_lo, scene_hi, rmax, pad, bin_px=1, shift_pad=0.0, centre=None, centres=False):
    """The frame of `camera`'s rays over the whole-image pixel box `box` (x0, y0, x1, y1: the
    pixels a render traces), for a scene within scene_lo..scene_hi whose largest radius is
    `rmax`, capsules widened `pad` times, bins of `bin_px` pixels a side. `centre`: the optical
    axis in pixels (default the camera's; a pass of the same view moved by a fraction of a
    pixel keeps the first's), `shift_pad`: how far (pixels) a pixel's samples may lie outside
    its bin, for the pixel sampler of such a pass (every cylinder is listed that much wider).
    `centres`: lists for the rays through the pixels' centres alone (one sample a pixel, this
    camera's own pixel grid: 1-pixel bins, no shift_pad). BeamsUnfit when the scene reaches
    the camera's plane (perspective)."""
    x0, y0, x1, y1 = (int(v) for v in box)
    b = int(bin_px)
    if centres and (b != 1 or shift_pad):
        raise ValueError("lists for the pixels' centres take 1-pixel bins and no shift_pad")
    dims = (-(-(x1 - x0) // b), -(-(y1 - y0) // b))
    R = np.asarray(camera.rotation, np.float64)
    ps = float(camera.pixel_size)
    cx, cy = (float(v) for v in (camera.centre_px if centre is None else centre))
    # Rows: image x (pixels right), image y (pixels down), depth along the view axis.
    axes = np.stack([R[:, 0] / (ps * b), -R[:, 1] / (ps * b), -R[:, 2]])
    offset = np.array([(cx - x0) / b, (cy - y0) / b])
    corners = box_corners(scene_lo, scene_hi)
    depth = corners @ -R[:, 2] - float(np.asarray(camera.position) @ -R[:, 2])
    dpad = rmax * pad
    near_limit = 0.0
    if camera.type == "PERSP":
        near_limit = layout.BEAM_NEAR_FRACTION * max(float(depth.max() - depth.min()), rmax)
        if float(depth.min()) - dpad <= near_limit:
            raise BeamsUnfit("the hair reaches the camera's plane")
        # The largest |x| (unit-depth image plane) over the bins' corners.
        us = (np.array([x0, x0 + dims[0] * b]) - cx) * ps
        vs = (cy - np.array([y0, y0 + dims[1] * b])) * ps
        reach = float(np.sqrt(1.0 + np.max(us ** 2) + np.max(vs ** 2)))
        scale = reach / (ps * b)
        kind = "persp"
    else:
        scale = 1.0 / (ps * b)
        kind = "ortho"
    if kind == "persp":     # keys are distances from the camera, which lies outside the box
        far = float(np.max(np.linalg.norm(corners - np.asarray(camera.position, np.float64), axis=1)))
        key0, step = _slices(float(depth.min()), far, dpad)
    else:
        key0, step = _slices(float(depth.min()), float(depth.max()), dpad)
    return BeamFrame(kind, np.asarray(camera.position, np.float64), axes, offset, scale, float(shift_pad) / b, key0,
                     step, dims, b, (x0, y0, x1, y1), near_limit, (cx, cy), bool(centres))


def sun_basis(towards):
    """Unit (u, v, w): w toward the sun, u and v across it (tracer.settings._basis's rule)."""
    w = np.asarray(towards, np.float64)
    w = w / np.linalg.norm(w)
    u = np.cross(w, [0.0, 0.0, 1.0]) if abs(w[2]) < 0.999 else np.cross(w, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    return u, np.cross(w, u), w


def sun_frame(towards, spread, scene_lo, scene_hi, rmax, pad, bin_size):
    """The frame of shadow rays toward a sun: unit `towards` (the shadow rays' direction),
    `spread` the tangent of the largest angle a ray makes with it (0: one direction), bins of
    `bin_size` scene units over the scene box's shadow."""
    u, v, w = sun_basis(towards)
    corners = box_corners(scene_lo, scene_hi)
    reach = rmax * pad
    height = corners @ w
    # Over the scene's height a ray drifts sideways by at most this.
    drift_units = float(spread) * float(height.max() - height.min() + 2 * reach)
    cu, cv = corners @ u, corners @ v
    margin = reach + drift_units
    lo_u, lo_v = float(cu.min()) - margin, float(cv.min()) - margin
    h = float(bin_size)
    dims = (max(1, int(np.ceil((float(cu.max()) + margin - lo_u) / h))),
            max(1, int(np.ceil((float(cv.max()) + margin - lo_v) / h))))
    key0, step = _slices(-float(height.max()), -float(height.min()), reach)
    return BeamFrame("sun", np.zeros(3), np.stack([u / h, v / h, w]), np.array([-lo_u / h, -lo_v / h]),
                     1.0 / h, drift_units / h, key0, step, dims, anchor=0.5 * (np.asarray(scene_lo, np.float64)
                                                                               + np.asarray(scene_hi, np.float64)))


def anchored(frame):
    """(anchor, its frame coordinates (axes · (anchor - origin), float64)): a point is then
    (axes · (point - anchor)) + those, which float32 computes from the point's small offset
    (BeamFrame.anchor; the frame's origin itself where it has none)."""
    anchor = frame.origin if frame.anchor is None else np.asarray(frame.anchor, np.float64)
    return anchor, np.asarray(frame.axes, np.float64) @ (anchor - np.asarray(frame.origin, np.float64))


def drift_at(extent, far_depth, most, depth):
    """How far shadow rays toward a point within `extent` of a light drift from their origins'
    directions at `depth` (times depth over the drifted point's own, module text): the extent
    times the most of the way toward the light a ray from the hair's farthest depth
    `far_depth` has gone there, less the nearer it lies to that depth; at most `most`
    (LightView.spread). The compute passes' project_cylinder the same."""
    return np.minimum(extent * np.maximum(far_depth - depth, 0.0) / (far_depth - extent), most)


def light_frame(position, extent, scene_lo, scene_hi, rmax, pad, bin_size, cone=None):
    """The frame of shadow rays toward a light at `position` whose rays end within `extent` of
    it (a point or spot light's radius, an area light's half diagonal; 0: at it): a perspective
    frame from the position toward the scene box's centre, square bins `bin_size` a side at unit
    depth over the box's projection widened by the widest listing radius, keys the distances
    from the position (as a perspective camera's). A ray from p toward a point q of the light
    meets a capsule only at distances from the position up to max(|p - position|, extent), and
    only where p's projection lies within (r + spread)·sqrt(1 + |x|²) / (depth - r) of the
    capsule's axis at unit depth (the camera's bound for the ray from the position through the
    meeting point, plus how far that point's projection lies from p's: a point s of the way
    from p to the light drifts from p's direction by at most s·extent·sqrt(1 + |x|²) over its
    depth, and at the hair's depths s is at most (far - near) / (far - extent), LightView.spread,
    once an origin deeper than the hair is moved along its ray to the hair's farthest depth,
    which the walk does). BeamsUnfit
    where the box comes within its near limit plus `extent` of the light's plane (a light among
    the hair), whose rays walk the grid. `cone` (a spot light: its unit axis and half angle):
    capsules wholly outside it lie in no shadow ray's way (outside_cone)."""
    view = light_view(position, extent, scene_lo, scene_hi, rmax, pad)
    h = float(bin_size)
    spread = view.spread(extent)
    widen = (view.dpad + spread) / view.nearest      # the listing radius over the slant factor
    # The bins reach past the box's projection by the widest listing radius, its slant factor
    # taken a bin past them (a few rounds settle it).
    margin = 0.0
    for _ in range(8):
        margin = widen * view.slant(margin + h) + h * layout.BEAM_BIN_EPS
    margin *= 1.01
    slant = view.slant(margin + h)
    if widen * slant + h * layout.BEAM_BIN_EPS > margin:
        raise BeamsUnfit("the light lies too near the hair for its bins to hold their listings")
    x0, y0 = float(view.tx.min()) - margin, float(view.ty.min()) - margin
    dims = (max(1, int(np.ceil((float(view.tx.max()) + margin - x0) / h))),
            max(1, int(np.ceil((float(view.ty.max()) + margin - y0) / h))))
    key0, step = _slices(float(view.depth.min()), view.far, view.dpad)
    return BeamFrame("persp", view.origin, np.stack([view.u / h, view.v / h, view.w]), np.array([-x0 / h, -y0 / h]),
                     slant / h, 0.0, key0, step, dims, near_limit=view.near_limit, extent=float(extent),
                     spread=spread, far_depth=float(view.depth.max()),
                     anchor=0.5 * (np.asarray(scene_lo, np.float64) + np.asarray(scene_hi, np.float64)),
                     cone=None if cone is None else tuple(float(x) for x in cone))


def outside_cone(cone, origin, extent, top, far, radius):
    """Which capsules top..far of `radius` no shadow ray toward a spot light crosses: the light
    at `origin` sends light only within `cone` (its axis, half angle theta) from each point of
    it, all within `extent` of the origin, so a shadow ray cast (trace_main.glsl casts none
    where the light gives nothing) lies within the cone widened by `extent`; a capsule whose
    bounding sphere (centre m, radius rho) lies farther from that cone, by an angle past
    theta + asin(rho / |m - origin|) (plus layout.BEAM_CONE_MARGIN), is crossed by none of them.
    shaders/beams_build.glsl, project_cylinder, makes the same test."""
    axis, theta = np.asarray(cone[:3], np.float64), float(cone[3])
    top, far = np.asarray(top, np.float64), np.asarray(far, np.float64)
    m = 0.5 * (top + far) - np.asarray(origin, np.float64)
    rho = 0.5 * np.sqrt(((far - top) ** 2).sum(axis=-1)) + np.asarray(radius, np.float64) + float(extent)
    d = np.sqrt((m * m).sum(axis=-1))
    along = m @ axis
    across = np.sqrt(np.maximum(d * d - along * along, 0.0))
    alpha = np.arctan2(across, along)
    beta = np.arctan2(rho, np.sqrt(np.maximum(d * d - rho * rho, 0.0)))
    return (d > rho) & (alpha > theta + beta + layout.BEAM_CONE_MARGIN)


@dataclass(frozen=True, eq=False)
class LightView:
    """What light_frame sees of a scene box from a light: its origin and axes (w toward the
    box's centre), the box corners' depths and their projections at unit depth (tx, ty), the
    capsules' nearest depth less their widest radius, that radius (dpad), the farthest corner's
    distance and the near limit."""
    origin: np.ndarray
    u: np.ndarray
    v: np.ndarray
    w: np.ndarray
    depth: np.ndarray
    tx: np.ndarray
    ty: np.ndarray
    nearest: float
    dpad: float
    far: float
    near_limit: float

    def spread(self, extent):
        """How far a ray toward a point within `extent` of the origin drifts, at most, from its
        origin's direction, times that point's depth over its own (module text): extent times
        the most of the way s toward the light it has gone at the hair's nearest depth, from an
        origin no deeper than the hair's farthest (one deeper starts, for the lists, where its
        ray comes back to that depth)."""
        near, far = float(self.depth.min()), float(self.depth.max())
        if not extent > 0.0:
            return 0.0
        return float(extent) * min(1.0, (far - near) / max(far - float(extent), 1e-30))

    def slant(self, past):
        """sqrt(1 + |x|²) at the farthest corner of the box's projection widened by `past`."""
        return float(np.sqrt(1.0 + (np.abs(self.tx).max() + past) ** 2 + (np.abs(self.ty).max() + past) ** 2))

    def tangents(self, points):
        """(tx, ty, depth) of (N,3) points."""
        q = np.asarray(points, np.float64) - self.origin
        z = q @ self.w
        return (q @ self.u) / z, (q @ self.v) / z, z


def light_view(position, extent, scene_lo, scene_hi, rmax, pad):
    """The LightView of light_frame; BeamsUnfit as there."""
    c = np.asarray(position, np.float64)
    lo, hi = np.asarray(scene_lo, np.float64), np.asarray(scene_hi, np.float64)
    to_centre = 0.5 * (lo + hi) - c
    length = float(np.linalg.norm(to_centre))
    if not length > 0.0:
        raise BeamsUnfit("the light lies at the hair's centre")
    u, v, w = sun_basis(to_centre / length)
    q = box_corners(lo, hi) - c
    depth = q @ w
    dpad = float(rmax) * float(pad)
    near_limit = layout.BEAM_NEAR_FRACTION * max(float(np.ptp(depth)), float(rmax))
    nearest = float(depth.min()) - dpad
    if nearest - float(extent) <= near_limit:
        raise BeamsUnfit("the hair reaches the light's plane")
    return LightView(c, u, v, w, depth, (q @ u) / depth, (q @ v) / depth, nearest, dpad,
                     float(np.max(np.linalg.norm(q, axis=1))), near_limit)


def frame_reach(frame, scene_lo, scene_hi, rmax, pad):
    """The largest listing radius (bins) of any capsule of a scene within scene_lo..scene_hi
    whose widest radius is `rmax`, widened `pad` times, in `frame`: what bins_touched widens
    a capsule's projected axis by (tracer/beams.py's rule; a perspective camera's at the
    scene box's nearest depth, which bounds every capsule's), so a ray of the family meets a
    cylinder only where its point lies within this of the cylinder's projected axis."""
    r = float(rmax) * float(pad) * frame.radius_scale
    if frame.kind == "persp":
        depth = (box_corners(scene_lo, scene_hi) - frame.origin) @ frame.axes[2]
        if frame.spread > 0.0:
            r = (float(rmax) * float(pad) + frame.spread) * frame.radius_scale / (float(depth.min()) - rmax * pad)
        else:
            r /= float(depth.min())
    return r + frame.drift + layout.BEAM_BIN_EPS


# --- listing -----------------------------------------------------------------------------
def project(frame, points):
    """(gx, gy, z) float64 of (N,3) points in `frame`."""
    q = np.asarray(points, np.float64) - frame.origin
    X, Y, Z = (q @ frame.axes[i] for i in range(3))
    if frame.kind == "persp":
        return X / Z + frame.offset[0], Y / Z + frame.offset[1], Z
    return X + frame.offset[0], Y + frame.offset[1], Z


def segment_distance(c, a, b):
    """Distance from point c (3,) to the segments a..b (N,3 each)."""
    ab = b - a
    ac = c - a
    s = np.clip(np.einsum("ij,ij->i", ac, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300), 0.0, 1.0)
    q = a + s[:, None] * ab - c
    return np.sqrt(np.einsum("ij,ij->i", q, q))


def _keys_and_radii(frame, top, far, z0, z1, r):
    """(key, rho in bins, ok) per capsule top..far of radius r (z0, z1: its ends' depths): its
    key (module text), how far its projection reaches, and False where it reaches the
    camera's plane (perspective)."""
    if frame.kind == "sun":
        rho = r * frame.radius_scale + frame.drift + layout.BEAM_BIN_EPS
        return -(np.maximum(z0, z1) + r), rho, np.ones(len(r), bool)
    near = np.minimum(z0, z1)
    if frame.kind == "ortho":
        return near - r, r * frame.radius_scale + frame.drift + layout.BEAM_BIN_EPS, np.ones(len(r), bool)
    ok = near - r > frame.near_limit
    key = segment_distance(frame.origin, np.asarray(top, np.float64), np.asarray(far, np.float64)) - r
    if frame.spread > 0.0:      # a light's rays drift from their origin's direction (light_frame)
        rho = (r + drift_at(frame.extent, frame.far_depth, frame.spread, near - r)) * frame.radius_scale / np.where(
            ok, near - r, 1.0)
    else:
        rho = r * frame.radius_scale / np.where(ok, near, 1.0)
    return key, rho + frame.drift + layout.BEAM_BIN_EPS, ok


def slice_of(frame, key, sub=0):
    """Each key's fine slice (2^sub a slice): the last whose start lies at or below it."""
    k = np.floor(((key - frame.key0) / frame.key_step - layout.BEAM_SLICE_EPS) * (1 << sub))
    return np.clip(k, 0, (layout.BEAM_SLICES << sub) - 1).astype(np.int64)


def bins_touched(frame, top, far, radius, sub=0):
    """(cylinder, bin id) for every bin the capsules top..far of `radius` may project into,
    and each cylinder's fine slice (slice_of, `sub` bits). BeamsUnfit when one reaches the
    camera's plane (perspective) or spans more than layout.BEAM_MAX_BINS_PER_CYLINDER bins."""
    nx, ny = (int(d) for d in frame.dims)
    gx0, gy0, z0 = project(frame, top)
    gx1, gy1, z1 = project(frame, far)
    r = np.asarray(radius, np.float64)
    key, rho, ok = _keys_and_radii(frame, top, far, z0, z1, r)
    behind = ~ok & (np.maximum(z0, z1) + r < 0)     # wholly behind the camera: never seen
    if np.any(~ok & ~behind):
        raise BeamsUnfit("the hair reaches the camera's plane")
    if frame.cone is not None:
        ok &= ~outside_cone(frame.cone, frame.origin, frame.extent, top, far, r)
    live = np.flatnonzero(ok)
    # The dominant axis of each projected segment, then (dominant, other) coordinates.
    dx, dy = gx1 - gx0, gy1 - gy0
    xdom = np.abs(dx) >= np.abs(dy)
    A0 = np.where(xdom, gx0, gy0)[live]
    dA = np.where(xdom, dx, dy)[live]
    B0 = np.where(xdom, gy0, gx0)[live]
    dB = np.where(xdom, dy, dx)[live]
    NA = np.where(xdom, nx, ny)[live]
    NB = np.where(xdom, ny, nx)[live]
    SA = np.where(xdom, 1, nx)[live]
    SB = np.where(xdom, nx, 1)[live]
    P = rho[live]
    if frame.centres:       # the columns whose centre line A = col + 1/2 the capsule's shadow meets
        a_lo = np.ceil(np.minimum(A0, A0 + dA) - P - 0.5)
        a_hi = np.floor(np.maximum(A0, A0 + dA) + P - 0.5)
    else:
        a_lo = np.floor(np.minimum(A0, A0 + dA) - P)
        a_hi = np.floor(np.maximum(A0, A0 + dA) + P)
    i0 = np.clip(a_lo, 0, NA - 1).astype(np.int64)
    i1 = np.clip(a_hi, 0, NA - 1).astype(np.int64)
    seen = (a_hi >= 0) & (a_lo <= NA - 1) & (a_lo <= a_hi)
    ncol = np.where(seen, i1 - i0 + 1, 0)
    # The bound the compute passes check before they loop (the same rule in both builds).
    bound = ncol * np.minimum(np.abs(dB) + 2 * P + 2, NB)
    if len(bound) and bound.max() > layout.BEAM_MAX_BINS_PER_CYLINDER:
        raise BeamsUnfit(f"a cylinder's projection spans up to {int(bound.max())} bins")
    total = int(ncol.sum())
    owner = np.repeat(np.arange(len(live)), ncol)
    col = np.arange(total) - np.repeat(np.cumsum(ncol) - ncol, ncol) + i0[owner]
    if frame.centres:       # the rows whose centre lies within rho of the projected axis
        lo, hi = centre_span(col + 0.5, A0[owner], dA[owner], B0[owner], dB[owner], P[owner])
        b_lo = np.ceil(lo - 0.5)
        b_hi = np.floor(hi - 0.5)
    else:
        # The part of the segment (s in [0, 1]) within rho of the column; a segment too short
        # to have a direction is taken whole.
        flat = np.abs(dA[owner]) < 1e-12
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / np.where(flat, 1.0, dA[owner])
            sa = (col - P[owner] - A0[owner]) * inv
            sb = (col + 1 + P[owner] - A0[owner]) * inv
        s0 = np.where(flat, 0.0, np.clip(np.minimum(sa, sb), 0.0, 1.0))
        s1 = np.where(flat, 1.0, np.clip(np.maximum(sa, sb), 0.0, 1.0))
        e0 = B0[owner] + s0 * dB[owner]
        e1 = B0[owner] + s1 * dB[owner]
        b_lo = np.floor(np.minimum(e0, e1) - P[owner])
        b_hi = np.floor(np.maximum(e0, e1) + P[owner])
    nb = NB[owner]
    j0 = np.clip(b_lo, 0, nb - 1).astype(np.int64)
    j1 = np.clip(b_hi, 0, nb - 1).astype(np.int64)
    rows = np.where((b_hi >= 0) & (b_lo <= nb - 1) & (b_lo <= b_hi), j1 - j0 + 1, 0)
    owner2 = np.repeat(np.arange(total), rows)
    row = np.arange(len(owner2)) - np.repeat(np.cumsum(rows) - rows, rows) + j0[owner2]
    c = owner[owner2]
    bins = col[owner2] * SA[c] + row * SB[c]
    cyl = live[c]
    return cyl, bins, slice_of(frame, key, sub)


def centre_span(a, A0, dA, B0, dB, P):
    """(lo, hi): where the line A = a (a column's centre line) crosses the points within P of
    the segment (A0, B0) + s·(dA, dB), s in [0, 1] (lo > hi: it does not). Those points are the
    discs of radius P about the two ends and the band along the segment whose points' feet lie
    on it; their union is convex, so its crossing is one interval, the hull of the three
    parts' (beams_build.glsl, centre_span, the same steps)."""
    lo = np.full(np.shape(a), np.inf)
    hi = np.full(np.shape(a), -np.inf)
    for end_a, end_b in ((A0, B0), (A0 + dA, B0 + dB)):
        da = a - end_a
        h2 = P * P - da * da
        h = np.sqrt(np.maximum(h2, 0.0))
        lo = np.where(h2 >= 0.0, np.minimum(lo, end_b - h), lo)
        hi = np.where(h2 >= 0.0, np.maximum(hi, end_b + h), hi)
    # The band: |B - mid| <= P·L/|dA| (its distance from the axis' line), and the foot's
    # t = da·dA + (B - B0)·dB within [0, L²]. A segment too short to have a direction has none.
    flat = np.abs(dA) < 1e-12
    da = a - A0
    sdA = np.where(flat, 1.0, dA)
    L2 = dA * dA + dB * dB
    mid = B0 + da / sdA * dB
    half = P * np.sqrt(L2) / np.abs(sdA)
    t0 = da * dA
    level = dB == 0.0
    sdB = np.where(level, 1.0, dB)
    f0 = B0 - t0 / sdB
    f1 = B0 + (L2 - t0) / sdB
    on = (t0 >= 0.0) & (t0 <= L2)
    foot_lo = np.where(level, np.where(on, -np.inf, np.inf), np.minimum(f0, f1))
    foot_hi = np.where(level, np.where(on, np.inf, -np.inf), np.maximum(f0, f1))
    band_lo = np.maximum(mid - half, foot_lo)
    band_hi = np.minimum(mid + half, foot_hi)
    band = ~flat & (band_lo <= band_hi)
    return np.where(band, np.minimum(lo, band_lo), lo), np.where(band, np.maximum(hi, band_hi), hi)


def fine_bits(sizes, refs):
    """The bits of fine slices a family's lists get (module text): `sizes` counts its listed
    cylinders by fine slice at the most bits the ids leave (layout.BEAM_SLICES << top of them),
    `refs` its references. The most bits for which the fine slices that hold a cylinder number
    no more than one per layout.BEAM_REFS_PER_FILL references: finer order shortens the walks,
    but the compute passes fill each fine slice in a dispatch of its own."""
    sizes = np.asarray(sizes)
    top = (len(sizes) // layout.BEAM_SLICES).bit_length() - 1
    for sub in range(top, 0, -1):
        filled = np.count_nonzero(sizes.reshape(-1, 1 << (top - sub)).sum(axis=1))
        if filled * layout.BEAM_REFS_PER_FILL <= refs:
            return sub
    return 0


def fill_plan(sizes, refs, n, bins, marks=False):
    """How the compute passes fill a family's lists, and the bits of their fine slices:
    (sorted, sub). `sizes` counts the listed cylinders by fine slice at the most bits (as for
    fine_bits), `refs` the lists' references, `n` the scene's cylinders, `bins` the frame's,
    `marks` whether the entries come with marks (two uint32 an entry, tracer/gpu_beams.py).
    Sorted (the cylinders in id order, then each bin's entries sorted; layout.py) where most
    cylinders are listed in at most BEAM_SORT_REFS_PER_CYLINDER references each
    (BEAM_SORT_REFS_PER_MARKED with marks), with the most bits (up to
    BEAM_SORT_SUB_BITS_MAX) whose fine slices number no more than BEAM_SORT_SLICES_PER_ENTRY
    times the entries of a bin on average; else a fine slice a dispatch, fine_bits' bits.
    Measured on llvmpipe: 100,000 wavy strands' coarse sun lists (3.7 references a listed
    cylinder) took 0.87-1.0 s against 1.06-1.22 without marks; their fine lists and the
    camera's of 1-pixel bins (7.5 and 6.9) took 1.9-2.1 and 1.7-1.9 s sorted against 1.8-1.9
    and 1.6-1.75. With marks, whose sort moves twice the bytes, the coarse lists took 1.9 s
    sorted against 1.5, and 10,000 strands' 176 ms against 159 (docs/DECISIONS.md)."""
    sizes = np.asarray(sizes)
    top = (len(sizes) // layout.BEAM_SLICES).bit_length() - 1
    listed = int(sizes.sum())
    per = layout.BEAM_SORT_REFS_PER_MARKED if marks else layout.BEAM_SORT_REFS_PER_CYLINDER
    if listed and 2 * listed >= n and refs <= per * listed:
        sub = 0
        while (sub < min(top, layout.BEAM_SORT_SUB_BITS_MAX)
               and (layout.BEAM_SLICES << (sub + 1)) * max(bins, 1) <= layout.BEAM_SORT_SLICES_PER_ENTRY * refs):
            sub += 1
        return True, sub
    return False, fine_bits(sizes, refs)


def capsule_far(c):
    """(N,3) float64: the far end of each capsule's axis of tracer.cylinders.Cylinders `c`,
    its tip moved on along the axis by its extension (shaders/capsule.glsl, capsule_far)."""
    axis = c.tip.astype(np.float64) - c.top
    length = np.sqrt(np.einsum("ij,ij->i", axis, axis))
    return c.tip + axis * (c.extension / np.maximum(length, 1e-30))[:, None]


def build_beams(frame, cylinders, pad_factor=1.0, max_refs=None):
    """Beams of `frame` over tracer.cylinders.Cylinders (capsules widened `pad_factor` times).
    BeamsUnfit past `max_refs` references (default: one buffer texture's worth,
    layout.BEAM_MAX_REFS) or where bins_touched says so."""
    n = len(cylinders)
    if n >= 1 << layout.BEAM_ID_BITS:
        raise BeamsUnfit(f"{n} cylinders: more than a beam entry's id holds")
    top = layout.beam_sub_bits(n)
    max_refs = layout.BEAM_MAX_REFS if max_refs is None else max_refs
    found = []
    sizes = np.zeros(layout.BEAM_SLICES << top, np.int64)
    refs = 0
    for a in range(0, n, CHUNK):
        c = cylinders.select(slice(a, min(n, a + CHUNK)))
        cyl, bins, slc = bins_touched(frame, c.top, capsule_far(c), c.radius.astype(np.float64) * pad_factor, top)
        refs += len(cyl)
        if refs > max_refs:
            raise TooManyRefs(f"more than {max_refs:,} references")
        sizes += np.bincount(slc[np.unique(cyl)], minlength=len(sizes))
        found.append((cyl + a, bins, slc[cyl]))
    _, sub = fill_plan(sizes, refs, n, frame.num_bins)
    id_bits = layout.BEAM_ID_BITS - sub
    keys = [(bins << 32) | ids | ((slc >> (top - sub)) << id_bits) for ids, bins, slc in found]
    key = np.sort(np.concatenate(keys)) if keys else np.zeros(0, np.int64)
    count = np.bincount(key >> 32, minlength=frame.num_bins).astype(np.int32)
    start = (np.cumsum(count, dtype=np.int64) - count).astype(np.int32)
    return Beams(frame, len(key), sub, start, count, (key & 0xFFFFFFFF).astype(np.uint32),
                 longest=int(count.max(initial=0)))

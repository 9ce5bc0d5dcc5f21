# SPDX-License-Identifier: GPL-3.0-or-later
"""Pinhole and orthographic cameras, defined so a Blender camera maps onto them exactly.

A camera is a rigid frame (position and rotation, camera-to-world; it looks down its local
-Z with +Y up, as Blender's cameras do) plus an image plane measured in pixels:

    u = (x - W/2 + shift_px[0]) * pixel_size        x: 0..W from the left edge
    v = (H - y - H/2 + shift_px[1]) * pixel_size    y: 0..H from the top edge

PERSP: the ray leaves the position along R·(u, v, -1) (the image plane at distance 1).
ORTHO: the ray leaves R·(u, v, 0) + position along R·(0, 0, -1).

Blender (BKE_camera_params_compute_viewplane) fits the sensor to one image dimension: AUTO
picks the larger one (width when W >= H) and always uses sensor_width; HORIZONTAL fits
sensor_width to W; VERTICAL fits sensor_height to H. With F the fitted dimension in pixels:

    pixel_size = (sensor / lens) / F        PERSP (sensor and lens both in mm)
    pixel_size = ortho_scale / F            ORTHO
    shift_px   = (shift_x * F, shift_y * F)

so a shift of 1 moves the view by one whole fitted dimension (the larger one under AUTO).
Pixel aspect is 1. Scale in matrix_world is removed (only its rotation and translation count).

A window (`Camera.window`, the tiles of a large render) sees pixels [x0, x0+w) x [y0, y0+h)
of a larger image: the same pixel size, the shift moved so its pixels are that image's, and
`pixel_origin` = (x0, y0) in that image. The tracers place a pixel's samples by its
coordinates in the whole image (pixel_origin + its own) and the sample index, so a window's
pixels are the whole image's, samples and all.

A pass (`Camera.for_pass`, the progressive preview's passes) moves every sample of the image by
one sub-pixel offset of the R2 sequence, so passes averaged together are new samples of each
pixel's area, not the same ones again.
"""
from dataclasses import dataclass

import numpy as np

from hairio import InputError

# The R2 sequence's steps (1/g, 1/g^2 for the plastic number g): the best-spread 2-D
# low-discrepancy sequence for any number of points (Roberts 2018).
_R2 = (0.7548776662466927, 0.5698402909980532)


def pass_offset(k):
    """Sub-pixel offset (x right, y down; each in [-0.5, 0.5)) of sample pass k: 0 for the
    first pass, then the R2 sequence, so any number of passes covers the pixel evenly."""
    if k == 0:
        return 0.0, 0.0
    return tuple(float((0.5 + k * a) % 1.0 - 0.5) for a in _R2)


@dataclass(frozen=True, eq=False)
class Camera:
    type: str                 # "PERSP" or "ORTHO"
    position: np.ndarray      # (3,) float64
    rotation: np.ndarray      # (3,3) float64, columns = camera x (right), y (up), z (backward)
    size: tuple               # (W, H) pixels
    pixel_size: float         # image-plane units per pixel (at distance 1 for PERSP)
    shift_px: np.ndarray      # (2,) pixels
    pixel_origin: tuple = (0, 0)   # (x0, y0): this image's pixel (0, 0) in the whole image

    def __post_init__(self):
        if self.type not in ("PERSP", "ORTHO"):
            raise InputError(f"camera type: {self.type!r}; use 'PERSP' or 'ORTHO'")
        w, h = self.size
        if int(w) < 1 or int(h) < 1:
            raise InputError(f"camera size: {self.size}; width and height must be >= 1")
        if not (np.isfinite(self.pixel_size) and self.pixel_size > 0):
            raise InputError(f"camera: pixel size {self.pixel_size} must be finite and > 0 "
                             "(check lens, sensor and ortho_scale)")
        ox, oy = self.pixel_origin
        if int(ox) != ox or int(oy) != oy or ox < 0 or oy < 0:
            raise InputError(f"camera pixel_origin: {self.pixel_origin}; expected two whole numbers >= 0")

    @property
    def width(self):
        return int(self.size[0])

    @property
    def height(self):
        return int(self.size[1])

    @property
    def forward(self):
        return -self.rotation[:, 2]

    @property
    def centre_px(self):
        """The optical axis (u = v = 0) in the whole image's pixel coordinates, x from the
        left, y from the top: the same for a camera and all its windows, so the tracer
        computes u, v from a pixel's whole-image coordinates the same way in each."""
        w, h = self.size
        return (self.pixel_origin[0] + w / 2 - float(self.shift_px[0]),
                self.pixel_origin[1] + h / 2 + float(self.shift_px[1]))

    # --- constructors -------------------------------------------------------------------
    @classmethod
    def look_at(cls, eye, target, up=(0, 0, 1), fov_deg=40.0, size=(512, 512), type="PERSP",
                ortho_scale=1.0):
        """Camera at `eye` looking at `target`; `fov_deg` spans the larger image dimension
        (PERSP), `ortho_scale` the larger dimension in scene units (ORTHO)."""
        eye = np.asarray(eye, np.float64)
        fwd = np.asarray(target, np.float64) - eye
        if not np.all(np.isfinite(fwd)) or np.linalg.norm(fwd) == 0:
            raise InputError("camera: eye and target must be finite and distinct")
        fwd /= np.linalg.norm(fwd)
        right = np.cross(fwd, np.asarray(up, np.float64))
        if np.linalg.norm(right) < 1e-9:     # looking along `up`: any right vector will do
            right = np.cross(fwd, [1.0, 0, 0] if abs(fwd[0]) < 0.9 else [0, 1.0, 0])
        right /= np.linalg.norm(right)
        cam_up = np.cross(right, fwd)
        rot = np.stack([right, cam_up, -fwd], axis=1)
        big = max(size)
        if type == "PERSP":
            if not 0 < fov_deg < 180:
                raise InputError(f"camera: fov {fov_deg}° must lie in (0, 180)")
            pix = 2 * np.tan(np.radians(fov_deg) / 2) / big
        else:
            pix = float(ortho_scale) / big
        return cls(type, eye, rot, (int(size[0]), int(size[1])), float(pix), np.zeros(2))

    @classmethod
    def frame_bounds(cls, lo, hi, size=(512, 512), direction=(0.0, 1.0, 0.0), up=(0, 0, 1),
                     fov_deg=40.0):
        """Perspective camera that sees the whole box: it looks along `direction` (default +Y,
        i.e. from Blender's front) at the box centre, far enough that the bounding sphere fits
        the smaller image dimension."""
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        centre = 0.5 * (lo + hi)
        radius = max(0.5 * float(np.linalg.norm(hi - lo)), 1e-6)
        half_small = np.arctan(np.tan(np.radians(fov_deg) / 2) * min(size) / max(size))
        dist = 1.05 * radius / np.sin(half_small)
        d = np.asarray(direction, np.float64)
        d /= np.linalg.norm(d)
        return cls.look_at(centre - d * dist, centre, up=up, fov_deg=fov_deg, size=size)

    @classmethod
    def from_blender(cls, matrix_world, size, type="PERSP", lens=50.0, sensor_width=36.0,
                     sensor_height=24.0, sensor_fit="AUTO", shift_x=0.0, shift_y=0.0,
                     ortho_scale=1.0):
        """The projection of a Blender camera (see the module docstring for the maths)."""
        m = np.asarray(matrix_world, np.float64)
        if m.shape != (4, 4) or not np.all(np.isfinite(m)):
            raise InputError("camera matrix_world: expected a finite 4x4 matrix")
        rot = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0)
        w, h = int(size[0]), int(size[1])
        if sensor_fit not in ("AUTO", "HORIZONTAL", "VERTICAL"):
            raise InputError(f"camera sensor_fit: {sensor_fit!r}; use AUTO, HORIZONTAL or VERTICAL")
        horizontal = (w >= h) if sensor_fit == "AUTO" else sensor_fit == "HORIZONTAL"
        fitted = w if horizontal else h
        if type == "PERSP":
            sensor = sensor_height if sensor_fit == "VERTICAL" else sensor_width
            if lens <= 0 or sensor <= 0:
                raise InputError(f"camera: lens {lens} and sensor {sensor} must be > 0")
            pix = (sensor / lens) / fitted
        elif type == "ORTHO":
            pix = float(ortho_scale) / fitted
        else:
            raise InputError(f"camera type: {type!r}; only PERSP and ORTHO are supported (not PANO)")
        shift = np.array([shift_x * fitted, shift_y * fitted], np.float64)
        return cls(type, m[:3, 3].copy(), rot, (w, h), float(pix), shift)

    def moved(self, position=None, rotation=None):
        """The same lens at a new place (re-render tests and benchmarks)."""
        return Camera(self.type, self.position if position is None else np.asarray(position, np.float64),
                      self.rotation if rotation is None else np.asarray(rotation, np.float64),
                      self.size, self.pixel_size, self.shift_px, self.pixel_origin)

    def window(self, x0, y0, w, h):
        """The camera that sees exactly pixels [x0, x0+w) x [y0, y0+h) of this camera's
        image, with the samples those pixels have in it (see the module docstring)."""
        W, H = self.size
        x0, y0, w, h = (int(v) for v in (x0, y0, w, h))
        if not (0 <= x0 and 0 <= y0 and w >= 1 and h >= 1 and x0 + w <= W and y0 + h <= H):
            raise InputError(f"camera window {w}x{h} at ({x0}, {y0}): it must lie inside the {W}x{H} image")
        shift = np.asarray(self.shift_px, np.float64) + [x0 + w / 2 - W / 2, H / 2 - h / 2 - y0]
        origin = (int(self.pixel_origin[0]) + x0, int(self.pixel_origin[1]) + y0)
        return Camera(self.type, self.position, self.rotation, (w, h), self.pixel_size, shift, origin)

    def for_pass(self, k, spp_n):
        """The camera of sample pass k (pass_offset) for n x n stratified samples: the samples
        move by the offset over one stratum (1/n of a pixel), so every sample stays near its
        own stratum and the passes' mean keeps the pixel's footprint (shifted by whole pixels
        it would blur). Pass 0 is this camera."""
        if k == 0:
            return self
        ox, oy = (c / spp_n for c in pass_offset(k))
        # shift_px moves the image centre: x as the samples' x, y up (the samples' y runs down).
        shift = np.asarray(self.shift_px, np.float64) + (ox, -oy)
        return Camera(self.type, self.position, self.rotation, self.size, self.pixel_size, shift, self.pixel_origin)

    # --- rays and projection ------------------------------------------------------------
    def rays(self, x, y):
        """Rays through continuous pixel coordinates x (from the left), y (from the top);
        float64 origins and unit directions, shapes x.shape + (3,)."""
        x = np.asarray(x, np.float64)
        y = np.asarray(y, np.float64)
        w, h = self.size
        u = (x - w / 2 + self.shift_px[0]) * self.pixel_size
        v = (h / 2 - y + self.shift_px[1]) * self.pixel_size
        r = self.rotation
        if self.type == "PERSP":
            d = u[..., None] * r[:, 0] + v[..., None] * r[:, 1] - r[:, 2]
            d /= np.linalg.norm(d, axis=-1, keepdims=True)
            o = np.broadcast_to(self.position, d.shape).copy()
        else:
            o = self.position + u[..., None] * r[:, 0] + v[..., None] * r[:, 1]
            d = np.broadcast_to(-r[:, 2], o.shape).copy()
        return o, d

    def project(self, points):
        """World points (N,3) -> pixel x, y (from the top-left) and depth along the view
        (> 0 in front of the camera)."""
        p = (np.asarray(points, np.float64) - self.position) @ self.rotation
        depth = -p[:, 2]
        w, h = self.size
        if self.type == "PERSP":
            with np.errstate(divide="ignore", invalid="ignore"):
                u, v = p[:, 0] / depth, p[:, 1] / depth
        else:
            u, v = p[:, 0], p[:, 1]
        x = u / self.pixel_size + w / 2 - self.shift_px[0]
        y = h / 2 - (v / self.pixel_size - self.shift_px[1])
        return x, y, depth

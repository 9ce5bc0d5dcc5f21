# SPDX-License-Identifier: GPL-3.0-or-later
"""Every general parameter of the model in one settings object (SPEC §2–6).

Validated on construction, so a bad value is reported where it enters, naming the
parameter; `to_dict`/`from_dict` round-trip through JSON (presets) and reject unknown keys.
"""
import dataclasses
from dataclasses import dataclass, field

import numpy as np

from hairio import InputError

from .sampling import SAMPLING_MODES

NEIGHBOUR_MODES = ("key", "root", "interpolate")
RESOLUTION_MODES = ("adaptive", "fixed")
TOLERANCE_UNITS = ("scene", "radius")
RADIUS_MODES = ("linear", "constant", "taper_from")
NORMAL_MODES = ("interpolated", "face")


@dataclass
class GroomParams:
    """General parameters. Lengths are in scene units (metres), angles in radians.

    count            number of ordinary strands (roots)
    seed             one seed for everything random
    sampling_mode    'uniform' (default, square-root warp) or 'seed' (the thesis's biased formula)
    normal_mode      'interpolated' (default) or 'face' (the thesis)
    up, front        the central line's direction and the face's direction (root frames)
    min_length, max_length   strands are trimmed at an arc-length fraction uniform in [min, max]
    tidiness         1 = every strand keeps its key's orientation; 0 = angles up to theta_max
    theta_max        largest random rotation about each root axis at tidiness 0
    n_influence      N in [0, 100]: 0/1 ≈ follow the main key, 100 = plain inverse distance
    neighbour_mode   'interpolate' (default: Blender's Interpolate Curves weighting, sharpened
                     by n_influence; no seam at wisp borders, the smoothest by measurement,
                     see measure.py), 'root' (thesis reading (b): 2nd and 3rd nearest keys to
                     the strand's root) or 'key' (reading (a): the two keys nearest the main
                     key's root)
    intelligence     True: each strand carries its key's shape into its own root frame
    resolution_mode  'adaptive' (fewest points within `tolerance`) or 'fixed'
    points_per_strand  points of every strand in 'fixed' mode, the most in 'adaptive'
                     (the thesis's 25 cylinders = 26 points)
    tolerance, tolerance_units   adaptive error bound, in scene units or in root radii
    radius, radius_mode, taper_start   root radius when a key has none; 'linear' r(1 - s),
                     'constant', or 'taper_from' (constant up to fraction taper_start)
    color, color_variation, color_variation_point   base RGB when a key has none; each channel
                     + U(-1,1)·variation per strand and + U(-1,1)·variation_point per point
    alpha_start, alpha_tip   alpha 1 up to fraction alpha_start, then linear to alpha_tip
    parting          None or {'point': (3,), 'normal': (3,)[, 'end': (3,)]}: roots on the
                     normal's side are group 1, the others group 0 (used when the scalp has no
                     groups); with 'end', only roots in front of it (toward `front`) are parted,
                     so a side parting can stop at the crown instead of running down the back
    clump, clump_shape   wisps: each strand is pulled toward its wisp's key by clump·σ^clump_shape
                     of the way (σ the fraction of the key's length: 0 at the root, loose, up to
                     clump at the tip, tight); clump 0 = no pull
    frizz            each strand wanders off its path by up to this (scene units) toward the tip,
                     a smooth per-strand random wave of 2-4 periods along its length
    curl, curl_period    each strand winds around its path in a helix of radius up to `curl`
                     (growing from the root) with one turn per `curl_period` of length
    collision        move strands out of the collider given to generate (none given: nothing
                     to collide with); key strands inside it are reported, never moved
    collision_margin every strand point ends at least its radius plus this outside the collider
    """
    count: int = 10000
    seed: int = 0
    sampling_mode: str = "uniform"
    normal_mode: str = "interpolated"
    up: tuple = (0.0, 0.0, 1.0)
    front: tuple = (0.0, -1.0, 0.0)
    min_length: float = 0.85
    max_length: float = 1.0
    tidiness: float = 0.9
    theta_max: float = 0.5
    n_influence: float = 50.0
    neighbour_mode: str = "interpolate"
    intelligence: bool = True
    resolution_mode: str = "adaptive"
    points_per_strand: int = 32
    tolerance: float = 3e-4
    tolerance_units: str = "scene"
    radius: float = 5e-5
    radius_mode: str = "linear"
    taper_start: float = 0.7
    color: tuple = (0.28, 0.17, 0.09)
    color_variation: tuple = (0.04, 0.03, 0.02)
    color_variation_point: tuple = (0.0, 0.0, 0.0)
    alpha_start: float = 1.0
    alpha_tip: float = 1.0
    parting: dict = field(default=None)
    clump: float = 0.0
    clump_shape: float = 1.0
    frizz: float = 0.0
    curl: float = 0.0
    curl_period: float = 0.02
    collision: bool = True
    collision_margin: float = 2e-4

    def __post_init__(self):
        self.count = _int("count", self.count, 1)
        self.seed = _int("seed", self.seed, 0)
        self.points_per_strand = _int("points_per_strand", self.points_per_strand, 2)
        _choice("sampling_mode", self.sampling_mode, SAMPLING_MODES)
        _choice("normal_mode", self.normal_mode, NORMAL_MODES)
        _choice("neighbour_mode", self.neighbour_mode, NEIGHBOUR_MODES)
        _choice("resolution_mode", self.resolution_mode, RESOLUTION_MODES)
        _choice("tolerance_units", self.tolerance_units, TOLERANCE_UNITS)
        _choice("radius_mode", self.radius_mode, RADIUS_MODES)
        self.up = _vec("up", self.up, nonzero=True)
        self.front = _vec("front", self.front, nonzero=True)
        self.min_length = _float("min_length", self.min_length, 0.0, 1.0, low_open=True)
        self.max_length = _float("max_length", self.max_length, 0.0, 1.0, low_open=True)
        if self.min_length > self.max_length:
            raise InputError(f"min_length: {self.min_length} exceeds max_length {self.max_length}")
        self.tidiness = _float("tidiness", self.tidiness, 0.0, 1.0)
        self.theta_max = _float("theta_max", self.theta_max, 0.0, np.pi)
        self.n_influence = _float("n_influence", self.n_influence, 0.0, 100.0)
        for name in ("intelligence", "collision"):
            value = getattr(self, name)
            if not isinstance(value, (bool, np.bool_)):
                raise InputError(f"{name}: expected true or false, got {value!r}")
            setattr(self, name, bool(value))
        self.clump = _float("clump", self.clump, 0.0, 1.0)
        self.clump_shape = _float("clump_shape", self.clump_shape, 0.0, 8.0, low_open=True)
        self.frizz = _float("frizz", self.frizz, 0.0, np.inf)
        self.curl = _float("curl", self.curl, 0.0, np.inf)
        self.curl_period = _float("curl_period", self.curl_period, 0.0, np.inf, low_open=True)
        self.collision_margin = _float("collision_margin", self.collision_margin, 0.0, np.inf)
        self.tolerance = _float("tolerance", self.tolerance, 0.0, np.inf, low_open=True)
        self.radius = _float("radius", self.radius, 0.0, np.inf)
        self.taper_start = _float("taper_start", self.taper_start, 0.0, 1.0)
        self.color = _vec("color", self.color, lo=0.0, hi=1.0)
        self.color_variation = _vec("color_variation", self.color_variation, lo=0.0, hi=1.0)
        self.color_variation_point = _vec("color_variation_point", self.color_variation_point, lo=0.0, hi=1.0)
        self.alpha_start = _float("alpha_start", self.alpha_start, 0.0, 1.0)
        self.alpha_tip = _float("alpha_tip", self.alpha_tip, 0.0, 1.0)
        if self.parting is not None:
            if (not isinstance(self.parting, dict) or not {"point", "normal"} <= set(self.parting)
                    or not set(self.parting) <= {"point", "normal", "end"}):
                raise InputError("parting: expected null or {'point': [x, y, z], 'normal': [x, y, z]} with an "
                                 "optional 'end': [x, y, z]")
            parting = {"point": _vec("parting point", self.parting["point"]),
                       "normal": _vec("parting normal", self.parting["normal"], nonzero=True)}
            if "end" in self.parting:
                parting["end"] = _vec("parting end", self.parting["end"])
            self.parting = parting

    def to_dict(self):
        d = dataclasses.asdict(self)
        for k, v in d.items():
            if isinstance(v, tuple):
                d[k] = list(v)
        if self.parting is not None:
            d["parting"] = {k: list(v) for k, v in self.parting.items()}
        return d

    @classmethod
    def from_dict(cls, data):
        if not isinstance(data, dict):
            raise InputError(f"parameters: expected a mapping, got {type(data).__name__}")
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise InputError(f"parameters: unknown name(s) {unknown}; known names are {sorted(known)}")
        return cls(**data)

    def replace(self, **changes):
        return dataclasses.replace(self, **changes)


def _int(name, v, lo):
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
        if isinstance(v, float) and v.is_integer():
            v = int(v)
        else:
            raise InputError(f"{name}: expected an integer, got {v!r}")
    if v < lo:
        raise InputError(f"{name}: must be >= {lo}, got {v}")
    return int(v)


def _float(name, v, lo, hi, low_open=False):
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise InputError(f"{name}: expected a number, got {v!r}")
    v = float(v)
    if not np.isfinite(v):
        raise InputError(f"{name}: must be finite, got {v}")
    if v < lo or v > hi or (low_open and v == lo):
        bracket = "(" if low_open else "["
        raise InputError(f"{name}: must lie in {bracket}{lo}, {hi}], got {v}")
    return v


def _choice(name, v, options):
    if v not in options:
        raise InputError(f"{name}: expected one of {options}, got {v!r}")


def _vec(name, v, lo=-np.inf, hi=np.inf, nonzero=False):
    try:
        a = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise InputError(f"{name}: expected 3 numbers, got {v!r}") from e
    if a.shape != (3,):
        raise InputError(f"{name}: expected 3 numbers, got {v!r}")
    if not np.isfinite(a).all():
        raise InputError(f"{name}: NaN/Inf in {v!r}")
    if (a < lo).any() or (a > hi).any():
        raise InputError(f"{name}: values must lie in [{lo}, {hi}], got {v!r}")
    if nonzero and not np.linalg.norm(a) > 0:
        raise InputError(f"{name}: must not be the zero vector")
    return tuple(float(x) for x in a)

# SPDX-License-Identifier: GPL-3.0-or-later
"""Hairstyles as data: key-strand profiles + parameters in `presets/*.json`.

A preset file:

    {"name": "wavy", "description": "...",
     "params": {... GroomParams names ...},
     "keys": [{"anchor": {"point": [x, y, z]}        # nearest scalp point to this
                        | {"direction": [x, y, z]},  # outermost scalp point seen from the
                                                     # scalp's centre in this direction
               "frame": "root" | "world",            # profile axes: root frame (x down the head,
                                                     # y across, z out) or world axes
               "profile": [[x, y, z], ...],          # control points, row 0 the root
               "angles": [ax, ay, az],               # radians about the root axes ("root" only)
               "kind": "bezier" | "cubic", "color": null | [r, g, b],
               "root_radius": null | r, "group": 0}, ...]}

`Preset.keys_on(scalp)` places the keys on any scalp mesh, so one preset grooms the bundled
head and a user's mesh alike.
"""
import json
import os
import pathlib

import numpy as np

from hairio import InputError, atomic_write

from .frames import root_frames
from .keys import KeyStrand, place_key
from .params import GroomParams

def _preset_dir():
    """$KEYSTRAND_PRESETS, else the repository's presets/, else the copy installed inside groom."""
    if "KEYSTRAND_PRESETS" in os.environ:
        return pathlib.Path(os.environ["KEYSTRAND_PRESETS"])
    here = pathlib.Path(__file__).resolve().parent
    in_repo = here.parent / "presets"
    return in_repo if in_repo.is_dir() else here / "_presets"


PRESET_DIR = _preset_dir()
_KEY_FIELDS = {"anchor", "frame", "profile", "angles", "kind", "color", "root_radius", "group"}


def list_presets():
    """Names of the bundled presets, sorted."""
    if not PRESET_DIR.is_dir():
        return []
    return sorted(p.stem for p in PRESET_DIR.glob("*.json"))


class Preset:
    """name, description, params (GroomParams) and key specs; `keys_on(scalp)` -> [KeyStrand]."""

    def __init__(self, name, params, key_specs, description=""):
        self.name, self.params, self.description = name, params, description
        if not key_specs:
            raise InputError(f"preset {name!r}: no keys; a preset needs at least one key strand")
        self.key_specs = [_check_spec(name, i, s) for i, s in enumerate(key_specs)]

    def keys_on(self, scalp):
        """Key strands placed on `scalp`: each anchor goes to the nearest (or the outermost,
        for a direction) surface point, and root-frame profiles use that point's frame."""
        specs = self.key_specs
        queries = np.array([_anchor_query(scalp, s["anchor"]) for s in specs])
        tri, bary, roots = scalp.closest_points(queries)
        normals = scalp.normals_at(tri, bary, self.params.normal_mode)
        frames = root_frames(normals, self.params.up, self.params.front)
        keys = []
        for s, root, frame in zip(specs, roots, frames):  # a few keys, not strands
            prof = np.asarray(s["profile"], dtype=np.float64)
            if s["frame"] == "root":
                pts = place_key(prof, root, frame, s["angles"])
            else:
                pts = root + (prof - prof[0])
            keys.append(KeyStrand(pts, s["kind"], s["color"], s["root_radius"], s["group"]))
        return keys

    def to_dict(self):
        return {"name": self.name, "description": self.description, "params": self.params.to_dict(),
                "keys": self.key_specs}


def _check_spec(name, i, spec):
    where = f"preset {name!r} key {i}"
    if not isinstance(spec, dict):
        raise InputError(f"{where}: expected an object")
    unknown = sorted(set(spec) - _KEY_FIELDS)
    if unknown:
        raise InputError(f"{where}: unknown field(s) {unknown}; known: {sorted(_KEY_FIELDS)}")
    anchor = spec.get("anchor")
    if not isinstance(anchor, dict) or len(anchor) != 1 or next(iter(anchor)) not in ("point", "direction"):
        raise InputError(f"{where}: anchor must be {{'point': [x, y, z]}} or {{'direction': [x, y, z]}}")
    kind, value = next(iter(anchor.items()))
    try:
        value = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        value = np.full(1, np.nan)
    if value.shape != (3,) or not np.isfinite(value).all() or (kind == "direction" and not value.any()):
        rule = ", not all zero" if kind == "direction" else ""
        raise InputError(f"{where}: anchor {kind} must be 3 finite numbers{rule}")
    frame = spec.get("frame", "root")
    if frame not in ("root", "world"):
        raise InputError(f"{where}: frame must be 'root' or 'world', got {frame!r}")
    out = {"anchor": {kind: value.tolist()}, "frame": frame,
           "profile": spec.get("profile"), "angles": spec.get("angles", [0.0, 0.0, 0.0]),
           "kind": spec.get("kind", "bezier"), "color": spec.get("color"),
           "root_radius": spec.get("root_radius"), "group": spec.get("group", 0)}
    try:
        angles = np.asarray(out["angles"], dtype=np.float64)
        if angles.shape != (3,) or not np.isfinite(angles).all():
            raise ValueError
        out["angles"] = angles.tolist()
    except (TypeError, ValueError):
        raise InputError(f"{where}: angles must be 3 finite numbers (radians)") from None
    # Validate the profile as a key strand (shape, NaN, kind rules) at the origin.
    try:
        KeyStrand(np.asarray(out["profile"], dtype=np.float64), out["kind"], out["color"], out["root_radius"],
                  out["group"])
    except (TypeError, ValueError) as e:
        raise InputError(f"{where}: {e}") from None
    return out


def _anchor_query(scalp, anchor):
    if "point" in anchor:
        return np.asarray(anchor["point"], dtype=np.float64)
    d = np.asarray(anchor["direction"], dtype=np.float64)
    d = d / np.linalg.norm(d)
    lo, hi = scalp.vertices.min(axis=0), scalp.vertices.max(axis=0)
    centre = 0.5 * (lo + hi)
    hit = _outermost_hit(scalp, centre, d)
    if hit is None:
        return centre + d * float(np.linalg.norm(hi - lo))
    return hit


def _outermost_hit(scalp, origin, direction):
    """Farthest intersection of the ray with the scalp (Möller–Trumbore over all triangles)."""
    v = scalp.vertices[scalp.triangles]
    e1, e2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    p = np.cross(direction, e2)
    det = np.einsum("td,td->t", e1, p)
    ok = np.abs(det) > 1e-300
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = origin - v[:, 0]
    u = np.einsum("td,td->t", s, p) * inv
    q = np.cross(s, e1)
    w = (q @ direction) * inv
    t = np.einsum("td,td->t", e2, q) * inv
    hit = ok & (u >= 0) & (w >= 0) & (u + w <= 1) & (t > 0)
    if not hit.any():
        return None
    return origin + direction * t[hit].max()


def _preset_path(name):
    p = pathlib.Path(name)
    if p.suffix == ".json" and p.is_file():
        return p
    available = list_presets()
    if name not in available:
        raise InputError(f"preset {name!r}: unknown; available presets are {', '.join(available) or '(none)'} "
                         f"(or give a path to a .json preset file)")
    return PRESET_DIR / f"{name}.json"


def load_preset(name):
    """A bundled preset by name, or a preset .json file by path."""
    path = _preset_path(str(name))
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as e:
        raise InputError(f"preset {str(path)!r}: cannot read it as JSON ({e})") from e
    if not isinstance(data, dict) or "keys" not in data:
        raise InputError(f"preset {str(path)!r}: expected an object with 'keys' and 'params'")
    unknown = sorted(set(data) - {"name", "description", "params", "keys"})
    if unknown:
        raise InputError(f"preset {str(path)!r}: unknown field(s) {unknown}")
    try:
        params = GroomParams.from_dict(data.get("params", {}))
    except InputError as e:
        raise InputError(f"preset {str(path)!r}: {e}") from None
    return Preset(data.get("name", path.stem), params, data["keys"], data.get("description", ""))


def save_preset(path, keys, params, name=None, description=""):
    """Write keys (absolute KeyStrands, stored as world-frame profiles anchored at their roots)
    and params as a preset file, atomically."""
    specs = []
    for k in keys:
        specs.append({"anchor": {"point": k.root.tolist()}, "frame": "world",
                      "profile": (k.points - k.root).tolist(), "kind": k.kind,
                      "color": None if k.color is None else k.color.tolist(),
                      "root_radius": k.root_radius, "group": k.group})
    name = name or pathlib.Path(path).stem
    preset = Preset(name, params, specs, description)
    text = json.dumps(preset.to_dict(), indent=1)
    with atomic_write(path, "w") as f:
        f.write(text + "\n")
    return preset

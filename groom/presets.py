# SPDX-License-Identifier: GPL-3.0-or-later
"""Hairstyles as data: key-strand profiles + parameters in `presets/*.json`.

A preset file:

    {"name": "wavy", "description": "...",
     "params": {... GroomParams names ...},
     "keys": [{"anchor": {"point": [x, y, z]}        # nearest scalp point to this
                        | {"direction": [x, y, z]},  # outermost scalp point seen from the
                                                     # head's centre in this direction
               "frame": "root" | "world",            # profile axes: root frame (x down the head,
                                                     # y across, z out) or world axes
               "profile": [[x, y, z], ...],          # control points, row 0 the root
               "angles": [ax, ay, az],               # radians about the root axes ("root" only)
               "kind": "bezier" | "cubic", "color": null | [r, g, b],
               "root_radius": null | r, "group": 0}, ...]}

Anchors and "world" profiles are in the bundled head's space (groom.default_scalp: metres,
Z up, -Y front). `Preset.place_keys(scalp, up, front)` carries them onto any scalp mesh
through a head frame fitted to it (head.py), so one preset grooms the bundled head and a
user's mesh alike, and says which keys could not find a root of their own.
"""
import json
import os
import pathlib

import numpy as np

from hairio import InputError, atomic_write

from .frames import root_frames
from .head import CANONICAL_FRONT, CANONICAL_UP, fit_head_frame
from .keys import KeyStrand, place_key
from .params import GroomParams

# Keys whose roots land closer than this fraction of the head's size (2 mm on the bundled
# head; bundled presets space their anchors 1.2 cm and more apart) share a root.
COLLAPSE_FRACTION = 0.02
# A key's anchor this far from its root (a fraction of the head's size) is off the scalp
# even away from an edge: the mesh is not head-shaped there (measured: 5 mm at most, 4.5 %,
# on the real cap and head of the test data).
_OFF_SURFACE_FRACTION = 0.15
# Outside these bounds of the bundled head's size the head is likely in other units.
_PLAUSIBLE_SCALE = (1.0 / 3.0, 3.0)

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
    """name, description, params (GroomParams) and key specs; `place_keys(scalp)` ->
    Placement, `keys_on(scalp)` -> [KeyStrand]."""

    def __init__(self, name, params, key_specs, description=""):
        self.name, self.params, self.description = name, params, description
        if not isinstance(key_specs, (list, tuple)):
            raise InputError(f"preset {name!r}: 'keys' must be a list of key objects, got {type(key_specs).__name__}")
        if not key_specs:
            raise InputError(f"preset {name!r}: no keys; a preset needs at least one key strand")
        self.key_specs = [_check_spec(name, i, s) for i, s in enumerate(key_specs)]

    def place_keys(self, scalp, up=None, front=None, collider=None):
        """Place the key strands on `scalp` (a groom.Scalp): a Placement.

        up, front: the head's axes in the scalp's own space (None: the preset parameters'
        up and front, those of the bundled head). A head frame is fitted to the scalp
        (head.fit_head_frame) and every anchor goes through it: a point anchor to the
        matching place on this head, then to the nearest scalp point; a direction anchor
        from the fitted centre along the mapped direction, to the outermost scalp point
        there. "root" profiles are drawn in each root's frame (normal, down the head),
        "world" profiles turn with the head.

        Profiles keep their lengths in metres, on a big head or a small one: a length is
        the hairstyle's (a 30 cm bob is 30 cm on any adult, whose heads differ by some
        10 %), and so are the parameters' radius and tolerance, which scaling the keys alone
        would make too thin or too coarse for the hair. A head in other units shows up as a
        size far from the bundled one, which Placement.warning reports.

        collider: the head the hair stays out of (collide.as_collider), or None. The keys
        were drawn on the bundled head; a real scalp can lie under its head's surface (the
        USC scalp does, by up to 7 mm), which puts the keys drawn along it inside the head.
        Those keys are moved out of it as generation moves hair (collide.resolve_strands on
        the key's path, then a cubic spline through the result) and listed in
        Placement.lifted, so the preset's own keys raise no "key inside the head" warning."""
        p = self.params
        up = p.up if up is None else up
        front = p.front if front is None else front
        frame = fit_head_frame(scalp, up, front)
        queries, missed = [], []
        for i, s in enumerate(self.key_specs):  # a few keys, not strands
            kind, value = next(iter(s["anchor"].items()))
            if kind == "point":
                queries.append(frame.to_scalp(value))
                continue
            d = frame.direction_to_scalp(value)
            hit = _outermost_hit(scalp, frame.centre, d)
            if hit is None:  # the scalp does not cover that direction: come as close as it lets
                missed.append(i)
                hit = frame.centre + d * float(np.linalg.norm(np.ptp(scalp.vertices, axis=0)))
            queries.append(hit)
        queries = np.array(queries)
        tri, bary, roots = scalp.closest_points(queries)
        normals = scalp.normals_at(tri, bary, p.normal_mode)
        # The raw up and front, as generate() uses them, so keys and hair share their frames.
        frames = root_frames(normals, up, front)
        turn = frame.rotation
        keys = []
        for s, root, root_frame in zip(self.key_specs, roots, frames):
            prof = np.asarray(s["profile"], dtype=np.float64)
            if s["frame"] == "root":
                pts = place_key(prof, root, root_frame, s["angles"])
            else:
                pts = root + (prof - prof[0]) @ turn.T
            keys.append(KeyStrand(pts, s["kind"], s["color"], s["root_radius"], s["group"]))
        off = np.linalg.norm(roots - queries, axis=1) / frame.size
        edge = _on_boundary(scalp, tri, bary)
        far = (edge & (off > COLLAPSE_FRACTION)) | (off > _OFF_SURFACE_FRACTION)
        off_scalp = sorted(set(missed) | set(np.flatnonzero(far).tolist()))
        params = p.replace(up=tuple(up), front=tuple(front))
        if p.parting is not None:
            parting = {"point": tuple(frame.to_scalp(p.parting["point"])),
                       "normal": tuple(frame.normal_to_scalp(p.parting["normal"]))}
            if "end" in p.parting:
                parting["end"] = tuple(frame.to_scalp(p.parting["end"]))
            params = params.replace(parting=parting)
        lifted = () if collider is None else _lift_out(keys, collider, params)
        return Placement(self.name, keys, frame, params, _collapsed(roots, COLLAPSE_FRACTION * frame.size),
                         tuple(off_scalp), lifted)

    def keys_on(self, scalp, up=None, front=None, collider=None):
        """The key strands of place_keys(scalp, up, front, collider), [KeyStrand]."""
        return self.place_keys(scalp, up, front, collider).keys

    def to_dict(self):
        return {"name": self.name, "description": self.description, "params": self.params.to_dict(),
                "keys": self.key_specs}


class Placement:
    """A preset's keys placed on one scalp (Preset.place_keys).

    keys         [KeyStrand], in the preset's order
    frame        the HeadFrame fitted to the scalp
    params       the preset's GroomParams for this scalp: its up and front, and the parting
                 plane carried onto this head (grow the hair with these)
    collapsed    [(i, j, ...)]: groups of key indices whose roots landed on the same place
                 (closer than COLLAPSE_FRACTION of the head's size); empty when every key
                 has its own root
    off_scalp    (i, ...): keys whose anchor the scalp does not reach (beyond its edge, far
                 from its surface, or in a direction it does not cover), placed on the
                 nearest scalp point instead
    lifted       (i, ...): keys moved out of the collider given to place_keys
    """

    def __init__(self, preset_name, keys, frame, params, collapsed, off_scalp, lifted=()):
        self.preset_name, self.keys, self.frame, self.params = preset_name, keys, frame, params
        self.collapsed, self.off_scalp, self.lifted = collapsed, off_scalp, tuple(lifted)

    def warning(self):
        """A few sentences for an artist when the placement is doubtful, else None."""
        parts = []
        if self.collapsed:
            groups = [_listing(g) for g in self.collapsed]
            roots = len(self.keys) - sum(len(g) - 1 for g in self.collapsed)
            parts.append(f"{len(self.keys)} keys on {roots} roots: keys {groups[0]} share a root"
                         + "".join(f", so do {g}" for g in groups[1:]))
        if self.off_scalp:
            parts.append(f"keys {_listing(self.off_scalp)} have their anchors off the scalp (beyond its edge or "
                         "far from its surface: the preset grows hair there, this scalp does not reach) and sit "
                         "on its nearest point")
        if parts:
            f = self.frame
            parts.append(f"if the scalp is upside down or faces another way, set its up and front (now up "
                         f"{_vector(f.up)}, front {_vector(f.front)}, in the scalp's own space); otherwise "
                         "extend the scalp or move these keys")
        lo, hi = _PLAUSIBLE_SCALE
        if not lo <= self.frame.scale <= hi:
            parts.append(f"this head is {self.frame.scale:.3g} times the size of the bundled one, and preset "
                         "lengths are in metres: check the mesh's units (or its object's scale)")
        if not parts:
            return None
        return f"preset {self.preset_name!r}: " + "; ".join(parts) + "."


def _listing(indices):
    """'3', '3 and 4', '3, 4 and 5' (0-based, as the key objects are numbered)."""
    names = [str(i) for i in indices]
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def _vector(v):
    return "(" + ", ".join(f"{x:.3g}" for x in np.where(np.abs(v) < 5e-4, 0.0, v)) + ")"


# Points along a key when it is moved out of the collider (its spline passes through them:
# more make the spline follow the walk's turns and ask the adaptive resolution for more
# cylinders, measured: 25 keep wavy on the USC head at the points it has without collision).
_LIFT_SAMPLES = 25
_LIFT_CLEARANCE = 0.01


def _lift_out(keys, collider, params):
    """Keys (in place in the list) that pass through the collider, moved out of it: the
    indices of those moved."""
    from .collide import as_collider, keys_inside, resolve_strands, with_clearance
    from .keys import arc_length_tables
    radii = np.array([params.radius if k.root_radius is None else k.root_radius for k in keys])
    collider = with_clearance(as_collider(collider), float(radii.max()) + params.collision_margin)
    found = keys_inside(collider, arc_length_tables(keys, 257), np.array([k.root for k in keys]), radii)
    # Clear of the head by a hundredth of its size (2 mm on a head): the spline between the
    # points it passes through must not dip back in.
    margin = params.collision_margin + _LIFT_CLEARANCE * collider.size
    for hit in found:
        k = keys[hit.key]
        path = k.resample(_LIFT_SAMPLES)
        out, _, _ = resolve_strands(collider, path, np.array([len(path)]), np.full(len(path), radii[hit.key]),
                                    margin, threads=1, dtype=np.float64)
        keys[hit.key] = KeyStrand(_spline_through(out), "cubic", k.color, k.root_radius, k.group)
    return tuple(h.key for h in found)


def _spline_through(points):
    """Piecewise cubic control rows [P0, H0out, H1in, P1, ...] through the points, handles
    from their neighbours (Catmull-Rom), so the curve passes through every point."""
    ext = np.vstack([2 * points[0] - points[1], points, 2 * points[-1] - points[-2]])
    rows = [points[0]]
    for i in range(len(points) - 1):  # a few dozen points of one key
        a, b, c, d = ext[i], ext[i + 1], ext[i + 2], ext[i + 3]
        rows += [b + (c - a) / 6.0, c - (d - b) / 6.0, c]
    return np.array(rows)


def _collapsed(roots, distance):
    """Groups (sorted tuples, sorted) of indices of roots within `distance` of another root
    of the group, chained (single linkage); singletons left out."""
    n = len(roots)
    d = np.linalg.norm(roots[:, None] - roots[None], axis=-1)
    group = list(range(n))

    def top(i):
        while group[i] != i:
            i = group[i]
        return i

    for i, j in zip(*np.nonzero(np.triu(d < distance, 1))):
        group[top(j)] = top(i)
    members = {}
    for i in range(n):
        members.setdefault(top(i), []).append(i)
    return sorted(tuple(m) for m in members.values() if len(m) > 1)


def _on_boundary(scalp, tri, bary):
    """Per surface point: does it lie on an open edge of the mesh (or an open edge's vertex)?"""
    t = scalp.triangles
    edges = np.sort(np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]]), axis=1)
    unique, count = np.unique(edges, axis=0, return_counts=True)
    open_edges = {tuple(e) for e in unique[count == 1].tolist()}
    open_vertices = {v for e in open_edges for v in e}
    out = []
    for ti, b in zip(tri, bary):  # a few keys
        corners = sorted(int(v) for v, w in zip(t[ti], b) if w > 1e-9)
        if len(corners) == 1:
            out.append(corners[0] in open_vertices)
        else:
            out.append(len(corners) == 2 and tuple(corners) in open_edges)
    return np.array(out, bool)


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
    except (OSError, ValueError, RecursionError) as e:     # RecursionError: JSON nested past Python's stack
        raise InputError(f"preset {str(path)!r}: cannot read it as JSON ({e})") from None
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


def save_preset(path, keys, params, name=None, description="", scalp=None):
    """Write keys (absolute KeyStrands, stored as world-frame profiles anchored at their roots)
    and params as a preset file, atomically.

    scalp: the groom.Scalp the keys sit on (its up and front those of params). Given, the
    anchors, profiles, up, front and parting go into the bundled head's space through the
    scalp's head frame, so the preset lands the same way on this head and on any other;
    without it they are taken to be in the bundled head's space already."""
    if scalp is not None:
        frame = fit_head_frame(scalp, params.up, params.front)
        turn = frame.rotation  # v @ turn: a scalp-space vector in canonical axes, same length
        canonical = []
        for k in keys:
            root = frame.to_canonical(k.root)
            canonical.append(KeyStrand(np.vstack([root, root + (k.points[1:] - k.root) @ turn]), k.kind,
                                       k.color, k.root_radius, k.group))
        keys = canonical
        parting = params.parting
        if parting is not None:
            mapped = {"point": tuple(frame.to_canonical(parting["point"])),
                      "normal": tuple(frame.normal_to_canonical(parting["normal"]))}
            if "end" in parting:
                mapped["end"] = tuple(frame.to_canonical(parting["end"]))
            parting = mapped
        params = params.replace(up=CANONICAL_UP, front=CANONICAL_FRONT, parting=parting)
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

# SPDX-License-Identifier: GPL-3.0-or-later
"""The groom Unreal Engine imports, computed from our arrays: one layout that the Alembic
writer (formats/alembic.py) and the USD writer (formats/usd.py) both write, and that both
readers turn back into Strands.

Names, scopes and types as Epic's "Alembic for Grooms" specification gives them (schema 1.5):

    groom_version_major / _minor   int16, on the topmost object          1 / 5
    groom_tool, groom_properties   string, on the topmost object         who wrote it; our axis and scale
    width                          per vertex (the curves' own widths)   2 * radius
    groom_color                    per vertex float32[3]                 base colour
    groom_guide                    per curve int32                       1 = guide (simulation) curve
    groom_id                       per curve int32                       unique over guides and strands
    groom_group_id                 per curve int32                       hair group (the key's parting group)
    groom_group_name               per curve string
    groom_root_uv                  per curve float32[2]                  the root's UV on the scalp
    groom_closest_guides           per curve int32[3]                    groom_id of the 3 guides driving it
    groom_guide_weights            per curve float32[3]                  their weights

Unreal maps groom_closest_guides through the guides' groom_id, within the strand's group, so
the key strands are the guide curves with groom_id = key index and the strands follow with
groom_id = K + strand index; our wisps never choose a key of another group. `alpha` and `wisp`
are ours (no groom_ prefix, so Unreal's importers pass over them) and make the file a lossless
copy of the arrays.

`groom_attributes` is the older per-curve form for Blender's own exporters (the fallback inside
a Blender without alembic3d): Blender has no constant domain and no int3 type on Curves, so
there the version numbers are per-curve ints and closest guides / weights float3 per curve.
"""
import json
from dataclasses import dataclass, field

import numpy as np

from .strands import Guides, Strands
from .validate import InputError, check_finite, check_shape

GROOM_VERSION = (1, 5)
GUIDES_NAME, STRANDS_NAME = "guides", "strands"


@dataclass
class GroomCurves:
    """One curves object of a groom file: points (N,3) f32 in the file's frame, counts (C,)
    i32, widths (N,) f32, and attributes {name: (scope, kind, array)} with scope 'vertex' or
    'uniform' (per curve) and kind one of 'int', 'float', 'float2', 'float3', 'int3', 'string'."""
    name: str
    points: np.ndarray
    counts: np.ndarray
    widths: np.ndarray
    attributes: dict = field(default_factory=dict)


def group_name(group_id):
    return f"group_{int(group_id)}"


def groom_layout(strands):
    """[GroomCurves] for `strands` (already in the file's frame and units): the guide curves
    first when the strands carry guides, then the strands. Attribute names as in the module
    docstring."""
    if not isinstance(strands, Strands):
        raise InputError(f"strands: expected hairio.Strands, got {type(strands).__name__}")
    n_s = strands.num_strands
    g = strands.guides
    n_k = 0 if g is None else g.keys.num_strands
    out = []
    if g is not None:
        k = g.keys
        out.append(GroomCurves(GUIDES_NAME, k.points, k.counts, 2 * k.radius, {
            "groom_color": ("vertex", "float3", k.color),
            "groom_guide": ("uniform", "int", np.ones(n_k, np.int32)),
            "groom_id": ("uniform", "int", np.arange(n_k, dtype=np.int32)),
            "groom_group_id": ("uniform", "int", g.group),
            "groom_group_name": ("uniform", "string", [group_name(x) for x in g.group]),
        }))
    attrs = {
        "groom_color": ("vertex", "float3", strands.color),
        "alpha": ("vertex", "float", strands.alpha),
        "wisp": ("uniform", "int", strands.wisp),
        "groom_id": ("uniform", "int", np.arange(n_k, n_k + n_s, dtype=np.int32)),
    }
    if g is not None:
        group = g.group[g.index[:, 0]]
        names = {int(x): group_name(x) for x in np.unique(group)}
        attrs.update({
            "groom_guide": ("uniform", "int", np.zeros(n_s, np.int32)),
            "groom_group_id": ("uniform", "int", group),
            "groom_group_name": ("uniform", "string", [names[int(x)] for x in group]),
            "groom_closest_guides": ("uniform", "int3", g.index),
            "groom_guide_weights": ("uniform", "float3", g.weights),
        })
    if strands.root_uv is not None:
        attrs["groom_root_uv"] = ("uniform", "float2", strands.root_uv)
    out.append(GroomCurves(STRANDS_NAME, strands.points, strands.counts, 2 * strands.radius, attrs))
    return out


def groom_properties(axis, scale):
    """groom_properties: the tool's options as JSON, so our reader can undo them exactly."""
    return json.dumps({"axis": axis, "scale": float(scale)})


def parse_groom_properties(text):
    """(axis, scale) from a groom_properties string we wrote, else None."""
    try:
        d = json.loads(text)
        return str(d["axis"]), float(d["scale"])
    except (ValueError, TypeError, KeyError):
        return None


def strands_from_groom(curves, source):
    """Strands from the GroomCurves a reader found (points already in our frame and metres,
    widths likewise): curves flagged groom_guide = 1 become the key strands, the others the
    strands, in file order. Guides and weights are kept when every closest guide names a
    guide's groom_id; `source` names the file in errors."""
    if not curves:
        raise InputError(f"{source}: no curves in this file; export the hair as curves")
    strand_parts, guide_parts = [], []
    for c in curves:
        flag = c.attributes.get("groom_guide")
        if flag is None:
            strand_parts.append(c)
            continue
        is_guide = np.asarray(flag[2]).reshape(-1) == 1
        if is_guide.size == 1:
            is_guide = np.full(len(c.counts), bool(is_guide[0]))
        if is_guide.size != len(c.counts):
            raise InputError(f"{source}: {c.name}: groom_guide has {is_guide.size} values for "
                             f"{len(c.counts)} curves; re-export it")
        if is_guide.all():
            guide_parts.append(c)
        elif not is_guide.any():
            strand_parts.append(c)
        else:
            guide_parts.append(_subset(c, is_guide))
            strand_parts.append(_subset(c, ~is_guide))
    if not strand_parts:
        strand_parts, guide_parts = guide_parts, []
    s = _joined(strand_parts, source)
    guides = None
    keys = _joined(guide_parts, source) if guide_parts else None
    if keys is not None:
        guides = _guides_of(strand_parts, guide_parts, keys, source)
    wisp = s["wisp"]
    if wisp is None:
        wisp = guides.index[:, 0] if guides is not None else None
    return Strands.from_arrays(s["points"], s["counts"], s["radius"], s["color"], s["alpha"], wisp,
                               guides=guides, root_uv=s["root_uv"])


def _subset(c, keep):
    point_keep = np.repeat(keep, c.counts)
    attrs = {}
    for name, (scope, kind, a) in c.attributes.items():
        a = np.asarray(a)
        if len(a) == len(c.counts):
            attrs[name] = (scope, kind, a[keep])
        elif len(a) == len(c.points):
            attrs[name] = (scope, kind, a[point_keep])
    return GroomCurves(c.name, c.points[point_keep], c.counts[keep], c.widths[point_keep], attrs)


def _values(c, name, per, source):
    """The attribute `name` of curves `c` with one row per curve (per='uniform') or per point
    ('vertex'), a constant broadcast; None when absent or of another length."""
    if name not in c.attributes:
        return None
    a = np.asarray(c.attributes[name][2])
    n = len(c.counts) if per == "uniform" else len(c.points)
    if len(a) == n:
        return a
    if len(a) == 1:
        return np.repeat(a, n, axis=0)
    if per == "vertex" and len(a) == len(c.counts):
        return np.repeat(a, c.counts, axis=0)
    raise InputError(f"{source}: {c.name}: {name} has {len(a)} values for {len(c.counts)} curves and "
                     f"{len(c.points)} points; re-export it")


def _joined(parts, source):
    out = {"points": np.concatenate([c.points for c in parts]),
           "counts": np.concatenate([c.counts for c in parts]),
           "radius": np.concatenate([c.widths for c in parts]) / 2}
    for key, name, per in (("color", "groom_color", "vertex"), ("alpha", "alpha", "vertex"),
                           ("wisp", "wisp", "uniform"), ("root_uv", "groom_root_uv", "uniform")):
        vals = [_values(c, name, per, source) for c in parts]
        out[key] = None if any(v is None for v in vals) else np.concatenate(vals)
    if out["alpha"] is not None:
        out["alpha"] = np.clip(out["alpha"], 0, 1)
    return out


def _guides_of(strand_parts, guide_parts, keys, source):
    closest = [_values(c, "groom_closest_guides", "uniform", source) for c in strand_parts]
    weights = [_values(c, "groom_guide_weights", "uniform", source) for c in strand_parts]
    ids = [_values(c, "groom_id", "uniform", source) for c in guide_parts]
    if any(v is None for v in closest + weights + ids):
        return None
    closest = np.concatenate(closest).astype(np.float64)
    guide_ids = np.concatenate(ids).astype(np.int64)
    order = np.argsort(guide_ids, kind="stable")
    pos = np.searchsorted(guide_ids[order], closest)
    pos = np.minimum(pos, len(order) - 1)
    if not (guide_ids[order][pos] == closest).all():
        return None     # closest guides that name no guide here: Unreal would not use them either
    group = [_values(c, "groom_group_id", "uniform", source) for c in guide_parts]
    group = None if any(v is None for v in group) else np.concatenate(group)
    return Guides.from_arrays(Strands.from_arrays(keys["points"], keys["counts"], keys["radius"], keys["color"]),
                              order[pos], np.concatenate(weights), group)


def groom_attributes(strands, root_uv=None, group_id=None, guide=None, closest_guides=None,
                     guide_weights=None):
    """{name: (domain, blender data type, array)} for a Curves datablock holding `strands`.

    Absent inputs are left out, except groom_version_* and groom_color (always known)."""
    if not isinstance(strands, Strands):
        raise InputError(f"strands: expected hairio.Strands, got {type(strands).__name__}")
    n_s = strands.num_strands
    out = {
        "groom_version_major": ("CURVE", "INT", np.full(n_s, GROOM_VERSION[0], np.int32)),
        "groom_version_minor": ("CURVE", "INT", np.full(n_s, GROOM_VERSION[1], np.int32)),
        "groom_color": ("POINT", "FLOAT_VECTOR", np.ascontiguousarray(strands.color, np.float32)),
    }
    if root_uv is not None:
        uv = check_finite("root_uv", check_shape("root_uv", np.asarray(root_uv), (n_s, 2)))
        out["groom_root_uv"] = ("CURVE", "FLOAT2", uv.astype(np.float32))
    if group_id is not None:
        g = check_shape("group_id", np.asarray(group_id), (n_s,))
        out["groom_group_id"] = ("CURVE", "INT", g.astype(np.int32))
    if guide is not None:
        g = check_shape("guide", np.asarray(guide), (n_s,))
        out["groom_guide"] = ("CURVE", "INT", g.astype(np.int32))
    if closest_guides is not None:
        c = check_shape("closest_guides", np.asarray(closest_guides), (n_s, 3))
        out["groom_closest_guides"] = ("CURVE", "FLOAT_VECTOR", c.astype(np.float32))
    if guide_weights is not None:
        w = check_finite("guide_weights", check_shape("guide_weights", np.asarray(guide_weights), (n_s, 3)))
        out["groom_guide_weights"] = ("CURVE", "FLOAT_VECTOR", w.astype(np.float32))
    return out

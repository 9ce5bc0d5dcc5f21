# SPDX-License-Identifier: GPL-3.0-or-later
"""The per-strand attributes Unreal Engine's groom importer reads, computed from our arrays.

Unreal reads a groom from Alembic curves (and USD BasisCurves) and looks for these optional
attributes (names as Unreal's groom Alembic specification gives them):

    groom_version_major / _minor   constant int      which attribute scheme the file follows
    groom_guide                    per curve int      1 = guide (simulation) curve, 0 = render
    groom_group_id                 per curve int      hair group (separate material/LOD)
    groom_root_uv                  per curve float2   the root's UV on the scalp
    groom_color                    per point float3   base color
    groom_closest_guides           per curve int[3]   indices of the 3 guides that drive it
    groom_guide_weights            per curve float[3] their weights (our wisp weights)

Blender's Alembic exporter writes positions, the curve counts and `width` only, and no Alembic
library installs from the package index here, so an .abc from us has none of them (see
`addon/export_blender.py` for the workaround). Blender's USD exporter writes every generic
Curves attribute as a primvar of the same name, so `groom_attributes` are carried into .usd
files. Blender has no constant (detail) domain and no int3 type on Curves, so the version
numbers become per-curve ints and closest guides / weights become float3 per curve; where
Unreal insists on its exact types, it regenerates guides and weights itself on import.
"""
import numpy as np

from .strands import Strands
from .validate import InputError, check_finite, check_shape

GROOM_VERSION = (1, 0)


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

# SPDX-License-Identifier: GPL-3.0-or-later
"""What the hair object's material tells the preview's "chiang" shading (the model of
Cycles' Principled Hair BSDF, tracer/shading/chiang.py), so the preview shows what Cycles
will: the node's sliders as RenderSettings.hair_* fields.

Read from the first material's first Principled Hair BSDF node, its unlinked sockets only (a
linked slider varies per strand, which the preview does not follow: its setting keeps the
tracer's default). Parametrization "Direct Coloring" is hair_color "strand" (the add-on's own
material feeds the strands' colour attribute to Color); "Melanin concentration" is
hair_color "melanin" with the node's Melanin and Melanin Redness (the strands' colour then
acts as the Tint); "Absorption coefficient" has no counterpart and is read as Direct
Coloring.
"""

# RenderSettings field <- the node's socket name
SLIDERS = (("hair_roughness", "Roughness"), ("hair_radial_roughness", "Radial Roughness"),
           ("hair_coat", "Coat"), ("hair_ior", "IOR"))
MELANIN = (("hair_melanin", "Melanin"), ("hair_melanin_redness", "Melanin Redness"))


def principled_hair_node(obj):
    """The first Principled Hair BSDF node of `obj`'s first material, or None."""
    data = getattr(obj, "data", None)
    materials = getattr(data, "materials", None) or ()
    mat = next((m for m in materials if m is not None), None)
    tree = getattr(mat, "node_tree", None)
    if tree is None:
        return None
    return next((n for n in tree.nodes if n.bl_idname == "ShaderNodeBsdfHairPrincipled"), None)


def _unlinked(node, name):
    socket = node.inputs.get(name)
    if socket is None or socket.is_linked or not getattr(socket, "enabled", True):
        return None
    return float(socket.default_value)


def principled_hair_settings(obj):
    """RenderSettings keyword arguments (hair_*) from `obj`'s Principled Hair BSDF; {} when
    it has none."""
    import math
    node = principled_hair_node(obj)
    if node is None:
        return {}
    out = {"hair_color": "melanin" if node.parametrization == 'MELANIN' else "strand"}
    sliders = SLIDERS + (MELANIN if out["hair_color"] == "melanin" else ())
    for field, name in sliders:
        value = _unlinked(node, name)
        if value is not None:
            out[field] = value
    if "hair_ior" in out:      # the node takes any IOR; the model is defined for 1..3
        out["hair_ior"] = min(max(out["hair_ior"], 1.0), 3.0)
    offset = _unlinked(node, "Offset")          # radians in the node, degrees in the settings
    if offset is not None:
        out["hair_cuticle_tilt"] = math.degrees(offset)
    return out

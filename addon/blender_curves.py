# SPDX-License-Identifier: GPL-3.0-or-later
"""hairio.Strands <-> Blender's native hair Curves object, with bulk array transfers only.

The Curves datablock stores exactly the SPEC §0 layout (points + per-strand counts), so the
conversion is a handful of `foreach_set`/`foreach_get` calls over whole arrays and never a
Python loop over strands or points. Attributes written:

    position     POINT  FLOAT_VECTOR  strand points (the object's local space)
    radius       POINT  FLOAT         Blender's built-in hair radius (Cycles, EEVEE read it)
    strand_rgba  POINT  FLOAT_COLOR   linear RGB, alpha in A (COLOR_ATTRIBUTE; not "color",
                                      which Cycles renders black, see below)
    alpha        POINT  FLOAT         the strand opacity profile on its own, for shader nodes
    wisp         CURVE  INT           index of the key strand whose wisp the strand belongs to

Curve type is POLY: the strands are polylines (the tracer's cylinders), so Blender's
evaluated curve, its exporters and the tracer all see the same points.
"""
import numpy as np
import bpy

from hairio import Strands

# The strand colour is not stored as "color": Cycles maps an Attribute node whose name is
# one of its standard names to that standard attribute, and "color" is the standard volume
# colour (like "density", "temperature", ...), which hair never has, so the node reads zero
# and the hair renders black. EEVEE reads either name; this one reaches both engines.
COLOR_ATTRIBUTE = "strand_rgba"
# The name the colour had before; read when no COLOR_ATTRIBUTE is present, and dropped on refill.
LEGACY_COLOR_ATTRIBUTE = "color"

ATTRIBUTES = ("position", "radius", COLOR_ATTRIBUTE, "alpha", "wisp")


def _attribute(curves, name, data_type, domain):
    """The attribute `name`, created (or re-created with the right type) when needed."""
    attr = curves.attributes.get(name)
    if attr is not None and (attr.data_type != data_type or attr.domain != domain):
        curves.attributes.remove(attr)
        attr = None
    if attr is None:
        attr = curves.attributes.new(name, data_type, domain)
    return attr


def fill_curves(curves, strands):
    """Replace the contents of the Curves datablock `curves` with `strands` (bulk writes).

    Keeps the datablock (and so its materials and users); resizes it only when the strand
    layout changed, otherwise overwrites the point attributes in place.
    """
    counts = np.asarray(strands.counts, np.int32)
    same_layout = len(curves.curves) == len(counts)
    if same_layout and len(counts):
        offsets = np.empty(len(counts) + 1, np.int32)
        curves.curve_offset_data.foreach_get("value", offsets)
        same_layout = np.array_equal(np.diff(offsets), counts)
    if not same_layout:
        if len(curves.curves):
            curves.remove_curves()
        if len(counts):
            # add_curves wants Python ints; one list conversion, not a loop in our code.
            curves.add_curves(counts.tolist())
        curves.set_types(type='POLY')
    if not len(counts):
        return curves
    n_p = strands.num_points
    curves.attributes["position"].data.foreach_set(
        "vector", np.ascontiguousarray(strands.points, np.float32).ravel())
    _attribute(curves, "radius", 'FLOAT', 'POINT').data.foreach_set(
        "value", np.ascontiguousarray(strands.radius, np.float32))
    rgba = np.empty((n_p, 4), np.float32)
    rgba[:, :3] = strands.color
    rgba[:, 3] = strands.alpha
    _attribute(curves, COLOR_ATTRIBUTE, 'FLOAT_COLOR', 'POINT').data.foreach_set("color", rgba.ravel())
    legacy = curves.attributes.get(LEGACY_COLOR_ATTRIBUTE)
    if legacy is not None and legacy.domain == 'POINT' and legacy.data_type == 'FLOAT_COLOR':
        # Written by an earlier version of this module: stale now, so nothing may read it.
        curves.attributes.remove(legacy)
    _attribute(curves, "alpha", 'FLOAT', 'POINT').data.foreach_set(
        "value", np.ascontiguousarray(strands.alpha, np.float32))
    _attribute(curves, "wisp", 'INT', 'CURVE').data.foreach_set(
        "value", np.ascontiguousarray(strands.wisp, np.int32))
    curves.update_tag()
    return curves


def strands_to_curves(name, strands, collection=None, parent=None, obj=None):
    """A hair Curves object named `name` holding `strands`; returns the object.

    collection: where to link a new object (default: the scene's active collection).
    parent: an object the strands are relative to (the scalp); the curves object gets an
    identity local matrix and parent inverse, so the strand points are read in the
    parent's local space, exactly the space `groom` worked in. A mesh parent also becomes
    the curves' `surface`, so Blender's hair sculpt tools attach to it.
    obj: an existing Curves object to refill instead of creating one (its datablock,
    materials and modifiers are kept).
    """
    if not isinstance(strands, Strands):
        raise TypeError(f"strands: expected hairio.Strands, got {type(strands).__name__}")
    if obj is None:
        curves = bpy.data.hair_curves.new(name)
        obj = bpy.data.objects.new(name, curves)
        if collection is None:
            collection = bpy.context.collection or bpy.context.scene.collection
        collection.objects.link(obj)
    elif obj.type != 'CURVES':
        raise TypeError(f"obj: {obj.name!r} is a {obj.type} object, expected a hair Curves object")
    fill_curves(obj.data, strands)
    if parent is not None:
        obj.parent = parent
        obj.matrix_parent_inverse.identity()
        obj.matrix_basis.identity()
        if parent.type == 'MESH':
            obj.data.surface = parent
    return obj


def _retarget_legacy_nodes(mat):
    """Point this module's material's Attribute nodes that read the old colour name (which
    Cycles renders black) at COLOR_ATTRIBUTE."""
    if mat.node_tree is None:
        return
    for node in mat.node_tree.nodes:
        if node.type == 'ATTRIBUTE' and node.attribute_name == LEGACY_COLOR_ATTRIBUTE:
            node.attribute_name = COLOR_ATTRIBUTE


def _is_ours(mat, name):
    return mat is not None and (mat.name == name or mat.name.startswith(name + "."))


def ensure_hair_material(obj, name="Key-Strand Hair"):
    """Give a hair Curves object without materials one that renders its COLOR_ATTRIBUTE
    (Principled Hair BSDF, direct colouring), so Cycles and EEVEE show the groomed colours.
    A material of this name made by an earlier version is repaired, an artist's own is
    left alone."""
    if len(obj.data.materials):
        mat = obj.data.materials[0]
        if _is_ours(mat, name):
            _retarget_legacy_nodes(mat)
        return mat
    mat = bpy.data.materials.get(name)
    if mat is not None:
        _retarget_legacy_nodes(mat)
    else:
        mat = bpy.data.materials.new(name)
        if bpy.app.version < (5, 0, 0):  # node trees are always on from 5.0 (use_nodes deprecated)
            mat.use_nodes = True
        nodes, links = mat.node_tree.nodes, mat.node_tree.links
        nodes.clear()
        out = nodes.new("ShaderNodeOutputMaterial")
        bsdf = nodes.new("ShaderNodeBsdfHairPrincipled")
        bsdf.parametrization = 'COLOR'
        attr = nodes.new("ShaderNodeAttribute")
        attr.attribute_name = COLOR_ATTRIBUTE
        attr.location, bsdf.location, out.location = (-400, 0), (-150, 0), (150, 0)
        links.new(attr.outputs["Color"], bsdf.inputs["Color"])
        links.new(bsdf.outputs[0], out.inputs["Surface"])
    obj.data.materials.append(mat)
    return mat


def curves_to_strands(obj):
    """The strands of a hair Curves object (or its Curves datablock) as hairio.Strands.

    Reads the evaluated control points of the datablock as stored (local space). Missing
    attributes get hairio's defaults; color comes from the COLOR_ATTRIBUTE's RGB (else, for
    objects written by earlier versions, from `color`), alpha from `alpha` (else the colour's
    A channel).
    """
    curves = obj.data if isinstance(obj, bpy.types.Object) else obj
    n_s, n_p = len(curves.curves), len(curves.points)
    if n_s == 0:
        return Strands.empty()
    offsets = np.empty(n_s + 1, np.int32)
    curves.curve_offset_data.foreach_get("value", offsets)
    points = np.empty(n_p * 3, np.float32)
    curves.attributes["position"].data.foreach_get("vector", points)
    kwargs = {}
    attrs = curves.attributes
    if "radius" in attrs and attrs["radius"].domain == 'POINT':
        radius = np.empty(n_p, np.float32)
        attrs["radius"].data.foreach_get("value", radius)
        kwargs["radius"] = radius
    rgba = None
    for name in (COLOR_ATTRIBUTE, LEGACY_COLOR_ATTRIBUTE):
        color_attr = attrs.get(name)
        if color_attr is not None and color_attr.domain == 'POINT' and color_attr.data_type == 'FLOAT_COLOR':
            break
    else:
        color_attr = None
    if color_attr is not None:
        rgba = np.empty(n_p * 4, np.float32)
        color_attr.data.foreach_get("color", rgba)
        rgba = rgba.reshape(n_p, 4)
        kwargs["color"] = rgba[:, :3]
    if "alpha" in attrs and attrs["alpha"].domain == 'POINT' and attrs["alpha"].data_type == 'FLOAT':
        alpha = np.empty(n_p, np.float32)
        attrs["alpha"].data.foreach_get("value", alpha)
        kwargs["alpha"] = alpha
    elif rgba is not None:
        kwargs["alpha"] = rgba[:, 3]
    if "wisp" in attrs and attrs["wisp"].domain == 'CURVE' and attrs["wisp"].data_type == 'INT':
        wisp = np.empty(n_s, np.int32)
        attrs["wisp"].data.foreach_get("value", wisp)
        kwargs["wisp"] = wisp
    return Strands.from_arrays(points.reshape(n_p, 3), np.diff(offsets), **kwargs)

# SPDX-License-Identifier: GPL-3.0-or-later
"""hairio.Strands <-> Blender's native hair Curves object, with bulk array transfers only.

The Curves datablock stores exactly the SPEC §0 layout (points + per-strand counts), so the
conversion is a handful of `foreach_set`/`foreach_get` calls over whole arrays and never a
Python loop over strands or points. Attributes written:

    position  POINT  FLOAT_VECTOR  strand points (the object's local space)
    radius    POINT  FLOAT         Blender's built-in hair radius (Cycles, EEVEE read it)
    color     POINT  FLOAT_COLOR   linear RGB, alpha in A
    alpha     POINT  FLOAT         the strand opacity profile on its own, for shader nodes
    wisp      CURVE  INT           index of the key strand whose wisp the strand belongs to

Curve type is POLY: the strands are polylines (the tracer's cylinders), so Blender's
evaluated curve, its exporters and the tracer all see the same points.
"""
import numpy as np
import bpy

from hairio import Strands

ATTRIBUTES = ("position", "radius", "color", "alpha", "wisp")


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
    _attribute(curves, "color", 'FLOAT_COLOR', 'POINT').data.foreach_set("color", rgba.ravel())
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


def ensure_hair_material(obj, name="Key-Strand Hair"):
    """Give a hair Curves object without materials one that renders its `color` attribute
    (Principled Hair BSDF, direct colouring), so Cycles and EEVEE show the groomed colours."""
    if len(obj.data.materials):
        return obj.data.materials[0]
    mat = bpy.data.materials.get(name)
    if mat is None:
        mat = bpy.data.materials.new(name)
        if bpy.app.version < (5, 0, 0):  # node trees are always on from 5.0 (use_nodes deprecated)
            mat.use_nodes = True
        nodes, links = mat.node_tree.nodes, mat.node_tree.links
        nodes.clear()
        out = nodes.new("ShaderNodeOutputMaterial")
        bsdf = nodes.new("ShaderNodeBsdfHairPrincipled")
        bsdf.parametrization = 'COLOR'
        attr = nodes.new("ShaderNodeAttribute")
        attr.attribute_name = "color"
        attr.location, bsdf.location, out.location = (-400, 0), (-150, 0), (150, 0)
        links.new(attr.outputs["Color"], bsdf.inputs["Color"])
        links.new(bsdf.outputs[0], out.inputs["Surface"])
    obj.data.materials.append(mat)
    return mat


def curves_to_strands(obj):
    """The strands of a hair Curves object (or its Curves datablock) as hairio.Strands.

    Reads the evaluated control points of the datablock as stored (local space). Missing
    attributes get hairio's defaults; color comes from the `color` attribute's RGB, alpha
    from `alpha` (else the color's A channel).
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
    if "color" in attrs and attrs["color"].domain == 'POINT' and attrs["color"].data_type == 'FLOAT_COLOR':
        rgba = np.empty(n_p * 4, np.float32)
        attrs["color"].data.foreach_get("color", rgba)
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

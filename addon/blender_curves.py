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
    surface_uv_coordinate  CURVE  FLOAT2  the root's UV on the scalp's UV map (Blender's own
                                      hair attachment attribute; only when the scalp has one)

The guides a groom carries (hairio.Guides: the key strands and how every strand follows
them), so an export from Blender carries them as the command line's does (only when the
strands have them; a refill without guides removes them, as they would be stale):

    keystrand_guide_index_0, _1, _2  CURVE  INT  the strand's main key (= wisp) and its two
                                      neighbours, key indices
    keystrand_guide_weights  CURVE  FLOAT_VECTOR  their interpolation weights (summing to 1)
    keystrand_key_points, _counts, _group, _radius, _color   the key strands, as custom
                                      properties of the Curves datablock (Curves have no key
                                      domain): float32 Pk*3, int32 K, int32 K, float32 Pk,
                                      float32 Pk*3, in the same space as the strands

Curve type is POLY: the strands are polylines (the tracer's cylinders), so Blender's
evaluated curve, its exporters and the tracer all see the same points.

Blender 4.2 has only `add_curves` on a Curves datablock (no `set_types`, `remove_curves`);
what each Blender has is tested for, not its version number: POLY comes from the built-in
`curve_type` attribute there, and a new strand layout from a new datablock put in the old
one's place (`_replace_datablock`).
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

# Blender's name for a hair curve's attachment UV (its sculpt tools and geometry nodes read it).
ROOT_UV_ATTRIBUTE = "surface_uv_coordinate"

# The guides (see above): three per-curve key indices, their weights, and the key strands.
GUIDE_INDEX_ATTRIBUTES = ("keystrand_guide_index_0", "keystrand_guide_index_1", "keystrand_guide_index_2")
GUIDE_WEIGHTS_ATTRIBUTE = "keystrand_guide_weights"
KEY_PROPERTIES = {"points": ("keystrand_key_points", np.float32), "counts": ("keystrand_key_counts", np.int32),
                  "group": ("keystrand_key_group", np.int32), "radius": ("keystrand_key_radius", np.float32),
                  "color": ("keystrand_key_color", np.float32)}

ATTRIBUTES = ("position", "radius", COLOR_ATTRIBUTE, "alpha", "wisp", ROOT_UV_ATTRIBUTE) + \
    GUIDE_INDEX_ATTRIBUTES + (GUIDE_WEIGHTS_ATTRIBUTE,)


def _attribute(curves, name, data_type, domain):
    """The attribute `name`, created (or re-created with the right type) when needed."""
    attr = curves.attributes.get(name)
    if attr is not None and (attr.data_type != data_type or attr.domain != domain):
        curves.attributes.remove(attr)
        attr = None
    if attr is None:
        attr = curves.attributes.new(name, data_type, domain)
    return attr


# Blender's CurveType value for poly curves (DNA_curves_types.h); the built-in `curve_type`
# attribute holds one such INT8 per curve.
CURVE_TYPE_POLY = 1

# Settings of a Curves datablock a replacement takes over (those this Blender has).
_CARRIED_SETTINGS = ("surface", "surface_uv_map", "surface_collision_distance", "use_mirror_x",
                     "use_mirror_y", "use_mirror_z", "use_sculpt_collision", "use_fake_user")


def make_poly(curves):
    """Make every curve of the Curves datablock `curves` a POLY (polyline) curve."""
    if hasattr(curves, "set_types"):
        curves.set_types(type='POLY')
        return
    attr = _attribute(curves, "curve_type", 'INT8', 'CURVE')
    attr.data.foreach_set("value", np.full(len(curves.curves), CURVE_TYPE_POLY, np.int8))
    # Blender keeps a count of the curves of each type beside that attribute, and a direct
    # attribute write does not recount: with the count still saying Catmull-Rom, evaluating
    # the curves writes past Blender's own buffers (heap corruption, a crash later). A topology
    # change recounts, and add_curves of nothing is one that adds nothing.
    curves.add_curves([])


def _relayout(curves, counts):
    """`curves` emptied and refilled with curves of `counts` points (POLY, attributes at their
    defaults); returns the datablock that now holds them (see _replace_datablock)."""
    if not hasattr(curves, "remove_curves"):
        return _replace_datablock(curves, counts)
    if len(curves.curves):
        curves.remove_curves()
    if len(counts):
        # add_curves wants Python ints; one list conversion, not a loop in our code.
        curves.add_curves(counts.tolist())
    make_poly(curves)
    return curves


def _replace_datablock(old, counts):
    """A new Curves datablock with curves of `counts` points (POLY) that takes `old`'s place:
    its name, materials, surface and settings, its other attributes (at their defaults, as
    a resize leaves them) and every user of `old`, which is removed. Where a Blender cannot
    resize a Curves datablock in place (4.2), this is the resize; a failure before the swap
    removes the new datablock and leaves `old` as it was."""
    new = bpy.data.hair_curves.new(old.name)
    try:
        if len(counts):
            new.add_curves(counts.tolist())
        make_poly(new)
        for mat in old.materials:
            new.materials.append(mat)
        for setting in _CARRIED_SETTINGS:
            if hasattr(old, setting):
                setattr(new, setting, getattr(old, setting))
        for key in old.keys():
            new[key] = old[key]
        for attr in old.attributes:
            if not attr.name.startswith(".") and attr.name not in new.attributes:
                new.attributes.new(attr.name, attr.data_type, attr.domain)
    except BaseException:
        bpy.data.hair_curves.remove(new)
        raise
    name = old.name
    old.user_remap(new)
    bpy.data.hair_curves.remove(old)
    new.name = name
    return new


# A point's RGB as one 12-byte item, and the same item at the start of a 16-byte RGBA.
_RGB_ITEM = np.dtype((np.void, 12))
_RGB_OF_RGBA = np.dtype({"names": ["rgb"], "formats": [_RGB_ITEM], "offsets": [0], "itemsize": 16})
_RGBA_ITEM = np.dtype((np.void, 16))


def _rgba(strands):
    """(P, 4) float32 RGBA of the strands' colours and alphas. Each RGB triple moves as one
    12-byte item (structured views): numpy copies three floats a row into a 4-wide array
    column by column at about twice the cost. Colour held a strand at a time
    (Strands.strand_color) goes straight from each strand's row, as one 16-byte item, to its
    points: no (P, 3) array of it is made on the way."""
    alpha = strands.alpha
    n = len(alpha)
    rgba = np.empty((n, 4), np.float32)
    if strands.strand_color is not None:
        rows = np.zeros((len(strands.counts), 4), np.float32)
        rows[:, :3] = strands.strand_color
        rgba.view(_RGBA_ITEM).reshape(n)[...] = np.repeat(rows.view(_RGBA_ITEM).reshape(-1), strands.counts)
    else:
        rgba.view(_RGB_OF_RGBA).reshape(n)["rgb"] = np.ascontiguousarray(
            strands.color, np.float32).view(_RGB_ITEM).reshape(n)
    rgba[:, 3] = alpha
    return rgba


def drop_written_attributes(curves):
    """Remove from the Curves datablock `curves` the attributes fill_curves writes (all but
    the built-in position, which cannot go). For a datablock whose arrays are shared (with
    the undo's copy, transaction.keep_curves, and the depsgraph's evaluated copy): a fill
    then writes them into fresh memory instead of first copying each shared array it is
    about to overwrite."""
    for name in ATTRIBUTES:
        attr = curves.attributes.get(name)
        if attr is not None and name != "position":
            curves.attributes.remove(attr)


def fill_curves(curves, strands, root_uv=None):
    """Replace the contents of the Curves datablock `curves` with `strands` (bulk writes);
    returns the datablock that holds them. root_uv: (S, 2) UVs of the roots on the surface's
    UV map, or None (then no ROOT_UV_ATTRIBUTE, since an old one would be stale).

    That is `curves` itself (materials, users and settings kept) unless the strand layout
    changed in a Blender that cannot resize a datablock in place: then a new one has taken
    its place (see _replace_datablock). When the layout is unchanged the point attributes
    are overwritten in place.
    """
    counts = np.asarray(strands.counts, np.int32)
    same_layout = len(curves.curves) == len(counts)
    if same_layout and len(counts):
        offsets = np.empty(len(counts) + 1, np.int32)
        curves.curve_offset_data.foreach_get("value", offsets)
        same_layout = np.array_equal(np.diff(offsets), counts)
    if root_uv is not None:
        root_uv = np.ascontiguousarray(root_uv, np.float32)
        if root_uv.shape != (len(counts), 2):
            raise ValueError(f"root_uv: shape {root_uv.shape}, expected ({len(counts)}, 2)")
    if not same_layout:
        curves = _relayout(curves, counts)
    stale = curves.attributes.get(ROOT_UV_ATTRIBUTE)
    if root_uv is None and stale is not None:
        curves.attributes.remove(stale)
    if not len(counts):
        return curves
    curves.attributes["position"].data.foreach_set(
        "vector", np.ascontiguousarray(strands.points, np.float32).ravel())
    _attribute(curves, "radius", 'FLOAT', 'POINT').data.foreach_set(
        "value", np.ascontiguousarray(strands.radius, np.float32))
    _attribute(curves, COLOR_ATTRIBUTE, 'FLOAT_COLOR', 'POINT').data.foreach_set(
        "color", _rgba(strands).ravel())
    legacy = curves.attributes.get(LEGACY_COLOR_ATTRIBUTE)
    if legacy is not None and legacy.domain == 'POINT' and legacy.data_type == 'FLOAT_COLOR':
        # Written by an earlier version of this module: stale now, so nothing may read it.
        curves.attributes.remove(legacy)
    _attribute(curves, "alpha", 'FLOAT', 'POINT').data.foreach_set(
        "value", np.ascontiguousarray(strands.alpha, np.float32))
    _attribute(curves, "wisp", 'INT', 'CURVE').data.foreach_set(
        "value", np.ascontiguousarray(strands.wisp, np.int32))
    if root_uv is not None:
        _attribute(curves, ROOT_UV_ATTRIBUTE, 'FLOAT2', 'CURVE').data.foreach_set("vector", root_uv.ravel())
    write_guides(curves, strands.guides)
    curves.update_tag()
    return curves


def write_guides(curves, guides):
    """Store hairio.Guides on the Curves datablock (the attributes and properties in the
    module's notes), or remove any stored there when `guides` is None."""
    if guides is None:
        for name in GUIDE_INDEX_ATTRIBUTES + (GUIDE_WEIGHTS_ATTRIBUTE,):
            old = curves.attributes.get(name)
            if old is not None:
                curves.attributes.remove(old)
        for name, _ in KEY_PROPERTIES.values():
            if name in curves:
                del curves[name]
        return
    index = np.ascontiguousarray(guides.index, np.int32)
    for column, name in enumerate(GUIDE_INDEX_ATTRIBUTES):
        _attribute(curves, name, 'INT', 'CURVE').data.foreach_set("value", np.ascontiguousarray(index[:, column]))
    _attribute(curves, GUIDE_WEIGHTS_ATTRIBUTE, 'FLOAT_VECTOR', 'CURVE').data.foreach_set(
        "vector", np.ascontiguousarray(guides.weights, np.float32).ravel())
    keys = guides.keys
    values = {"points": keys.points, "counts": keys.counts, "group": guides.group, "radius": keys.radius,
              "color": keys.color}
    for field, (name, dtype) in KEY_PROPERTIES.items():
        # Through Python lists (doubles and ints, exact for float32 and int32 values): an ID
        # property made from a numpy buffer here crashed Blender 5.0 later, when the
        # transaction removed its backup copy of the datablock (a bus error in the
        # viewport-count live update after a Generate).
        curves[name] = np.asarray(values[field], dtype).ravel().tolist()


def read_guides(curves):
    """The hairio.Guides stored on a Curves datablock (write_guides), or None when it holds
    none. InputError when they no longer fit the curves (edited since Generate)."""
    from hairio import Guides, InputError
    attrs = curves.attributes
    names = GUIDE_INDEX_ATTRIBUTES + (GUIDE_WEIGHTS_ATTRIBUTE,)
    if any(name not in attrs for name in names) or any(name not in curves for name, _ in KEY_PROPERTIES.values()):
        return None
    n_s = len(curves.curves)
    index = np.empty((3, n_s), np.int32)
    for column, name in enumerate(GUIDE_INDEX_ATTRIBUTES):
        attrs[name].data.foreach_get("value", index[column])
    weights = np.empty(n_s * 3, np.float32)
    attrs[GUIDE_WEIGHTS_ATTRIBUTE].data.foreach_get("vector", weights)
    values = {field: np.array(curves[name], dtype) for field, (name, dtype) in KEY_PROPERTIES.items()}
    try:
        keys = Strands.from_arrays(values["points"].reshape(-1, 3), values["counts"], values["radius"],
                                   values["color"].reshape(-1, 3))
        return Guides.from_arrays(keys, index.T, weights.reshape(-1, 3), values["group"], num_strands=n_s)
    except InputError as e:
        raise InputError(f"{curves.name}: the guides stored with the hair no longer fit it ({e}); "
                         "press Generate to store them again") from None


def root_uv(curves):
    """(S, 2) float32 root UVs stored on a Curves datablock (ROOT_UV_ATTRIBUTE), or None."""
    attr = curves.attributes.get(ROOT_UV_ATTRIBUTE)
    if attr is None or attr.domain != 'CURVE' or attr.data_type != 'FLOAT2':
        return None
    uv = np.empty(len(curves.curves) * 2, np.float32)
    attr.data.foreach_get("vector", uv)
    return uv.reshape(-1, 2)


def strands_to_curves(name, strands, collection=None, parent=None, obj=None, root_uv=None):
    """A hair Curves object named `name` holding `strands`; returns the object.

    collection: where to link a new object (default: the scene's active collection).
    parent: an object the strands are relative to (the scalp); the curves object gets an
    identity local matrix and parent inverse, so the strand points are read in the
    parent's local space, exactly the space `groom` worked in. A mesh parent also becomes
    the curves' `surface`, so Blender's hair sculpt tools attach to it.
    obj: an existing Curves object to refill instead of creating one (its modifiers and its
    datablock's name, materials and settings are kept; see fill_curves).
    root_uv: (S, 2) root UVs on the parent mesh's active UV map (see fill_curves), which
    then becomes the curves' `surface_uv_map`.
    """
    if not isinstance(strands, Strands):
        raise TypeError(f"strands: expected hairio.Strands, got {type(strands).__name__}")
    if obj is not None and obj.type != 'CURVES':
        raise TypeError(f"obj: {obj.name!r} is a {obj.type} object, expected a hair Curves object")
    if obj is None:
        curves = bpy.data.hair_curves.new(name)
        obj = bpy.data.objects.new(name, curves)
        if collection is None:
            collection = bpy.context.collection or bpy.context.scene.collection
        collection.objects.link(obj)
    fill_curves(obj.data, strands, root_uv)
    if parent is not None:
        obj.parent = parent
        obj.matrix_parent_inverse.identity()
        obj.matrix_basis.identity()
        if parent.type == 'MESH':
            obj.data.surface = parent
            uv_map = parent.data.uv_layers.active
            if root_uv is not None and uv_map is not None:
                obj.data.surface_uv_map = uv_map.name
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


def transform_strand_arrays(points, radius, matrix):
    """(points, radius) as float32 carried by the 4x4 `matrix`, computed in float64: points by
    the matrix, radii by its uniform scale (the cube root of its volume scale). One rule for
    every consumer of world-space strands (preview, the panel's exports, Alembic/USD), so
    their files agree to the bit."""
    m = np.asarray(matrix, np.float64)
    world = np.asarray(points, np.float64) @ m[:3, :3].T + m[:3, 3]
    scale = abs(np.linalg.det(m[:3, :3])) ** (1.0 / 3.0)
    return world.astype(np.float32), (np.asarray(radius, np.float64) * scale).astype(np.float32)


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


def hair_strands(obj, world_space=True):
    """The hair Curves object's strands with what it stores beside them (guides, root UVs),
    as the export writes them: in world space (points by the object's matrix, radii by its
    uniform scale, the key strands likewise) or in the object's own space."""
    from hairio import Guides
    s = curves_to_strands(obj)
    guides = read_guides(obj.data)
    m = np.array(obj.matrix_world, np.float64)
    if world_space and not np.allclose(m, np.eye(4)):
        points, radius = transform_strand_arrays(s.points, s.radius, m)
        s = Strands.from_arrays(points, s.counts, radius, s.color, s.alpha, s.wisp)
        if guides is not None:
            k = guides.keys
            points, radius = transform_strand_arrays(k.points, k.radius, m)
            guides = Guides(Strands.from_arrays(points, k.counts, radius, k.color), guides.group, guides.index,
                            guides.weights)
    return s.with_guides(guides, root_uv(obj.data))

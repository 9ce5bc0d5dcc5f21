# SPDX-License-Identifier: GPL-3.0-or-later
"""Blender objects -> the arrays groom takes, and key strand curve objects <-> groom.KeyStrand;
the scene's meshes as the preview's tracer takes them (`scene_meshes`).

Everything groom reads is in the scalp object's local space (the space groom works in and the
generated hair is stored in): mesh arrays come out with `foreach_get`, key strands are
carried into scalp space by one 4x4 matrix each. The preview's meshes are in world space,
where the preview puts the hair.
"""
import contextlib
from dataclasses import dataclass

import numpy as np
import bpy
from hairio import InputError


def find_scalp(context):
    """The scalp the user means: the scalp of the active key strand or hair; the active mesh's
    own scalp when it is a head carrying one (Add Head's head, active after a click in the
    viewport: the scalp on it is drawn as a wire and hard to pick); else the active mesh."""
    obj = context.active_object if context is not None else None
    if obj is None:
        return None
    role = obj.keystrand_hair.role
    if role in ('KEY', 'HAIR'):
        scalp = obj.keystrand_hair.scalp
        return scalp if scalp is not None and scalp.type == 'MESH' else None
    if obj.type != 'MESH':
        return None
    if role != 'SCALP':
        scalps = sorted((c for c in obj.children if c.type == 'MESH' and c.keystrand_hair.role == 'SCALP'),
                        key=lambda c: c.name)
        if scalps:
            return scalps[0]
    return obj


def key_objects(scalp):
    """The key strand objects of a scalp, in a stable order (by name): index i is key i."""
    keys = [o for o in bpy.data.objects
            if o.type == 'CURVE' and o.keystrand_hair.role == 'KEY' and o.keystrand_hair.scalp == scalp]
    return sorted(keys, key=lambda o: o.name)


def remove_key_objects(objs):
    """Remove key strand objects, and their curves when nothing else uses them, in one batch."""
    if not objs:
        return
    curves = {o.data.session_uid: o.data for o in objs}
    bpy.data.batch_remove(list(objs))
    orphans = [c for c in curves.values() if c.users == 0]
    if orphans:
        bpy.data.batch_remove(orphans)


def _matrix(m):
    return np.array(m, dtype=np.float64).reshape(4, 4)


def _to_scalp_space(obj, scalp):
    """The 4x4 carrying `obj`'s coordinates into the scalp's; InputError when the scalp is
    flattened (its matrix has no inverse, so nothing can be placed in its space)."""
    m = _matrix(scalp.matrix_world)
    size = float(np.abs(m[:3, :3]).max())
    if not size > 0 or abs(np.linalg.det(m[:3, :3])) <= 1e-12 * size ** 3:
        raise InputError(f"Scalp {scalp.name!r} has a zero scale on some axis: give it a non-zero scale")
    return np.linalg.solve(m, _matrix(obj.matrix_world))


def _is_identity(m):
    return np.allclose(m, np.eye(4), rtol=0.0, atol=1e-9)


@contextlib.contextmanager
def _mesh_of(obj, depsgraph=None):
    """The object's mesh, with modifiers applied when a depsgraph is given (a temporary
    mesh, freed on leaving)."""
    if depsgraph is None:
        yield obj.data
        return
    source = obj.evaluated_get(depsgraph)
    try:
        yield source.to_mesh()
    finally:
        source.to_mesh_clear()


def canonical_triangles(triangles):
    """A mesh's triangles (T,3) vertex indices, int64, in an order of its vertices' own, not
    Blender's: each starts at its smallest vertex index (a rotation: the winding is kept),
    and they are sorted by their vertex indices.

    Blender versions list the same loop triangles in different orders and start them at
    different corners, and the same UV sphere made in 5.0 and 5.3 numbers its faces and
    loops differently over the same vertices; roots are sampled triangle by triangle, so the
    same scene grew other hair in each."""
    t = np.asarray(triangles, np.int64).reshape(-1, 3)
    start = np.argmin(t, axis=1)
    t = np.take_along_axis(t, (start[:, None] + np.arange(3)) % 3, axis=1)
    return t[np.lexsort((t[:, 2], t[:, 1], t[:, 0]))]


def _mesh_geometry(mesh):
    """(vertices (V,3) float64, triangles (T,3) int64 in canonical_triangles' order) of a mesh."""
    mesh.calc_loop_triangles()
    vertices = np.empty(len(mesh.vertices) * 3, np.float64)
    mesh.vertices.foreach_get("co", vertices)
    triangles = np.empty(len(mesh.loop_triangles) * 3, np.int32)
    mesh.loop_triangles.foreach_get("vertices", triangles)
    return vertices.reshape(-1, 3), canonical_triangles(triangles)


def _mesh_geometry_by_material(mesh):
    """(vertices (V,3) float64, [(material slot, triangles (T,3) int64 in canonical_triangles'
    order), ...] one entry per slot the faces use, slots ascending) of a mesh."""
    mesh.calc_loop_triangles()
    vertices = np.empty(len(mesh.vertices) * 3, np.float64)
    mesh.vertices.foreach_get("co", vertices)
    triangles = np.empty(len(mesh.loop_triangles) * 3, np.int32)
    mesh.loop_triangles.foreach_get("vertices", triangles)
    slot = np.empty(len(mesh.loop_triangles), np.int32)
    mesh.loop_triangles.foreach_get("material_index", slot)
    triangles = triangles.reshape(-1, 3)
    return vertices.reshape(-1, 3), [(int(k), canonical_triangles(triangles[slot == k])) for k in np.unique(slot)]


def read_scalp(obj, depsgraph=None):
    """groom.Scalp of a mesh object, in its local space, with modifiers applied when a
    depsgraph is given. Optional point attributes: float `hair_density` (root density
    weight) and int `hair_group` (parting groups). Raises InputError without faces."""
    from groom import Scalp
    if obj is None or obj.type != 'MESH':
        raise InputError("Select a scalp mesh (or one of its key strands) first")
    with _mesh_of(obj, depsgraph) as mesh:
        vertices, triangles = _mesh_geometry(mesh)
        if len(triangles) == 0:
            raise InputError(f"Scalp {obj.name!r} has no faces: hair grows from faces, "
                             "so give the mesh a surface (e.g. fill it or use a sphere)")
        uv = None
        if mesh.uv_layers.active is not None and len(mesh.loops):
            loop_uv = np.empty(len(mesh.loops) * 2, np.float64)
            mesh.uv_layers.active.uv.foreach_get("vector", loop_uv)
            loop_vertex = np.empty(len(mesh.loops), np.int32)
            mesh.loops.foreach_get("vertex_index", loop_vertex)
            # Per-vertex UV: a vertex on a seam takes one of its loops' UVs.
            uv = np.zeros((len(vertices), 2))
            uv[loop_vertex] = loop_uv.reshape(-1, 2)
        density = _point_attribute(mesh, "hair_density", 'FLOAT', np.float64)
        groups = _point_attribute(mesh, "hair_group", 'INT', np.int32)
    return Scalp(vertices, triangles, density=density, uv=uv, groups=groups)


def collider_object(scalp):
    """The object a scalp's hair stays out of: its Collider setting, or the scalp itself."""
    chosen = scalp.keystrand_hair.collider
    return scalp if chosen is None else chosen


def collider_signature(scalp):
    """What decides the collider read_collider reads, save the mesh's contents (an edited
    head takes a Generate): Collision, the object, its mesh and its place relative to the
    scalp. None when Collision is off."""
    if not scalp.keystrand_hair.collision:
        return None
    obj = collider_object(scalp)
    try:
        # Rounded (and -0 made 0): a head moved with its scalp keeps its place but for the last bits.
        place = (np.round(_to_scalp_space(obj, scalp), 9) + 0.0).tobytes()
    except InputError:
        place = None
    data = obj.data.session_uid if obj.data is not None else None
    return obj.session_uid, data, place


def read_collider(scalp, depsgraph=None, scalp_data=None, collision=None):
    """(vertices (V,3), triangles (T,3), name) of the scalp's collider in the scalp's own
    space (where groom works), modifiers applied when a depsgraph is given; None when
    collision is off (collision: True or False, or None for the scalp's Collision setting).
    scalp_data: the scalp's groom.Scalp when already read (a scalp that is its own collider
    is then not read twice). Raises InputError for a collider that is not a mesh; groom
    judges its faces."""
    if not (scalp.keystrand_hair.collision if collision is None else collision):
        return None
    obj = collider_object(scalp)
    if obj.type != 'MESH':
        raise InputError(f"Collider {obj.name!r} of scalp {scalp.name!r} is a {obj.type.lower()}, not a "
                         "mesh: choose the head mesh as Collider, or clear it to use the scalp itself")
    if obj == scalp:
        if scalp_data is None:
            scalp_data = read_scalp(scalp, depsgraph)
        return scalp_data.vertices, scalp_data.triangles, obj.name
    to_scalp = _to_scalp_space(obj, scalp)
    with _mesh_of(obj, depsgraph) as mesh:
        vertices, triangles = _mesh_geometry(mesh)
    if not _is_identity(to_scalp):
        # A scalp parented to its head as Add Head makes it has the head's coordinates: kept exactly.
        vertices = vertices @ to_scalp[:3, :3].T + to_scalp[:3, 3]
    return vertices, triangles, obj.name


def _point_attribute(mesh, name, data_type, dtype):
    attr = mesh.attributes.get(name)
    if attr is None or attr.domain != 'POINT' or attr.data_type != data_type:
        return None
    out = np.empty(len(mesh.vertices), dtype)
    attr.data.foreach_get("value", out)
    return out


def key_control_points(key_obj, scalp):
    """(points (n,3) in scalp space, kind) of a key strand's first spline."""
    curve = key_obj.data
    if not curve.splines:
        raise InputError(f"Key strand {key_obj.name!r} has no spline; delete it or draw one")
    spline = curve.splines[0]
    if spline.type == 'BEZIER':
        from groom.bezier import handles_to_cubic
        n = len(spline.bezier_points)
        if n < 2:
            raise InputError(f"Key strand {key_obj.name!r} needs at least 2 points")
        co, left, right = (np.empty(n * 3, np.float64) for _ in range(3))
        spline.bezier_points.foreach_get("co", co)
        spline.bezier_points.foreach_get("handle_left", left)
        spline.bezier_points.foreach_get("handle_right", right)
        local = handles_to_cubic(co.reshape(n, 3), left.reshape(n, 3), right.reshape(n, 3))
        kind = "cubic"
    else:
        n = len(spline.points)
        if n < 2:
            raise InputError(f"Key strand {key_obj.name!r} needs at least 2 points")
        co = np.empty(n * 4, np.float64)
        spline.points.foreach_get("co", co)
        local = co.reshape(n, 4)[:, :3]
        kind = "bezier"
    to_scalp = _to_scalp_space(key_obj, scalp)
    if _is_identity(to_scalp):
        # A key parented as Add Key Strand does it: its coordinates are the scalp's, exactly
        # (the round trip through the inverse would add float noise to every point).
        return local, kind
    return local @ to_scalp[:3, :3].T + to_scalp[:3, 3], kind


def read_keys(scalp):
    """groom.KeyStrand list of the scalp's key strands (scalp space); raises InputError
    when there are none."""
    from groom import KeyStrand
    objs = key_objects(scalp)
    if not objs:
        raise InputError(f"Scalp {scalp.name!r} has no key strands: add one with Add Key Strand "
                         "or load a preset")
    keys = []
    for obj in objs:  # a handful of keys, not strands
        keys.append(key_from_object(obj, scalp, KeyStrand))
    return keys


def key_from_object(obj, scalp, key_class=None):
    if key_class is None:
        from groom import KeyStrand as key_class
    points, kind = key_control_points(obj, scalp)
    s = obj.keystrand_hair
    return key_class(points, kind=kind,
                     color=tuple(s.key_color) if s.use_key_color else None,
                     root_radius=s.key_radius if s.key_radius > 0 else None,
                     group=int(s.key_group))


def new_key_object(scalp, points, name="Key Strand", collection=None, handles=None):
    """A Bézier curve object through `points` (n,3, scalp space), parented to the scalp
    (identity parent inverse: its coordinates are the scalp's) and registered as its key.

    handles: (left, right) arrays, or None for smooth Catmull-Rom handles
    (groom.bezier.smooth_handles). For a groom KeyStrand of kind 'cubic' pass its own
    handles to keep its exact shape.
    """
    points = np.asarray(points, np.float64)
    if handles is None:
        from groom.bezier import smooth_handles
        handles = smooth_handles(points)
    left, right = handles
    curve = bpy.data.curves.new(name, 'CURVE')
    curve.dimensions = '3D'
    spline = curve.splines.new('BEZIER')
    spline.bezier_points.add(len(points) - 1)
    bp = spline.bezier_points
    bp.foreach_set("co", points.astype(np.float32).ravel())
    bp.foreach_set("handle_left", np.asarray(left, np.float32).ravel())
    bp.foreach_set("handle_right", np.asarray(right, np.float32).ravel())
    # FREE keeps the handles exactly where they were put; the artist can change the type.
    for p in bp:  # a key has a few points, not a hot path
        p.handle_left_type = 'FREE'
        p.handle_right_type = 'FREE'
    obj = bpy.data.objects.new(name, curve)
    if collection is None:
        collection = scalp.users_collection[0] if scalp.users_collection else bpy.context.scene.collection
    collection.objects.link(obj)
    obj.parent = scalp
    obj.matrix_parent_inverse.identity()
    obj.keystrand_hair.role = 'KEY'
    obj.keystrand_hair.scalp = scalp
    return obj


def key_strand_to_object(scalp, key, name="Key Strand", collection=None):
    """A key curve object from a groom.KeyStrand (scalp space); 'bezier' keys of any
    degree are drawn through points sampled on the curve."""
    if key.kind == "cubic":
        from groom.bezier import cubic_to_handles
        co, left, right = cubic_to_handles(key.points)
        obj = new_key_object(scalp, co, name, collection, handles=(left, right))
    else:
        samples = key.evaluate(np.linspace(0.0, 1.0, max(4, len(key.points) + 2)))
        obj = new_key_object(scalp, samples, name, collection)
    s = obj.keystrand_hair
    if key.color is not None:
        s.use_key_color = True
        s.key_color = tuple(float(c) for c in key.color)
    if key.root_radius is not None:
        s.key_radius = float(key.root_radius)
    s.key_group = int(key.group)
    return obj


# --- the scene's meshes for the preview ---------------------------------------------------
# Cycles shades a mesh without a material with a grey diffuse of this albedo.
NO_MATERIAL_RGB = (0.8, 0.8, 0.8)


def material_base_color(material):
    """The linear RGB a material shows in the preview: its Principled BSDF's Base Color
    (the one feeding the output, or the first one), or its viewport display colour when it
    has no node tree, no Principled BSDF or a Base Color driven by a texture or other node;
    NO_MATERIAL_RGB for no material."""
    if material is None:
        return NO_MATERIAL_RGB
    tree = material.node_tree
    # Blender 5 always renders a material's nodes (use_nodes is deprecated there).
    if tree is not None and bpy.app.version < (5, 0, 0) and not material.use_nodes:
        tree = None
    if tree is not None:
        principled = [n for n in tree.nodes if n.type == 'BSDF_PRINCIPLED']
        if principled:
            socket = _surface_principled(tree, principled).inputs["Base Color"]
            if not socket.is_linked:
                return tuple(float(c) for c in socket.default_value[:3])
    return tuple(float(c) for c in material.diffuse_color[:3])


def _surface_principled(tree, principled):
    """The Principled BSDF linked straight into the active Material Output's Surface, else
    the first Principled BSDF of the tree."""
    outputs = [n for n in tree.nodes if n.type == 'OUTPUT_MATERIAL']
    active = [n for n in outputs if n.is_active_output] or outputs
    for out in active:
        surface = out.inputs.get("Surface")
        if surface is not None and surface.is_linked:
            node = surface.links[0].from_node
            if node.type == 'BSDF_PRINCIPLED':
                return node
    return principled[0]


def mesh_triangle_count(obj, depsgraph):
    """Triangles of an object's evaluated mesh, counted without triangulating it: a face
    of n corners makes n - 2 triangles."""
    mesh = obj.evaluated_get(depsgraph).data
    return len(mesh.loops) - 2 * len(mesh.polygons)


def read_world_mesh(obj, depsgraph):
    """The preview's meshes of one object: [(vertices (V,3) float64 in world space, triangles
    (T,3) int64, rgb, name), ...], one per material slot its faces use (the evaluated mesh,
    modifiers applied, carried by its evaluated matrix_world); [] without faces."""
    evaluated = obj.evaluated_get(depsgraph)
    m = _matrix(evaluated.matrix_world)
    with _mesh_of(obj, depsgraph) as mesh:
        vertices, groups = _mesh_geometry_by_material(mesh)
    if not _is_identity(m):
        vertices = vertices @ m[:3, :3].T + m[:3, 3]
    slots = obj.material_slots
    out = []
    for k, triangles in groups:
        material = slots[k].material if k < len(slots) else None
        name = obj.name if len(groups) == 1 else f"{obj.name} ({material.name if material else 'no material'})"
        out.append((vertices, triangles, material_base_color(material), name))
    return out


@dataclass
class SceneMeshes:
    """What the preview shows beside the hair: `meshes` as tracer.Renderer.set_meshes takes
    them, `triangles` their count, `skipped` the triangles of the visible meshes left out
    for the budget (0 when none were). The arrays are not changed once read."""
    meshes: list
    triangles: int
    skipped: int = 0
    digest: str = None      # the preview's digest of the arrays, made on first upload


def preview_mesh_objects(scene, view_layer, scalp):
    """(the scalp and its collider, the other meshes) that a render of the scene shows:
    every mesh object not hidden from renders; the others must also be visible in the view
    layer (the scalp and collider are shown even when hidden in the viewport, as while
    drawing keys on a scalp whose head is hidden). Each list in a stable order, by name."""
    own = [scalp]
    collider = collider_object(scalp)
    if collider is not scalp and collider.type == 'MESH':
        own.append(collider)
    own = [o for o in own if not o.hide_render]
    others = sorted((o for o in scene.objects
                     if o.type == 'MESH' and not o.hide_render and o not in own
                     and o.visible_get(view_layer=view_layer)), key=lambda o: o.name)
    return own, others


def scene_meshes(scene, view_layer, depsgraph, scalp, budget):
    """SceneMeshes of the scene for the preview: the scalp, its collider and the scene's other
    visible meshes, with their world transforms and base colours; when all of them together
    pass `budget` triangles, only the scalp and collider (and `skipped` says how many
    triangles were left out)."""
    own, others = preview_mesh_objects(scene, view_layer, scalp)
    counts = {o.name: mesh_triangle_count(o, depsgraph) for o in own + others}
    total = sum(counts.values())
    chosen, skipped = own + others, 0
    if total > budget:
        chosen, skipped = own, sum(counts[o.name] for o in others)
    meshes = [m for o in chosen for m in read_world_mesh(o, depsgraph)]
    return SceneMeshes(meshes, sum(len(m[1]) for m in meshes), skipped)

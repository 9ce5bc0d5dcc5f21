# SPDX-License-Identifier: GPL-3.0-or-later
"""Small scenes built in code for the extension tests, and a snapshot to prove that a
failed operator changed nothing."""
import hashlib
import pathlib

import numpy as np
import bpy


def clear_scene():
    data = bpy.data
    blocks = (list(data.objects) + list(data.meshes) + list(data.curves) + list(data.hair_curves)
              + list(data.cameras) + list(data.lights) + list(data.images))
    if blocks:
        data.batch_remove(blocks)


def make_scalp(name="Scalp", radius=0.1, segments=24, rings=12, uv=False):
    """A UV sphere standing in for a head, made from arrays (no operators, no context);
    uv: with a UV map."""
    import bmesh
    mesh = bpy.data.meshes.new(name)
    bm = bmesh.new()
    if uv:
        bm.loops.layers.uv.new("UVMap")
    bmesh.ops.create_uvsphere(bm, u_segments=segments, v_segments=rings, radius=radius, calc_uvs=uv)
    bm.to_mesh(mesh)
    bm.free()
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    return obj


def in_mesh_order(triangles):
    """Triangles (T,3) in the order the extension reads a mesh's triangles, worked out here
    on its own, one triangle at a time: each starts at its smallest vertex index (its
    winding kept), sorted by vertex indices. (Blender's own order of loop triangles, the
    corner each starts at, and the numbering of faces and loops of the same primitive
    changed between versions.)"""
    out = []
    for corners in np.asarray(triangles).tolist():
        first = corners.index(min(corners))
        out.append(corners[first:] + corners[:first])
    return np.array(sorted(out), np.int64).reshape(-1, 3)


def mesh_arrays(obj):
    """(vertices (V,3) float64, triangles (T,3) int64 in_mesh_order) of a mesh object in its
    own coordinates."""
    mesh = obj.data
    mesh.calc_loop_triangles()
    v = np.empty(len(mesh.vertices) * 3)
    mesh.vertices.foreach_get("co", v)
    return v.reshape(-1, 3), in_mesh_order([list(tri.vertices) for tri in mesh.loop_triangles])


def make_camera(location=(0.0, -0.7, 0.05), rotation=(1.5708, 0.0, 0.0), lens=50.0):
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.lens = lens
    bpy.context.scene.collection.objects.link(cam)
    cam.location = location
    cam.rotation_euler = rotation
    bpy.context.scene.camera = cam
    bpy.context.view_layer.update()
    return cam


def activate(obj):
    bpy.context.view_layer.objects.active = obj


def _id_collections():
    """Every collection of datablocks in bpy.data (objects, meshes, hair_curves, images, ...)."""
    return [p.identifier for p in bpy.types.BlendData.bl_rna.properties if p.type == 'COLLECTION']


def _digest(array):
    return hashlib.sha1(np.ascontiguousarray(array).tobytes()).hexdigest()


def _attribute_digest(attr):
    n = len(attr.data)
    key = ("vector" if attr.data_type in ('FLOAT_VECTOR', 'FLOAT2') else
           "color" if attr.data_type in ('FLOAT_COLOR', 'BYTE_COLOR') else "value")
    width = {"FLOAT_VECTOR": 3, "FLOAT2": 2, "FLOAT_COLOR": 4, "BYTE_COLOR": 4}.get(attr.data_type, 1)
    dtype = {"INT": np.int32, "INT8": np.int32, "BOOLEAN": bool}.get(attr.data_type, np.float32)
    values = np.empty(n * width, dtype)
    if n:
        attr.data.foreach_get(key, values)
    return (attr.domain, attr.data_type, _digest(values))


def _settings(obj):
    s = obj.keystrand_hair
    props = {}
    for name in s.bl_rna.properties.keys():
        if name in ("rna_type", "name"):
            continue
        value = getattr(s, name)
        props[name] = value.name if isinstance(value, bpy.types.ID) else (
            tuple(value) if hasattr(value, "__len__") and not isinstance(value, str) else value)
    return props


def scene_snapshot():
    """Everything an operator could change: the name and user count of every datablock of
    every type, each object's settings, parent, transform and data, key and hair geometry
    with every attribute's values, images' sizes and pixels, the scene camera and the active
    object. Equal before and after a failed press means the press left no trace."""
    d = bpy.data
    snap = {}
    for kind in _id_collections():
        snap[kind] = sorted((b.name, b.users) for b in getattr(d, kind))
    for obj in d.objects:
        snap["obj:" + obj.name] = (_settings(obj), obj.parent.name if obj.parent else None,
                                   tuple(tuple(r) for r in obj.matrix_world),
                                   obj.data.name if obj.data else None,
                                   tuple(m.name if m else None for m in getattr(obj.data, "materials", ())))
    for curve in d.curves:
        for i, spline in enumerate(curve.splines):
            co = np.empty(len(spline.bezier_points) * 3, np.float32)
            spline.bezier_points.foreach_get("co", co)
            snap[f"curve:{curve.name}:{i}"] = co.tobytes()
    for hc in d.hair_curves:
        snap["hair:" + hc.name] = (len(hc.curves), len(hc.points),
                                   hc.surface.name if hc.surface else None, hc.surface_uv_map,
                                   tuple(sorted((a.name, _attribute_digest(a)) for a in hc.attributes)))
    for img in d.images:
        pixels = np.empty(len(img.pixels), np.float32)
        img.pixels.foreach_get(pixels)
        snap["image:" + img.name] = (tuple(img.size), _digest(pixels))
    snap["camera"] = bpy.context.scene.camera.name if bpy.context.scene.camera else None
    snap["active"] = bpy.context.view_layer.objects.active.name if bpy.context.view_layer.objects.active else None
    return snap


def files_snapshot(folder):
    """{relative path: sha1} of every file under `folder` (hidden temporary files included)."""
    folder = pathlib.Path(folder)
    return {str(p.relative_to(folder)): hashlib.sha1(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}

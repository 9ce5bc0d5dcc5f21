# SPDX-License-Identifier: GPL-3.0-or-later
"""Small scenes built in code for the extension tests, and a snapshot to prove that a
failed operator changed nothing."""
import numpy as np
import bpy


def clear_scene():
    data = bpy.data
    blocks = (list(data.objects) + list(data.meshes) + list(data.curves) + list(data.hair_curves)
              + list(data.cameras) + list(data.lights) + list(data.images))
    if blocks:
        data.batch_remove(blocks)


def make_scalp(name="Scalp", radius=0.1, segments=24, rings=12):
    """A UV sphere standing in for a head, made from arrays (no operators, no context)."""
    import bmesh
    mesh = bpy.data.meshes.new(name)
    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=segments, v_segments=rings, radius=radius)
    bm.to_mesh(mesh)
    bm.free()
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    return obj


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


def scene_snapshot():
    """Everything an operator could change: datablock names per type, each object's
    settings, parent and transform, key and hair geometry, images' sizes."""
    d = bpy.data
    snap = {}
    for kind in ("objects", "meshes", "curves", "hair_curves", "cameras", "images", "materials",
                 "collections", "scenes", "node_groups"):
        snap[kind] = sorted(b.name for b in getattr(d, kind))
    for obj in d.objects:
        s = obj.keystrand_hair
        props = {}
        for name in s.bl_rna.properties.keys():
            if name in ("rna_type", "name"):
                continue
            value = getattr(s, name)
            props[name] = value.name if isinstance(value, bpy.types.ID) else (
                tuple(value) if hasattr(value, "__len__") and not isinstance(value, str) else value)
        snap["obj:" + obj.name] = (props, obj.parent.name if obj.parent else None,
                                   tuple(tuple(r) for r in obj.matrix_world))
    for curve in d.curves:
        for i, spline in enumerate(curve.splines):
            co = np.empty(len(spline.bezier_points) * 3, np.float32)
            spline.bezier_points.foreach_get("co", co)
            snap[f"curve:{curve.name}:{i}"] = co.tobytes()
    for hc in d.hair_curves:
        pos = np.empty(len(hc.points) * 3, np.float32)
        if len(hc.points):
            hc.attributes["position"].data.foreach_get("vector", pos)
        snap["hair:" + hc.name] = (len(hc.curves), pos.tobytes())
    for img in d.images:
        snap["image:" + img.name] = tuple(img.size)
    snap["camera"] = bpy.context.scene.camera.name if bpy.context.scene.camera else None
    snap["active"] = bpy.context.view_layer.objects.active.name if bpy.context.view_layer.objects.active else None
    return snap

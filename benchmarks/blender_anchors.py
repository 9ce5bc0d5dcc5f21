# SPDX-License-Identifier: GPL-3.0-or-later
"""Blender doing our jobs, as the yardsticks the report measures against (SPEC §8).

* `InterpolateAnchor`: Blender's Interpolate Curves geometry node
  (`GeometryNodeInterpolateCurves`) grows ordinary strands at given roots from guide curves,
  which is exactly what `groom` does from key strands. Same roots, same keys (resampled to the
  same point count), same number of influences (3), root normals as the "up" vectors.
* `CyclesAnchor`: Blender Cycles on the CPU renders the same strands (a native hair Curves
  object, round "3D curves") with the same camera and one shadow-casting sun.

Only this module (and the sections that use it) import `bpy`; it is imported lazily so the
rest of the benchmark package works where Blender is missing.
"""
import os
import time

import numpy as np


def _bpy():
    import bpy
    return bpy


def empty_node_material(name):
    """(material, its node tree) for a new material `name` with nodes on and none in it yet."""
    mat = _bpy().data.materials.new(name)
    if hasattr(mat, "use_nodes") and not mat.use_nodes:
        mat.use_nodes = True
    nt = mat.node_tree
    nt.nodes.clear()
    return mat, nt


def reset_scene():
    bpy = _bpy()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return bpy.context.scene


def _link(obj):
    bpy = _bpy()
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _curves_object(name, points, counts, radius=None, curve_attrs=None):
    """A hair Curves object from flat arrays (bulk foreach_set only)."""
    bpy = _bpy()
    curves = bpy.data.hair_curves.new(name)
    curves.add_curves(np.asarray(counts, np.int64).tolist())
    curves.set_types(type='POLY')
    curves.position_data.foreach_set("vector", np.ascontiguousarray(points, np.float32).ravel())
    if radius is not None:
        attr = curves.attributes.get("radius") or curves.attributes.new("radius", 'FLOAT', 'POINT')
        attr.data.foreach_set("value", np.ascontiguousarray(radius, np.float32))
    for name_, values in (curve_attrs or {}).items():
        attr = curves.attributes.new(name_, 'FLOAT_VECTOR', 'CURVE')
        attr.data.foreach_set("vector", np.ascontiguousarray(values, np.float32).ravel())
    return _link(bpy.data.objects.new(name, curves))


class InterpolateAnchor:
    """Interpolate Curves on `roots` (S,3) with root normals `root_up` (S,3) from key strands
    `keys` (K,n,3) with key root normals `key_up` (K,3). `evaluate()` runs the node tree once
    (the timed job); `positions()` reads the result back as (S,n,3)."""

    def __init__(self, roots, root_up, keys, key_up, neighbors=3):
        bpy = _bpy()
        reset_scene()
        roots = np.ascontiguousarray(roots, np.float32)
        keys = np.ascontiguousarray(keys, np.float32)
        self.shape = (len(roots), keys.shape[1], 3)
        mesh = bpy.data.meshes.new("roots")
        mesh.vertices.add(len(roots))
        mesh.vertices.foreach_set("co", roots.ravel())
        up = mesh.attributes.new("up", 'FLOAT_VECTOR', 'POINT')
        up.data.foreach_set("vector", np.ascontiguousarray(root_up, np.float32).ravel())
        mesh.update()
        root_obj = _link(bpy.data.objects.new("roots", mesh))
        key_obj = _curves_object("keys", keys.reshape(-1, 3), [keys.shape[1]] * len(keys),
                                 curve_attrs={"up": key_up})
        out = bpy.data.hair_curves.new("interpolated")
        self.obj = _link(bpy.data.objects.new("interpolated", out))

        tree = bpy.data.node_groups.new("interpolate", "GeometryNodeTree")
        tree.interface.new_socket("Geometry", in_out='OUTPUT', socket_type='NodeSocketGeometry')
        nodes, links = tree.nodes, tree.links
        group_out = nodes.new("NodeGroupOutput")
        info_roots = nodes.new("GeometryNodeObjectInfo")
        info_roots.inputs["Object"].default_value = root_obj
        info_roots.transform_space = 'ORIGINAL'
        info_keys = nodes.new("GeometryNodeObjectInfo")
        info_keys.inputs["Object"].default_value = key_obj
        info_keys.transform_space = 'ORIGINAL'
        interp = nodes.new("GeometryNodeInterpolateCurves")
        interp.inputs["Max Neighbors"].default_value = int(neighbors)
        up_field = nodes.new("GeometryNodeInputNamedAttribute")
        up_field.data_type = 'FLOAT_VECTOR'
        up_field.inputs["Name"].default_value = "up"
        links.new(info_keys.outputs["Geometry"], interp.inputs["Guide Curves"])
        links.new(info_roots.outputs["Geometry"], interp.inputs["Points"])
        # The same field reads "up" on the guide curves (curve domain) and on the root points.
        links.new(up_field.outputs["Attribute"], interp.inputs["Guide Up"])
        links.new(up_field.outputs["Attribute"], interp.inputs["Point Up"])
        links.new(interp.outputs["Curves"], group_out.inputs[0])
        mod = self.obj.modifiers.new("interpolate", 'NODES')
        mod.node_group = tree
        self.depsgraph = bpy.context.evaluated_depsgraph_get()

    def invalidate(self):
        """Tag the output object so the next evaluation re-runs the whole node tree."""
        self.obj.update_tag()

    def evaluate(self):
        self.depsgraph.update()
        return self.obj.evaluated_get(self.depsgraph)

    def positions(self):
        ev = self.evaluate().data
        pos = np.empty(len(ev.points) * 3, np.float32)
        ev.position_data.foreach_get("vector", pos)
        return pos.reshape(len(ev.curves), -1, 3) if len(ev.curves) else pos.reshape(0, 0, 3)


def look_at_matrix(eye, target, up=(0.0, 0.0, 1.0)):
    """A Blender camera's matrix_world: the camera looks down its local -Z with +Y up."""
    eye = np.asarray(eye, np.float64)
    forward = np.asarray(target, np.float64) - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    if np.linalg.norm(right) < 1e-9:   # looking straight along `up`: any right will do
        right = np.cross(forward, (0.0, 1.0, 0.0))
    right /= np.linalg.norm(right)
    cam_up = np.cross(right, forward)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, cam_up, -forward, eye
    return m


class CyclesAnchor:
    """Cycles (CPU, all cores, no denoiser, no adaptive sampling) rendering hair strands.

    Material: Diffuse BSDF with the strand colour, mixed with a Transparent BSDF by the strand
    alpha — the closest Cycles node set-up to the tracer's lit-colour-plus-alpha-layers model.
    Light paths: direct light only (max bounces 0) with `layers` transparent bounces, one sun
    with a zero angle (hard shadows), film transparent, "Standard" view transform.
    """
    MATERIAL = ("Diffuse BSDF (strand colour attribute) mixed with Transparent BSDF by the strand "
                "alpha; direct light only (max bounces 0); transparent bounces = tracer layers; "
                "round 3D curves; one sun, angle 0 (hard shadows); Standard view transform")

    def __init__(self, strands, camera_matrix, lens=50.0, sensor_width=36.0, size=(512, 512),
                 sun_direction=(-0.3, 0.4, -0.85), layers=4, threads=None):
        bpy = _bpy()
        sc = reset_scene()
        self.scene = sc
        obj = None
        try:   # the project's own Strands → Curves conversion, when the extension has it
            from addon.blender_curves import strands_to_curves
            obj = strands_to_curves("hair", strands, collection=sc.collection)
            self.converter = "addon.blender_curves.strands_to_curves"
        except ImportError:
            obj = _curves_object("hair", strands.points, strands.counts, strands.radius)
            self.converter = "benchmark's own foreach_set"
        curves = obj.data
        # Cycles does not hand an attribute called "color" to shader nodes on hair curves
        # (it stays black); a copy under another name does reach the Attribute node.
        rgba = np.empty((strands.num_points, 4), np.float32)
        rgba[:, :3] = strands.color
        rgba[:, 3] = strands.alpha
        attr = curves.attributes.get("strand_rgba") or curves.attributes.new("strand_rgba", 'FLOAT_COLOR', 'POINT')
        attr.data.foreach_set("color", rgba.ravel())
        curves.materials.clear()
        curves.materials.append(self._material())
        self.hair = obj

        cam = bpy.data.cameras.new("camera")
        cam.lens = float(lens)
        cam.sensor_width = float(sensor_width)
        cam.sensor_fit = 'AUTO'
        cam.clip_start, cam.clip_end = 1e-3, 1e4
        self.camera = _link(bpy.data.objects.new("camera", cam))
        self.set_camera(camera_matrix)
        sc.camera = self.camera

        sun = bpy.data.lights.new("sun", 'SUN')
        sun.energy = 3.0
        sun.angle = 0.0
        sun_obj = _link(bpy.data.objects.new("sun", sun))
        sun_obj.matrix_world = _matrix(look_at_matrix(-np.asarray(sun_direction) * 10, (0, 0, 0)))

        sc.render.engine = 'CYCLES'
        sc.cycles.device = 'CPU'
        sc.render.threads_mode = 'FIXED'
        sc.render.threads = int(threads or os.cpu_count())
        sc.render.resolution_x, sc.render.resolution_y = int(size[0]), int(size[1])
        sc.render.resolution_percentage = 100
        sc.render.film_transparent = True
        sc.render.use_persistent_data = False   # every render pays sync + BVH, like a first render
        sc.cycles.use_denoising = False
        sc.cycles.use_adaptive_sampling = False
        sc.cycles.max_bounces = 0
        sc.cycles.transparent_max_bounces = int(layers)
        sc.cycles_curves.shape = 'THICK'
        sc.view_settings.view_transform = 'Standard'
        sc.view_settings.look = 'None'

    def _material(self):
        mat, nt = empty_node_material("hair")
        attr = nt.nodes.new("ShaderNodeAttribute")
        attr.attribute_name = "strand_rgba"
        diffuse = nt.nodes.new("ShaderNodeBsdfDiffuse")
        transparent = nt.nodes.new("ShaderNodeBsdfTransparent")
        mix = nt.nodes.new("ShaderNodeMixShader")
        out = nt.nodes.new("ShaderNodeOutputMaterial")
        nt.links.new(attr.outputs["Color"], diffuse.inputs["Color"])
        nt.links.new(attr.outputs["Alpha"], mix.inputs["Fac"])
        nt.links.new(transparent.outputs[0], mix.inputs[1])
        nt.links.new(diffuse.outputs[0], mix.inputs[2])
        nt.links.new(mix.outputs[0], out.inputs["Surface"])
        return mat

    def set_camera(self, matrix):
        self.camera.matrix_world = _matrix(matrix)

    def render(self, samples):
        """One full render (scene sync + BVH + sampling); returns its wall time in seconds."""
        bpy = _bpy()
        self.scene.cycles.samples = int(samples)
        t0 = time.perf_counter()
        bpy.ops.render.render()
        return time.perf_counter() - t0

    def save_last(self, path):
        """Write the last render (sRGB PNG with straight alpha)."""
        bpy = _bpy()
        bpy.data.images["Render Result"].save_render(filepath=os.fspath(path))


def _matrix(m):
    import mathutils
    return mathutils.Matrix(np.asarray(m, np.float64).tolist())

# SPDX-License-Identifier: GPL-3.0-or-later
"""The preview's meshes: the scalp, its collider and the scene's other visible meshes, each
read evaluated (modifiers applied) and carried into world space by its matrix, with its
material's base colour; a scene past the triangle budget keeps only the scalp and collider.
Expected arrays are read here with foreach_get, independently of the extension."""
import importlib

import numpy as np
import pytest
import bpy

from blender_scene import make_scalp, mesh_arrays


def scene_data(extension):
    return importlib.import_module(f"{extension.__name__}.addon.scene_data")


def world(obj):
    """(vertices (V,3) in world space, triangles in mesh order) of a mesh object without modifiers."""
    v, t = mesh_arrays(obj)
    m = np.array(obj.matrix_world, np.float64)
    return v @ m[:3, :3].T + m[:3, 3], t


def make_cube(name, location=(0.0, 0.0, 0.0), size=0.1):
    import bmesh
    mesh = bpy.data.meshes.new(name)
    bm = bmesh.new()
    bmesh.ops.create_cube(bm, size=size)
    bm.to_mesh(mesh)
    bm.free()
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    obj.location = location
    return obj


def principled_material(name, rgb):
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    bsdf = next(n for n in mat.node_tree.nodes if n.type == 'BSDF_PRINCIPLED')
    bsdf.inputs["Base Color"].default_value = (*rgb, 1.0)
    mat.diffuse_color = (0.1, 0.9, 0.1, 1.0)   # the viewport colour, which must not be used here
    return mat


def read(extension, scalp, budget=10 ** 9):
    ctx = bpy.context
    ctx.view_layer.update()
    return scene_data(extension).scene_meshes(ctx.scene, ctx.view_layer, ctx.evaluated_depsgraph_get(),
                                              scalp, budget)


def by_name(found):
    return {m[3]: m for m in found.meshes}


def test_scalp_collider_and_other_meshes_come_in_world_space_with_their_colours(clean):
    scalp = make_scalp(radius=0.1)
    head = make_cube("Head", size=0.3)
    body = make_cube("Body", location=(0.0, 0.0, -0.5), size=0.4)
    scalp.keystrand_hair.collider = head
    head.location, head.rotation_euler, head.scale = (0.2, -0.1, 1.5), (0.3, 0.2, 1.0), (1.0, 2.0, 0.5)
    scalp.location = (0.2, -0.1, 1.6)
    head.data.materials.append(principled_material("Skin", (0.7, 0.4, 0.3)))
    flat = bpy.data.materials.new("Flat")          # no Principled BSDF: its viewport display colour
    if flat.node_tree is not None:
        for node in [n for n in flat.node_tree.nodes if n.type == 'BSDF_PRINCIPLED']:
            flat.node_tree.nodes.remove(node)
    flat.diffuse_color = (0.2, 0.3, 0.9, 1.0)
    body.data.materials.append(flat)
    found = by_name(read(clean, scalp))
    assert sorted(found) == ["Body", "Head", "Scalp"]
    for obj, rgb in ((scalp, (0.8, 0.8, 0.8)), (head, (0.7, 0.4, 0.3)), (body, (0.2, 0.3, 0.9))):
        vertices, triangles, colour, _ = found[obj.name]
        v, t = world(obj)
        np.testing.assert_allclose(vertices, v, atol=1e-9)
        np.testing.assert_array_equal(triangles, t)
        np.testing.assert_allclose(colour, rgb, atol=1e-6)


def test_hidden_meshes_stay_out_but_the_scalp_and_collider_show_when_hidden_in_the_viewport(clean):
    scalp = make_scalp()
    head = make_cube("Head", size=0.3)
    scalp.keystrand_hair.collider = head
    make_cube("Not Rendered").hide_render = True
    make_cube("Hidden").hide_set(True)
    make_cube("Shown")
    head.hide_set(True)       # hidden while drawing keys on the scalp: still the head of the render
    assert sorted(by_name(read(clean, scalp))) == ["Head", "Scalp", "Shown"]
    scalp.hide_render = True  # Add Head's scalp: a wire on the head, left out of renders
    assert sorted(by_name(read(clean, scalp))) == ["Head", "Shown"]


def test_meshes_are_read_with_their_modifiers(clean):
    scalp = make_scalp()
    cube = make_cube("Smooth")
    cube.modifiers.new("Subdivision", 'SUBSURF').levels = 2
    found = read(clean, scalp)
    vertices, triangles, _, _ = by_name(found)["Smooth"]
    assert len(triangles) == 6 * 16 * 2      # each quad of the cube made 16 quads, 2 triangles each
    assert len(vertices) == 98
    # Subdivision pulls the corners in: nothing reaches the cube's corner any more.
    assert np.abs(vertices).max() < 0.05 - 1e-3
    assert found.triangles == sum(len(m[1]) for m in found.meshes) and found.skipped == 0


def test_each_material_of_a_mesh_keeps_its_colour(clean):
    scalp = make_scalp()
    cube = make_cube("Two Tone")
    cube.data.materials.append(principled_material("Red", (0.9, 0.1, 0.1)))
    cube.data.materials.append(principled_material("Blue", (0.1, 0.1, 0.9)))
    top = np.zeros(len(cube.data.polygons), np.int32)
    normals = np.empty(3 * len(top))
    cube.data.polygons.foreach_get("normal", normals)
    top[normals.reshape(-1, 3)[:, 2] > 0.5] = 1     # the top face blue, the rest red
    cube.data.polygons.foreach_set("material_index", top)
    cube.data.update()
    found = by_name(read(clean, scalp))
    red, blue = found["Two Tone (Red)"], found["Two Tone (Blue)"]
    np.testing.assert_allclose(red[2], (0.9, 0.1, 0.1), atol=1e-6)
    np.testing.assert_allclose(blue[2], (0.1, 0.1, 0.9), atol=1e-6)
    assert len(red[1]) == 10 and len(blue[1]) == 2
    assert np.allclose(blue[0][blue[1]][..., 2], 0.05)   # the blue triangles are the top face's


@pytest.mark.parametrize("linked", [False, True])
def test_a_textured_base_colour_falls_back_to_the_viewport_colour(clean, linked):
    mat = principled_material("Skin", (0.7, 0.4, 0.3))
    if linked:
        tree = mat.node_tree
        tex = tree.nodes.new('ShaderNodeTexNoise')
        bsdf = next(n for n in tree.nodes if n.type == 'BSDF_PRINCIPLED')
        tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    got = scene_data(clean).material_base_color(mat)
    np.testing.assert_allclose(got, (0.1, 0.9, 0.1) if linked else (0.7, 0.4, 0.3), atol=1e-6)


def test_past_the_budget_only_the_scalp_and_collider_are_shown(clean):
    scalp = make_scalp(segments=24, rings=12)
    head = make_cube("Head", size=0.3)
    scalp.keystrand_hair.collider = head
    body = make_cube("Body", location=(0.0, 0.0, -0.5))
    body.modifiers.new("Subdivision", 'SUBSURF').levels = 3     # 6 * 64 quads: 768 triangles
    everything = read(clean, scalp)
    assert sorted(by_name(everything)) == ["Body", "Head", "Scalp"] and everything.skipped == 0
    own = len(mesh_arrays(scalp)[1]) + 12
    assert everything.triangles == own + 768
    within = read(clean, scalp, budget=own + 768)
    assert within.triangles == own + 768
    past = read(clean, scalp, budget=own + 767)
    assert sorted(by_name(past)) == ["Head", "Scalp"]
    assert past.triangles == own and past.skipped == 768

# SPDX-License-Identifier: GPL-3.0-or-later
"""The head a hairstyle sits on: Add Head (the bundled head and its scalp), presets landing
on any head (the bundled one moved and turned, real scalps imported with Blender's OBJ
importer), and the head's axes that Generate and Load Preset share."""
import importlib
import pathlib

import numpy as np
import pytest
import bpy

from blender_scene import activate, in_mesh_order, make_scalp, mesh_arrays, scene_snapshot

DATA = pathlib.Path(__file__).resolve().parents[3] / "shared" / "data"
REAL_HEADS = ("neuralhaircut_final_scalp.obj", "usc_head_model.obj")


def ext_module(extension, name):
    return importlib.import_module(f"{extension.__name__}.addon.{name}")


def bundled_presets():
    from groom import list_presets
    names = list_presets()
    assert len(names) >= 5, names
    return names


def mesh_surface(obj):
    """groom.Scalp of a mesh object in its own coordinates, read here with foreach_get
    (not through the extension)."""
    from groom import Scalp
    return Scalp(*mesh_arrays(obj))


def key_roots(scalp):
    """First control point of each of the scalp's key strands, in the scalp's coordinates
    (keys are parented with an identity inverse, so their own coordinates are the scalp's)."""
    keys = sorted((o for o in bpy.data.objects if o.keystrand_hair.role == 'KEY' and o.keystrand_hair.scalp == scalp),
                  key=lambda o: o.name)
    for k in keys:
        assert k.parent == scalp and np.allclose(np.array(k.matrix_parent_inverse), np.eye(4))
    return np.array([k.data.splines[0].bezier_points[0].co for k in keys], np.float64)


def import_obj(name):
    path = DATA / name
    if not path.is_file():
        pytest.fail(f"{path} is missing: the real scalps live in ../shared/data")
    before = set(bpy.data.objects)
    assert bpy.ops.wm.obj_import(filepath=str(path)) == {'FINISHED'}
    new = [o for o in bpy.data.objects if o not in before and o.type == 'MESH']
    assert len(new) == 1, [o.name for o in new]
    obj = new[0]
    bpy.context.view_layer.update()
    activate(obj)
    return obj


def spacing(roots, size):
    """Smallest distance between two roots, as a fraction of the head's size."""
    d = np.linalg.norm(roots[:, None] - roots[None], axis=2)
    d[np.eye(len(roots), dtype=bool)] = np.inf
    return float(d.min()) / size


def assert_every_key_on_its_own_root(obj, roots, count, name):
    """Each root on the mesh, and no two on the same place. 'The same place' is measured
    against the bundled head: there the closest two keys of a preset are ~6 % of the head's
    size apart; keys closer than a tenth of that have collapsed onto one root."""
    assert len(roots) == count, f"{name}: {len(roots)} keys for {count} in the preset"
    surface = mesh_surface(obj)
    size = float(np.ptp(surface.vertices, axis=0).max())
    _, _, on = surface.closest_points(roots)
    off = float(np.linalg.norm(on - roots, axis=1).max())
    assert off < 1e-5 * size, f"{name}: a root lies {off:.3g} off the mesh"
    if count > 1:
        assert spacing(roots, size) > 0.006, f"{name}: keys share a root (spacing {spacing(roots, size):.4f})"


# --- Add Head ------------------------------------------------------------------------------

def add_head(**kwargs):
    assert bpy.ops.hair.add_head(**kwargs) == {'FINISHED'}
    scalp = bpy.context.view_layer.objects.active
    bpy.context.view_layer.update()
    return scalp.parent, scalp


def test_add_head_makes_a_closed_head_with_the_bundled_scalp_on_it(clean):
    from groom import default_head, default_scalp
    other = make_scalp("Other")
    bpy.context.scene.cursor.location = (0.4, -0.3, 1.2)
    head, scalp = add_head()
    # Ready for Load Preset: the scalp alone selected and active, with its role.
    assert scalp is not None and head is not None and head.type == 'MESH' and scalp.type == 'MESH'
    assert scalp.keystrand_hair.role == 'SCALP'
    assert bpy.context.selected_objects == [scalp] and not other.select_get()
    assert ext_module(clean, "scene_data").find_scalp(bpy.context) == scalp
    # At the 3D cursor, the scalp exactly on the head.
    np.testing.assert_allclose(np.array(head.matrix_world), np.array(((1, 0, 0, 0.4), (0, 1, 0, -0.3),
                                                                       (0, 0, 1, 1.2), (0, 0, 0, 1))), atol=1e-6)
    np.testing.assert_array_equal(np.array(scalp.matrix_world), np.array(head.matrix_world))
    # The bundled arrays (the same triangles, wound the same way), the scalp with its UVs.
    want_head, want_scalp = default_head(), default_scalp()
    got_head, got_scalp = mesh_surface(head), mesh_surface(scalp)
    np.testing.assert_allclose(got_head.vertices, want_head.vertices, atol=1e-7)
    np.testing.assert_array_equal(got_head.triangles, in_mesh_order(want_head.triangles))
    np.testing.assert_allclose(got_scalp.vertices, want_scalp.vertices, atol=1e-7)
    np.testing.assert_array_equal(got_scalp.triangles, in_mesh_order(want_scalp.triangles))
    uv = np.empty(len(scalp.data.loops) * 2, np.float32)
    scalp.data.uv_layers.active.uv.foreach_get("vector", uv)
    np.testing.assert_allclose(uv.reshape(-1, 2), want_scalp.uv[want_scalp.triangles.ravel()], atol=1e-6)
    # Closed and consistently wound: every directed edge once, its reverse once.
    t = got_head.triangles
    directed = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    assert len(np.unique(directed, axis=0)) == len(directed), "an edge is walked twice the same way"
    assert {tuple(e) for e in directed} == {tuple(e) for e in directed[:, ::-1]}, "the head has a hole"
    # Wound outward: the enclosed volume is positive.
    p = got_head.vertices[t]
    assert np.einsum("td,td->t", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum() > 0
    # The scalp lies on the head (in the head's coordinates, which are the scalp's).
    _, _, on = got_head.closest_points(got_scalp.vertices)
    assert np.linalg.norm(on - got_scalp.vertices, axis=1).max() < 1e-3 * 0.2


def test_failed_add_head_leaves_nothing_behind(clean, monkeypatch):
    add_head_module = ext_module(clean, "add_head")
    other = make_scalp("Other")
    real = add_head_module._add_mesh_object
    calls = []

    def fail_after_the_second(*args, **kwargs):
        obj = real(*args, **kwargs)
        calls.append(obj.name)
        if len(calls) == 2:  # head and scalp made and linked, nothing set up yet
            raise RuntimeError("disk on fire")
        return obj

    monkeypatch.setattr(add_head_module, "_add_mesh_object", fail_after_the_second)
    before = scene_snapshot()
    with pytest.raises(RuntimeError, match="disk on fire"):
        bpy.ops.hair.add_head()
    assert len(calls) == 2
    assert scene_snapshot() == before
    assert other.select_get() and bpy.context.view_layer.objects.active == other


def test_the_head_stands_for_its_scalp_when_it_is_the_active_object(clean):
    """A click on Add Head's head makes the head active (the scalp on it is a wire): the
    panel and the operators then work on the scalp, not on the head."""
    find_scalp = ext_module(clean, "scene_data").find_scalp
    head, scalp = add_head()
    activate(head)
    assert find_scalp(bpy.context) == scalp
    assert bpy.ops.hair.load_preset(preset="wavy") == {'FINISHED'}
    scalp.keystrand_hair.count = 200
    activate(head)
    assert bpy.ops.hair.generate() == {'FINISHED'}
    assert scalp.keystrand_hair.hair_object is not None and head.keystrand_hair.hair_object is None
    assert head.keystrand_hair.role == 'NONE'
    # The scalp itself, a mesh with no scalp on it, and one whose child is not a scalp: themselves.
    activate(scalp)
    assert find_scalp(bpy.context) == scalp
    plain, child = make_scalp("Plain"), make_scalp("Child")
    child.parent = plain
    activate(plain)
    assert find_scalp(bpy.context) == plain
    child.keystrand_hair.role = 'SCALP'
    assert find_scalp(bpy.context) == child
    plain.keystrand_hair.role = 'SCALP'  # a scalp on a scalp: the active one is meant
    assert find_scalp(bpy.context) == plain


def test_add_head_is_in_the_add_menu_and_in_the_panel_without_a_scalp(clean):
    ours = lambda f: getattr(f, "__module__", "").startswith(clean.__name__)  # noqa: E731
    assert [f for f in bpy.types.VIEW3D_MT_add._dyn_ui_initialize() if ours(f)]
    shown = []

    class Layout:
        def operator(self, idname, **kwargs):
            shown.append(idname)

        def __getattr__(self, name):
            return lambda *a, **k: self

    activate(None)
    panel = bpy.types.VIEW3D_PT_keystrand_hair
    assert panel.poll(bpy.context)
    panel.draw(type("P", (), {"layout": Layout()})(), bpy.context)
    assert shown == ["hair.add_head"]


def test_disabling_removes_add_head_and_its_menu_entry(extension, ext_enable):
    enable, disable = ext_enable
    ours = lambda f: getattr(f, "__module__", "").startswith(extension.__name__)  # noqa: E731
    disable()
    try:
        assert not [f for f in bpy.types.VIEW3D_MT_add._dyn_ui_initialize() if ours(f)]
        assert not hasattr(bpy.types, "HAIR_OT_add_head")
    finally:
        enable()
    assert hasattr(bpy.types, "HAIR_OT_add_head")


# --- presets on any head -------------------------------------------------------------------

@pytest.mark.parametrize("obj_name", REAL_HEADS)
def test_every_preset_lands_on_its_own_roots_on_a_real_scalp(clean, obj_name):
    """Through the operator: the OBJ importer leaves the mesh Y up with a rotation on the
    object, and the anchors still reach distinct places on it, the ones head.place_preset
    finds with the scalp's axes (whose frame the next test checks is upright)."""
    from groom import load_preset
    head = ext_module(clean, "head")
    scene_data = ext_module(clean, "scene_data")
    obj = import_obj(obj_name)
    assert abs(obj.rotation_euler[0]) > 1.0, "the importer no longer turns a Y-up file: this test needs it"
    surface = scene_data.read_scalp(obj, bpy.context.evaluated_depsgraph_get())
    for name in bundled_presets():
        activate(obj)
        assert bpy.ops.hair.load_preset(preset=name) == {'FINISHED'}, name
        roots = key_roots(obj)
        assert_every_key_on_its_own_root(obj, roots, len(load_preset(name).key_specs), f"{obj_name} {name}")
        placed = np.array([k.root for k in head.place_preset(load_preset(name), obj, surface).keys])
        np.testing.assert_allclose(roots, placed, atol=1e-6, err_msg=f"{obj_name} {name}")


@pytest.mark.parametrize("obj_name", REAL_HEADS)
def test_place_preset_fits_the_head_with_the_scalp_s_own_axes(clean, obj_name):
    """head.place_preset on its own: the frame it fits is upright in the scene (the importer's
    rotation carried into the mesh), and every key lands on its own root."""
    from groom import load_preset
    head = ext_module(clean, "head")
    scene_data = ext_module(clean, "scene_data")
    obj = import_obj(obj_name)
    surface = scene_data.read_scalp(obj, bpy.context.evaluated_depsgraph_get())
    m = np.array(obj.matrix_world)[:3, :3]
    for name in bundled_presets():
        placement = head.place_preset(load_preset(name), obj, surface)
        up_in_scene = m @ placement.frame.up
        front_in_scene = m @ placement.frame.front
        np.testing.assert_allclose(up_in_scene / np.linalg.norm(up_in_scene), (0, 0, 1), atol=1e-6)
        np.testing.assert_allclose(front_in_scene / np.linalg.norm(front_in_scene), (0, -1, 0), atol=1e-6)
        roots = np.array([k.root for k in placement.keys])
        assert_every_key_on_its_own_root(obj, roots, len(load_preset(name).key_specs), f"{obj_name} {name}")
        assert not placement.collapsed, f"{obj_name} {name}: {placement.warning()}"


def test_presets_land_the_same_on_a_moved_and_turned_head(clean):
    """The bundled head's axes are its mesh's, so turning and moving the head carries the
    keys with it: in the scalp's coordinates they are where they are on the head at rest."""
    from groom import load_preset
    _, rest = add_head()
    expected = {}
    for name in bundled_presets():
        activate(rest)
        assert bpy.ops.hair.load_preset(preset=name) == {'FINISHED'}
        expected[name] = key_roots(rest)
    head, scalp = add_head(location=(0.7, -1.1, 0.4), rotation=(0.5, -0.3, 2.0))
    assert not np.allclose(np.array(scalp.matrix_world)[:3, :3], np.eye(3), atol=0.1)
    for name in bundled_presets():
        activate(scalp)
        assert bpy.ops.hair.load_preset(preset=name) == {'FINISHED'}
        roots = key_roots(scalp)
        assert_every_key_on_its_own_root(scalp, roots, len(load_preset(name).key_specs), name)
        np.testing.assert_allclose(roots, expected[name], atol=1e-6, err_msg=name)


# --- the head's axes -----------------------------------------------------------------------

def test_an_imported_head_is_read_upright_in_the_scene(clean):
    """The OBJ importer keeps a Y-up file Y up in the mesh: Scene axes find up at the mesh's
    +Y and the face at +Z, and Generate's parameters carry the same axes as the placement."""
    head = ext_module(clean, "head")
    properties = ext_module(clean, "properties")
    obj = import_obj(REAL_HEADS[1])
    up, front = head.scalp_axes(obj)
    np.testing.assert_allclose(up, (0, 1, 0), atol=1e-6)
    np.testing.assert_allclose(front, (0, 0, 1), atol=1e-6)
    params = properties.groom_params(obj.keystrand_hair)
    assert params.up == up and params.front == front


def test_switching_head_axes_keeps_the_hair(clean):
    """Scene <-> Mesh rewrites Up and Front in the other space: on a scalp moved but not
    turned the values and the hair are identical bit for bit; on a turned one the axes stay."""
    head = ext_module(clean, "head")
    hair = ext_module(clean, "hair")
    scene_data = ext_module(clean, "scene_data")
    scalp = make_scalp()
    scalp.location = (0.3, -0.2, 1.5)
    bpy.context.view_layer.update()
    assert bpy.ops.hair.load_preset(preset="wavy") == {'FINISHED'}
    s = scalp.keystrand_hair
    s.up, s.front = (0.2, 0.1, 1.0), (0.1, -1.0, 0.05)  # not the defaults: any axes carry over
    surface, keys = hair.read_inputs(scalp, bpy.context.evaluated_depsgraph_get())

    def strands():
        return hair.build_generator(surface, keys, s, count=400)[1].strands

    assert s.head_axes == 'WORLD'
    world_axes, world = head.scalp_axes(scalp), strands()
    s.head_axes = 'LOCAL'
    assert head.scalp_axes(scalp) == world_axes
    local = strands()
    np.testing.assert_array_equal(local.points, world.points)
    np.testing.assert_array_equal(local.counts, world.counts)
    # Turned: the mesh's axes differ from the scene's, and switching still keeps them.
    s.head_axes = 'WORLD'
    scalp.rotation_euler = (1.5707963, 0.0, 0.4)
    bpy.context.view_layer.update()
    turned = head.scalp_axes(scalp)
    assert not np.allclose(turned[0], world_axes[0], atol=0.1)
    s.head_axes = 'LOCAL'
    np.testing.assert_allclose(head.scalp_axes(scalp), turned, atol=1e-6)
    assert not np.allclose(tuple(s.up), (0.2, 0.1, 1.0), atol=0.1)  # now the mesh's own numbers


def test_head_axes_decide_the_hair_on_a_turned_scalp(clean):
    """The setting is used: on a turned scalp, Scene and Mesh axes with the same numbers
    grow different hair (so the identical hair above is not an accident)."""
    hair = ext_module(clean, "hair")
    scalp = make_scalp()
    scalp.rotation_euler = (1.5707963, 0.0, 0.0)
    bpy.context.view_layer.update()
    assert bpy.ops.hair.load_preset(preset="wavy") == {'FINISHED'}
    s = scalp.keystrand_hair
    surface, keys = hair.read_inputs(scalp, bpy.context.evaluated_depsgraph_get())
    world = hair.build_generator(surface, keys, s, count=200)[1].strands.points
    s.head_axes = 'LOCAL'
    s.up, s.front = (0.0, 0.0, 1.0), (0.0, -1.0, 0.0)  # the same numbers, now in the mesh
    local = hair.build_generator(surface, keys, s, count=200)[1].strands.points
    assert world.shape == local.shape and np.abs(world - local).max() > 1e-3


def test_load_preset_places_its_keys_with_the_head_s_own_axes(clean):
    """A preset describes a hairstyle, not a head: on a scalp whose head is Y up and faces +Z
    in its mesh, the keys land where the preset placed with those axes puts them, not where
    its own (Z up) axes would, and Generate then grows hair with the same axes."""
    from groom import load_preset
    scalp = make_scalp()
    s = scalp.keystrand_hair
    s.head_axes = 'LOCAL'
    s.up, s.front = (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
    assert bpy.ops.hair.load_preset(preset="wavy", replace=True) == {'FINISHED'}
    preset = load_preset(clean.__path__[0] + "/presets/wavy.json")
    surface = mesh_surface(scalp)
    mine = np.array([k.root for k in preset.place_keys(surface, up=(0, 1, 0), front=(0, 0, 1)).keys])
    its_own = np.array([k.root for k in preset.place_keys(surface).keys])
    roots = key_roots(scalp)
    np.testing.assert_allclose(roots, mine, atol=1e-6)
    assert np.abs(roots - its_own).max() > 0.02, "the preset's own axes give the same roots: no proof"
    assert ext_module(clean, "properties").groom_params(s).up == (0.0, 1.0, 0.0)


def test_a_flattened_scalp_is_reported_not_raised(clean):
    head = ext_module(clean, "head")
    scene_data = ext_module(clean, "scene_data")
    scalp = make_scalp()
    scalp.scale = (1.0, 0.0, 1.0)
    bpy.context.view_layer.update()
    with pytest.raises(scene_data.InputError, match="zero scale.*Head Axes to Mesh"):
        head.scalp_axes(scalp)

# SPDX-License-Identifier: GPL-3.0-or-later
"""The artist's path through the installed extension: keys by surface point, Generate,
live update, Render Preview, presets, export, each checked against a direct call of the
pure packages on arrays read here independently of the extension."""
import importlib
import json

import numpy as np
import pytest
import bpy

from blender_scene import activate, make_camera, make_scalp, mesh_arrays

KEY_POINTS = [(0.0, 0.0, 0.1), (0.07, 0.0, 0.07), (-0.07, 0.0, 0.07), (0.0, -0.07, 0.07), (0.0, 0.07, 0.07)]


def ext_module(extension, name):
    return importlib.import_module(f"{extension.__name__}.addon.{name}")


def add_keys(scalp, points=KEY_POINTS, shape='STRAIGHT'):
    scalp.keystrand_hair.key_shape = shape
    for p in points:
        activate(scalp)
        assert bpy.ops.hair.add_key_strand(location=p) == {'FINISHED'}
    activate(scalp)
    return sorted((o for o in bpy.data.objects if o.type == 'CURVE'), key=lambda o: o.name)


def read_scalp_arrays(obj):
    """groom.Scalp from the mesh, read here with foreach_get (not through the extension)."""
    from groom import Scalp
    return Scalp(*mesh_arrays(obj))


def read_key(obj):
    """groom.KeyStrand of a Bézier key object whose coordinates are the scalp's."""
    from groom import KeyStrand
    bp = obj.data.splines[0].bezier_points
    co = np.array([p.co for p in bp], float)
    left = np.array([p.handle_left for p in bp], float)
    right = np.array([p.handle_right for p in bp], float)
    rows = [co[0]]
    for i in range(1, len(co)):
        rows += [right[i - 1], left[i], co[i]]
    return KeyStrand(np.array(rows), kind="cubic")


def params_of(scalp, **overrides):
    """GroomParams with the values Blender holds (its float properties are float32, so
    0.7 reads back as 0.699999988: the direct call must use the same numbers)."""
    import dataclasses
    from groom import GroomParams
    s = scalp.keystrand_hair
    values = {}
    for field in dataclasses.fields(GroomParams):
        if field.name in s.bl_rna.properties:
            v = getattr(s, field.name)
            values[field.name] = tuple(v) if hasattr(v, "__len__") and not isinstance(v, str) else v
    values.update(overrides)
    return GroomParams(**values)


def curves_arrays(obj):
    c = obj.data
    offsets = np.empty(len(c.curves) + 1, np.int32)
    c.curve_offset_data.foreach_get("value", offsets)
    n = len(c.points)
    out = {"counts": np.diff(offsets)}
    for name, width, key in (("position", 3, "vector"), ("radius", 1, "value"), ("strand_rgba", 4, "color"),
                             ("alpha", 1, "value")):
        a = np.empty(n * width, np.float32)
        c.attributes[name].data.foreach_get(key, a)
        out[name] = a.reshape(n, width) if width > 1 else a
    wisp = np.empty(len(c.curves), np.int32)
    c.attributes["wisp"].data.foreach_get("value", wisp)
    out["wisp"] = wisp
    return out


def test_add_key_strand_grows_a_bezier_key_from_the_nearest_surface_point(clean):
    scalp = make_scalp()
    keys = add_keys(scalp, [(0.0, 0.0, 0.13), (0.1, 0.0, 0.0)])
    assert len(keys) == 2
    surface = read_scalp_arrays(scalp)
    for key in keys:
        assert key.data.splines[0].type == 'BEZIER' and len(key.data.splines[0].bezier_points) >= 4
        assert key.parent == scalp and key.keystrand_hair.role == 'KEY' and key.keystrand_hair.scalp == scalp
        root = np.array(key.data.splines[0].bezier_points[0].co)
        _, _, nearest = surface.closest_points(root[None])
        assert np.linalg.norm(nearest[0] - root) < 1e-6, "the key's root is not on the scalp"
    # The key asked for at (0, 0, 0.13) roots at the top of the sphere and starts outward.
    top = keys[0].data.splines[0].bezier_points
    assert np.allclose(top[0].co, (0.0, 0.0, 0.1), atol=2e-3)
    assert top[1].co.z > top[0].co.z


def test_add_key_strand_follows_the_head_s_axes_on_a_turned_scalp(clean):
    """A head imported Y up (a quarter turn on the object): the key still falls down the
    head in the scene, with the scene's Up, as the hair Generate grows beside it."""
    scalp = make_scalp()
    scalp.rotation_euler = (1.5708, 0.0, 0.0)
    bpy.context.view_layer.update()
    (key,) = add_keys(scalp, [(0.0, -0.08, 0.06)])
    m = np.array(key.matrix_world)
    bp = key.data.splines[0].bezier_points
    root, tip = ((m @ np.append(np.array(bp[i].co), 1.0))[:3] for i in (0, -1))
    assert tip[2] < root[2] - 0.05, (root, tip)
    assert abs(tip[0] - root[0]) < 0.02


def test_generate_writes_the_curves_groom_computes(clean):
    from groom import generate
    scalp = make_scalp()
    keys = add_keys(scalp)
    s = scalp.keystrand_hair
    s.count, s.seed, s.tidiness = 1500, 3, 0.7
    assert bpy.ops.hair.generate() == {'FINISHED'}
    hair = s.hair_object
    assert hair is not None and hair.type == 'CURVES' and hair.parent == scalp
    assert hair.keystrand_hair.role == 'HAIR'
    material = hair.data.materials[0]
    attribute_nodes = [n for n in material.node_tree.nodes if n.type == 'ATTRIBUTE']
    assert [n.attribute_name for n in attribute_nodes] == ["strand_rgba"], "the material does not show the hair colour"
    surface = read_scalp_arrays(scalp)
    # With no Collider set, the scalp itself is the collider.
    expected = generate(surface, [read_key(k) for k in keys], params_of(scalp),
                        collider=(surface.vertices, surface.triangles)).strands
    assert params_of(scalp).tidiness == pytest.approx(0.7) and params_of(scalp).count == 1500
    got = curves_arrays(hair)
    assert len(got["counts"]) == 1500 == expected.num_strands
    np.testing.assert_array_equal(got["counts"], expected.counts)
    np.testing.assert_array_equal(got["position"], expected.points)
    np.testing.assert_array_equal(got["radius"], expected.radius)
    np.testing.assert_array_equal(got["strand_rgba"][:, :3], expected.color)
    np.testing.assert_array_equal(got["alpha"], expected.alpha)
    np.testing.assert_array_equal(got["wisp"], expected.wisp)


def _mixed_faces():
    """A mesh of triangles, quads and an ngon: a UV sphere (quads, triangle fans at the
    poles) with a hexagon beside it."""
    import bmesh
    obj = make_scalp(segments=12, rings=6)
    bm = bmesh.new()
    bm.from_mesh(obj.data)
    angles = np.linspace(0.0, 2.0 * np.pi, 7)[:-1]
    bm.faces.new([bm.verts.new((0.3 + 0.05 * np.cos(a), 0.05 * np.sin(a), 0.0)) for a in angles])
    bm.to_mesh(obj.data)
    bm.free()
    assert {len(p.vertices) for p in obj.data.polygons} == {3, 4, 6}
    return obj


def test_the_scalp_s_triangles_are_read_in_the_mesh_s_own_order(clean):
    """Not in Blender's order of loop triangles (it changed between versions): each from its
    smallest vertex, sorted by vertices, as worked out here apart."""
    scene_data = ext_module(clean, "scene_data")
    obj = _mixed_faces()
    v, t = mesh_arrays(obj)
    for depsgraph in (None, bpy.context.evaluated_depsgraph_get()):
        surface = scene_data.read_scalp(obj, depsgraph)
        np.testing.assert_array_equal(surface.vertices, v)
        np.testing.assert_array_equal(surface.triangles, t)


def test_a_shuffled_order_of_loop_triangles_grows_the_same_hair(clean):
    """Blender 5.3 lists the loop triangles of 5.0 in another order, each started at another
    corner: read the extension's way, both grow the same hair (read as listed, they would not)."""
    from groom import GroomParams, KeyStrand, Scalp, generate
    scene_data = ext_module(clean, "scene_data")
    obj = make_scalp()
    mesh = obj.data
    mesh.calc_loop_triangles()
    listed = np.empty(3 * len(mesh.loop_triangles), np.int64)
    mesh.loop_triangles.foreach_get("vertices", listed)
    listed = listed.reshape(-1, 3)
    rs = np.random.default_rng(7)
    turn = rs.integers(0, 3, len(listed))[:, None]
    shuffled = np.take_along_axis(listed[rs.permutation(len(listed))], (turn + np.arange(3)) % 3, axis=1)
    v, _ = mesh_arrays(obj)
    key = KeyStrand(np.array([[0.0, 0.0, 0.1], [0.02, 0.0, 0.14], [0.06, 0.0, 0.12], [0.09, 0.0, 0.02]]))
    params = GroomParams(count=300, collision=False)

    def grown(triangles):
        return generate(Scalp(v, triangles), [key], params).strands.points

    canonical = scene_data.canonical_triangles(listed)
    np.testing.assert_array_equal(scene_data.canonical_triangles(shuffled), canonical)
    np.testing.assert_array_equal(grown(canonical), grown(scene_data.canonical_triangles(shuffled)))
    assert not np.array_equal(grown(listed), grown(shuffled)), \
        "the order of the triangles does not matter: the test proves nothing"


def test_generate_again_refills_the_same_hair_object(clean):
    scalp = make_scalp()
    add_keys(scalp)
    scalp.keystrand_hair.count = 300
    bpy.ops.hair.generate()
    first = scalp.keystrand_hair.hair_object
    scalp.keystrand_hair.count = 500
    activate(scalp)
    bpy.ops.hair.generate()
    assert scalp.keystrand_hair.hair_object == first
    assert len(first.data.curves) == 500
    assert len([o for o in bpy.data.objects if o.type == 'CURVES']) == 1


@pytest.mark.parametrize("change", ["colour", "count"])
def test_generate_again_keeps_what_the_artist_gave_the_hair_s_datablock(clean, change):
    """Generate rewrites the hair's Curves datablock (keeping a copy for the undo until the
    press succeeds, and in 4.2 replacing it on a new strand layout): the artist's name,
    material, settings, custom property, own attribute (its values too while the strand
    layout is unchanged) and every user carry over, and no other Curves datablock is left."""
    scalp = make_scalp()
    add_keys(scalp)
    scalp.keystrand_hair.count = 300
    bpy.ops.hair.generate()
    hair = scalp.keystrand_hair.hair_object
    data = hair.data
    data.name = "Artist's Hair"
    material = bpy.data.materials.new("Artist's Material")
    data.materials[0] = material
    data.use_fake_user = True
    data["artist_note"] = 7
    mine = data.attributes.new("artist_mask", 'FLOAT', 'CURVE')
    mask = np.linspace(0.0, 1.0, 300, dtype=np.float32)
    mine.data.foreach_set("value", mask)
    before = np.empty(len(data.points) * 4, np.float32)
    data.attributes["strand_rgba"].data.foreach_get("color", before)
    twin = bpy.data.objects.new("Twin", data)
    bpy.context.scene.collection.objects.link(twin)
    if change == "colour":
        scalp.keystrand_hair.color = (0.9, 0.1, 0.1)
    else:
        scalp.keystrand_hair.count = 400
    activate(scalp)
    assert bpy.ops.hair.generate() == {'FINISHED'}
    data = hair.data
    assert twin.data == data and [c.name for c in bpy.data.hair_curves] == ["Artist's Hair"]
    assert list(data.materials) == [material] and data.surface == scalp and data.use_fake_user
    assert data["artist_note"] == 7 and data.users == 3  # two objects and the fake user
    assert len(data.curves) == (300 if change == "colour" else 400)
    if change == "colour":
        rgba = np.empty(len(data.points) * 4, np.float32)
        data.attributes["strand_rgba"].data.foreach_get("color", rgba)
        assert not np.allclose(rgba, before)  # written, not the old datablock kept
    mine = data.attributes.get("artist_mask")
    assert mine is not None and mine.domain == 'CURVE' and mine.data_type == 'FLOAT'
    if change == "colour":
        back = np.empty(300, np.float32)
        mine.data.foreach_get("value", back)
        assert np.array_equal(back, mask)


def test_the_settings_read_into_groom_are_exactly_groom_s_parameters(clean):
    """The add-on's list of model settings and GroomParams' fields are the same names: a
    parameter added to groom without a setting (or a setting groom does not know) fails."""
    import dataclasses
    from groom import GroomParams
    properties = ext_module(clean, "properties")
    s = make_scalp().keystrand_hair
    fields = {f.name for f in dataclasses.fields(GroomParams)}
    assert set(properties.settings_to_dict(s)) == fields
    assert set(properties.PARAM_FIELDS) == fields - {"parting"}  # parting: its five settings
    assert all(name in s.bl_rna.properties for name in properties.PARAM_FIELDS + properties.PARTING_FIELDS)


def test_each_setting_has_its_parameter_s_type_default_and_choices(clean):
    from groom import GroomParams
    from groom import params as groom_params
    from groom.sampling import SAMPLING_MODES
    properties = ext_module(clean, "properties")
    s = make_scalp().keystrand_hair
    defaults = GroomParams()
    choices = {"sampling_mode": SAMPLING_MODES, "normal_mode": groom_params.NORMAL_MODES,
               "neighbour_mode": groom_params.NEIGHBOUR_MODES, "resolution_mode": groom_params.RESOLUTION_MODES,
               "tolerance_units": groom_params.TOLERANCE_UNITS, "radius_mode": groom_params.RADIUS_MODES}
    for name in properties.PARAM_FIELDS:
        prop, value, default = s.bl_rna.properties[name], getattr(s, name), getattr(defaults, name)
        assert prop.description, f"setting {name} has no tooltip"
        if isinstance(default, bool):
            assert prop.type == 'BOOLEAN' and value == default, name
        elif isinstance(default, int):
            assert prop.type == 'INT' and value == default, name
        elif isinstance(default, float):
            assert prop.type == 'FLOAT' and not prop.is_array and value == pytest.approx(default, rel=1e-6), name
        elif isinstance(default, tuple):
            assert prop.type == 'FLOAT' and prop.array_length == len(default), name
            assert np.allclose(tuple(value), default, atol=1e-6), name
        else:
            assert prop.type == 'ENUM' and value == default, name
            assert {item.identifier for item in prop.enum_items} == set(choices[name]), name
    # Parting off by default, as GroomParams' parting None.
    assert defaults.parting is None and not s.use_parting


def test_every_value_a_setting_allows_groom_accepts(clean):
    """The settings' hard limits lie inside groom's ranges: an artist cannot type a value
    that Generate then refuses (only min > max length, checked by groom, remains)."""
    properties = ext_module(clean, "properties")
    scalp = make_scalp()
    s = scalp.keystrand_hair
    tried = 0
    for name in properties.PARAM_FIELDS:
        prop = s.bl_rna.properties[name]
        if prop.type not in ('INT', 'FLOAT'):
            continue
        for bound in (prop.hard_min, prop.hard_max):
            if not np.isfinite(bound) or abs(bound) >= 2 ** 31 - 1:
                continue
            before = {n: getattr(s, n) for n in ("min_length", "max_length")}
            value = (bound,) * prop.array_length if prop.is_array else bound
            setattr(s, name, value)
            if name in ("min_length", "max_length"):  # both at once: groom wants min <= max
                s.min_length = s.max_length = bound
            try:
                properties.groom_params(s)
            except Exception as e:
                pytest.fail(f"{name} = {bound} (its limit in the panel) is refused by groom: {e}")
            finally:
                s.property_unset(name)
                s.min_length, s.max_length = before["min_length"], before["max_length"]
            tried += 1
    assert tried >= 25, f"only {tried} limits tried"


def test_live_update_regrows_only_the_edited_keys_wisps(clean):
    from groom import generate
    live = ext_module(clean, "live")
    scalp = make_scalp()
    keys = add_keys(scalp)
    s = scalp.keystrand_hair
    s.count, s.viewport_count = 1200, 400
    bpy.ops.hair.generate()
    before = curves_arrays(s.hair_object)
    # Drag the tip of key 1 sideways, as an artist would in edit mode.
    tip = keys[1].data.splines[0].bezier_points[-1]
    tip.co.y += 0.05
    tip.handle_left.y += 0.05
    tip.handle_right.y += 0.05
    keys[1].data.update_tag()
    bpy.context.view_layer.update()
    assert live.process(settle=False) == 1
    params = params_of(scalp, count=400)
    during = curves_arrays(s.hair_object)
    new_keys = [read_key(k) for k in keys]
    scalp_arrays = read_scalp_arrays(scalp)
    own = (scalp_arrays.vertices, scalp_arrays.triangles)  # the scalp is its own collider
    expected_view = generate(scalp_arrays, new_keys, params, collider=own).strands
    np.testing.assert_array_equal(during["position"], expected_view.points)
    # Once the edit settles, the full count comes back, equal to a full regeneration.
    assert live.process(settle=True) == 1
    after = curves_arrays(s.hair_object)
    expected = generate(scalp_arrays, new_keys, params_of(scalp), collider=own).strands
    np.testing.assert_array_equal(after["counts"], expected.counts)
    np.testing.assert_array_equal(after["position"], expected.points)
    # Strands that no key-1 weight touches kept their points.
    touched = np.isin(generate(scalp_arrays, new_keys, params_of(scalp), collider=own).guides, [1]).any(axis=1)
    off_b = np.concatenate([[0], np.cumsum(before["counts"])])
    off_a = np.concatenate([[0], np.cumsum(after["counts"])])
    for i in np.flatnonzero(~touched)[:50]:
        np.testing.assert_array_equal(before["position"][off_b[i]:off_b[i + 1]],
                                      after["position"][off_a[i]:off_a[i + 1]])
    assert touched.any() and (~touched).any()


def test_render_preview_fills_the_image_with_the_tracer_s_pixels(clean):
    from groom import generate
    from tracer import Camera, RenderSettings, Renderer
    scalp = make_scalp()
    keys = add_keys(scalp)
    s = scalp.keystrand_hair
    s.count, s.preview_size, s.radius = 800, 96, 4e-4
    bpy.ops.hair.generate()
    cam = make_camera()
    activate(scalp)
    assert bpy.ops.hair.render_preview() == {'FINISHED'}
    image = bpy.data.images["Hair Preview"]
    w, h = image.size
    r = bpy.context.scene.render
    assert (w, h) == (96, round(96 * r.resolution_y / r.resolution_x))
    pixels = np.empty(w * h * 4, np.float32)
    image.pixels.foreach_get(pixels)
    got = pixels.reshape(h, w, 4)[::-1]
    surface = read_scalp_arrays(scalp)
    strands = generate(surface, [read_key(k) for k in keys], params_of(scalp),
                       collider=(surface.vertices, surface.triangles)).strands
    camera = Camera.from_blender(np.array(cam.matrix_world), (w, h), lens=cam.data.lens,
                                 sensor_width=cam.data.sensor_width, sensor_height=cam.data.sensor_height,
                                 sensor_fit=cam.data.sensor_fit)
    renderer = Renderer()
    renderer.set_strands(strands)
    # The scalp renders (it has no material: Cycles' default grey) and hides the hair behind it.
    m = np.array(scalp.matrix_world, np.float64)
    renderer.set_meshes([(surface.vertices @ m[:3, :3].T + m[:3, 3], surface.triangles, (0.8, 0.8, 0.8))])
    expected = renderer.render(camera, RenderSettings())
    assert expected[..., 3].max() > 0.5, "the test camera does not see the hair"
    np.testing.assert_allclose(got, expected, atol=1e-5)


def test_moving_the_camera_re_renders_without_re_uploading(clean):
    preview = ext_module(clean, "preview")
    scalp = make_scalp()
    add_keys(scalp)
    scalp.keystrand_hair.count, scalp.keystrand_hair.preview_size = 300, 48
    bpy.ops.hair.generate()
    cam = make_camera()
    activate(scalp)
    bpy.ops.hair.render_preview()
    renderer = preview.current_renderer()
    calls = []
    original = renderer.set_strands
    renderer.set_strands = lambda strands: (calls.append(1), original(strands))
    try:
        cam.location.x += 0.05
        bpy.context.view_layer.update()
        assert bpy.ops.hair.render_preview() == {'FINISHED'}
        assert preview.current_renderer() is renderer and calls == []
        # New hair is uploaded.
        scalp.keystrand_hair.seed = 9
        bpy.ops.hair.generate()
        bpy.ops.hair.render_preview()
        assert calls == [1]
    finally:
        del renderer.set_strands


@pytest.mark.parametrize("fmt", ["npz", "hair", "tfx"])
def test_export_writes_the_hair_in_world_space(clean, tmp_path, fmt):
    from hairio.formats import read_strands
    scalp = make_scalp()
    add_keys(scalp)
    scalp.keystrand_hair.count = 200
    bpy.ops.hair.generate()
    scalp.location = (1.0, 2.0, 3.0)
    bpy.context.view_layer.update()
    path = tmp_path / f"hair.{fmt}"
    assert bpy.ops.hair.export(filepath=str(path), format=fmt) == {'FINISHED'}
    back = read_strands(str(path))
    assert back.num_strands == 200
    hair = curves_arrays(scalp.keystrand_hair.hair_object)
    # Roots (point 0 of every strand) moved with the scalp.
    roots = back.points[np.concatenate([[0], np.cumsum(back.counts)[:-1]])]
    expected_roots = hair["position"][np.concatenate([[0], np.cumsum(hair["counts"])[:-1]])] + (1.0, 2.0, 3.0)
    np.testing.assert_allclose(roots, expected_roots, atol=1e-5)


@pytest.mark.parametrize("fmt", ["abc", "usd"])
def test_export_through_blender_s_exporters_leaves_the_scene_alone(clean, tmp_path, fmt):
    from blender_scene import scene_snapshot
    scalp = make_scalp()
    add_keys(scalp)
    scalp.keystrand_hair.count = 100
    bpy.ops.hair.generate()
    before = scene_snapshot()
    path = tmp_path / f"hair.{fmt}"
    assert bpy.ops.hair.export(filepath=str(path), format=fmt) == {'FINISHED'}
    assert path.is_file() and path.stat().st_size > 0
    assert scene_snapshot() == before


def test_load_preset_creates_its_keys_and_settings(clean):
    from groom import load_preset
    scalp = make_scalp()
    add_keys(scalp, KEY_POINTS[:1])
    preset_path = clean.__path__[0] + "/presets/wavy.json"
    preset = load_preset(preset_path)
    activate(scalp)
    assert bpy.ops.hair.load_preset(preset='wavy') == {'FINISHED'}
    keys = [o for o in bpy.data.objects if o.keystrand_hair.role == 'KEY']
    assert len(keys) == len(preset.key_specs), "the old key was not replaced"
    assert scalp.keystrand_hair.count == preset.params.count
    assert scalp.keystrand_hair.n_influence == pytest.approx(preset.params.n_influence)


def test_save_preset_round_trips_keys_and_settings(clean, tmp_path):
    scalp = make_scalp()
    keys = add_keys(scalp, KEY_POINTS[:3], shape='WAVY')
    scalp.keystrand_hair.tidiness = 0.42
    scalp.keystrand_hair.count = 777
    path = tmp_path / "mine.json"
    assert bpy.ops.hair.save_preset(filepath=str(path)) == {'FINISHED'}
    data = json.loads(path.read_text())
    assert data["params"]["tidiness"] == pytest.approx(0.42) and data["params"]["count"] == 777
    old = [read_key(k).points for k in keys]
    # Load it onto a fresh scalp: same keys, same settings.
    other = make_scalp("Other")
    assert bpy.ops.hair.load_preset(filepath=str(path)) == {'FINISHED'}
    new = sorted((o for o in bpy.data.objects if o.keystrand_hair.role == 'KEY' and o.keystrand_hair.scalp == other),
                 key=lambda o: o.name)
    assert len(new) == 3
    for a, b in zip(old, [read_key(k).points for k in new]):
        np.testing.assert_allclose(a, b, atol=1e-6)
    assert other.keystrand_hair.count == 777


def test_render_preview_out_of_process_matches_and_reports_a_killed_worker(clean, monkeypatch):
    import os
    import signal
    preview = ext_module(clean, "preview")
    scalp = make_scalp()
    add_keys(scalp)
    s = scalp.keystrand_hair
    s.count, s.preview_size, s.radius = 400, 48, 4e-4
    bpy.ops.hair.generate()
    make_camera()

    def render():
        activate(scalp)
        assert bpy.ops.hair.render_preview() == {'FINISHED'}
        image = bpy.data.images["Hair Preview"]
        px = np.empty(len(image.pixels), np.float32)
        image.pixels.foreach_get(px)
        return px

    in_process = render()
    monkeypatch.setenv("KEYSTRAND_PREVIEW_IN_PROCESS", "0")
    try:
        out_of_process = render()
        worker = preview.current_renderer()
        assert type(worker).__name__ == "WorkerClient" and worker.pid not in (None, os.getpid())
        np.testing.assert_allclose(out_of_process, in_process, atol=1e-6)
        assert in_process.reshape(-1, 4)[:, 3].max() > 0.5
        # The worker dies between renders: the next Render Preview is a readable error that
        # changes nothing, and the one after starts a fresh worker.
        from blender_scene import scene_snapshot
        old_pid = worker.pid
        os.kill(old_pid, signal.SIGKILL)
        worker._proc.wait(timeout=10)
        before = scene_snapshot()
        activate(scalp)
        with pytest.raises(RuntimeError, match="renderer stopped"):
            bpy.ops.hair.render_preview()
        assert scene_snapshot() == before
        again = render()
        assert preview.current_renderer().pid not in (None, old_pid)
        np.testing.assert_allclose(again, in_process, atol=1e-6)
    finally:
        preview.close()


def test_live_catch_up_runs_off_the_main_thread_and_uses_current_settings(clean):
    import threading
    from groom import generate
    live = ext_module(clean, "live")
    scalp = make_scalp()
    keys = add_keys(scalp)
    s = scalp.keystrand_hair
    s.count, s.viewport_count = 900, 300
    bpy.ops.hair.generate()
    s.tidiness = 0.5  # changed after Generate: the live update must pick it up
    tip = keys[2].data.splines[0].bezier_points[-1]
    tip.co.z -= 0.03
    keys[2].data.update_tag()
    bpy.context.view_layer.update()
    assert live.process(settle=False) == 1
    # Past the settle time, the catch-up starts on a thread and the call returns at once.
    live.process(now=1e12)
    names = [t.name for t in threading.enumerate()]
    state = next(iter(ext_module(clean, "generator_cache").states()))[1]
    assert state.catchup is None or "keystrand-hair-catch-up" in names
    live.process(settle=True)
    assert state.catchup is None
    surface = read_scalp_arrays(scalp)
    expected = generate(surface, [read_key(k) for k in keys], params_of(scalp),
                        collider=(surface.vertices, surface.triangles)).strands
    got = curves_arrays(s.hair_object)
    np.testing.assert_array_equal(got["counts"], expected.counts)
    np.testing.assert_array_equal(got["position"], expected.points)


@pytest.mark.parametrize("parented", [True, False], ids=["keys-parented", "keys-apart"])
def test_live_update_regrows_when_turning_the_scalp_turns_its_scene_axes(clean, parented):
    """Head Axes 'Scene': the head's up and front are fixed in the scene, so turning the scalp
    turns them in its mesh and the hair must fall anew, as Generate pressed again grows it;
    moving the scalp, or turning one whose axes are the mesh's, changes nothing that is grown.
    Keys apart from the scalp (unparented, left in the scene) see no update of their own."""
    head = ext_module(clean, "head")
    live = ext_module(clean, "live")
    scalp = make_scalp()
    keys = add_keys(scalp)
    if not parented:
        for key in keys:
            world = key.matrix_world.copy()
            key.parent = None
            key.matrix_world = world
    s = scalp.keystrand_hair
    s.count = s.viewport_count = 500
    assert bpy.ops.hair.generate() == {'FINISHED'}
    before = curves_arrays(s.hair_object)
    bpy.context.view_layer.update()
    live.process(settle=True)  # the scene's first evaluation since the keys were made
    if parented:
        scalp.location = (0.2, 0.0, 0.3)
        bpy.context.view_layer.update()
        assert live.process(settle=True) == 0, "moving the scalp moves its axes nowhere"
    scalp.rotation_euler = (0.6, 0.0, 0.2)
    bpy.context.view_layer.update()
    assert not np.allclose(head.scalp_axes(scalp)[0], (0.0, 0.0, 1.0), atol=0.1)
    assert live.process(settle=True) == 1
    after = curves_arrays(s.hair_object)
    activate(scalp)
    assert bpy.ops.hair.generate() == {'FINISHED'}
    pressed = curves_arrays(s.hair_object)
    np.testing.assert_array_equal(after["counts"], pressed["counts"])
    np.testing.assert_array_equal(after["position"], pressed["position"])
    assert after["position"].shape != before["position"].shape or np.abs(after["position"] - before["position"]).max() > 1e-3
    if parented:
        # Axes in the mesh turn with it: nothing to regrow. (Switching rewrites Up and Front
        # in the mesh, rounded to the setting's float32: that may regrow, once.)
        s.head_axes = 'LOCAL'
        bpy.context.view_layer.update()
        live.process(settle=True)
        scalp.rotation_euler = (0.0, 0.5, 0.0)
        bpy.context.view_layer.update()
        assert live.process(settle=True) == 0


def test_live_update_reads_the_collider_again_when_it_moves(clean):
    from test_blender_collision import add_falling_keys, depths, make_cap, make_head_for
    live = ext_module(clean, "live")
    cap = make_cap()
    head = make_head_for(cap)
    add_falling_keys(cap)
    s = cap.keystrand_hair
    s.collider = head
    s.count = s.viewport_count = 400
    assert bpy.ops.hair.generate() == {'FINISHED'}
    bpy.context.view_layer.update()
    assert live.process(settle=True) == 0  # the scene's first evaluation since the keys were made
    head.location.x += 0.0015  # a slip of 1.5 mm: the hair now cuts into the head's far side
    bpy.context.view_layer.update()
    state = next(iter(ext_module(clean, "generator_cache").states()))[1]
    assert live.process(settle=True) == 1 and state.collider_version == 1
    d, _, allowed = depths(s.hair_object, head)
    assert not (d < allowed).any(), d.min()
    # Nothing moved since: nothing read or grown again.
    bpy.context.view_layer.update()
    assert live.process(settle=True) == 0 and state.collider_version == 1


# --- partings ------------------------------------------------------------------------------

def parting_of(settings):
    """GroomParams.parting as the settings hold it (float32 values), or None."""
    if not settings.use_parting:
        return None
    parting = {"point": tuple(settings.parting_point), "normal": tuple(settings.parting_normal)}
    if settings.parting_use_end:
        parting["end"] = tuple(settings.parting_end)
    return parting


def key_with_settings(obj):
    """read_key with the key's own settings: its part group, colour and root radius."""
    from groom import KeyStrand
    k = obj.keystrand_hair
    return KeyStrand(read_key(obj).points, kind="cubic", group=k.key_group,
                     color=tuple(k.key_color) if k.use_key_color else None,
                     root_radius=k.key_radius if k.key_radius > 0 else None)


def test_load_preset_carries_its_parting_onto_the_scalp(clean):
    from groom import load_preset
    scalp = make_scalp()
    scalp.location = (0.2, 0.1, 1.3)  # the parting is kept in the mesh's own space
    bpy.context.view_layer.update()
    s = scalp.keystrand_hair
    assert not s.use_parting
    assert bpy.ops.hair.load_preset(preset="parted") == {'FINISHED'}
    preset = load_preset(clean.__path__[0] + "/presets/parted.json")
    expected = preset.place_keys(read_scalp_arrays(scalp), up=(0.0, 0.0, 1.0), front=(0.0, -1.0, 0.0)).params.parting
    assert expected is not None and set(expected) == {"point", "normal", "end"}
    got = parting_of(s)
    assert got is not None and set(got) == set(expected)
    for name in expected:
        np.testing.assert_allclose(got[name], expected[name], atol=1e-6, err_msg=name)
    # A preset without a parting switches it off again.
    assert bpy.ops.hair.load_preset(preset="wavy") == {'FINISHED'}
    assert not s.use_parting


def test_generate_parts_the_hair_as_groom_does(clean):
    """Every hair follows keys of its own side of the parting only, and the Curves object is
    what groom grows with the settings' parting."""
    from groom import generate
    scalp = make_scalp()
    assert bpy.ops.hair.load_preset(preset="parted") == {'FINISHED'}
    s = scalp.keystrand_hair
    s.count = 1500
    assert bpy.ops.hair.generate() == {'FINISHED'}
    got = curves_arrays(s.hair_object)
    keys = sorted((o for o in bpy.data.objects if o.keystrand_hair.role == 'KEY'), key=lambda o: o.name)
    surface = read_scalp_arrays(scalp)
    parting = parting_of(s)
    expected = generate(surface, [key_with_settings(k) for k in keys], params_of(scalp, parting=parting),
                        collider=(surface.vertices, surface.triangles)).strands
    np.testing.assert_array_equal(got["counts"], expected.counts)
    np.testing.assert_array_equal(got["position"], expected.points)
    # Roots on the normal's side of the plane, in front of its end, are parted (group 1).
    roots = got["position"][np.concatenate([[0], np.cumsum(got["counts"])[:-1]])].astype(np.float64)
    p, n, end = (np.array(parting[k]) for k in ("point", "normal", "end"))
    parted = ((roots - p) @ n > 0) & ((roots - end) @ np.array(s.front) >= 0)
    assert 0.05 < parted.mean() < 0.95, "the parting parts nothing here: the check below proves nothing"
    key_group = np.array([k.keystrand_hair.key_group for k in keys])
    np.testing.assert_array_equal(key_group[got["wisp"]], parted.astype(int))


def test_save_preset_keeps_the_parting(clean, tmp_path):
    from groom import load_preset
    scalp = make_scalp()
    assert bpy.ops.hair.load_preset(preset="parted") == {'FINISHED'}
    s = scalp.keystrand_hair
    s.parting_point = (0.03, 0.0, 0.0)  # the artist moves it
    path = tmp_path / "mine.json"
    assert bpy.ops.hair.save_preset(filepath=str(path)) == {'FINISHED'}
    placed = load_preset(str(path)).place_keys(read_scalp_arrays(scalp), up=(0.0, 0.0, 1.0),
                                               front=(0.0, -1.0, 0.0)).params.parting
    for name, value in parting_of(s).items():
        np.testing.assert_allclose(placed[name], value, atol=1e-5, err_msg=name)

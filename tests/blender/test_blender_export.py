# SPDX-License-Identifier: GPL-3.0-or-later
"""The panel's Export writes the files the command line writes: the same hair exported from
Blender and by `python -m groom export` (from the panel's own .npz, with the root UVs the
hair holds) gives equal files in every format, groom primvars, guides and root UVs included.
The operator, its file filter and the File > Export menu offer exactly the format registry's
formats; the guides Generate interpolated with are stored on the hair and reach the files."""
import importlib
import json
import re
import types

import numpy as np
import pytest
import bpy

from blender_scene import activate, make_scalp

FORMATS = ("npz", "hair", "tfx", "usda", "abc")


def _generated_hair(uv):
    """A generated hair on a moved, turned and scaled scalp (with a UV map when `uv`)."""
    scalp = make_scalp(uv=uv)
    for p in [(0.0, 0.0, 0.1), (0.07, 0.0, 0.07), (-0.05, 0.05, 0.07)]:
        activate(scalp)
        assert bpy.ops.hair.add_key_strand(location=p) == {'FINISHED'}
    activate(scalp)
    scalp.keystrand_hair.count = 150
    assert bpy.ops.hair.generate() == {'FINISHED'}
    scalp.location = (0.3, -0.2, 1.1)
    scalp.rotation_euler = (0.2, 0.0, 0.7)
    scalp.scale = (1.25, 1.25, 1.25)
    bpy.context.view_layer.update()
    activate(scalp)
    return scalp, scalp.keystrand_hair.hair_object


def _stored_root_uv(hair):
    """The hair's root UVs, read here from Blender's attachment attribute."""
    attr = hair.data.attributes.get("surface_uv_coordinate")
    if attr is None:
        return None
    uv = np.empty(len(hair.data.curves) * 2, np.float32)
    attr.data.foreach_get("vector", uv)
    return uv.reshape(-1, 2)


def _panel_and_command_line(tmp_path, hair):
    """Export every format from the panel and through the command line; the paths by format."""
    from hairio.cli import export_main
    from hairio.formats import format_of
    panel, cli = tmp_path / "panel", tmp_path / "cli"
    panel.mkdir()
    cli.mkdir()
    for ext in FORMATS:
        fmt = "usd" if ext == "usda" else ext
        assert bpy.ops.hair.export(filepath=str(panel / f"hair.{ext}"), format=fmt) == {'FINISHED'}
    uv = _stored_root_uv(hair)
    uv_args = []
    if uv is not None:
        np.save(tmp_path / "uv.npy", uv)
        uv_args = ["--root-uv", str(tmp_path / "uv.npy")]
    for ext in FORMATS:
        # --root-uv only where the format takes it: the others refuse it
        fmt = format_of(f"hair.{ext}")
        takes_uv = "root_uv" in fmt.options
        args = [str(panel / "hair.npz"), "--out", str(cli / f"hair.{ext}"), *(uv_args if takes_uv else [])]
        # Where a groom library is missing (the bpy module of 4.2 has no pxr), the command
        # line says what to install and writes nothing; the panel used Blender's exporter.
        assert export_main(args) == (0 if fmt.available() else 2), ext
        assert (cli / f"hair.{ext}").exists() == fmt.available(), ext
    return panel, cli


def _usda_body(path, name):
    """The stage's text with the hair's own name made neutral (the object's and its data's,
    "Scalp Hair" from the panel, "hair" from a strand file, quoted and as a prim name) and
    Blender's version line dropped; everything else, every array and primvar, is compared
    as written."""
    text = re.sub(r'doc = "Blender v[^"]*"', 'doc = ""', path.read_text())
    text = text.replace(f'"{name}"', '"HAIR"')
    return re.sub(r"(?<![\w:-])" + re.escape(re.sub(r"\W", "_", name)) + r"(?![\w:])", "HAIR", text)


def _alembic_arrays(path):
    """Points, radii, counts and matrix of each Curves object Blender's importer makes of
    `path` (the strands, and the guides when the file has them), by object name."""
    before = set(bpy.data.objects)
    bpy.ops.wm.alembic_import(filepath=str(path))
    new = [o for o in bpy.data.objects if o not in before]
    try:
        found = {}
        for obj in sorted((o for o in new if o.type == 'CURVES'), key=lambda o: o.name):
            c = obj.data
            n, s = len(c.points), len(c.curves)
            pts, radius, offsets = np.empty(3 * n, np.float32), np.empty(n, np.float32), np.empty(s + 1, np.int32)
            c.attributes["position"].data.foreach_get("vector", pts)
            c.attributes["radius"].data.foreach_get("value", radius)
            c.curve_offset_data.foreach_get("value", offsets)
            found[obj.name] = (pts.reshape(n, 3), radius, np.diff(offsets), np.array(obj.matrix_world))
        return found
    finally:
        data = [o.data for o in new]
        bpy.data.batch_remove(new)
        bpy.data.batch_remove([d for d in data if d is not None and d.users == 0])


@pytest.mark.parametrize("uv", [False, True], ids=["no-uv-map", "uv-map"])
def test_panel_export_equals_the_command_line_s(clean, tmp_path, uv):
    scalp, hair = _generated_hair(uv)
    panel, cli = _panel_and_command_line(tmp_path, hair)
    # npz: the same arrays and sidecar; only `source` says where each came from.
    a, b = np.load(panel / "hair.npz"), np.load(cli / "hair.npz")
    assert sorted(a.files) == sorted(b.files)
    for name in a.files:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    side_a = json.loads((panel / "hair.npz.json").read_text())
    side_b = json.loads((cli / "hair.npz.json").read_text())
    assert side_a.pop("source").endswith(hair.name) and side_b.pop("source") == "hair.npz"
    assert side_a == side_b
    for ext in ("hair", "tfx"):
        assert (panel / f"hair.{ext}").read_bytes() == (cli / f"hair.{ext}").read_bytes(), ext
    from hairio.formats import get_format
    text = _usda_body(panel / "hair.usda", hair.name)
    if get_format("usd").available():       # pxr writes Unreal's groom layout, the same both ways
        assert text == _usda_body(cli / "hair.usda", "hair")
        assert "GroomAPI" in text
        for user_property in ("groom_version_major", "groom_version_minor"):
            assert f"userProperties:{user_property} = " in text, user_property
    else:                                   # Blender's exporter writes the attributes as primvars
        for primvar in ("groom_version_major", "groom_version_minor"):
            assert f"primvars:{primvar} = [" in text, primvar
    assert "primvars:groom_color = [" in text
    assert ("primvars:groom_root_uv = [" in text) == uv
    if not get_format("abc").available():    # Blender's exporter: the strands only
        assert len(_alembic_arrays(panel / "hair.abc")) == 1
        return
    got, want = _alembic_arrays(panel / "hair.abc"), _alembic_arrays(cli / "hair.abc")
    assert len(got) == 2 and list(got) == list(want), (list(got), list(want))      # strands and guides
    for name in got:
        for a, b in zip(got[name], want[name]):
            np.testing.assert_array_equal(a, b, err_msg=name)


def test_root_uvs_are_the_roots_on_the_scalp_s_uv_map(clean, tmp_path):
    """The UVs the panel exports are groom's, for the roots it grew on the scalp's UV map
    (read here from the mesh: a vertex on a seam takes one of its loops' UVs, as groom's)."""
    from groom import Scalp
    from hairio.formats import load_tfx
    scalp, hair = _generated_hair(uv=True)
    mesh = scalp.data
    mesh.calc_loop_triangles()
    v = np.empty(len(mesh.vertices) * 3)
    mesh.vertices.foreach_get("co", v)
    t = np.empty(len(mesh.loop_triangles) * 3, np.int64)
    mesh.loop_triangles.foreach_get("vertices", t)
    loop_uv = np.empty(len(mesh.loops) * 2)
    mesh.uv_layers.active.uv.foreach_get("vector", loop_uv)
    loop_vertex = np.empty(len(mesh.loops), np.int64)
    mesh.loops.foreach_get("vertex_index", loop_vertex)
    vertex_uv = np.zeros((len(mesh.vertices), 2))
    vertex_uv[loop_vertex] = loop_uv.reshape(-1, 2)
    surface = Scalp(v.reshape(-1, 3), t.reshape(-1, 3), uv=vertex_uv)
    offsets = np.empty(len(hair.data.curves) + 1, np.int32)
    hair.data.curve_offset_data.foreach_get("value", offsets)
    pts = np.empty(len(hair.data.points) * 3, np.float32)
    hair.data.attributes["position"].data.foreach_get("vector", pts)
    roots = pts.reshape(-1, 3)[offsets[:-1]]
    tri, bary, _ = surface.closest_points(roots)
    expected = surface.uv_at(tri, bary)
    stored = _stored_root_uv(hair)
    np.testing.assert_allclose(stored, expected, atol=2e-4)
    assert np.ptp(stored, axis=0).min() > 0.1, "the roots' UVs do not spread over the map"
    assert hair.data.surface_uv_map == mesh.uv_layers.active.name
    # TressFX files carry them per strand, V flipped (DirectX), where the command line's
    # default spherical projection would put others.
    path = tmp_path / "hair.tfx"
    assert bpy.ops.hair.export(filepath=str(path), format='tfx') == {'FINISHED'}
    in_file = load_tfx(str(path)).strand_uv
    np.testing.assert_allclose(in_file, np.column_stack([stored[:, 0], 1 - stored[:, 1]]), atol=1e-6)


class _RecordingLayout:
    """Stands in for a menu's layout: records each operator entry and what is set on it."""

    def __init__(self):
        self.entries = []

    def operator(self, idname, text="", **_kwargs):
        entry = types.SimpleNamespace(idname=idname, text=text)
        self.entries.append(entry)
        return entry


def test_export_menu_lists_exactly_the_registry_s_formats(clean):
    from hairio.formats import FORMATS
    operators = importlib.import_module(f"{clean.__name__}.addon.operators")
    ours = [f for f in bpy.types.TOPBAR_MT_file_export._dyn_ui_initialize()
            if getattr(f, "__module__", "").startswith(clean.__name__)]
    assert ours == [operators.menu_export]
    menu = types.SimpleNamespace(layout=_RecordingLayout())
    operators.menu_export(menu, bpy.context)
    entries = menu.layout.entries
    assert [e.idname for e in entries] == ["hair.export"] * len(entries)
    assert [e.format for e in entries] == [f.name for f in FORMATS]
    assert [e.text for e in entries] == [f"Key-Strand Hair: {f.label}" for f in FORMATS]


def test_export_operator_offers_and_filters_the_registry_s_formats(clean):
    from hairio.formats import FORMATS
    props = bpy.ops.hair.export.get_rna_type().properties
    items = props["format"].enum_items
    assert [i.identifier for i in items] == [f.name for f in FORMATS]
    assert [i.name for i in items] == [f.label for f in FORMATS]
    patterns = props["filter_glob"].default.split(";")
    assert patterns == ["*" + ext for f in FORMATS for ext in f.extensions]


def test_generate_stores_the_guides_on_the_hair_and_every_groom_export_carries_them(clean, tmp_path):
    """The key strands, each strand's three keys and weights are Curves attributes of the
    documented names after Generate; the panel's .npz, .abc and .usda hold them, in world space."""
    from hairio.formats import read_strands
    scalp, hair = _generated_hair(uv=False)
    names = {a.name for a in hair.data.attributes}
    for name in ("keystrand_guide_index_0", "keystrand_guide_index_1", "keystrand_guide_index_2",
                 "keystrand_guide_weights"):
        assert name in names, name
    assert hair.data.attributes["keystrand_guide_weights"].data_type == 'FLOAT_VECTOR'
    curves = importlib.import_module(f"{clean.__name__}.addon.blender_curves")
    stored = curves.read_guides(hair.data)
    assert stored is not None and stored.keys.num_strands == 3
    wisp = np.empty(len(hair.data.curves), np.int32)
    hair.data.attributes["wisp"].data.foreach_get("value", wisp)
    np.testing.assert_array_equal(stored.index[:, 0], wisp)
    np.testing.assert_allclose(stored.weights.sum(axis=1), 1.0, atol=1e-5)
    # Each key strand's root is its key object's first point, in the scalp's space.
    keys = [o for o in bpy.data.objects if o.type == 'CURVE' and o.parent == scalp]
    want = sorted(tuple(np.round(np.array(scalp.matrix_world.inverted() @ (k.matrix_world @
                                                                           k.data.splines[0].bezier_points[0].co)), 5))
                  for k in keys)
    got = sorted(tuple(np.round(p, 5)) for p in stored.keys.points[stored.keys.offsets])
    np.testing.assert_allclose(got, want, atol=1e-5)
    world = np.array(hair.matrix_world)
    expected_roots = stored.keys.points[stored.keys.offsets] @ world[:3, :3].T + world[:3, 3]
    from hairio.formats import format_of
    for ext in ("npz", "abc", "usda"):
        path = tmp_path / f"hair.{ext}"
        if not format_of(path).available():
            continue        # Blender's exporter has no place for guides (the fallback's own test)
        assert bpy.ops.hair.export(filepath=str(path), format="usd" if ext == "usda" else ext) == {'FINISHED'}
        back = read_strands(str(path))
        assert back.guides is not None, ext
        np.testing.assert_array_equal(back.guides.index, stored.index, err_msg=ext)
        np.testing.assert_allclose(back.guides.weights, stored.weights, atol=1e-6, err_msg=ext)
        np.testing.assert_allclose(back.guides.keys.points[back.guides.keys.offsets], expected_roots,
                                   atol=1e-5, err_msg=ext)


def test_a_groom_library_missing_in_blender_falls_back_to_blender_s_exporter_and_says_so(clean, tmp_path,
                                                                                          monkeypatch):
    from hairio.formats import Format
    operators = importlib.import_module(f"{clean.__name__}.addon.operators")
    scalp, hair = _generated_hair(uv=False)
    monkeypatch.setattr(Format, "available", lambda self: self.library is None)
    written, warning = operators.export_to_file(hair, str(tmp_path / "hair.abc"), "abc")
    assert written == [str(tmp_path / "hair.abc")]
    assert "alembic3d" in warning and "no guides" in warning
    objects = _alembic_arrays(tmp_path / "hair.abc")
    assert len(objects) == 1, "Blender's exporter writes the strands alone"
    (points, radius, counts, matrix), = objects.values()
    assert len(counts) == len(hair.data.curves)


def test_a_bug_in_a_writer_is_an_internal_error_not_a_user_message(clean, tmp_path, monkeypatch):
    """A ValueError from our own code is a bug: reported as one, not as bad input."""
    import hairio.formats.npz as npz_format
    _generated_hair(uv=False)

    def broken(*args, **kwargs):
        raise ValueError("planted bug")
    monkeypatch.setattr(npz_format, "write_npz", broken)
    with pytest.raises(RuntimeError, match="Internal error") as info:
        bpy.ops.hair.export(filepath=str(tmp_path / "hair.npz"), format='npz')
    assert "planted bug" in str(info.value) and "Please report" in str(info.value)
    assert list(tmp_path.iterdir()) == []


def test_the_extension_brings_the_alembic_library_it_writes_grooms_with(clean):
    """The zip ships alembic3d for each Python and platform it serves, so the panel writes the
    Alembic groom (guides included) in every Blender, not Blender's strands-only file; USD
    is written with the pxr Blender ships (the bpy module of 4.2 lacks it: there, Blender's
    USD exporter, as the fallback test shows)."""
    from hairio.formats import get_format
    assert get_format("abc").available()
    import alembic3d
    assert alembic3d.__name__ == "alembic3d"


def test_live_update_stores_the_guides_of_the_hair_it_regrows(clean):
    """A dragged key regrows its wisps at the viewport count, then the full count: each time
    the stored guides are those of the hair now on screen (the moved key's new shape)."""
    live = importlib.import_module(f"{clean.__name__}.addon.live")
    curves = importlib.import_module(f"{clean.__name__}.addon.blender_curves")
    scalp, hair = _generated_hair(uv=False)
    s = scalp.keystrand_hair
    s.viewport_count = 60
    before = curves.read_guides(hair.data)
    key = next(o for o in bpy.data.objects if o.type == 'CURVE' and o.parent == scalp)
    tip = key.data.splines[0].bezier_points[-1]
    for point in (tip.co, tip.handle_left, tip.handle_right):
        point.y += 0.05
    key.data.update_tag()
    bpy.context.view_layer.update()
    for settle, count in ((False, 60), (True, 150)):
        assert live.process(settle=settle) == 1
        hair = s.hair_object
        stored = curves.read_guides(hair.data)
        assert stored is not None and len(stored.index) == len(hair.data.curves) == count
        wisp = np.empty(count, np.int32)
        hair.data.attributes["wisp"].data.foreach_get("value", wisp)
        np.testing.assert_array_equal(stored.index[:, 0], wisp)
        moved = np.abs(stored.keys.points - before.keys.points).max(axis=1) > 1e-6
        assert moved.any() and not moved.all(), "only the dragged key's shape changed"

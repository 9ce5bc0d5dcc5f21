# SPDX-License-Identifier: GPL-3.0-or-later
"""The panel's Export writes the files the command line writes: the same hair exported from
Blender and by `python -m groom export` (from the panel's own .npz, with the root UVs the
hair holds) gives equal files in every format, groom primvars and root UVs included."""
import json
import pathlib
import re
import sys

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
        assert export_main([str(panel / "hair.npz"), "--out", str(cli / f"hair.{ext}"), *uv_args]) == 0
    # The command line's Blender shares this one's user folder, as it would a running
    # Blender's: it must leave the extensions' wheels installed there alone.
    site = pathlib.Path(bpy.utils.user_resource('EXTENSIONS')) / ".local" / "lib" / \
        f"python{sys.version_info.major}.{sys.version_info.minor}" / "site-packages"
    assert (site / "groom").is_dir(), "the command line's export removed the extension's wheels"
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
    """Points, radii and counts of the one Curves object Blender's importer makes of `path`."""
    before = set(bpy.data.objects)
    bpy.ops.wm.alembic_import(filepath=str(path))
    new = [o for o in bpy.data.objects if o not in before]
    try:
        (obj,) = [o for o in new if o.type == 'CURVES']
        c = obj.data
        n, s = len(c.points), len(c.curves)
        pts, radius, offsets = np.empty(3 * n, np.float32), np.empty(n, np.float32), np.empty(s + 1, np.int32)
        c.attributes["position"].data.foreach_get("vector", pts)
        c.attributes["radius"].data.foreach_get("value", radius)
        c.curve_offset_data.foreach_get("value", offsets)
        return pts.reshape(n, 3), radius, np.diff(offsets), np.array(obj.matrix_world)
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
    text = _usda_body(panel / "hair.usda", hair.name)
    assert text == _usda_body(cli / "hair.usda", "hair")
    from hairio.cli import groom_library_available
    if groom_library_available("usd"):      # pxr writes Unreal's groom layout
        assert "GroomAPI" in text
        for user_property in ("groom_version_major", "groom_version_minor"):
            assert f"userProperties:{user_property} = " in text, user_property
    else:                                   # Blender's exporter writes the attributes as primvars
        for primvar in ("groom_version_major", "groom_version_minor"):
            assert f"primvars:{primvar} = [" in text, primvar
    assert "primvars:groom_color = [" in text
    assert ("primvars:groom_root_uv = [" in text) == uv
    for got, want in zip(_alembic_arrays(panel / "hair.abc"), _alembic_arrays(cli / "hair.abc")):
        np.testing.assert_array_equal(got, want)


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

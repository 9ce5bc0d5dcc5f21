# SPDX-License-Identifier: GPL-3.0-or-later
"""Alembic and USD through Blender's exporters (bpy in a subprocess, a few seconds):
what the files hold, scale and axes, the scene left as it was, no file after a failure."""
import json
import os
import pathlib
import re
import subprocess
import sys

import numpy as np
import pytest

from hairio_scenes import make_wavy

ROOT = pathlib.Path(__file__).resolve().parents[2]

SCRIPT = r'''
import json, sys
import numpy as np
import bpy
sys.path.insert(0, ROOT)
from hairio import Strands
from addon.blender_curves import strands_to_curves
from addon.export_blender import export_curves_object
from hairio.unreal import groom_attributes

def state():
    out = {}
    for coll in ("objects", "scenes", "hair_curves", "collections", "meshes"):
        out[coll] = sorted(b.name for b in getattr(bpy.data, coll))
    ob = bpy.data.objects.get("groom")
    out["matrix"] = [list(r) for r in ob.matrix_world] if ob else None
    out["data"] = ob.data.name if ob else None
    out["scene"] = bpy.context.scene.name
    return out

bpy.ops.wm.read_factory_settings(use_empty=True)
s = Strands.load_npz(TMP + "/in.npz")
# Written first with a few strands, then refilled with a new layout: in place where Blender
# can resize a Curves datablock, by a new datablock in its place in 4.2; both evaluated.
k = 7
n = int(s.counts[:k].sum())
few = Strands.from_arrays(s.points[:n], s.counts[:k], s.radius[:n], s.color[:n], s.alpha[:n], s.wisp[:k])
ob = strands_to_curves("groom", few, collection=bpy.context.scene.collection)
ob.data.materials.append(bpy.data.materials.new("look"))
bpy.context.view_layer.update()
strands_to_curves("groom", s, obj=ob)
ob.location = (1.0, 2.0, 3.0)
bpy.context.view_layer.update()
types = np.empty(len(ob.data.curves), np.int32)
ob.data.attributes["curve_type"].data.foreach_get("value", types)
refill = {"data": ob.data.name, "materials": [m.name for m in ob.data.materials],
          "curves": len(ob.data.curves), "types": sorted(set(types.tolist())),
          "hair_curves": [c.name for c in bpy.data.hair_curves]}
before = state()
uv = np.linspace(0, 1, 2 * s.num_strands).reshape(-1, 2)
attrs = groom_attributes(s, root_uv=uv, group_id=np.arange(s.num_strands) % 2)
export_curves_object(ob, TMP + "/y.abc", "abc", scale=100.0)
export_curves_object(ob, TMP + "/z.abc", "abc", scale=100.0, axis="z-up")
export_curves_object(ob, TMP + "/h.usda", "usd", attributes=attrs)
export_curves_object(ob, TMP + "/cm.usda", "usd", scale=100.0, axis="y-up")
errors = []
for bad in (dict(path=TMP + "/missing/x.abc"), dict(path=TMP + "/x.obj"), dict(path=TMP + "/x.abc", axis="sideways"),
            dict(path=TMP + "/x.usda", format="usd", attributes={"groom_root_uv": ("CURVE", "FLOAT2", np.zeros((3, 2)))})):
    try:
        export_curves_object(ob, **{"format": "abc", **bad})
        errors.append(None)
    except Exception as e:
        errors.append(type(e).__name__)
after = state()
result = {"same_state": before == after, "before": before, "after": after, "errors": errors, "refill": refill}
for name in ("y", "z"):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.alembic_import(filepath=TMP + "/" + name + ".abc")
    obs = [o for o in bpy.data.objects if o.type == "CURVES"]
    o = obs[0]
    n = len(o.data.points)
    p = np.empty(3 * n, np.float32); o.data.attributes["position"].data.foreach_get("vector", p)
    r = np.empty(n, np.float32); o.data.attributes["radius"].data.foreach_get("value", r)
    np.savez(TMP + "/" + name + "_back.npz", points=p.reshape(n, 3), radius=r,
             matrix=np.array(o.matrix_world), names=np.array([o.name]))
json.dump(result, open(TMP + "/result.json", "w"))
'''


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("blender")
    s = make_wavy(30, (5, 12), seed=4)
    s.save_npz(tmp / "in.npz")
    code = f"ROOT = {str(ROOT)!r}; TMP = {str(tmp)!r}\n" + SCRIPT
    # A user folder of its own: the script resets to factory settings, and Blender then
    # removes the wheels of extensions no longer enabled from the user folder's site-packages.
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp / "blender-user"))
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env)
    assert run.returncode == 0, run.stderr[-3000:]
    return tmp, s, json.loads((tmp / "result.json").read_text())


def test_a_new_strand_layout_keeps_the_datablock_its_name_and_materials(exported):
    """Refilled with another strand count, the object keeps one Curves datablock of its name
    and material, all POLY (curve type 1); the process then exits cleanly (a stale curve type
    count in Blender corrupts its heap, which ends the subprocess with a signal)."""
    tmp, s, result = exported
    assert result["refill"] == {"data": "groom", "materials": ["look"], "curves": s.num_strands,
                                "types": [1], "hair_curves": ["groom"]}


def test_scene_is_left_exactly_as_it_was(exported):
    tmp, s, result = exported
    assert result["same_state"], (result["before"], result["after"])
    assert result["before"]["objects"] == ["groom"]


def test_failed_exports_raise_and_leave_no_file(exported):
    tmp, s, result = exported
    # missing folder, wrong extension, unknown axis: rejected up front; an attribute of the
    # wrong length fails inside Blender, after the temporary file was made
    assert result["errors"][:3] == ["InputError"] * 3
    assert result["errors"][3] is not None
    assert not list(tmp.glob("x.*")) and not list(tmp.glob(".tmp-*"))


def _usda(path):
    return path.read_text()


def _array(text, decl):
    m = re.search(re.escape(decl) + r" = \[([^\]]*)\]", text)
    assert m, decl
    return np.array([float(v) for v in re.findall(r"-?[\d.]+(?:e-?\d+)?", m.group(1))])


def test_usd_is_linear_basis_curves_with_vertex_widths_and_groom_primvars(exported):
    tmp, s, _ = exported
    text = _usda(tmp / "h.usda")
    assert 'def BasisCurves "groom"' in text
    assert 'uniform token type = "linear"' in text
    assert 'upAxis = "Z"' in text and "metersPerUnit = 1" in text
    np.testing.assert_array_equal(_array(text, "int[] curveVertexCounts"), s.counts)
    widths = _array(text, "float[] widths")
    np.testing.assert_allclose(widths, 2 * s.radius, rtol=1e-6)
    assert re.search(r'float\[\] widths = \[[^\]]*\] \(\s*interpolation = "vertex"', text)
    pts = _array(text, "point3f[] points").reshape(-1, 3)
    np.testing.assert_allclose(pts, s.points + [1, 2, 3], atol=1e-6)     # world matrix baked in
    for name, interp in (("groom_root_uv", "uniform"), ("groom_group_id", "uniform"),
                         ("groom_color", "vertex"), ("groom_version_major", "uniform")):
        assert re.search(r"primvars:" + name + r" = \[[^\]]*\] \(\s*interpolation = \"" + interp, text), name
    np.testing.assert_array_equal(_array(text, "int[] primvars:groom_group_id"), np.arange(s.num_strands) % 2)


def test_usd_units_and_axis_are_stage_metadata(exported):
    """Centimetres and Y up are said by the stage: metersPerUnit 0.01, upAxis Y with a root
    rotation. The factor 100 is a root scale where Blender's USD exporter converts units
    (5.x), and in the points where it cannot (4.2, which takes metersPerUnit from the scene's
    unit scale, a float32: 0.0099999998): either way a point of the file is 100 x the world
    point, in the rotated root."""
    tmp, s, _ = exported
    text = _usda(tmp / "cm.usda")
    assert 'upAxis = "Y"' in text and "xformOp:rotateXYZ = (-90" in text
    mpu = float(re.search(r"metersPerUnit = ([\d.e-]+)", text).group(1))
    assert mpu == pytest.approx(0.01, rel=1e-6)
    root_scale = re.search(r"xformOp:scale = \(([^)]*)\)", text)
    factor = 1.0 if root_scale is None else float(root_scale.group(1).split(",")[0])
    pts = _array(text, "point3f[] points").reshape(-1, 3)
    np.testing.assert_allclose(factor * pts, 100 * (s.points + [1, 2, 3]), rtol=1e-6, atol=1e-4)
    widths = _array(text, "float[] widths")
    np.testing.assert_allclose(factor * widths, 100 * 2 * s.radius, rtol=1e-5)


def test_alembic_holds_scaled_points_and_widths_in_the_chosen_axes(exported):
    tmp, s, _ = exported
    world = s.points.astype(np.float64) + [1, 2, 3]
    for name in ("y", "z"):
        raw = (tmp / f"{name}.abc").read_bytes()
        assert raw[:5] == b"Ogawa" and b"width" in raw and b"groom" in raw
        back = np.load(tmp / f"{name}_back.npz")
        # Blender's importer undoes the Y-up conversion it knows of; with z-up we pre-rotated,
        # so the importer, undoing a conversion that was not there, turns it: (x, -z, y).
        assert (back["matrix"] == np.eye(4)).all()
        pts = back["points"].astype(np.float64)
        want = 100 * world if name == "y" else 100 * world @ np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]]).T
        np.testing.assert_allclose(pts, want, rtol=1e-5, atol=1e-3)
        np.testing.assert_allclose(back["radius"], 100 * s.radius, rtol=1e-5)

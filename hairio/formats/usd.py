# SPDX-License-Identifier: GPL-3.0-or-later
"""USD grooms written and read with Pixar's own library (`pxr`: the usd-core package, or the
one Blender ships inside Blender).

What a file from `write_usd` holds (the layout of hairio.unreal.groom_layout):

    /Groom            Xform, defaultPrim, apiSchemas ["GroomAPI"] (what Unreal's USD groom
                      translator looks for), userProperties:groom_version_major/_minor (int),
                      groom_tool, groom_properties (string): the groom-level attributes, read
                      by Unreal from the groom prim's userProperties: namespace
      guides          BasisCurves (when the strands carry guides): the key strands, groom_guide 1
      strands         BasisCurves: the strands

Both curves are linear and non-periodic with per-vertex `widths` (2 * radius, in the stage's
units like the points, so they are right under any --scale: metersPerUnit = 1 / scale) and an
extent that includes the half-widths. The groom_* attributes are primvars with the types
Unreal's USD reader converts (int, float, float2/texCoord2f, float3, string): groom_color is
float3 (it reads no color3f) and groom_closest_guides float3 (it reads no int3; the ids are
exact in float32 below 2**24, which is checked). alpha is primvars:displayOpacity.
"""
import os
import sys

import numpy as np

from ..atomic import atomic_path
from ..unreal import GROOM_VERSION, GroomCurves, groom_layout, groom_properties, strands_from_groom
from ..validate import InputError
from ._common import TOOL_NAME, TOOL_VERSION, check_export_options, check_strands
from .axes import convert_strands, unconvert_points

AXES = ("z-up", "y-up")
EXTENSIONS = (".usd", ".usda", ".usdc")
GROOM_PRIM = "/Groom"
_FLOAT32_EXACT_INT = 2 ** 24


def pxr_modules():
    """(Usd, UsdGeom, Sdf, Vt, Gf) from pxr; inside Blender its own pxr (also where the bpy
    module keeps it off sys.path). InputError naming the fix when there is none."""
    try:
        from pxr import Gf, Sdf, Usd, UsdGeom, Vt
    except ImportError:
        if not _add_blender_pxr():
            raise InputError("USD export needs Pixar's USD library: pip install usd-core==26.11 "
                             "(Blender 4.2 and later ship it)") from None
        from pxr import Gf, Sdf, Usd, UsdGeom, Vt
    return Usd, UsdGeom, Sdf, Vt, Gf


def _add_blender_pxr():
    """Put the pxr that Blender ships on sys.path when Blender runs here; True if found."""
    bpy = sys.modules.get("bpy")
    if bpy is None:
        return False
    try:
        base = os.path.dirname(bpy.__file__) if getattr(bpy, "__file__", None) else None
        version = "%d.%d" % bpy.app.version[:2]
    except AttributeError:
        return False
    for root in filter(None, (base, os.path.dirname(sys.executable))):
        lib = os.path.join(root, version, "python", "lib")
        if not os.path.isdir(lib):
            continue
        for entry in sorted(os.listdir(lib)):
            site = os.path.join(lib, entry, "site-packages")
            if os.path.isdir(os.path.join(site, "pxr")):
                sys.path.append(site)
                return True
    return False


def write_usd(path, strands, axis="z-up", scale=1.0):
    """Write `strands` (and the guides they carry) as a USD groom, atomically. Points and
    widths are multiplied by `scale` and the stage says metersPerUnit = 1 / scale; axis
    'z-up' keeps our frame, 'y-up' turns it (x, z, -y) and says upAxis Y."""
    s = check_strands(strands)
    scale = check_export_options(path, "USD", EXTENSIONS, AXES, axis, scale)
    Usd, UsdGeom, Sdf, Vt, Gf = pxr_modules()
    if s.guides is not None and s.guides.keys.num_strands > _FLOAT32_EXACT_INT:
        raise InputError(f"guides: {s.guides.keys.num_strands} key strands; USD carries at most "
                         f"{_FLOAT32_EXACT_INT} exactly (closest guides are float3)")
    s = convert_strands(s, "none" if axis == "z-up" else "y-up", scale)
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z if axis == "z-up" else UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0 / scale)
    groom = UsdGeom.Xform.Define(stage, GROOM_PRIM).GetPrim()
    stage.SetDefaultPrim(groom)
    groom.AddAppliedSchema("GroomAPI")
    for name, type_name, value in (("groom_version_major", Sdf.ValueTypeNames.Int, GROOM_VERSION[0]),
                                   ("groom_version_minor", Sdf.ValueTypeNames.Int, GROOM_VERSION[1]),
                                   ("groom_tool", Sdf.ValueTypeNames.String, f"{TOOL_NAME} {TOOL_VERSION}"),
                                   ("groom_properties", Sdf.ValueTypeNames.String, groom_properties(axis, scale))):
        groom.CreateAttribute("userProperties:" + name, type_name, custom=True).Set(value)
    for c in groom_layout(s):
        _define_curves(stage, f"{GROOM_PRIM}/{c.name}", c, UsdGeom, Sdf, Vt)
    with atomic_path(path) as tmp:
        if not stage.GetRootLayer().Export(tmp):
            raise OSError(f"USD could not write {tmp}")
    return [os.fspath(path)]


def _define_curves(stage, prim_path, c, UsdGeom, Sdf, Vt):
    curves = UsdGeom.BasisCurves.Define(stage, prim_path)
    curves.CreateTypeAttr(UsdGeom.Tokens.linear)
    curves.CreateWrapAttr(UsdGeom.Tokens.nonperiodic)
    points = Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(c.points, np.float32))
    widths = Vt.FloatArray.FromNumpy(np.ascontiguousarray(c.widths, np.float32))
    curves.CreatePointsAttr(points)
    curves.CreateCurveVertexCountsAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(c.counts, np.int32)))
    curves.CreateWidthsAttr(widths)
    curves.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
    curves.CreateExtentAttr(UsdGeom.Curves.ComputeExtent(points, widths))
    primvars = UsdGeom.PrimvarsAPI(curves)
    names = Sdf.ValueTypeNames
    types = {"int": (names.IntArray, Vt.IntArray, np.int32), "float": (names.FloatArray, Vt.FloatArray, np.float32),
             "float2": (names.TexCoord2fArray, Vt.Vec2fArray, np.float32),
             "float3": (names.Float3Array, Vt.Vec3fArray, np.float32),
             "int3": (names.Float3Array, Vt.Vec3fArray, np.float32)}
    for name, (scope, kind, values) in c.attributes.items():
        interpolation = UsdGeom.Tokens.vertex if scope == "vertex" else UsdGeom.Tokens.uniform
        if name == "alpha":
            name, kind = "displayOpacity", "float"
        if kind == "string":
            pv = primvars.CreatePrimvar(name, names.StringArray, interpolation)
            pv.Set(Vt.StringArray(list(values)))
            continue
        type_name, vt_type, dtype = types[kind]
        pv = primvars.CreatePrimvar(name, type_name, interpolation)
        pv.Set(vt_type.FromNumpy(np.ascontiguousarray(values, dtype)))


def read_usd(path):
    """Strands from the BasisCurves of a USD file (ours or another tool's): points and widths
    in each prim's world transform, brought back to our frame (Z up) and metres from the
    stage's upAxis and metersPerUnit; curves with groom_guide = 1 become the key strands.
    Non-linear curves are read by their control points. InputError for a file USD cannot open,
    one with no curves, or with counts that do not match its points."""
    Usd, UsdGeom, Sdf, Vt, Gf = pxr_modules()
    from pxr import Tf
    path = os.fspath(path)
    try:
        stage = Usd.Stage.Open(path)
    except Tf.ErrorException as e:
        raise InputError(f"{path}: USD cannot open this file ({str(e).strip().splitlines()[-1]}); re-export it") from None
    if stage is None:
        raise InputError(f"{path}: USD cannot open this file; re-export it")
    mpu = UsdGeom.GetStageMetersPerUnit(stage)
    axis = "y-up" if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y else "none"
    time = Usd.TimeCode.Default()
    found = []
    for prim in stage.Traverse():
        if not prim.IsA(UsdGeom.BasisCurves):
            continue
        found.append(_read_curves(path, prim, UsdGeom.BasisCurves(prim), time, mpu, axis, UsdGeom, Sdf))
    return strands_from_groom(found, path)


def _read_curves(path, prim, curves, time, mpu, axis, UsdGeom, Sdf):
    name = f"{path}: {prim.GetPath()}"
    points = curves.GetPointsAttr().Get(time)
    counts = curves.GetCurveVertexCountsAttr().Get(time)
    points = np.zeros((0, 3), np.float32) if points is None else np.array(points, np.float32).reshape(-1, 3)
    counts = np.zeros(0, np.int64) if counts is None else np.array(counts, np.int64).reshape(-1)
    if counts.size and counts.min() < 1:
        raise InputError(f"{name}: curveVertexCounts holds {int(counts.min())}; every curve needs points")
    if int(counts.sum()) != len(points):
        raise InputError(f"{name}: curveVertexCounts sum to {int(counts.sum())} but there are {len(points)} "
                         f"points; the file is broken, re-export it")
    world = np.array(curves.ComputeLocalToWorldTransform(time), np.float64)
    width_scale = mpu
    if not np.array_equal(world, np.eye(4)):
        # USD matrices act on row vectors: p' = p · M.
        points = (points.astype(np.float64) @ world[:3, :3] + world[3, :3]).astype(np.float32)
        width_scale *= abs(np.linalg.det(world[:3, :3])) ** (1 / 3)
    widths = _widths(curves, time, counts, len(points), name, UsdGeom)
    attrs = {}
    for pv in UsdGeom.PrimvarsAPI(prim).GetPrimvarsWithValues():
        pname = pv.GetPrimvarName()
        if not (pname.startswith("groom_") or pname in ("wisp", "displayOpacity", "displayColor")):
            continue
        value = pv.ComputeFlattened(time)
        if value is None:
            continue
        scope = "vertex" if pv.GetInterpolation() in (UsdGeom.Tokens.vertex, UsdGeom.Tokens.varying) else "uniform"
        arr = list(value) if pv.GetTypeName().scalarType == Sdf.ValueTypeNames.String else np.array(value)
        if pname == "displayOpacity":
            pname = "alpha"
        elif pname == "displayColor":
            if "groom_color" in attrs:
                continue
            pname = "groom_color"
        attrs[pname] = (scope, None, arr)
    pts = unconvert_points(points, axis, 1.0)
    if mpu != 1.0:
        pts = (pts.astype(np.float64) * mpu).astype(np.float32)
    w = widths if width_scale == 1.0 else (widths.astype(np.float64) * width_scale).astype(np.float32)
    return GroomCurves(str(prim.GetPath()), pts, counts, w, attrs)


def _widths(curves, time, counts, n_points, name, UsdGeom):
    """Per-point widths from any interpolation (none: Strands' default radius)."""
    w = curves.GetWidthsAttr().Get(time)
    if w is None or len(w) == 0:
        return np.full(n_points, 2e-4, np.float32)
    w = np.array(w, np.float32).reshape(-1)
    if len(w) == n_points:
        return w
    if len(w) == len(counts):
        return np.repeat(w, counts)
    if len(w) == 1:
        return np.full(n_points, w[0], np.float32)
    raise InputError(f"{name}: {len(w)} widths for {len(counts)} curves and {n_points} points; re-export it")

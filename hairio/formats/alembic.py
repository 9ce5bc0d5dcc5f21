# SPDX-License-Identifier: GPL-3.0-or-later
"""Alembic grooms written and read with the Alembic library itself (PyAlembic, from the
`alembic3d` package), laid out as Epic's "Alembic for Grooms" specification asks
(hairio.unreal.groom_layout):

    /groom            IXform; arbGeomParams groom_version_major / _minor (int16, constant),
                      groom_tool, groom_properties (string, constant: our axis and scale)
      guides          ICurves (when the strands carry guides): the key strands, groom_guide 1
      strands         ICurves: the strands

Curves are linear and non-periodic with widths per vertex (2 * radius); groom_color float32[3]
per vertex; groom_guide, groom_id, groom_group_id (int32), groom_group_name (string),
groom_root_uv (float32[2]), groom_closest_guides (int32[3]), groom_guide_weights (float32[3])
per curve (uniform scope). Alembic has no units or up axis: axis 'y-up' (Unreal's default
import: Rotation X 90, Scale Y -1) or 'z-up', and `scale` (100 for Unreal's centimetres), are
explicit and recorded in groom_properties, which our reader undoes; another tool's file is read
with the axis and scale given to `read_abc`.
"""
import os

import numpy as np

from ..atomic import atomic_path
from ..unreal import (GROOM_VERSION, GroomCurves, groom_layout, groom_properties,
                      parse_groom_properties, strands_from_groom)
from ..validate import InputError
from ._common import TOOL_NAME, TOOL_VERSION, check_export_options, check_strands
from .axes import convert_strands, unconvert_points

AXES = ("y-up", "z-up")
GROOM_OBJECT = "groom"


def alembic_modules():
    """(Abc, AbcGeom, imath) from alembic3d; InputError naming the fix when it is missing."""
    try:
        import imath
        from alembic3d import Abc, AbcGeom
    except ImportError:
        raise InputError("Alembic export needs the Alembic library: pip install alembic3d==1.8.12.1 "
                         "(inside Blender without it, the extension uses Blender's own exporter)") from None
    return Abc, AbcGeom, imath


def available():
    try:
        alembic_modules()
    except InputError:
        return False
    return True


def write_abc(path, strands, axis="y-up", scale=1.0):
    """Write `strands` (and the guides they carry) as an Alembic groom, atomically. Points
    and widths are multiplied by `scale`; axis 'y-up' turns our Z-up frame (x, z, -y)."""
    s = check_strands(strands)
    scale = check_export_options(path, "Alembic", (".abc",), AXES, axis, scale)
    Abc, AbcGeom, imath = alembic_modules()
    s = convert_strands(s, "y-up" if axis == "y-up" else "none", scale)
    with atomic_path(path) as tmp:
        archive = Abc.OArchive(tmp)
        try:
            top = AbcGeom.OXform(archive.getTop(), GROOM_OBJECT)
            params = top.getSchema().getArbGeomParams()
            _constant(AbcGeom, imath, params, "groom_version_major", "int16", GROOM_VERSION[0])
            _constant(AbcGeom, imath, params, "groom_version_minor", "int16", GROOM_VERSION[1])
            _constant(AbcGeom, imath, params, "groom_tool", "string", f"{TOOL_NAME} {TOOL_VERSION}")
            _constant(AbcGeom, imath, params, "groom_properties", "string", groom_properties(axis, scale))
            top.getSchema().set(AbcGeom.XformSample())
            for c in groom_layout(s):
                _write_curves(AbcGeom, imath, top, c)
        finally:
            # The archive is written out when its last reference goes; before the rename.
            del archive
            top = params = None
    return [os.fspath(path)]


def _constant(AbcGeom, imath, params, name, kind, value):
    if kind == "string":
        arr = imath.StringArray(1)
        arr[0] = value
        param = AbcGeom.OStringGeomParam(params, name, False, AbcGeom.GeometryScope.kConstantScope, 1)
        param.set(AbcGeom.OStringGeomParamSample(arr, AbcGeom.GeometryScope.kConstantScope))
    else:
        arr = imath.ShortArray(1)
        arr[0] = int(value)
        param = AbcGeom.OInt16GeomParam(params, name, False, AbcGeom.GeometryScope.kConstantScope, 1)
        param.set(AbcGeom.OInt16GeomParamSample(arr, AbcGeom.GeometryScope.kConstantScope))


def _write_curves(AbcGeom, imath, parent, c):
    scope = AbcGeom.GeometryScope
    obj = AbcGeom.OCurves(parent, c.name)
    schema = obj.getSchema()
    widths = AbcGeom.OFloatGeomParamSample(imath.FloatArrayFromBuffer(np.ascontiguousarray(c.widths, np.float32)),
                                           scope.kVertexScope)
    sample = AbcGeom.OCurvesSchemaSample(imath.V3fArrayFromBuffer(np.ascontiguousarray(c.points, np.float32)),
                                         imath.IntArrayFromBuffer(np.ascontiguousarray(c.counts, np.int32)),
                                         AbcGeom.CurveType.kLinear, AbcGeom.CurvePeriodicity.kNonPeriodic, widths)
    params = schema.getArbGeomParams()
    kinds = {"int": (AbcGeom.OInt32GeomParam, AbcGeom.OInt32GeomParamSample, imath.IntArrayFromBuffer, np.int32),
             "float": (AbcGeom.OFloatGeomParam, AbcGeom.OFloatGeomParamSample, imath.FloatArrayFromBuffer, np.float32),
             "float2": (AbcGeom.OV2fGeomParam, AbcGeom.OV2fGeomParamSample, imath.V2fArrayFromBuffer, np.float32),
             "float3": (AbcGeom.OV3fGeomParam, AbcGeom.OV3fGeomParamSample, imath.V3fArrayFromBuffer, np.float32),
             "int3": (AbcGeom.OV3iGeomParam, AbcGeom.OV3iGeomParamSample, imath.V3iArrayFromBuffer, np.int32)}
    for name, (where, kind, values) in c.attributes.items():
        sc = scope.kVertexScope if where == "vertex" else scope.kUniformScope
        if kind == "string":
            arr = imath.StringArray(len(values))
            for i, v in enumerate(values):
                arr[i] = v
            AbcGeom.OStringGeomParam(params, name, False, sc, 1).set(AbcGeom.OStringGeomParamSample(arr, sc))
            continue
        param_type, sample_type, from_buffer, dtype = kinds[kind]
        param = param_type(params, name, False, sc, 1)
        param.set(sample_type(from_buffer(np.ascontiguousarray(values, dtype)), sc))
    schema.set(sample)


def read_abc(path, axis="y-up", scale=1.0):
    """Strands from the ICurves of an Alembic file (ours or another tool's), each in its
    parents' transforms, brought back to our frame: by the axis and scale our writer recorded
    (groom_properties), else by `axis` and `scale`. Curves with groom_guide = 1 become the key
    strands. InputError for a file Alembic cannot open, with no curves or with broken counts."""
    Abc, AbcGeom, imath = alembic_modules()
    path = os.fspath(path)
    if axis not in AXES:
        raise InputError(f"axis: {axis!r} for abc; choose one of {', '.join(AXES)}")
    try:
        archive = Abc.IArchive(path)
    except RuntimeError as e:
        raise InputError(f"{path}: Alembic cannot open this file ({str(e).strip().splitlines()[-1]}); "
                         "re-export it") from None
    found = []
    recorded = [None]
    _walk(Abc, AbcGeom, archive.getTop(), np.eye(4), path, found, recorded, top=True)
    if recorded[0] is not None:
        axis, scale = recorded[0]
    curves = [_to_our_frame(c, axis, float(scale), m) for c, m in found]
    return strands_from_groom(curves, path)


def _walk(Abc, AbcGeom, obj, matrix, path, found, recorded, top=False):
    for i in range(obj.getNumChildren()):
        child = obj.getChild(i)
        header = child.getHeader()
        m = matrix
        if AbcGeom.IXform.matches(header):
            xform = AbcGeom.IXform(child, Abc.WrapExistingFlag.kWrapExisting)
            schema = xform.getSchema()
            if top and recorded[0] is None:
                recorded[0] = _recorded_options(AbcGeom, schema.getArbGeomParams())
            if schema.getNumSamples():
                local = np.array([[schema.getValue().getMatrix()[r][c] for c in range(4)] for r in range(4)])
                m = local @ matrix          # Alembic matrices act on row vectors too
            _walk(Abc, AbcGeom, child, m, path, found, recorded, top=False)
        elif AbcGeom.ICurves.matches(header):
            found.append((_read_curves(AbcGeom, AbcGeom.ICurves(child, Abc.WrapExistingFlag.kWrapExisting),
                                       f"{path}: {child.getFullName()}"), m))
            _walk(Abc, AbcGeom, child, m, path, found, recorded)
        else:
            _walk(Abc, AbcGeom, child, m, path, found, recorded)


def _recorded_options(AbcGeom, params):
    if not params.valid() or not params.getPropertyHeader("groom_properties"):
        return None
    try:
        value = AbcGeom.IStringGeomParam(params, "groom_properties").getExpandedValue().getVals()[0]
    except (RuntimeError, IndexError):
        return None
    got = parse_groom_properties(value)
    return got if got is not None and got[0] in AXES and got[1] > 0 else None


def _array(values, dtype, width=None):
    try:
        a = np.array(memoryview(values), dtype=dtype)
    except TypeError:           # the int8/int16 arrays have no buffer: element by element
        a = np.array([values[i] for i in range(len(values))], dtype=dtype)
    return a.reshape(-1, width) if width else a.reshape(-1)


def _read_curves(AbcGeom, curves, name):
    schema = curves.getSchema()
    if not schema.getNumSamples():
        return GroomCurves(name, np.zeros((0, 3), np.float32), np.zeros(0, np.int64), np.zeros(0, np.float32))
    sample = schema.getValue()
    points = _array(sample.getPositions(), np.float32, 3)
    counts = _array(sample.getCurvesNumVertices(), np.int64)
    if counts.size and counts.min() < 1:
        raise InputError(f"{name}: nVertices holds {int(counts.min())}; every curve needs points")
    if int(counts.sum()) != len(points):
        raise InputError(f"{name}: nVertices sum to {int(counts.sum())} but there are {len(points)} points; "
                         "the file is broken, re-export it")
    widths = _widths(schema, counts, len(points), name)
    attrs = {}
    params = schema.getArbGeomParams()
    if params.valid():
        for i in range(params.getNumProperties()):
            header = params.getPropertyHeader(i)
            pname = header.getName()
            if not (pname.startswith("groom_") or pname in ("alpha", "wisp")):
                continue
            value = _read_param(AbcGeom, params, header)
            if value is not None:
                attrs[pname] = value
    return GroomCurves(name, points, counts, widths, attrs)


_PARAMS = {  # (pod, extent) -> (IGeomParam type name, numpy dtype)
    ("int16", 1): ("IInt16GeomParam", np.int16), ("int32", 1): ("IInt32GeomParam", np.int32),
    ("int8", 1): ("ICharGeomParam", np.int8), ("float32", 1): ("IFloatGeomParam", np.float32),
    ("float32", 2): ("IV2fGeomParam", np.float32), ("float32", 3): ("IV3fGeomParam", np.float32),
    ("int32", 3): ("IV3iGeomParam", np.int32), ("float64", 2): ("IV2dGeomParam", np.float64),
    ("float64", 3): ("IV3dGeomParam", np.float64),
}


def _read_param(AbcGeom, params, header):
    """(scope, None, values) of one arbGeomParam, or None for a type we do not read."""
    dt = header.getDataType()
    pod = str(dt.getPod()).rsplit(".", 1)[-1].removeprefix("k").removesuffix("POD").lower()
    extent = int(dt.getExtent())
    name = header.getName()
    if pod == "string":
        param = AbcGeom.IStringGeomParam(params, name)
        vals = param.getExpandedValue().getVals()
        return _scope(param), None, [vals[i] for i in range(len(vals))]
    kind = _PARAMS.get((pod, extent))
    if kind is None:
        return None
    param = getattr(AbcGeom, kind[0])(params, name)
    vals = param.getExpandedValue().getVals()
    return _scope(param), None, _array(vals, kind[1], extent if extent > 1 else None)


def _scope(param):
    return "vertex" if str(param.getScope()).endswith(("kVertexScope", "kVaryingScope")) else "uniform"


def _widths(schema, counts, n_points, name):
    wp = schema.getWidthsParam()
    if not wp.valid():
        return np.full(n_points, 2e-4, np.float32)
    w = _array(wp.getExpandedValue().getVals(), np.float32)
    if len(w) == n_points:
        return w
    if len(w) == len(counts):
        return np.repeat(w, counts)
    if len(w) == 1:
        return np.full(n_points, w[0], np.float32)
    raise InputError(f"{name}: {len(w)} widths for {len(counts)} curves and {n_points} points; re-export it")


def _to_our_frame(c, axis, scale, matrix):
    points, widths = c.points, c.widths
    if not np.array_equal(matrix, np.eye(4)):
        points = (points.astype(np.float64) @ matrix[:3, :3] + matrix[3, :3]).astype(np.float32)
        widths = (widths * abs(np.linalg.det(matrix[:3, :3])) ** (1 / 3)).astype(np.float32)
    points = unconvert_points(points, "y-up" if axis == "y-up" else "none", scale)
    if scale != 1.0:
        widths = (widths.astype(np.float64) / scale).astype(np.float32)
    return GroomCurves(c.name, points, c.counts, widths, c.attributes)

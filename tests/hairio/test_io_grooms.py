# SPDX-License-Identifier: GPL-3.0-or-later
"""Alembic and USD grooms (hairio/formats/alembic.py, usd.py): each file read back with the
library itself (alembic3d, pxr) against Epic's groom schema, Pixar's validators, exact round
trips with guides and weights, and files that must be refused."""
import os

import numpy as np
import pytest

from hairio import Guides, InputError, Strands
from hairio.cli import export_main
from hairio.formats import read_strands, write_strands
from hairio.formats import alembic as abc_format
from hairio.formats import usd as usd_format
from hairio_scenes import make_wavy

alembic3d = pytest.importorskip("alembic3d")     # pinned in requirements.txt
pxr = pytest.importorskip("pxr")
from alembic3d import Abc, AbcGeom            # noqa: E402
from pxr import Sdf, Usd, UsdGeom              # noqa: E402


def groom(num_keys=6, seed=1):
    """Wavy strands carrying guides: keys in two parting groups, each strand's three guides
    drawn from its main key's group, random weights summing to 1, root UVs."""
    s = make_wavy(num_strands=40, seed=seed)
    rng = np.random.default_rng(seed)
    keys = make_wavy(num_strands=num_keys, points=(12, 12), seed=seed + 7)
    group = np.arange(num_keys, dtype=np.int32) % 2
    main = rng.integers(0, num_keys, s.num_strands)
    same = [np.flatnonzero(group == group[m]) for m in main]
    index = np.array([[m, rng.choice(g), rng.choice(g)] for m, g in zip(main, same)])
    weights = rng.dirichlet([2, 1, 1], s.num_strands)
    guides = Guides.from_arrays(keys, index, weights, group)
    return Strands.from_arrays(s.points, s.counts, s.radius, s.color, s.alpha, main, guides=guides,
                               root_uv=rng.uniform(0, 1, (s.num_strands, 2)))


def assert_same(a, b, exact=True):
    check = np.testing.assert_array_equal if exact else (
        lambda x, y: np.testing.assert_allclose(x, y, rtol=2.5e-7, atol=0))
    for name in ("points", "radius"):
        check(getattr(a, name), getattr(b, name))
    for name in ("counts", "color", "alpha", "wisp", "root_uv"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    check(a.guides.keys.points, b.guides.keys.points)
    check(a.guides.keys.radius, b.guides.keys.radius)
    for name in ("index", "weights", "group"):
        np.testing.assert_array_equal(getattr(a.guides, name), getattr(b.guides, name))
    np.testing.assert_array_equal(a.guides.keys.color, b.guides.keys.color)


# --- Alembic, read with alembic3d -----------------------------------------------------------

def _abc_objects(path):
    top = Abc.IArchive(path).getTop()
    groom_obj = top.getChild("groom")
    assert AbcGeom.IXform.matches(groom_obj.getHeader())
    xform = AbcGeom.IXform(groom_obj, Abc.WrapExistingFlag.kWrapExisting)
    curves = {}
    for i in range(groom_obj.getNumChildren()):
        child = groom_obj.getChild(i)
        assert AbcGeom.ICurves.matches(child.getHeader())
        curves[child.getName()] = AbcGeom.ICurves(child, Abc.WrapExistingFlag.kWrapExisting).getSchema()
    return xform.getSchema(), curves


def _param(params, name):
    header = params.getPropertyHeader(name)
    assert header is not None, f"{name} missing"
    dt = header.getDataType()
    return str(dt.getPod()).rsplit(".", 1)[-1], int(dt.getExtent())


def _values(cls, params, name):
    p = cls(params, name)
    vals = p.getExpandedValue().getVals()
    try:
        arr = np.array(memoryview(vals))
    except TypeError:
        arr = np.array([vals[i] for i in range(len(vals))])
    return str(p.getScope()).rsplit(".", 1)[-1], arr


def test_alembic_holds_epics_groom_schema(tmp_path):
    s = groom()
    path = str(tmp_path / "hair.abc")
    write_strands(path, s, axis="y-up", scale=100.0)
    top, curves = _abc_objects(path)
    assert set(curves) == {"guides", "strands"}
    tp = top.getArbGeomParams()
    for name, value in (("groom_version_major", 1), ("groom_version_minor", 5)):
        assert _param(tp, name) == ("kInt16POD", 1)
        scope, v = _values(AbcGeom.IInt16GeomParam, tp, name)
        assert scope == "kConstantScope" and v.tolist() == [value]
    strands, guides = curves["strands"], curves["guides"]
    sample = strands.getValue()
    assert str(sample.getType()).endswith("kLinear")
    np.testing.assert_array_equal(np.array(memoryview(sample.getCurvesNumVertices())), s.counts)
    # Per-vertex widths, 2 * radius in centimetres.
    w = strands.getWidthsParam()
    assert str(w.getScope()).endswith("kVertexScope")
    np.testing.assert_allclose(np.array(memoryview(w.getExpandedValue().getVals())), 200 * s.radius, rtol=1e-6)
    sp, gp = strands.getArbGeomParams(), guides.getArbGeomParams()
    expect = {"groom_color": ("kFloat32POD", 3, "kVertexScope"), "groom_root_uv": ("kFloat32POD", 2, "kUniformScope"),
              "groom_closest_guides": ("kInt32POD", 3, "kUniformScope"),
              "groom_guide_weights": ("kFloat32POD", 3, "kUniformScope"),
              "groom_guide": ("kInt32POD", 1, "kUniformScope"), "groom_id": ("kInt32POD", 1, "kUniformScope"),
              "groom_group_id": ("kInt32POD", 1, "kUniformScope"),
              "groom_group_name": ("kStringPOD", 1, "kUniformScope")}
    cls = {(p, e): c for p, e, c in (("kFloat32POD", 3, AbcGeom.IV3fGeomParam), ("kFloat32POD", 2, AbcGeom.IV2fGeomParam),
                                     ("kInt32POD", 3, AbcGeom.IV3iGeomParam), ("kInt32POD", 1, AbcGeom.IInt32GeomParam))}
    got = {}
    for name, (pod, extent, scope) in expect.items():
        assert _param(sp, name) == (pod, extent), name
        if pod == "kStringPOD":
            p = AbcGeom.IStringGeomParam(sp, name)
            assert str(p.getScope()).endswith(scope)
            vals = p.getExpandedValue().getVals()
            got[name] = [vals[i] for i in range(len(vals))]
            continue
        sc, got[name] = _values(cls[pod, extent], sp, name)
        assert sc == scope, name
    g = s.guides
    np.testing.assert_array_equal(got["groom_color"].reshape(-1, 3), s.color)
    np.testing.assert_array_equal(got["groom_guide_weights"].reshape(-1, 3), g.weights)
    assert (got["groom_guide"] == 0).all()
    _, guide_flag = _values(AbcGeom.IInt32GeomParam, gp, "groom_guide")
    _, guide_ids = _values(AbcGeom.IInt32GeomParam, gp, "groom_id")
    _, guide_groups = _values(AbcGeom.IInt32GeomParam, gp, "groom_group_id")
    assert (guide_flag == 1).all()
    # Every closest guide names a guide's groom_id in the strand's own group; ids are unique.
    closest = got["groom_closest_guides"].reshape(-1, 3)
    lookup = {int(i): k for k, i in enumerate(guide_ids)}
    np.testing.assert_array_equal(np.vectorize(lookup.__getitem__)(closest), g.index)
    assert (guide_groups[np.vectorize(lookup.__getitem__)(closest)] == got["groom_group_id"][:, None]).all()
    ids = np.concatenate([guide_ids, got["groom_id"]])
    assert len(np.unique(ids)) == len(ids)
    assert got["groom_group_name"] == [f"group_{x}" for x in g.group[g.index[:, 0]]]
    # Y up: our Z becomes the file's Y, our Y its -Z.
    pts = np.array(memoryview(sample.getPositions())).reshape(-1, 3)
    np.testing.assert_allclose(pts[:, 1], 100 * s.points[:, 2], rtol=1e-6)
    np.testing.assert_allclose(pts[:, 2], -100 * s.points[:, 1], rtol=1e-6)


@pytest.mark.parametrize("axis", ["y-up", "z-up"])
def test_alembic_round_trip_is_exact(tmp_path, axis):
    s = groom()
    npz, abc, back = (str(tmp_path / n) for n in ("a.npz", "a.abc", "b.npz"))
    write_strands(npz, s)
    write_strands(abc, read_strands(npz), axis=axis)
    write_strands(back, read_strands(abc))
    assert_same(s, read_strands(back))


def test_alembic_round_trip_in_centimetres_within_float32(tmp_path):
    s = groom()
    path = str(tmp_path / "a.abc")
    write_strands(path, s, scale=100.0)
    assert_same(s, read_strands(path), exact=False)


# --- USD, read with pxr ------------------------------------------------------------------------

def test_usd_is_a_groom_prim_unreal_imports(tmp_path):
    s = groom()
    path = str(tmp_path / "hair.usda")
    write_strands(path, s, scale=100.0)
    stage = Usd.Stage.Open(path)
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(0.01)
    groom_prim = stage.GetDefaultPrim()
    # Unreal registers GroomAPI itself; plain USD keeps the name in the prim's apiSchemas.
    assert groom_prim.GetMetadata("apiSchemas").GetAddedOrExplicitItems() == ["GroomAPI"]
    props = {p.GetBaseName(): p.Get() for p in groom_prim.GetAuthoredPropertiesInNamespace("userProperties")}
    assert props["groom_version_major"] == 1 and props["groom_version_minor"] == 5
    assert groom_prim.GetAttribute("userProperties:groom_version_major").GetTypeName() == Sdf.ValueTypeNames.Int
    strands = UsdGeom.BasisCurves(stage.GetPrimAtPath("/Groom/strands"))
    guides = UsdGeom.BasisCurves(stage.GetPrimAtPath("/Groom/guides"))
    assert strands and guides
    assert strands.GetTypeAttr().Get() == "linear"
    assert strands.GetWidthsInterpolation() == UsdGeom.Tokens.vertex
    widths = np.array(strands.GetWidthsAttr().Get())
    # In the stage's units like the points: metres * metersPerUnit gives 2 * radius back.
    np.testing.assert_allclose(widths * 0.01, 2 * s.radius, rtol=1e-6)
    pts = np.array(strands.GetPointsAttr().Get())
    extent = np.array(strands.GetExtentAttr().Get())
    half = widths.max() / 2
    np.testing.assert_allclose(extent[0], pts.min(axis=0) - half, rtol=1e-6)
    np.testing.assert_allclose(extent[1], pts.max(axis=0) + half, rtol=1e-6)
    pv = UsdGeom.PrimvarsAPI(strands.GetPrim())
    types = {"groom_color": (Sdf.ValueTypeNames.Float3Array, "vertex"),
             "groom_closest_guides": (Sdf.ValueTypeNames.Float3Array, "uniform"),
             "groom_guide_weights": (Sdf.ValueTypeNames.Float3Array, "uniform"),
             "groom_root_uv": (Sdf.ValueTypeNames.TexCoord2fArray, "uniform"),
             "groom_guide": (Sdf.ValueTypeNames.IntArray, "uniform"),
             "groom_id": (Sdf.ValueTypeNames.IntArray, "uniform"),
             "groom_group_id": (Sdf.ValueTypeNames.IntArray, "uniform"),
             "groom_group_name": (Sdf.ValueTypeNames.StringArray, "uniform"),
             "displayOpacity": (Sdf.ValueTypeNames.FloatArray, "vertex")}
    for name, (type_name, interpolation) in types.items():
        p = pv.GetPrimvar(name)
        assert p and p.GetTypeName() == type_name and p.GetInterpolation() == interpolation, name
    closest = np.array(pv.GetPrimvar("groom_closest_guides").Get())
    guide_ids = np.array(UsdGeom.PrimvarsAPI(guides.GetPrim()).GetPrimvar("groom_id").Get())
    assert (np.array(UsdGeom.PrimvarsAPI(guides.GetPrim()).GetPrimvar("groom_guide").Get()) == 1).all()
    np.testing.assert_array_equal(guide_ids[s.guides.index], closest)
    np.testing.assert_array_equal(np.array(pv.GetPrimvar("groom_guide_weights").Get()), s.guides.weights)


def test_usd_validators_report_nothing(tmp_path):
    validation = pytest.importorskip("pxr.UsdValidation")
    path = str(tmp_path / "hair.usd")
    write_strands(path, groom(), axis="y-up", scale=100.0)
    validators = validation.ValidationRegistry().GetOrLoadAllValidators()
    assert len(validators) > 10
    errors = validation.ValidationContext(validators).Validate(Usd.Stage.Open(path))
    assert [e.GetMessage() for e in errors] == []


@pytest.mark.parametrize("ext,axis", [(".usd", "z-up"), (".usda", "y-up"), (".usdc", "z-up")])
def test_usd_round_trip_is_exact(tmp_path, ext, axis):
    s = groom()
    npz, usd, back = (str(tmp_path / n) for n in ("a.npz", "a" + ext, "b.npz"))
    write_strands(npz, s)
    write_strands(usd, read_strands(npz), axis=axis)
    write_strands(back, read_strands(usd))
    assert_same(s, read_strands(back))


def test_usd_round_trip_in_centimetres_within_float32(tmp_path):
    s = groom()
    path = str(tmp_path / "a.usd")
    write_strands(path, s, scale=100.0)
    assert_same(s, read_strands(path), exact=False)


def test_another_tools_usd_is_read_in_its_transform_and_units(tmp_path):
    path = str(tmp_path / "other.usda")
    stage = Usd.Stage.CreateNew(path)
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    xf = UsdGeom.Xform.Define(stage, "/Hair")
    xf.AddTranslateOp().Set((10.0, 0.0, 0.0))
    c = UsdGeom.BasisCurves.Define(stage, "/Hair/curves")
    c.CreatePointsAttr([(0, 0, 0), (0, 0, 5), (1, 0, 0), (1, 0, 4), (1, 0, 8)])
    c.CreateCurveVertexCountsAttr([2, 3])
    c.CreateWidthsAttr([0.2, 0.4])
    c.SetWidthsInterpolation(UsdGeom.Tokens.uniform)
    stage.Save()
    s = read_strands(path)
    np.testing.assert_array_equal(s.counts, [2, 3])
    np.testing.assert_allclose(s.points[:, 0], [0.1, 0.1, 0.11, 0.11, 0.11], rtol=1e-6)
    np.testing.assert_allclose(s.radius, [0.001, 0.001, 0.002, 0.002, 0.002], rtol=1e-6)
    assert s.guides is None


# --- guides in the .npz -------------------------------------------------------------------------

def test_npz_carries_guides_and_refuses_a_partial_set(tmp_path):
    s = groom()
    path = str(tmp_path / "g.npz")
    write_strands(path, s)
    assert_same(s, read_strands(path))
    arrays = dict(np.load(path))
    del arrays["guide_weights"]
    np.savez(path, **arrays)
    with pytest.raises(InputError, match="guide_weights"):
        read_strands(path)


def test_guides_naming_a_missing_key_are_refused():
    s = make_wavy(num_strands=4)
    keys = make_wavy(num_strands=2, seed=3)
    with pytest.raises(InputError, match=r"guides: key indices must lie in \[0, 2\)"):
        Guides.from_arrays(keys, np.full((4, 3), 2), np.full((4, 3), 1 / 3))
    with pytest.raises(InputError, match="guides: 3 rows for 4 strands"):
        s.with_guides(Guides.from_arrays(keys, np.zeros((3, 3)), np.full((3, 3), 1 / 3)))


# --- bad input ----------------------------------------------------------------------------------

@pytest.mark.parametrize("name,module,failing", [("hair.abc", abc_format, "_write_curves"),
                                                  ("hair.usd", usd_format, "_define_curves")])
def test_a_failed_export_leaves_no_half_file(tmp_path, monkeypatch, name, module, failing):
    calls = []
    real = getattr(module, failing)

    def fail_second(*args):
        calls.append(1)
        if len(calls) == 2:
            raise RuntimeError("disk gone")
        return real(*args)
    monkeypatch.setattr(module, failing, fail_second)
    with pytest.raises(RuntimeError, match="disk gone"):
        write_strands(str(tmp_path / name), groom())
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("ext", [".abc", ".usd"])
def test_export_to_an_unwritable_place_writes_nothing(tmp_path, capsys, ext):
    src = str(tmp_path / "in.npz")
    write_strands(src, groom())
    out = str(tmp_path / "missing" / ("out" + ext))
    assert export_main([src, "--out", out]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert sorted(os.listdir(tmp_path)) == ["in.npz", "in.npz.json"]


def test_command_line_writes_grooms_with_guides(tmp_path):
    src = str(tmp_path / "in.npz")
    s = groom()
    write_strands(src, s)
    for ext in (".abc", ".usd"):
        out = str(tmp_path / ("out" + ext))
        assert export_main([src, "--out", out, "--scale", "100"]) == 0
        assert_same(s, read_strands(out), exact=False)


def _abc_without_curves(path):
    archive = Abc.OArchive(path)
    AbcGeom.OXform(archive.getTop(), "empty").getSchema().set(AbcGeom.XformSample())
    del archive


def _abc_broken_counts(path):
    import imath
    archive = Abc.OArchive(path)
    curves = AbcGeom.OCurves(archive.getTop(), "hair")
    curves.getSchema().set(AbcGeom.OCurvesSchemaSample(
        imath.V3fArrayFromBuffer(np.zeros((5, 3), np.float32)), imath.IntArrayFromBuffer(np.array([2, 4], np.int32)),
        AbcGeom.CurveType.kLinear))
    del archive, curves


def _usd_without_curves(path):
    stage = Usd.Stage.CreateNew(path)
    UsdGeom.Xform.Define(stage, "/Empty")
    stage.Save()


def _usd_broken_counts(path):
    stage = Usd.Stage.CreateNew(path)
    c = UsdGeom.BasisCurves.Define(stage, "/Hair")
    c.CreatePointsAttr([(0, 0, 0)] * 5)
    c.CreateCurveVertexCountsAttr([2, 4])
    stage.Save()


@pytest.mark.parametrize("name,make,message", [
    ("empty.abc", _abc_without_curves, "no curves"),
    ("broken.abc", _abc_broken_counts, "nVertices sum to 6 but there are 5 points"),
    ("empty.usda", _usd_without_curves, "no curves"),
    ("broken.usda", _usd_broken_counts, "curveVertexCounts sum to 6 but there are 5 points"),
])
def test_grooms_with_no_or_broken_curves_are_refused(tmp_path, name, make, message):
    path = str(tmp_path / name)
    make(path)
    with pytest.raises(InputError, match=message):
        read_strands(path)


@pytest.mark.parametrize("name", ["junk.abc", "junk.usd"])
def test_a_file_the_library_cannot_open_is_refused(tmp_path, name):
    path = tmp_path / name
    path.write_bytes(b"not a groom at all" * 10)
    with pytest.raises(InputError, match="cannot open this file"):
        read_strands(str(path))


def test_groom_generate_writes_the_guides_it_interpolated(tmp_path):
    from groom import default_scalp, generate, load_preset
    from groom.__main__ import main
    out = str(tmp_path / "parted.npz")
    assert main(["generate", "--preset", "parted", "--count", "300", "--seed", "3", "--collider", "none",
                 "--out", out]) == 0
    s = read_strands(out)
    preset = load_preset("parted")
    scalp = default_scalp()
    placement = preset.place_keys(scalp)
    result = generate(scalp, placement.keys, placement.params.replace(count=300, seed=3))
    np.testing.assert_array_equal(s.guides.index, result.guides)
    np.testing.assert_array_equal(s.guides.weights, result.guide_weights)
    np.testing.assert_array_equal(s.guides.group, [k.group for k in placement.keys])
    assert len(np.unique(s.guides.group)) == 2                  # a parting: two groups of keys
    np.testing.assert_array_equal(s.guides.keys.points[s.guides.keys.offsets],
                                  np.float32([k.root for k in placement.keys]))
    np.testing.assert_array_equal(s.wisp, result.guides[:, 0])


@pytest.mark.parametrize("axis", ["y-up", "unreal", "directx"])
def test_a_groom_turned_into_a_frame_and_back_is_the_same_groom_exactly(axis):
    from hairio.formats.axes import convert_strands, unconvert_strands
    g = groom()
    turned = convert_strands(g, axis)
    assert not np.array_equal(turned.guides.keys.points, g.guides.keys.points)   # the keys turned too
    assert_same(unconvert_strands(turned, axis), g)
    assert unconvert_strands(g, "none") is g

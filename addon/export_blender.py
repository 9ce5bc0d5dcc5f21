# SPDX-License-Identifier: GPL-3.0-or-later
"""Alembic and USD export of a hair Curves object through Blender's own exporters.

The panel's Export writes Alembic and USD with hairio's own writers (alembic3d, and the pxr
Blender ships), as the command line does; this module is its fallback where the format's
library does not import inside Blender (hairio.formats.registry: Format.available), and the
operator then says what the file lacks. `export_hair` adds the groom attributes Unreal reads
(hairio.unreal.groom_attributes, root UVs when known) and runs `export_curves_object`.

`export_curves_object` never touches the user's scene: it copies the Curves datablock,
bakes the object's world matrix, the scale and the axis choice into the copy's points and
radii (so the file holds final coordinates and widths with identity transforms), links it
alone into a temporary scene, runs `wm.alembic_export` / `wm.usd_export` there on a
temporary file name, renames it into place, and removes everything it created.

What the files hold (verified by tests/hairio/test_io_blender_export.py):
- Alembic: one ICurves, linear (POLY), `width` per point = 2 * radius, nVertices per curve.
  Blender's Alembic exporter always converts to Y up ((x, y, z) -> (x, z, -y)); axis="y-up"
  keeps that (Unreal's groom import default conversion, Rotation X 90 and Scale Y -1, then
  brings it to Unreal's Z-up left-handed frame); axis="z-up" pre-rotates so the file holds
  Blender's Z-up coordinates (import into Unreal with Rotation 0, Scale Y -1).
  Unreal is in centimetres: pass scale=100 for a scene in metres; points and widths are both
  scaled in the file.
  Limitation: Blender writes no other curve attributes to Alembic (checked in Blender 5.0:
  only `width`), so groom_guide, groom_group_id, groom_root_uv, groom_color,
  groom_closest_guides, groom_guide_weights and groom_version_* are not in this fallback's
  .abc (hairio's writer, with the alembic3d the extension ships, writes them all). In Unreal:
  import it with "Generate guides", let Unreal compute root UVs, and set the colour in the
  groom material.
- USD: a BasisCurves prim, type "linear", curveVertexCounts, per-vertex `widths`
  (= 2 * radius), and every attribute of `attributes` as a primvar of the same name
  (hairio.unreal.groom_attributes). Orientation and units are left to Blender's USD options
  so the stage stays self-describing: axis="y-up" sets upAxis Y with a root rotation,
  scale s sets metersPerUnit = 1/s with a root scale (a Blender whose USD exporter has no
  unit options, 4.2, gets the points scaled by s instead, and the same metersPerUnit).

Bad requests are hairio.InputError (named input, what to do); a Blender exporter that ran and
wrote nothing is ExporterFailed.
"""
import contextlib
import os
import tempfile

import numpy as np
import bpy

from hairio import InputError

# The formats Blender's own exporters write (their extensions and axes: the format registry's).
FORMATS = ("abc", "usd")

# Blender's Alembic writer maps (x, y, z) -> (x, z, -y); its inverse, applied first, makes
# the file hold Blender's own Z-up coordinates.
_ALEMBIC_KEEP_Z_UP = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], np.float64)


class ExporterFailed(RuntimeError):
    """Blender's exporter ran and wrote no file; the message says what it reported."""


def _check(format, path, axis, scale):
    from hairio.formats import BY_NAME
    if format not in FORMATS:
        raise InputError(f"format: {format!r}; choose one of {', '.join(FORMATS)}")
    fmt = BY_NAME[format]
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext not in fmt.extensions:
        raise InputError(f"{path}: a {format} file must end in {' or '.join(fmt.extensions)}")
    axis = fmt.axes[0] if axis is None else axis
    if axis not in fmt.axes:
        raise InputError(f"axis: {axis!r} for {format}; choose one of {', '.join(fmt.axes)}")
    scale = float(scale)
    if not np.isfinite(scale) or scale <= 0:
        raise InputError(f"scale: {scale} is not a positive finite number")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise InputError(f"{path}: output folder {folder!r} does not exist; create it first")
    return ext, axis, scale


def _bake(data, matrix, attributes):
    """Make the Curves datablock `data` (a copy) POLY, carry its points and radii by `matrix`
    (blender_curves.transform_strand_arrays), add the generic `attributes`, drop its
    materials (Blender's shading is no part of the file: the USD exporter would still bind
    an empty material to the curves even with materials off)."""
    from .blender_curves import make_poly, transform_strand_arrays
    data.materials.clear()
    n_p = len(data.points)
    if len(data.curves):
        make_poly(data)
    if n_p:
        pos = np.empty(n_p * 3, np.float32)
        data.attributes["position"].data.foreach_get("vector", pos)
        radius = np.full(n_p, 0.0, np.float32)
        attr = data.attributes.get("radius")
        if attr is not None and attr.domain == 'POINT' and attr.data_type == 'FLOAT':
            attr.data.foreach_get("value", radius)
        else:
            attr = data.attributes.new("radius", 'FLOAT', 'POINT')
            radius[:] = 0.005  # Blender's own default hair radius when none is stored
        pos, radius = transform_strand_arrays(pos.reshape(n_p, 3), radius, matrix)
        data.attributes["position"].data.foreach_set("vector", pos.ravel())
        attr.data.foreach_set("value", radius)
    for name, (domain, data_type, values) in (attributes or {}).items():
        old = data.attributes.get(name)
        if old is not None:
            data.attributes.remove(old)
        attr = data.attributes.new(name, data_type, domain)
        key = "vector" if data_type in ('FLOAT_VECTOR', 'FLOAT2') else (
            "color" if data_type == 'FLOAT_COLOR' else "value")
        attr.data.foreach_set(key, np.ascontiguousarray(values).ravel())
    data.update_tag()


def export_hair(obj, path, format="abc", scale=1.0, axis=None, root_uv=None, groom_attributes=True):
    """Export the hair Curves object `obj` with the per-strand attributes Unreal's groom
    importer reads (hairio.unreal.groom_attributes; `root_uv` (S, 2), e.g. from the scalp's
    UV map, becomes groom_root_uv). The panel's Export and the command line both run this.
    Other arguments as export_curves_object; returns the path written."""
    from .blender_curves import ROOT_UV_ATTRIBUTE, curves_to_strands
    _check(format, path, axis, scale)
    attributes = {}
    if groom_attributes:
        from hairio.unreal import groom_attributes as attributes_of
        attributes = attributes_of(curves_to_strands(obj), root_uv=root_uv)
    if root_uv is not None:
        from hairio.validate import check_finite, check_shape
        root_uv = check_finite("root_uv", check_shape("root_uv", np.asarray(root_uv), (len(obj.data.curves), 2)))
        # Blender's own attachment attribute, as Generate stores it: the file is then the same
        # whether the hair came from a scalp or, with its UVs, from a strand file.
        attributes[ROOT_UV_ATTRIBUTE] = ('CURVE', 'FLOAT2', np.asarray(root_uv, np.float32))
    return export_curves_object(obj, path, format, scale=scale, axis=axis, attributes=attributes)


def export_curves_object(obj, path, format="abc", scale=1.0, axis=None, attributes=None):
    """Export the hair Curves object `obj` to `path` as Alembic ("abc") or USD ("usd").

    scale: multiplies points and widths (100 turns metres into Unreal's centimetres).
    axis: abc "y-up" (default, Blender's Alembic convention) or "z-up"; usd "z-up" (default)
    or "y-up". attributes: {name: (domain, data type, array)} extra Curves attributes, e.g.
    hairio.unreal.groom_attributes(...); USD writes them as primvars, Alembic drops them.
    The file appears complete or not at all; the open scene is left exactly as it was.
    Returns the path written.
    """
    if obj is None or obj.type != 'CURVES':
        raise InputError(f"obj: expected a hair Curves object, got "
                         f"{'nothing' if obj is None else obj.type}")
    ext, axis, scale = _check(format, path, axis, scale)
    world = np.array(obj.matrix_world, np.float64)
    matrix = world.copy()
    # Alembic has no units, and a USD exporter without unit options (Blender 4.2) takes the
    # stage's metersPerUnit from the scene's unit scale: both get `scale` baked into the
    # points (widths follow the matrix's uniform scale, so into them too).
    bake_scale = format == "abc" or not _usd_unit_options()
    if bake_scale:
        conv = scale * (_ALEMBIC_KEEP_Z_UP if format == "abc" and axis == "z-up" else np.eye(3))
        matrix[:3, :] = conv @ world[:3, :]
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp_path = tempfile.mkstemp(prefix=".tmp-", suffix=ext, dir=folder)
    os.close(fd)
    created = []
    # The file names its prims after the object and its data: lend both names to the copies
    # while exporting, and give them back afterwards.
    name, data_name = obj.name, obj.data.name
    try:
        data = obj.data.copy()
        created.append(data)
        _bake(data, matrix, attributes)
        obj.name = name + ".hair-export-original"
        obj.data.name = data_name + ".hair-export-original"
        data.name = data_name
        tmp_obj = bpy.data.objects.new(name, data)
        created.append(tmp_obj)
        scene = bpy.data.scenes.new(".hair-export")
        created.append(scene)
        scene.collection.objects.link(tmp_obj)
        scene.frame_start = scene.frame_end = scene.frame_current = bpy.context.scene.frame_current
        view_layer = scene.view_layers[0]
        with bpy.context.temp_override(scene=scene, view_layer=view_layer), _exporter_errors(format):
            if format == "abc":
                result = bpy.ops.wm.alembic_export(
                    filepath=tmp_path, check_existing=False, selected=False,
                    start=scene.frame_current, end=scene.frame_current, global_scale=1.0,
                    export_custom_properties=False, as_background_job=False,
                    evaluation_mode='RENDER', init_scene_frame_range=False)
            else:
                unit_opts = {}
                if bake_scale:
                    scene.unit_settings.scale_length = 1.0 / scale
                else:
                    units = {1.0: 'METERS', 100.0: 'CENTIMETERS', 1000.0: 'MILLIMETERS'}.get(scale, 'CUSTOM')
                    unit_opts = dict(convert_scene_units=units, meters_per_unit=1.0 / scale)
                result = bpy.ops.wm.usd_export(
                    filepath=tmp_path, check_existing=False, selected_objects_only=False,
                    export_animation=False, export_materials=False,
                    convert_orientation=(axis == "y-up"), export_global_up_selection='Y',
                    export_global_forward_selection='NEGATIVE_Z',
                    evaluation_mode='RENDER', **unit_opts)
        if 'FINISHED' not in result or os.path.getsize(tmp_path) == 0:
            raise ExporterFailed(f"Blender's {format} exporter did not finish ({result})")
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp_path, 0o666 & ~umask)  # mkstemp made it private; exports are ordinary files
        os.replace(tmp_path, path)
        return os.fspath(path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp_path)
        for block in reversed(created):
            _remove(block)
        obj.name = name
        obj.data.name = data_name


def _usd_unit_options():
    """Whether this Blender's USD exporter converts units itself (convert_scene_units; 4.2's has not)."""
    return "convert_scene_units" in bpy.ops.wm.usd_export.get_rna_type().properties.keys()


@contextlib.contextmanager
def _exporter_errors(format):
    # bpy.ops raises RuntimeError with the operator's own error report.
    try:
        yield
    except RuntimeError as e:
        raise ExporterFailed(f"Blender's {format} exporter failed: {e}") from e


def _remove(block):
    if isinstance(block, bpy.types.Scene):
        bpy.data.scenes.remove(block)
    elif isinstance(block, bpy.types.Object):
        bpy.data.objects.remove(block)
    else:
        bpy.data.hair_curves.remove(block)

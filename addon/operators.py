# SPDX-License-Identifier: GPL-3.0-or-later
"""Operators: Add Key Strand, Generate, Render Preview, presets, export.

Each one checks and computes everything it needs before its first change to the file, and
its press is one transaction (transaction.reports_errors), so a failure is a report in the UI
and leaves the scene and the files exactly as they were (and makes no undo step). A bad
input is reported as the user's to fix; anything else is a bug, reported as an internal
error with its traceback in the console, and undone all the same. Never a traceback in the
UI. Heavy modules (groom, tracer, moderngl) are imported inside execute(), so enabling the
extension costs nothing.
"""
import os
import pathlib
import time

import numpy as np
import bpy
from bpy.props import EnumProperty, FloatProperty, FloatVectorProperty, BoolProperty, StringProperty
from bpy.types import Operator
from bpy_extras import view3d_utils
from bpy_extras.io_utils import ExportHelper

from hairio.formats.registry import BY_NAME, FORMATS

from . import blender_curves, head, preview, progress, progressive, scene_data
from .hair import existing_hair, generate, prepare_workers_meanwhile, read_collider
from .properties import dict_to_settings, groom_params
from .scene_data import find_scalp
from .transaction import reports_errors, transaction

# The export formats are hairio's one table (hairio.formats.registry); the operator's list,
# its file filter and extension, and the File > Export menu are all read from it.
EXPORT_FORMATS = tuple((f.name, f.label, f.description) for f in FORMATS)


def _scalp_or_report(op, context):
    """The scalp the operator works on, or None after reporting why there is none."""
    scalp = find_scalp(context)
    if scalp is None:
        op.report({'ERROR'}, "Select a scalp mesh first")
    return scalp


def _poll_scalp(cls, context):
    if find_scalp(context) is None:
        cls.poll_message_set("Select a scalp mesh, or one of its key strands or its hair")
        return False
    return True


def _poll_hair(cls, context):
    if not _poll_scalp(cls, context):
        return False
    if existing_hair(find_scalp(context)) is None:
        cls.poll_message_set("Generate the hair first")
        return False
    return True


def preset_folders():
    """Folders holding preset .json files: the ones shipped with the extension, then the
    user's saved ones (in the extension's user folder when installed as an extension)."""
    folders = [pathlib.Path(__file__).resolve().parents[1] / "presets"]
    package = __package__.rpartition(".")[0]
    if package.startswith("bl_ext."):
        try:
            folders.append(pathlib.Path(bpy.utils.extension_path_user(package, path="presets", create=False)))
        except (ValueError, RuntimeError):
            pass
    return [f for f in folders if f.is_dir()]


def preset_files():
    """{name: path} of every preset found (a user preset of the same name wins)."""
    found = {}
    for folder in preset_folders():
        for path in sorted(folder.glob("*.json")):
            found[path.stem] = path
    return found


_preset_items = []


def _preset_enum(self, context):
    # Blender needs the item strings kept alive while the enum is shown.
    global _preset_items
    _preset_items = [(name, name.replace("_", " ").title(), str(path)) for name, path in preset_files().items()]
    return _preset_items or [('NONE', "(no presets)", "No preset files found")]


class HAIR_OT_add_key_strand(Operator):
    """Add a key strand: click on the scalp where it should grow (Esc to cancel)"""
    bl_idname = "hair.add_key_strand"
    bl_label = "Add Key Strand"
    bl_options = {'REGISTER', 'UNDO'}

    location: FloatVectorProperty(name="Location", size=3, subtype='XYZ',
                                  description="Point on or near the scalp (world space); the key "
                                              "grows from the nearest surface point")

    @classmethod
    def poll(cls, context):
        return _poll_scalp(cls, context)

    def invoke(self, context, event):
        if context.area is None or context.area.type != 'VIEW_3D':
            return self.execute(context)
        context.window_manager.modal_handler_add(self)
        context.workspace.status_text_set("Click on the scalp to add a key strand; Esc or right-click cancels")
        return {'RUNNING_MODAL'}

    def modal(self, context, event):
        if event.type in {'ESC', 'RIGHTMOUSE'} and event.value == 'PRESS':
            context.workspace.status_text_set(None)
            return {'CANCELLED'}
        if event.type == 'LEFTMOUSE' and event.value == 'PRESS':
            hit = self._raycast(context, event)
            if hit is None:
                self.report({'WARNING'}, "Click on the scalp mesh")
                return {'RUNNING_MODAL'}
            context.workspace.status_text_set(None)
            self.location = hit
            return self.execute(context)
        return {'PASS_THROUGH'} if event.type in {'MIDDLEMOUSE', 'WHEELUPMOUSE', 'WHEELDOWNMOUSE'} \
            else {'RUNNING_MODAL'}

    @staticmethod
    def _raycast(context, event):
        scalp = find_scalp(context)
        region, rv3d = context.region, context.region_data
        if scalp is None or region is None or rv3d is None:
            return None
        coord = (event.mouse_region_x, event.mouse_region_y)
        origin = view3d_utils.region_2d_to_origin_3d(region, rv3d, coord)
        direction = view3d_utils.region_2d_to_vector_3d(region, rv3d, coord)
        inv = scalp.matrix_world.inverted()
        o_local = inv @ origin
        d_local = (inv.to_3x3() @ direction).normalized()
        evaluated = scalp.evaluated_get(context.evaluated_depsgraph_get())
        ok, loc, _normal, _face = evaluated.ray_cast(o_local, d_local)
        return (scalp.matrix_world @ loc) if ok else None

    @reports_errors
    def execute(self, context):
        from groom import place_key
        from groom.frames import root_frames
        from groom.keys import shape_profile
        scalp = _scalp_or_report(self, context)
        if scalp is None:
            return {'CANCELLED'}
        settings = scalp.keystrand_hair
        scalp_data = scene_data.read_scalp(scalp, context.evaluated_depsgraph_get())
        world = np.append(np.asarray(self.location, np.float64), 1.0)
        local = (np.linalg.inv(np.array(scalp.matrix_world, np.float64)) @ world)[:3]
        tri, bary, root = scalp_data.closest_points(local[None])
        normal = scalp_data.normals_at(tri, bary, settings.normal_mode)
        # The head's axes in the mesh, the ones Generate grows the hair with.
        frame = root_frames(normal, *head.scalp_axes(scalp))[0]
        profile = shape_profile(settings.key_shape.lower(), settings.key_length)
        points = place_key(profile, root[0], frame)
        with transaction() as tx:
            tx.keep_settings(scalp)
            settings.role = 'SCALP'
            key = scene_data.new_key_object(scalp, points, name=f"{scalp.name} Key")
        for obj in context.selected_objects:
            obj.select_set(False)
        key.select_set(True)
        context.view_layer.objects.active = key
        self.report({'INFO'}, f"Added key strand {key.name!r}")
        return {'FINISHED'}


class HAIR_OT_generate(Operator):
    """Grow the hair on the scalp from its key strands (replaces the scalp's hair)"""
    bl_idname = "hair.generate"
    bl_label = "Generate Hair"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        return _poll_scalp(cls, context)

    @reports_errors
    def execute(self, context):
        scalp = _scalp_or_report(self, context)
        if scalp is None:
            return {'CANCELLED'}
        with progress.BlenderProgress(context.window_manager, context.workspace, "Generating hair") as shown:
            hair, result, t = generate(scalp, context.evaluated_depsgraph_get(), progress=shown)
        s = result.strands
        collision = result.collision
        moved = "" if collision is None else f", {collision.strands_moved:,} moved out of {collision.collider!r}"
        self.report({'INFO'}, f"Generated {s.num_strands:,} strands ({s.num_points:,} points{moved}) in "
                              f"{t['total_s']:.2f} s (model {t['collider_s'] + t['groom_s']:.2f} s)")
        warning = collision.warning() if collision is not None else None
        if warning is not None:
            names = [k.name for k in scene_data.key_objects(scalp)]
            which = ", ".join(f"key {k.key} is {names[k.key]!r}" for k in collision.keys_inside)
            self.report({'WARNING'}, f"{warning} ({which})")
        return {'FINISHED'}


class HAIR_OT_render_preview(Operator):
    """Render the scene camera's view of the hair with the hair tracer into the image "Hair Preview\""""
    bl_idname = "hair.render_preview"
    bl_label = "Render Preview"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        return _poll_scalp(cls, context)

    @reports_errors(failures=((preview.RendererDied, lambda op, e: (
        f"The preview renderer stopped ({e}). Blender is fine; press Render Preview again to start a "
        "new renderer")),))
    def execute(self, context):
        scalp = _scalp_or_report(self, context)
        if scalp is None:
            return {'CANCELLED'}
        hair = existing_hair(scalp)
        if hair is None:
            self.report({'ERROR'}, f"Scalp {scalp.name!r} has no hair yet: press Generate first")
            return {'CANCELLED'}
        camera = context.scene.camera
        if camera is None or camera.type != 'CAMERA':
            self.report({'ERROR'}, "The scene has no camera: add one and make it the active camera "
                                   "(Ctrl+Numpad 0 on a camera)")
            return {'CANCELLED'}
        t0 = time.perf_counter()
        # The first image now; progressive.py refines it while nothing changes.
        session = progressive.start(context, scalp, hair, camera)
        image = bpy.data.images[preview.IMAGE_NAME]
        preview.show_image(context, image)
        w, h = image.size
        self.report({'INFO'}, f"Rendered {w}x{h} in {time.perf_counter() - t0:.2f} s"
                              + ("" if bpy.app.background else "; refining while nothing changes"))
        if session.note is not None:
            self.report({'WARNING'}, session.note)
        return {'FINISHED'}


class HAIR_OT_load_preset(Operator):
    """Load a hairstyle onto the scalp: its key strands (replacing the scalp's) and its settings"""
    bl_idname = "hair.load_preset"
    bl_label = "Load Preset"
    bl_options = {'REGISTER', 'UNDO'}

    preset: EnumProperty(name="Preset", items=_preset_enum, description="The hairstyle to load")
    filepath: StringProperty(name="File", subtype='FILE_PATH', default="",
                             description="A preset .json file; when set, used instead of Preset")
    replace: BoolProperty(name="Replace Keys", default=True,
                          description="Delete the scalp's current key strands first")

    @classmethod
    def poll(cls, context):
        return _poll_scalp(cls, context)

    @reports_errors
    def execute(self, context):
        from groom import load_preset
        scalp = _scalp_or_report(self, context)
        if scalp is None:
            return {'CANCELLED'}
        source = self.filepath or str(preset_files().get(self.preset, ""))
        if not source:
            self.report({'ERROR'}, f"Preset {self.preset!r} not found")
            return {'CANCELLED'}
        preset = load_preset(source)
        depsgraph = context.evaluated_depsgraph_get()
        scalp_data = scene_data.read_scalp(scalp, depsgraph)
        # The preset's Collision is the scalp's once loaded: its keys are placed with it.
        collider = read_collider(scalp, depsgraph, scalp_data, preset.params.collision)
        placement = head.place_preset(preset, scalp, scalp_data, collider)
        keys = placement.keys
        with transaction() as tx:
            tx.keep_settings(scalp)
            old = scene_data.key_objects(scalp) if self.replace else []
            settings = scalp.keystrand_hair
            settings.role = 'SCALP'
            # The placement's parameters: the preset's, its parting carried onto this head.
            dict_to_settings(settings, placement.params.to_dict())
            names = [f"{scalp.name} Key {i:02d}" for i in range(len(keys))]
            made = [scene_data.key_strand_to_object(scalp, key, name=name)
                    for key, name in zip(keys, names)]
            # Removing cannot be undone, so the old keys go last, once every new one is
            # made; the new ones then take the names the old ones held.
            scene_data.remove_key_objects(old)
            for obj, name in zip(made, names):
                obj.name = obj.data.name = name
        prepare_workers_meanwhile(collider)
        lifted = f", {len(placement.lifted)} lifted out of {collider.name!r}" if placement.lifted else ""
        self.report({'INFO'}, f"Loaded preset {preset.name!r}: {len(keys)} key strands{lifted}")
        warning = placement.warning()
        if warning is not None:
            self.report({'WARNING'}, warning)
        return {'FINISHED'}


class HAIR_OT_save_preset(Operator, ExportHelper):
    """Save the scalp's key strands and settings as a preset file"""
    bl_idname = "hair.save_preset"
    bl_label = "Save Preset"
    bl_options = {'REGISTER'}

    filename_ext = ".json"
    filter_glob: StringProperty(default="*.json", options={'HIDDEN'})
    description: StringProperty(name="Description", default="", description="A line saying what the style is")

    @classmethod
    def poll(cls, context):
        return _poll_scalp(cls, context)

    def invoke(self, context, event):
        package = __package__.rpartition(".")[0]
        if package.startswith("bl_ext.") and not self.filepath:
            folder = bpy.utils.extension_path_user(package, path="presets", create=True)
            self.filepath = os.path.join(folder, "my_hairstyle.json")
        return ExportHelper.invoke(self, context, event)

    @reports_errors(failures=((OSError, lambda op, e: f"Cannot write {op.filepath}: {e}"),))
    def execute(self, context):
        from groom import save_preset
        scalp = _scalp_or_report(self, context)
        if scalp is None:
            return {'CANCELLED'}
        keys = scene_data.read_keys(scalp)
        params = groom_params(scalp.keystrand_hair)
        # Given the scalp, the preset is stored in the bundled head's space through this
        # head's frame, so Load Preset places it the same way here and on any other head.
        scalp_data = scene_data.read_scalp(scalp, context.evaluated_depsgraph_get())
        save_preset(self.filepath, keys, params, description=self.description, scalp=scalp_data)
        self.report({'INFO'}, f"Saved preset {self.filepath}")
        return {'FINISHED'}


def export_to_file(hair, path, format, world_space=True, scale=1.0):
    """Write a hair object to `path` in `format` (a registry name) through the command line's
    own writers (hairio.cli.export_strands), with the guides, root UVs and source it holds, so
    `python -m groom export` on the hair's .npz writes the same file. Returns (files written,
    a warning or None). Only where a groom format's library does not import inside Blender
    (alembic3d missing) does Blender's own exporter write it (export_blender), and the
    warning says what that file lacks. Groom formats are always world space."""
    from hairio.cli import export_strands
    fmt = BY_NAME[format]
    uv = blender_curves.root_uv(hair.data)
    if not fmt.available():
        from . import export_blender
        if fmt.name not in export_blender.FORMATS:
            fmt.require()       # the InputError that says what to install
        export_blender.export_hair(hair, path, fmt.name, scale=scale, root_uv=uv)
        return [path], (f"{fmt.library} is not installed in this Blender, so Blender's own exporter wrote "
                        f"{os.path.basename(path)}: positions and widths only, no guides or groom "
                        f"attributes; install {fmt.library} into Blender's Python for the full groom")
    if fmt.library is not None:
        world_space = True
    strands = blender_curves.hair_strands(hair, world_space)
    source = f"{os.path.basename(bpy.data.filepath) or 'unsaved .blend file'}: {hair.name}"
    given = {"scale": scale, "source": source}
    options = {name: value for name, value in given.items() if name in fmt.options}
    return export_strands(strands, path, fmt.name, **options), None


def _follow_format(op):
    """Keep the file browser's extension and filter in step with the chosen format."""
    fmt = BY_NAME[op.format]
    op.filename_ext = fmt.extension
    op.filter_glob = fmt.file_filter
    return fmt


def _cannot_write():
    """The errors that mean the file could not be written (not the user's input, not a bug)."""
    from .export_blender import ExporterFailed
    return (OSError, ExporterFailed)


class HAIR_OT_export(Operator, ExportHelper):
    """Export the generated hair to a file"""
    bl_idname = "hair.export"
    bl_label = "Export Hair"
    bl_options = {'REGISTER'}

    filename_ext = FORMATS[0].extension
    filter_glob: StringProperty(default=";".join(f.file_filter for f in FORMATS), options={'HIDDEN'})
    format: EnumProperty(name="Format", items=EXPORT_FORMATS, default=FORMATS[0].name,
                         description="File format; the file name's extension follows it")
    world_space: BoolProperty(name="World Space", default=True,
                              description="Write points as placed in the scene (otherwise in the scalp's own "
                                          "space; Alembic and USD grooms are always world space)")
    scale: FloatProperty(name="Scale", default=1.0, min=1e-6, soft_max=1000.0,
                         description="Multiply points and widths (100 turns metres into Unreal's centimetres)")

    @classmethod
    def poll(cls, context):
        return _poll_hair(cls, context)

    def check(self, context):
        fmt = _follow_format(self)
        if self.filepath.lower().endswith(fmt.extensions):
            return False        # .usda / .usdc stay as typed
        return ExportHelper.check(self, context)

    def invoke(self, context, event):
        _follow_format(self)
        return ExportHelper.invoke(self, context, event)

    # InputError is reported as the user's to fix, a file that cannot be written as such;
    # anything else is a bug and says so (a ValueError from our own code is one too).
    @reports_errors(failures=((_cannot_write, lambda op, e: f"Cannot write {op.export_path}: {e}"),))
    def execute(self, context):
        from hairio.formats import with_extension
        scalp = find_scalp(context)
        hair = existing_hair(scalp) if scalp is not None else None
        if hair is None:
            self.report({'ERROR'}, "No generated hair to export: select a scalp and press Generate first")
            return {'CANCELLED'}
        if not self.filepath:
            self.report({'ERROR'}, "No file name given")
            return {'CANCELLED'}
        path = with_extension(self.filepath, BY_NAME[self.format])
        self.export_path = path  # named when it cannot be written
        written, warning = export_to_file(hair, path, self.format, self.world_space, self.scale)
        if warning:
            self.report({'WARNING'}, warning)
        self.report({'INFO'}, f"Exported {', '.join(written)}")
        return {'FINISHED'}


def menu_export(self, context):
    """File > Export: one entry per format of the registry."""
    for fmt in FORMATS:
        op = self.layout.operator(HAIR_OT_export.bl_idname, text=f"Key-Strand Hair: {fmt.label}")
        op.format = fmt.name


CLASSES = (HAIR_OT_add_key_strand, HAIR_OT_generate, HAIR_OT_render_preview, HAIR_OT_load_preset,
           HAIR_OT_save_preset, HAIR_OT_export)

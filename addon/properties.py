# SPDX-License-Identifier: GPL-3.0-or-later
"""Settings stored on objects: `Object.keystrand_hair`.

One property group serves three roles: the scalp (mesh) holds every general parameter of
the model (mirroring groom.GroomParams field by field, same names) and the preview render
settings; a key strand (Bézier curve object) and the generated hair (Curves object) point
back to their scalp. Tooltips are written for artists.
"""
import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty,
                       IntProperty, PointerProperty)
from bpy.types import PropertyGroup

from hairio import InputError

from . import generator_cache, head
from .transaction import forget_background

ROLES = (
    ('NONE', "None", "Not part of a hairstyle"),
    ('SCALP', "Scalp", "A mesh that grows hair"),
    ('KEY', "Key Strand", "A Bézier curve that shapes the hair around its root"),
    ('HAIR', "Hair", "Hair generated from a scalp's key strands"),
)

_SHADING_ITEMS = []


def _shading_items(self, context):
    """The tracer's registry of shading models (its first is the default), read when the menu
    is first asked for, so that enabling the add-on imports no tracer. Blender needs the list
    kept alive while it shows it, hence the module-level cache."""
    if not _SHADING_ITEMS:
        from tracer.shading import enum_items
        _SHADING_ITEMS.extend(enum_items())
    return _SHADING_ITEMS


HEAD_AXES = (
    ('WORLD', "Scene", "Up and Front are directions in the scene (by default +Z is up and the face "
                       "looks along -Y), whatever the scalp object's rotation: a head imported Y-up "
                       "with a rotation on the object is read the right way up"),
    ('LOCAL', "Mesh", "Up and Front are directions in the scalp mesh's own coordinates: they turn "
                      "with the object (use it once a head is turned or tilted on purpose)"),
)

KEY_SHAPES = (
    ('STRAIGHT', "Straight", "Grows out of the scalp, then falls straight down the head"),
    ('WAVY', "Wavy", "Falls down the head in gentle S-waves"),
    ('CURLY', "Curly", "Tight corkscrew curls"),
    ('SWEPT', "Swept", "Swept back and up, like a quiff or a mohawk"),
)


def _get_head_axes(self):
    return self.get("head_axes", 0)


def _set_head_axes(self, value):
    # Switching rewrites Up and Front in the other space, so the head's axes (and the hair)
    # stay where they are; from then on they follow the scene or the mesh. A flattened
    # object has no such rewrite: the vectors are kept and Generate reports the scale.
    if value != _get_head_axes(self) and isinstance(self.id_data, bpy.types.Object):
        to_mesh = HEAD_AXES[value][0] == 'LOCAL'
        try:
            self.up, self.front = (head.scene_to_mesh if to_mesh else head.mesh_to_scene)(
                self.id_data, (tuple(self.up), tuple(self.front)))
        except InputError:
            pass
    self["head_axes"] = value


def _is_mesh(self, obj):
    return obj.type == 'MESH'


def _live_update(self, context):
    # Switching live update off drops the cached generators, so no stale copy lingers.
    if not self.live_update:
        generator_cache.forget(self.id_data)
        forget_background(self.id_data)


class HairSettings(PropertyGroup):
    role: EnumProperty(name="Role", items=ROLES, default='NONE',
                       description="What this object is in a key-strand hairstyle")
    scalp: PointerProperty(type=bpy.types.Object, name="Scalp",
                           description="The scalp mesh this key strand or hair belongs to")
    hair_object: PointerProperty(type=bpy.types.Object, name="Hair",
                                 description="The hair Curves object last generated from this scalp")

    # --- the model (names match groom.GroomParams) ---------------------------------------
    count: IntProperty(name="Strands", default=10000, min=1, soft_max=200000,
                       description="How many hairs grow on the scalp when you press Generate")
    viewport_count: IntProperty(name="Viewport Strands", default=2000, min=1, soft_max=50000,
                                description="How many hairs are shown while you drag a key strand; "
                                            "the full count returns when you stop")
    live_update: BoolProperty(name="Live Update", default=True, update=_live_update,
                              description="Regrow the hair around a key strand while you edit it "
                                          "(only the hairs that follow that key are recomputed)")
    seed: IntProperty(name="Seed", default=0, min=0,
                      description="Change it for another random layout of the same hairstyle")
    sampling_mode: EnumProperty(
        name="Root Placement", default='uniform',
        items=(('uniform', "Uniform", "Roots spread evenly over each triangle"),
               ('seed', "Thesis", "The original formula, which crowds roots toward one corner")),
        description="How hair roots are scattered over the scalp's triangles")
    normal_mode: EnumProperty(
        name="Normals", default='interpolated',
        items=(('interpolated', "Smooth", "Blend the vertex normals: hair flows smoothly across faces"),
               ('face', "Flat", "Each triangle's own normal, as in the thesis")),
        description="Which surface direction the hair grows from")
    head_axes: EnumProperty(name="Head Axes", items=HEAD_AXES, default='WORLD',
                            get=_get_head_axes, set=_set_head_axes,
                            description="Which coordinates Up and Front are given in (switching keeps "
                                        "the head's axes as they are); hairs grow down the head and "
                                        "presets land on it by these two directions")
    up: FloatVectorProperty(name="Up", size=3, default=(0.0, 0.0, 1.0), subtype='DIRECTION',
                            description="The head's up direction (in the scene or in the mesh, as Head Axes says)")
    front: FloatVectorProperty(name="Front", size=3, default=(0.0, -1.0, 0.0), subtype='DIRECTION',
                               description="The direction the face looks (in the scene or in the mesh, "
                                           "as Head Axes says)")
    min_length: FloatProperty(name="Min Length", default=0.85, min=0.001, max=1.0, subtype='FACTOR',
                              description="Shortest hair, as a fraction of its key strand's length")
    max_length: FloatProperty(name="Max Length", default=1.0, min=0.001, max=1.0, subtype='FACTOR',
                              description="Longest hair, as a fraction of its key strand's length")
    tidiness: FloatProperty(name="Tidiness", default=0.9, min=0.0, max=1.0, subtype='FACTOR',
                            description="1 = every hair follows its key strand exactly; "
                                        "lower = more random turns for a messier look")
    theta_max: FloatProperty(name="Messiness Angle", default=0.5, min=0.0, max=3.14159, subtype='ANGLE',
                             description="The largest random turn of a hair when Tidiness is 0")
    n_influence: FloatProperty(name="N-Influence", default=50.0, min=0.0, max=100.0,
                               description="How much neighbouring key strands pull on a hair: "
                                           "0 = follow the nearest key only, 100 = blend evenly by distance "
                                           "(also sharpens or softens Smooth Blend)")
    neighbour_mode: EnumProperty(
        name="Neighbours", default='interpolate',
        items=(('interpolate', "Smooth Blend", "Blend the nearest keys by distance, as Blender's "
                                               "Interpolate Curves node does (no seams between clumps)"),
               ('root', "Nearest to Hair", "Blend with the 2nd and 3rd nearest keys to each hair"),
               ('key', "Nearest to Key", "Blend with the two keys nearest the main key (the thesis; "
                                        "can show seams between clumps)")),
        description="Which key strands a hair blends between")
    intelligence: BoolProperty(name="Follow Scalp", default=True,
                               description="On: each hair turns with the scalp under it, so one key "
                                           "can groom a whole head. Off: hairs copy the key's shape as is")
    resolution_mode: EnumProperty(
        name="Resolution", default='adaptive',
        items=(('adaptive', "Adaptive", "As few points as the curve needs within the tolerance"),
               ('fixed', "Fixed", "The same number of points on every hair")),
        description="How many points each hair gets")
    points_per_strand: IntProperty(name="Points", default=32, min=2, soft_max=128,
                                   description="Points per hair (Fixed), or the most a hair may get (Adaptive)")
    tolerance: FloatProperty(name="Tolerance", default=3e-4, min=1e-9, soft_max=0.01, precision=5,
                             description="How far a hair may stray from its exact curve; "
                                         "smaller = smoother but heavier hair")
    tolerance_units: EnumProperty(
        name="Tolerance Units", default='scene',
        items=(('scene', "Scene Units", "Tolerance in metres"),
               ('radius', "Hair Radii", "Tolerance as a multiple of the hair's root radius")),
        description="What the tolerance is measured in")
    radius: FloatProperty(name="Root Radius", default=5e-5, min=0.0, soft_max=0.001, precision=6,
                          subtype='DISTANCE', description="Thickness (radius) of a hair at its root")
    radius_mode: EnumProperty(
        name="Taper", default='linear',
        items=(('linear', "To Tip", "Thin out evenly from root to tip"),
               ('constant', "None", "Same thickness all along"),
               ('taper_from', "From Point", "Keep the root thickness, then thin out from Taper Start")),
        description="How hairs get thinner toward the tip")
    taper_start: FloatProperty(name="Taper Start", default=0.7, min=0.0, max=1.0, subtype='FACTOR',
                               description="Where thinning starts, as a fraction of the hair's length")
    color: FloatVectorProperty(name="Color", size=3, default=(0.28, 0.17, 0.09), min=0.0, max=1.0,
                               subtype='COLOR', description="Base hair colour (key strands may override it)")
    color_variation: FloatVectorProperty(name="Variation", size=3, default=(0.04, 0.03, 0.02),
                                         min=0.0, max=1.0, subtype='COLOR',
                                         description="How far each hair's colour may wander from the base")
    color_variation_point: FloatVectorProperty(name="Along Hair", size=3, default=(0.0, 0.0, 0.0),
                                               min=0.0, max=1.0, subtype='COLOR',
                                               description="Colour noise from point to point along one hair")
    alpha_start: FloatProperty(name="Fade Start", default=1.0, min=0.0, max=1.0, subtype='FACTOR',
                               description="Where hairs start to turn see-through, as a fraction of length")
    alpha_tip: FloatProperty(name="Tip Opacity", default=1.0, min=0.0, max=1.0, subtype='FACTOR',
                             description="Opacity at the tip: 1 = solid, lower = softer, wispy tips")
    clump: FloatProperty(name="Clump", default=0.0, min=0.0, max=1.0, subtype='FACTOR',
                         description="How tightly the hairs of a wisp gather around their key strand: "
                                     "loose at the root, tightest at the tip; 0 = no clumping")
    clump_shape: FloatProperty(name="Clump Shape", default=1.0, min=0.01, max=8.0,
                               description="How clumping grows along the hair: 1 = evenly from root to "
                                           "tip, higher = loose for longer and tight only near the tip, "
                                           "lower = tight soon after the root")
    frizz: FloatProperty(name="Frizz", default=0.0, min=0.0, soft_max=0.01, precision=4, subtype='DISTANCE',
                         description="How far each hair wanders off its path toward the tip, in a few "
                                     "smooth random waves; 0 = none")
    curl: FloatProperty(name="Curl", default=0.0, min=0.0, soft_max=0.02, precision=4, subtype='DISTANCE',
                        description="Radius of the corkscrew each hair winds around its path, growing "
                                    "from the root; 0 = no curl")
    curl_period: FloatProperty(name="Curl Length", default=0.02, min=1e-5, soft_max=0.1, precision=4,
                               subtype='DISTANCE',
                               description="Length of hair per turn of the curl: smaller = tighter curls")
    collision: BoolProperty(name="Collision", default=True,
                            description="Keep the hair out of the collider (the head): hairs are combed "
                                        "out along its surface without stretching. Key strands that pass "
                                        "through it are reported, never moved")
    collider: PointerProperty(type=bpy.types.Object, name="Collider", poll=_is_mesh,
                              description="The mesh the hair stays out of, usually the head the scalp "
                                          "lies on; empty = the scalp itself (Add Head sets its head)")
    collision_margin: FloatProperty(name="Margin", default=2e-4, min=0.0, soft_max=0.005, precision=5,
                                    subtype='DISTANCE',
                                    description="The gap kept between every hair's surface and the collider")
    # GroomParams.parting, a plane through the scalp (None when Parting is off), held as the
    # five settings below; groom_params and dict_to_settings convert.
    use_parting: BoolProperty(name="Parting", default=False,
                              description="Part the hair along a plane: the roots on the side Normal points "
                                          "to are Part Group 1, the others 0, and hairs only follow key "
                                          "strands of their own group. A scalp mesh with a `hair_group` "
                                          "attribute uses its groups instead")
    parting_point: FloatVectorProperty(name="Point", size=3, default=(0.0, 0.0, 0.0), subtype='XYZ',
                                       description="A point on the parting plane, in the scalp mesh's own "
                                                   "coordinates")
    parting_normal: FloatVectorProperty(name="Normal", size=3, default=(1.0, 0.0, 0.0), subtype='XYZ',
                                        description="The direction across the parting (mesh coordinates): "
                                                    "roots on the side it points to are Part Group 1")
    parting_use_end: BoolProperty(name="Stop at End", default=False,
                                  description="Part only the roots in front of End (toward the face), so a "
                                              "side parting can stop at the crown instead of running down "
                                              "the back")
    parting_end: FloatVectorProperty(name="End", size=3, default=(0.0, 0.0, 0.0), subtype='XYZ',
                                     description="Where the parting stops, in the scalp mesh's own "
                                                 "coordinates: behind it (away from the face) the hair "
                                                 "falls as one")

    # --- drawing key strands -------------------------------------------------------------
    key_shape: EnumProperty(name="Key Shape", items=KEY_SHAPES, default='STRAIGHT',
                            description="The shape a new key strand starts with")
    key_length: FloatProperty(name="Key Length", default=0.2, min=0.001, soft_max=2.0, subtype='DISTANCE',
                              description="Length of a new key strand")
    use_key_color: BoolProperty(name="Own Colour", default=False,
                                description="Give the hair around this key strand its own colour")
    key_color: FloatVectorProperty(name="Key Colour", size=3, default=(0.28, 0.17, 0.09), min=0.0, max=1.0,
                                   subtype='COLOR', description="Colour of the hair around this key strand")
    key_radius: FloatProperty(name="Key Root Radius", default=0.0, min=0.0, soft_max=0.001, precision=6,
                              subtype='DISTANCE',
                              description="Root radius of the hair around this key; 0 = the scalp's radius")
    key_group: IntProperty(name="Part Group", default=0, min=0,
                           description="Hairs only follow keys of their own group (use it for partings)")
    symmetry: EnumProperty(
        name="Symmetry", default='X',
        items=(('NONE', "Off", "Draw Key Strand makes one key; paired keys are no longer kept mirrored"),
               ('X', "X", "Left-right across the head (its Up and Front): a drawn key gets its mirror "
                          "image, and each of a pair follows when the other is edited"),
               ('Y', "Y", "Front-back across the head"),
               ('Z', "Z", "Up-down across the head's centre")),
        description="Which plane of the head key strands are mirrored across when drawn, and kept mirrored")

    # --- preview render (the tracer) -----------------------------------------------------
    preview_size: IntProperty(name="Width", default=512, min=16, soft_max=2048,
                              description="Width of the preview image in pixels "
                                          "(the height follows the scene's aspect ratio)")
    preview_samples: EnumProperty(
        name="Samples", default='1',
        items=(('1', "1", "One ray per pixel: fastest, jagged edges"),
               ('4', "4", "2 x 2 rays per pixel"),
               ('9', "9", "3 x 3 rays per pixel"),
               ('16', "16", "4 x 4 rays per pixel: smooth edges, slowest")),
        description="Rays per pixel: more = smoother edges, slower")
    preview_shadows: BoolProperty(name="Shadows", default=True,
                                  description="Hairs shadow each other (costs one extra ray per light)")
    preview_shadow_mode: EnumProperty(
        name="Shadow Type", default='hard',
        items=(('hard', "Hard", "Any hair in the way casts a full shadow"),
               ('transmittance', "Soft", "See-through hairs let some light pass")),
        description="How hair shadows are computed")
    preview_layers: IntProperty(name="Layers", default=4, min=1, soft_max=16,
                                description="How many see-through hair layers are blended per pixel")
    preview_shading: EnumProperty(
        name="Shading", default=0, items=_shading_items,    # tracer's registry, its default first
        description="How the hair reacts to light")
    preview_min_pixel_width: BoolProperty(
        name="Min Pixel Width", default=False,
        description="Widen hairs thinner than a pixel and make them fainter, "
                    "so distant hair doesn't break up into dots")
    preview_scene_lights: BoolProperty(
        name="Scene Lights", default=True,
        description="Light the preview with the scene's lights; with Principled Hair shading as "
                    "Cycles does (their power, fall-off with distance, spot cones) and with the world's "
                    "colour, else at one intensity without fall-off; off, or with none in the scene, "
                    "a default key light")
    preview_in_process: BoolProperty(
        name="Render Inside Blender", default=False,
        description="Run the preview renderer inside Blender instead of a separate process "
                    "(for headless use; a graphics driver fault could then close Blender)")


CLASSES = (HairSettings,)


def register_properties():
    bpy.types.Object.keystrand_hair = PointerProperty(type=HairSettings, name="Key-Strand Hair")


def unregister_properties():
    del bpy.types.Object.keystrand_hair


# GroomParams fields that are set from the settings of the same name.
PARAM_FIELDS = ("count", "seed", "sampling_mode", "normal_mode", "up", "front", "min_length",
                "max_length", "tidiness", "theta_max", "n_influence", "neighbour_mode",
                "intelligence", "resolution_mode", "points_per_strand", "tolerance",
                "tolerance_units", "radius", "radius_mode", "taper_start", "color",
                "color_variation", "color_variation_point", "alpha_start", "alpha_tip", "clump",
                "clump_shape", "frizz", "curl", "curl_period", "collision", "collision_margin")
# The settings that hold GroomParams.parting.
PARTING_FIELDS = ("use_parting", "parting_point", "parting_normal", "parting_use_end", "parting_end")
RENDER_FIELDS = ("preview_size", "preview_samples", "preview_shadows", "preview_shadow_mode",
                 "preview_layers", "preview_shading", "preview_min_pixel_width",
                 "preview_scene_lights", "preview_in_process")


# Settings that describe the head, not the hairstyle: a preset leaves them as they are
# (its keys are placed with the head's own axes, and Generate must use the same ones).
HEAD_FIELDS = ("up", "front")


def settings_to_dict(settings):
    """The model parameters as a plain dict (every GroomParams field name, JSON-able values),
    as the settings hold them (up and front in the space Head Axes names)."""
    out = {}
    for name in PARAM_FIELDS:
        value = getattr(settings, name)
        out[name] = list(value) if hasattr(value, "__len__") and not isinstance(value, str) else value
    out["parting"] = None
    if settings.use_parting:
        out["parting"] = {"point": list(settings.parting_point), "normal": list(settings.parting_normal)}
        if settings.parting_use_end:
            out["parting"]["end"] = list(settings.parting_end)
    return out


def dict_to_settings(settings, params):
    """Set the settings from a GroomParams-like dict (a preset's, its parting in the scalp's
    space); unknown names and the head's axes are left alone, a parting of None switches
    Parting off."""
    for name in PARAM_FIELDS:
        if name in HEAD_FIELDS:
            continue
        if name in params and params[name] is not None:
            setattr(settings, name, tuple(params[name]) if isinstance(params[name], (list, tuple))
                    else params[name])
    if "parting" in params:
        parting = params["parting"]
        settings.use_parting = parting is not None
        if parting is not None:
            settings.parting_point = tuple(parting["point"])
            settings.parting_normal = tuple(parting["normal"])
            settings.parting_use_end = "end" in parting
            if "end" in parting:
                settings.parting_end = tuple(parting["end"])


def groom_params(settings, count=None):
    """groom.GroomParams from a scalp's settings, with up and front in the scalp's own space
    (the space groom works in), the same axes presets are placed with (InputError on an
    out-of-range combination or a scalp whose axes cannot be read)."""
    from groom import GroomParams
    d = settings_to_dict(settings)
    if count is not None:
        d["count"] = int(count)
    d["up"], d["front"] = head.scalp_axes(settings.id_data)
    for name in ("color", "color_variation", "color_variation_point"):
        d[name] = tuple(d[name])
    if d["parting"] is not None:
        d["parting"] = {k: tuple(v) for k, v in d["parting"].items()}
    return GroomParams(**d)

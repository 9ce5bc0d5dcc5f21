# SPDX-License-Identifier: GPL-3.0-or-later
"""What the stroke tools (Draw Key Strand, Comb Key) share: the stroke as an operator
property, the view it was drawn in, the scalp under the mouse, and the lines they draw
while dragging.

A stroke is kept as Blender's own stroke operators keep theirs: a collection of points, each
with its place in the world (`location`) and on the screen (`mouse`, region pixels). The
modal tools fill it with world points and the view they were drawn in (direction, eye,
world size of a pixel at the root), so a redo (Adjust Last Operation) and a script calling
the operator with the same properties make exactly the same key, with or without a 3D
viewport.
"""
import numpy as np
import bpy
from bpy.props import BoolProperty, CollectionProperty, EnumProperty, FloatProperty, FloatVectorProperty
from bpy.types import PropertyGroup
from bpy_extras import view3d_utils
from mathutils import Vector
from hairio import InputError


# Events that move the view: a stroke tool passes them on while it waits for its press.
VIEW_NAVIGATION = frozenset({'MIDDLEMOUSE', 'WHEELUPMOUSE', 'WHEELDOWNMOUSE', 'TRACKPADPAN', 'TRACKPADZOOM'})

STROKE_SPACES = (
    ('WORLD', "World", "Stroke points are world locations (on or near the drawing surface)"),
    ('SCREEN', "Screen", "Stroke points are mouse positions in the 3D viewport's region, in pixels"),
)

# Without a viewport (a script, a test) and no pixel size given, a pixel is this fraction
# of the head frame's size (its mean half-axis): a head about 250 pixels in half-height.
HEAD_PIXELS = 250.0


class HAIR_PG_stroke_point(PropertyGroup):
    location: FloatVectorProperty(name="Location", size=3, subtype='XYZ',
                                  description="Where the point lies in the world")
    mouse: FloatVectorProperty(name="Mouse", size=2,
                               description="Where the point lies on the screen (region pixels)")


class StrokeView:
    """Operator properties (a mixin): the stroke and the view it was drawn in. Hidden: the
    modal tool fills them; a script may give them."""
    stroke: CollectionProperty(type=HAIR_PG_stroke_point, name="Stroke", options={'HIDDEN', 'SKIP_SAVE'},
                               description="The stroke's points, first to last")
    stroke_space: EnumProperty(name="Stroke Space", items=STROKE_SPACES, default='WORLD',
                               options={'HIDDEN', 'SKIP_SAVE'},
                               description="What the stroke's points are: world locations or mouse positions")
    view_direction: FloatVectorProperty(name="View Direction", size=3, default=(0.0, 1.0, 0.0),
                                        subtype='DIRECTION', options={'HIDDEN', 'SKIP_SAVE'},
                                        description="The way the view looks, in the world "
                                                    "(default: Blender's Front view)")
    view_eye: FloatVectorProperty(name="Eye", size=3, default=(0.0, 0.0, 0.0), subtype='XYZ',
                                  options={'HIDDEN', 'SKIP_SAVE'},
                                  description="Where a perspective view looks from (world)")
    view_perspective: BoolProperty(name="Perspective", default=False, options={'HIDDEN', 'SKIP_SAVE'},
                                   description="The stroke was drawn in a perspective view (from Eye)")
    pixel_size: FloatProperty(name="Pixel Size", default=0.0, min=0.0, subtype='DISTANCE',
                              options={'HIDDEN', 'SKIP_SAVE'},
                              description="World size of one screen pixel at the root; 0 = the viewport's, "
                                          "or without one a 250th of the head's size")


def _matrix(m):
    return np.array(m, dtype=np.float64).reshape(4, 4)


def region_view(context):
    """(region, region_3d) of the 3D viewport's main region the operator runs in (a script
    with a viewport's context), or (None, None)."""
    area, region = context.area, context.region
    if area is None or area.type != 'VIEW_3D' or region is None or region.type != 'WINDOW':
        return None, None
    return region, region.data


class ViewUnderMouse:
    """The 3D viewport region a modal tool draws in, found under the mouse when it starts.

    A tool started from the Hair tab's button runs in the sidebar's region, whose coordinates
    and view are not the viewport's; so regions and mouse positions are taken from the area's
    own main regions (the one under the mouse, in a quad view) and the window coordinates."""

    def __init__(self, context):
        self.area = context.area if context.area is not None and context.area.type == 'VIEW_3D' else None
        self.region = self.rv3d = None

    def pick(self, event):
        """The main region under the mouse becomes the tool's; False when there is none."""
        for region in (self.area.regions if self.area is not None else ()):
            if region.type == 'WINDOW' and region.x <= event.mouse_x < region.x + region.width \
                    and region.y <= event.mouse_y < region.y + region.height:
                self.region, self.rv3d = region, region.data
                return True
        return False

    def coord(self, event):
        """The mouse in the tool's region's pixels."""
        return (float(event.mouse_x - self.region.x), float(event.mouse_y - self.region.y))

    def redraw(self):
        if self.area is not None:
            self.area.tag_redraw()


def capture_view(op, region, rv3d, root_world):
    """Store the viewport's view in the operator's view properties: its direction, its eye
    (perspective), and the world size of a pixel at the depth of `root_world`."""
    direction = rv3d.view_rotation @ Vector((0.0, 0.0, -1.0))
    op.view_direction = direction.normalized()
    op.view_perspective = bool(rv3d.is_perspective)
    op.view_eye = rv3d.view_matrix.inverted().translation if rv3d.is_perspective else (0.0, 0.0, 0.0)
    root = Vector(root_world)
    at = view3d_utils.location_3d_to_region_2d(region, rv3d, root)
    if at is None:  # behind a perspective eye: the view cannot see the root
        at = Vector((region.width / 2, region.height / 2))
    a = view3d_utils.region_2d_to_location_3d(region, rv3d, at, root)
    b = view3d_utils.region_2d_to_location_3d(region, rv3d, at + Vector((1.0, 0.0)), root)
    op.pixel_size = (b - a).length


def screen_to_world(region, rv3d, coords, depth_world):
    """Region pixel coordinates (n,2) -> world points (n,3) on the plane facing the view
    through `depth_world`."""
    depth = Vector(depth_world)
    return np.array([tuple(view3d_utils.region_2d_to_location_3d(region, rv3d, Vector(c), depth)) for c in coords],
                    np.float64)


def view_of(op):
    """(unit view direction (3,), eye (3,) or None) in the world, from the operator's
    properties; InputError for a view direction of zero."""
    direction = np.array(op.view_direction, np.float64)
    length = float(np.linalg.norm(direction))
    if not (np.isfinite(direction).all() and length > 0):
        raise InputError(f"view_direction: expected a direction, got {tuple(op.view_direction)}")
    eye = np.array(op.view_eye, np.float64) if op.view_perspective else None
    return direction / length, eye


def stroke_points(op, context):
    """The operator's stroke: world points (n,3), or for a screen stroke its mouse positions
    (n,2), which need the 3D viewport they were drawn in (InputError without one)."""
    n = len(op.stroke)
    if n == 0:
        raise InputError("The stroke is empty: drag in the viewport, or give the stroke's points")
    if op.stroke_space == 'WORLD':
        flat = np.empty(n * 3, np.float64)
        op.stroke.foreach_get("location", flat)
        return flat.reshape(n, 3)
    if region_view(context)[0] is None:
        raise InputError("A screen stroke needs the 3D viewport it was drawn in; "
                         "give world locations (stroke_space 'WORLD') instead")
    flat = np.empty(n * 2, np.float64)
    op.stroke.foreach_get("mouse", flat)
    return flat.reshape(n, 2)


def set_stroke(op, world_points, mouse=None):
    """Fill the operator's stroke with world points (n,3) (and their mouse positions)."""
    op.stroke.clear()
    for i, p in enumerate(world_points):  # a stroke has a few hundred points
        item = op.stroke.add()
        item.location = tuple(p)
        if mouse is not None:
            item.mouse = tuple(mouse[i])
    op.stroke_space = 'WORLD'


def pixel_world_size(op, head_frame, scalp_obj):
    """The world size of a pixel at the root: the operator's, or without one a fraction of
    the head (HEAD_PIXELS) carried into the world by the scalp object's scale."""
    if op.pixel_size > 0:
        return float(op.pixel_size)
    return head_frame.size * object_scale(scalp_obj) / HEAD_PIXELS


def object_scale(obj):
    """The object's mean linear scale (cube root of its matrix's volume change)."""
    det = abs(float(np.linalg.det(_matrix(obj.matrix_world)[:3, :3])))
    if not det > 0:
        raise InputError(f"Object {obj.name!r} has a zero scale on some axis: give it a non-zero scale")
    return det ** (1.0 / 3.0)


def to_local(obj, world_points):
    inv = np.linalg.inv(_matrix(obj.matrix_world))
    return np.asarray(world_points, np.float64) @ inv[:3, :3].T + inv[:3, 3]


def to_world(obj, local_points):
    m = _matrix(obj.matrix_world)
    return np.asarray(local_points, np.float64) @ m[:3, :3].T + m[:3, 3]


def direction_to_local(obj, direction):
    """A world direction as a direction in the object's mesh (M⁻¹ d, unit): a view ray stays
    the same line in both spaces."""
    d = np.linalg.solve(_matrix(obj.matrix_world)[:3, :3], np.asarray(direction, np.float64))
    return d / np.linalg.norm(d)


def ray_cast_scalp(context, region, rv3d, scalp, coord):
    """The world point of the scalp under region pixel `coord`, or None (as Add Key Strand
    finds it: the evaluated mesh, in its own space)."""
    if scalp is None or region is None:
        return None
    origin = view3d_utils.region_2d_to_origin_3d(region, rv3d, coord)
    direction = view3d_utils.region_2d_to_vector_3d(region, rv3d, coord)
    inv = scalp.matrix_world.inverted()
    evaluated = scalp.evaluated_get(context.evaluated_depsgraph_get())
    ok, loc, _normal, _face = evaluated.ray_cast(inv @ origin, (inv.to_3x3() @ direction).normalized())
    return np.array(scalp.matrix_world @ loc, np.float64) if ok else None


def draw_strips(strips, color, viewport_size, width=2.0):
    """World polylines in one colour into the current GPU frame buffer (the view set by the
    caller)."""
    import gpu
    from gpu_extras.batch import batch_for_shader
    if not strips:
        return
    shader = gpu.shader.from_builtin('POLYLINE_UNIFORM_COLOR')
    gpu.state.blend_set('ALPHA')
    shader.bind()
    shader.uniform_float("viewportSize", tuple(viewport_size))
    shader.uniform_float("lineWidth", width)
    shader.uniform_float("color", color)
    for strip in strips:
        batch_for_shader(shader, 'LINE_STRIP', {"pos": strip}).draw(shader)
    gpu.state.blend_set('NONE')


class PreviewLines:
    """Lines drawn over the 3D viewport while a tool drags (a gpu draw handler). In
    background mode (no GPU drawing) it keeps the lines and draws nothing."""

    def __init__(self, color=(1.0, 0.55, 0.1, 1.0)):
        self.color = color
        self.strips = []       # world polylines (n,3)
        self._handle = None
        if not bpy.app.background:
            self._handle = bpy.types.SpaceView3D.draw_handler_add(self._draw, (), 'WINDOW', 'POST_VIEW')

    def set(self, *strips):
        self.strips = [np.asarray(s, np.float32) for s in strips if s is not None and len(s) >= 2]

    def _draw(self):
        region = bpy.context.region
        draw_strips(self.strips, self.color, (region.width, region.height))

    def remove(self):
        if self._handle is not None:
            bpy.types.SpaceView3D.draw_handler_remove(self._handle, 'WINDOW')
            self._handle = None
        self.strips = []


CLASSES = (HAIR_PG_stroke_point,)

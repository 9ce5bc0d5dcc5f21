# SPDX-License-Identifier: GPL-3.0-or-later
"""Drawing key strands by stroke, their mirror, the comb and the wisp overlay, driven
headless through the operators' stroke properties (world points, as a script gives them) and
checked against arrays read here from the scene and groom.stroke's own measures."""
import importlib
import types

import numpy as np
import pytest
import bpy

from blender_scene import activate, make_scalp, scene_snapshot

PIXEL = 5e-4          # world size of a pixel at the root, given to the operator
TOLERANCE_PX = 2.0


def ext_module(extension, name):
    return importlib.import_module(f"{extension.__name__}.addon.{name}")


def hanging_stroke(root=(0.1, 0.0, 0.0), n=80, side=1.0, jitter_y=0.0):
    """A strand drawn from `root` on the sphere's side: out, then down with a wave. The y
    jitter puts points off the drawing plane; the operator must project them onto it."""
    s = np.linspace(0.0, 1.0, n)
    p = np.stack([side * (0.05 * np.sin(np.pi * s) + 0.01 * s), np.zeros_like(s),
                  -0.18 * s + 0.01 * np.sin(6 * s)], 1) + np.asarray(root)
    p[1:, 1] += jitter_y * np.sin(17 * s[1:])
    return p


def stroke_arg(points):
    """The stroke property's value (Blender wants every field of each element, as for its own
    stroke operators)."""
    return [{"name": "", "location": tuple(map(float, p)), "mouse": (0.0, 0.0)} for p in points]


def draw(points, **kwargs):
    args = dict(stroke=stroke_arg(points), pixel_size=PIXEL, tolerance=TOLERANCE_PX)
    args.update(kwargs)
    return bpy.ops.hair.draw_key_strand(**args)


def key_objects():
    return sorted((o for o in bpy.data.objects if o.type == 'CURVE'), key=lambda o: o.name)


def control_points(obj):
    """groom's cubic layout of a Bézier key object's spline, read here."""
    bp = obj.data.splines[0].bezier_points
    co = np.array([p.co for p in bp], float)
    left = np.array([p.handle_left for p in bp], float)
    right = np.array([p.handle_right for p in bp], float)
    rows = [co[0]]
    for i in range(1, len(co)):
        rows += [right[i - 1], left[i], co[i]]
    return np.array(rows)


def scalp_arrays(obj):
    from groom import Scalp
    mesh = obj.data
    mesh.calc_loop_triangles()
    v = np.empty(len(mesh.vertices) * 3)
    mesh.vertices.foreach_get("co", v)
    t = np.empty(len(mesh.loop_triangles) * 3, np.int64)
    mesh.loop_triangles.foreach_get("vertices", t)
    return Scalp(v.reshape(-1, 3), t.reshape(-1, 3))


def length_of(control):
    from groom.stroke import sample_cubic
    return float(np.linalg.norm(np.diff(sample_cubic(control, 4000), axis=0), axis=1).sum())


@pytest.fixture()
def scalp(clean):
    obj = make_scalp()
    obj.keystrand_hair.symmetry = 'NONE'
    return obj


def test_a_stroke_makes_one_key_rooted_on_the_scalp_leaving_along_its_normal(scalp):
    from groom.stroke import curve_deviation, distance_to_polyline, sample_cubic
    points = hanging_stroke(jitter_y=0.03)
    assert draw(points) == {'FINISHED'}
    (key,) = key_objects()
    assert key.keystrand_hair.role == 'KEY' and key.keystrand_hair.scalp == scalp and key.parent == scalp
    assert key.data.splines[0].type == 'BEZIER'
    c = control_points(key)
    surface = scalp_arrays(scalp)
    tri, bary, nearest = surface.closest_points(c[:1])
    assert np.linalg.norm(nearest[0] - c[0]) < 1e-6, "the root is not on the scalp"
    normal = surface.normals_at(tri, bary)[0]
    leave = (c[1] - c[0]) / np.linalg.norm(c[1] - c[0])
    np.testing.assert_allclose(leave, normal, atol=1e-5)
    # The stroke's projection: the plane through the root facing the default (front) view.
    projected = points.copy()
    projected[:, 1] = c[0, 1]
    projected[0] = c[0]
    tolerance = TOLERANCE_PX * PIXEL
    assert curve_deviation(c, projected).max() <= tolerance * (1 + 1e-4)
    assert distance_to_polyline(sample_cubic(c, 256), projected).max() <= tolerance * (1 + 1e-4)
    assert 1 <= (len(c) - 1) // 3 <= 8, "a key of a few segments"
    assert bpy.context.view_layer.objects.active == key


def test_the_tolerance_is_in_pixels_of_the_view(scalp):
    points = hanging_stroke()
    draw(points, pixel_size=PIXEL / 8)
    fine = control_points(key_objects()[0])
    draw(points, pixel_size=PIXEL * 8)
    coarse = control_points(key_objects()[1])
    assert len(coarse) < len(fine)


def test_a_stroke_over_the_scalp_lies_on_the_shell(scalp):
    """Seen from above, a stroke across the top of the head lands offset above its surface."""
    from groom.stroke import sample_cubic
    x = np.linspace(0.0, 0.07, 50)
    points = np.stack([x, np.zeros_like(x), np.full_like(x, 0.3)], 1)
    points[0] = (0.0, 0.0, 0.1)
    offset = 0.01
    assert draw(points, surface='SHELL', shell_offset=offset, view_direction=(0.0, 0.0, -1.0)) == {'FINISHED'}
    c = control_points(key_objects()[0])
    along = sample_cubic(c, 64)
    far = along[np.linalg.norm(along[:, :2], axis=1) > 0.03]  # past the rise from the root
    assert len(far) > 10
    # The sphere of radius 0.1 is a mesh of flat faces: within its facets' depth of the shell.
    np.testing.assert_allclose(np.linalg.norm(far, axis=1), 0.1 + offset, atol=2.5e-3)


def test_mirror_makes_the_mirrored_key_and_keeps_the_pair_mirrored(scalp):
    scalp.keystrand_hair.symmetry = 'X'
    assert draw(hanging_stroke()) == {'FINISHED'}
    a, b = key_objects()
    assert a.keystrand_mirror == b and b.keystrand_mirror == a
    flip = np.array([-1.0, 1.0, 1.0])  # the sphere's head frame: centred, Up +Z, Front -Y
    np.testing.assert_allclose(control_points(b), control_points(a) * flip, atol=1e-6)
    # Edit one (its tip, as in edit mode): the other follows on the next update.
    for edited, other in ((a, b), (b, a)):
        tip = edited.data.splines[0].bezier_points[-1]
        tip.co.y += 0.03
        tip.handle_left.y += 0.03
        tip.handle_right.y += 0.03
        edited.data.update_tag()
        activate(edited)
        bpy.context.view_layer.update()
        np.testing.assert_allclose(control_points(other), control_points(edited) * flip, atol=1e-6)
    # Settled: further updates rewrite nothing.
    before = [control_points(k) for k in (a, b)]
    bpy.context.view_layer.update()
    bpy.context.view_layer.update()
    for k, c in zip((a, b), before):
        np.testing.assert_array_equal(control_points(k), c)


def test_a_key_drawn_on_the_mirror_plane_gets_no_twin(scalp):
    scalp.keystrand_hair.symmetry = 'X'
    points = hanging_stroke(root=(0.0, -0.1, 0.0))
    points[:, 0] = 0.0  # down the middle of the face
    assert draw(points, view_direction=(1.0, 0.0, 0.0)) == {'FINISHED'}
    assert len(key_objects()) == 1


def test_a_failed_stroke_leaves_the_scene_as_it_was(scalp):
    before = scene_snapshot()
    with pytest.raises(RuntimeError, match="drag away from the root"):
        draw(np.zeros((4, 3)) + (0.1, 0.0, 0.0))
    assert scene_snapshot() == before
    with pytest.raises(RuntimeError, match="empty"):
        bpy.ops.hair.draw_key_strand(stroke=[])
    assert scene_snapshot() == before
    with pytest.raises(RuntimeError, match="3D viewport"):
        bpy.ops.hair.draw_key_strand(stroke=[{"name": "", "location": (0, 0, 0), "mouse": m}
                                                               for m in ((10, 10), (40, 40))], stroke_space='SCREEN')
    assert scene_snapshot() == before


def test_a_failure_midway_removes_the_key_already_made(scalp, monkeypatch):
    mirror = ext_module(scalp_extension(), "mirror")
    scalp.keystrand_hair.symmetry = 'X'
    before = scene_snapshot()

    def broken(a, b):
        raise RuntimeError("injected")
    monkeypatch.setattr(mirror, "pair", broken)
    with pytest.raises(RuntimeError, match="Internal error in Draw Key Strand"):
        draw(hanging_stroke())
    assert scene_snapshot() == before


def scalp_extension():
    import sys
    return sys.modules[next(m for m in sys.modules if m.endswith(".keystrand_hair") and m.startswith("bl_ext."))]


def test_dragging_makes_nothing_until_release(scalp):
    """The modal tool's press and drag (StrokeFit, PreviewLines) write nothing to the file, so
    Esc, which only stops them, leaves the scene as it was."""
    draw_key = ext_module(scalp_extension(), "draw_key")
    stroke_input = ext_module(scalp_extension(), "stroke_input")
    before = scene_snapshot()
    op = types.SimpleNamespace(tolerance=TOLERANCE_PX, surface='SHELL', shell_offset=0.01, pixel_size=PIXEL,
                               view_direction=(0.0, 1.0, 0.0), view_perspective=True, view_eye=(0.0, -1.0, 0.0))
    points = hanging_stroke()
    fit = draw_key.StrokeFit(op, bpy.context, scalp, points[0])
    preview = stroke_input.PreviewLines()
    for p in points[1:]:
        fit.add(p[None])
    control = fit.fit()
    preview.set(control, fit.mirror_of(control))
    preview.remove()
    assert (len(control) - 1) % 3 == 0
    assert scene_snapshot() == before


def test_undo_removes_the_drawn_keys(scalp):
    """Draw Key Strand is an undo step (its UNDO option); a background Blender pushes no steps
    for operators, so the test pushes them where the UI would, before and after the press."""
    scalp.keystrand_hair.symmetry = 'X'
    assert 'UNDO' in bpy.types.HAIR_OT_draw_key_strand.bl_options
    bpy.ops.ed.undo_push(message="before drawing")
    assert draw(hanging_stroke()) == {'FINISHED'}
    bpy.ops.ed.undo_push(message="Draw Key Strand")
    assert len(key_objects()) == 2
    bpy.ops.ed.undo()
    assert key_objects() == []
    assert [o.name for o in bpy.data.objects] == ["Scalp"]
    bpy.ops.ed.redo()
    a, b = key_objects()
    assert a.keystrand_mirror == b and b.keystrand_mirror == a


def test_comb_bends_the_key_and_keeps_its_length(scalp):
    from groom import KeyStrand
    scalp.keystrand_hair.symmetry = 'X'
    draw(hanging_stroke())
    key, twin = key_objects()
    before = control_points(key)
    mid = KeyStrand(before, kind="cubic").evaluate([0.6])[0]
    path = mid + np.linspace(0.0, 1.0, 12)[:, None] * np.array([0.04, 0.0, 0.0])
    activate(key)
    assert bpy.ops.hair.comb_key(stroke=stroke_arg(path), radius=40.0, pixel_size=PIXEL) == {'FINISHED'}
    after = control_points(key)
    assert np.abs(after - before).max() > 0.01, "the comb did not bend the key"
    assert abs(length_of(after) - length_of(before)) < 1e-5 * length_of(before)
    np.testing.assert_array_equal(after[0], before[0])
    leave = lambda c: (c[1] - c[0]) / np.linalg.norm(c[1] - c[0])  # noqa: E731
    np.testing.assert_allclose(leave(after), leave(before), atol=1e-6)
    np.testing.assert_allclose(control_points(twin), after * [-1.0, 1.0, 1.0], atol=1e-6)


def test_a_comb_that_misses_changes_nothing(scalp):
    draw(hanging_stroke())
    (key,) = key_objects()
    activate(key)
    before = scene_snapshot()
    far = np.array([[0.5, 0.5, 0.5], [0.6, 0.5, 0.5]])
    assert bpy.ops.hair.comb_key(stroke=stroke_arg(far), pixel_size=PIXEL) == {'CANCELLED'}
    assert scene_snapshot() == before


def test_the_overlay_colours_each_wisp_and_highlights_the_active_key_s(scalp):
    overlay = ext_module(scalp_extension(), "overlay_wisps")
    for root, side in (((0.1, 0.0, 0.0), 1.0), ((-0.1, 0.0, 0.0), -1.0), ((0.0, 0.0, 0.1), 1.0)):
        activate(scalp)
        draw(hanging_stroke(root=root, side=side), view_direction=(0.0, 1.0, 0.0))
    keys = key_objects()
    activate(scalp)
    scalp.keystrand_hair.count = 600
    assert bpy.ops.hair.generate() == {'FINISHED'}
    hair = scalp.keystrand_hair.hair_object
    wisp = np.empty(len(hair.data.curves), np.int32)
    hair.data.attributes["wisp"].data.foreach_get("value", wisp)
    assert set(wisp.tolist()) == {0, 1, 2}
    colors = overlay.strand_colors(wisp, len(keys))
    for w in range(3):  # one colour per wisp, a different one for each
        mine = colors[wisp == w]
        assert (mine == mine[0]).all()
        for other in range(w):
            assert np.abs(mine[0, :3] - colors[wisp == other][0, :3]).max() > 0.1
    lit = overlay.strand_colors(wisp, len(keys), active=1)
    assert (lit[wisp == 1, 3] == 1.0).all() and (lit[wisp != 1, 3] < 0.5).all()
    brightness = lit[:, :3].sum(axis=1)
    assert brightness[wisp == 1].min() > brightness[wisp != 1].max()
    # Strands of a key deleted since Generate are grey.
    grey = overlay.strand_colors(wisp, 2)
    assert np.allclose(grey[wisp == 2], overlay.LOST)
    # Lines: one per segment, none across strands.
    counts = np.array([3, 1, 4])
    np.testing.assert_array_equal(overlay.segment_indices(counts), [[0, 1], [1, 2], [4, 5], [5, 6], [6, 7]])
    bpy.context.window_manager.keystrand_show_wisps = True  # background: no GPU drawing, no handler
    assert overlay._handle is None
    bpy.context.window_manager.keystrand_show_wisps = False


def test_the_shortcut_is_registered_and_removed_with_the_extension(extension, ext_enable):
    enable, disable = ext_enable

    def entries():
        kc = bpy.context.window_manager.keyconfigs.addon
        km = kc.keymaps.get("Object Mode")
        return [] if km is None else [k for k in km.keymap_items if k.idname == "hair.draw_key_strand"]
    (item,) = entries()
    assert (item.type, item.shift, item.alt, item.ctrl) == ('D', True, True, False)
    disable()
    try:
        assert entries() == []
        assert not hasattr(bpy.types.Object, "keystrand_mirror")
        assert not hasattr(bpy.types.WindowManager, "keystrand_show_wisps")
    finally:
        enable()
    assert len(entries()) == 1


def test_a_drawn_key_has_its_wisp_at_the_viewport_count_after_one_live_update(scalp):
    """From release (the operator's execute) one live update regrows the hair around the new
    key at the viewport count. (The time it takes is a figure of the benchmark report's
    Blender versions section, not of a test.)"""
    live = ext_module(scalp_extension(), "live")
    s = scalp.keystrand_hair
    draw(hanging_stroke(root=(-0.1, 0.0, 0.0), side=-1.0))
    activate(scalp)
    s.count, s.viewport_count = 20000, 2000
    assert bpy.ops.hair.generate() == {'FINISHED'}
    activate(scalp)
    assert draw(hanging_stroke()) == {'FINISHED'}
    bpy.context.view_layer.update()
    assert live.process(settle=False) == 1
    hair = s.hair_object
    assert len(hair.data.curves) == 2000
    wisp = np.empty(2000, np.int32)
    hair.data.attributes["wisp"].data.foreach_get("value", wisp)
    assert set(wisp.tolist()) == {0, 1}, "the new key has no wisp yet"


# --- the modal tools, driven by events -------------------------------------------------
# A background Blender has no window to send events to, so the tools' modal handlers are
# called here with events and a context made for them: a 3D viewport (a perspective view
# from the front) whose main region sits beside the sidebar the tool was started from.

class _StrokePoint:
    """A stroke element: its vectors held in float32, as Blender's properties hold them."""

    def __init__(self):
        self.name, self.location, self.mouse = "", (0.0, 0.0, 0.0), (0.0, 0.0)

    def __setattr__(self, name, value):
        object.__setattr__(self, name, value if name == "name" else tuple(np.float32(value).tolist()))


class _Stroke(list):
    """Stands in for the operator's stroke collection."""

    def add(self):
        self.append(_StrokePoint())
        return self[-1]

    def foreach_get(self, name, out):
        out[:] = np.ravel([tuple(getattr(item, name)) for item in self])


def _viewport(eye=(0.05, -0.6, 0.02), target=(0.05, 0.0, -0.08), size=(800, 600), fov_y=0.8):
    from mathutils import Matrix, Vector
    eye, target = Vector(eye), Vector(target)
    z = (eye - target).normalized()
    x = Vector((0.0, 0.0, 1.0)).cross(z).normalized()
    y = z.cross(x)
    camera = Matrix(((x[0], y[0], z[0], eye[0]), (x[1], y[1], z[1], eye[1]),
                     (x[2], y[2], z[2], eye[2]), (0.0, 0.0, 0.0, 1.0)))
    view = camera.inverted()
    f, aspect, near, far = 1.0 / np.tan(fov_y / 2), size[0] / size[1], 0.01, 100.0
    window = Matrix(((f / aspect, 0, 0, 0), (0, f, 0, 0),
                     (0, 0, (far + near) / (near - far), 2 * far * near / (near - far)), (0, 0, -1, 0)))
    rv3d = types.SimpleNamespace(view_matrix=view, perspective_matrix=window @ view, is_perspective=True,
                                 view_perspective='PERSP', view_rotation=camera.to_quaternion())
    main = types.SimpleNamespace(type='WINDOW', x=40, y=30, width=size[0], height=size[1], data=rv3d)
    sidebar = types.SimpleNamespace(type='UI', x=40 + size[0], y=30, width=300, height=size[1], data=None)
    area = types.SimpleNamespace(type='VIEW_3D', regions=[sidebar, main], tag_redraw=lambda: None)
    return area, main, sidebar


class _Context:
    """bpy.context with a viewport area and the sidebar as the region (a button's context)."""

    def __init__(self, area, sidebar):
        self.area, self.region, self.region_data = area, sidebar, None
        self.window_manager = types.SimpleNamespace(modal_handler_add=lambda op: None)
        self.workspace = types.SimpleNamespace(status_text_set=lambda text: None)

    def __getattr__(self, name):
        return getattr(bpy.context, name)


def _operator(cls, **props):
    """An instance standing in for `cls`: its methods, its properties as plain values."""
    ours = cls.__module__.rpartition(".")[0]
    methods = {k: v for c in reversed(cls.__mro__) for k, v in vars(c).items()
               if isinstance(v, types.FunctionType) and v.__module__.startswith(ours)}
    op = type("Fake" + cls.__name__, (), methods)()
    op.bl_label = cls.bl_label
    op.reports = []
    op.report = lambda kind, message: op.reports.append((kind, message))
    op.stroke = _Stroke()
    module, name = cls.bl_idname.split(".")
    for name, prop in getattr(getattr(bpy.ops, module), name).get_rna_type().properties.items():
        if prop.type not in ('POINTER', 'COLLECTION'):
            default = prop.default_array if getattr(prop, "is_array", False) else prop.default
            setattr(op, name, tuple(default) if getattr(prop, "is_array", False) else default)
    for name, value in props.items():
        setattr(op, name, value)
    return op


def _event(kind, value, region, coord):
    return types.SimpleNamespace(type=kind, value=value, mouse_x=region.x + coord[0], mouse_y=region.y + coord[1])


def _pixel(region, world):
    from bpy_extras import view3d_utils
    return tuple(view3d_utils.location_3d_to_region_2d(region, region.data, world))


def _drag_events(op, context, region, pixels, finish=('LEFTMOUSE', 'RELEASE')):
    result = op.modal(context, _event('LEFTMOUSE', 'PRESS', region, pixels[0]))
    for p in pixels[1:]:
        result = op.modal(context, _event('MOUSEMOVE', 'NOTHING', region, p))
    return op.modal(context, _event(*finish, region, pixels[-1]))


def _screen_stroke(region, n=60):
    """Mouse positions of a hanging strand drawn from a point of the sphere facing the view."""
    root = np.array([0.06, -0.079, 0.02])
    root = 0.1 * root / np.linalg.norm(root)
    return [_pixel(region, p) for p in hanging_stroke(root=root, n=n)]


def test_the_modal_tool_draws_the_key_under_the_mouse_within_the_tolerance_in_pixels(scalp):
    from groom.stroke import distance_to_polyline, sample_cubic
    draw_key = ext_module(scalp_extension(), "draw_key")
    area, main, sidebar = _viewport()
    context = _Context(area, sidebar)
    op = _operator(bpy.types.HAIR_OT_draw_key_strand)
    pixels = _screen_stroke(main)
    assert draw_key.HAIR_OT_draw_key_strand.invoke(op, context, None) == {'RUNNING_MODAL'}
    assert _drag_events(op, context, main, pixels) == {'FINISHED'}, op.reports
    (key,) = key_objects()
    c = control_points(key)
    assert abs(np.linalg.norm(c[0]) - 0.1) < 2e-3, "the root is not on the sphere"
    np.testing.assert_allclose(_pixel(main, c[0]), pixels[0], atol=0.05)  # under the press
    on_screen = np.array([_pixel(main, p) for p in sample_cubic(c, 64)])
    mouse = np.array(pixels)
    to_curve = distance_to_polyline(np.c_[mouse, np.zeros(len(mouse))], np.c_[on_screen, np.zeros(len(on_screen))])
    assert to_curve.max() <= op.tolerance * 1.01, to_curve.max()
    assert op.pixel_size > 0 and op.view_perspective
    # The stroke and the view it left in the operator's properties make the same key again
    # (a redo, or a script) without a viewport.
    assert len(op.stroke) == len(pixels)
    assert draw([item.location for item in op.stroke], pixel_size=op.pixel_size, view_direction=op.view_direction,
                view_eye=op.view_eye, view_perspective=True) == {'FINISHED'}
    np.testing.assert_array_equal(control_points(key_objects()[1]), c)


def test_esc_while_dragging_leaves_nothing(scalp):
    draw_key = ext_module(scalp_extension(), "draw_key")
    scalp.keystrand_hair.symmetry = 'X'
    area, main, sidebar = _viewport()
    context = _Context(area, sidebar)
    before = scene_snapshot()
    op = _operator(bpy.types.HAIR_OT_draw_key_strand)
    draw_key.HAIR_OT_draw_key_strand.invoke(op, context, None)
    assert _drag_events(op, context, main, _screen_stroke(main), finish=('ESC', 'PRESS')) == {'CANCELLED'}
    assert op._preview.strips == [] and op._preview._handle is None
    assert scene_snapshot() == before


def test_a_press_off_the_scalp_waits_for_one_on_it(scalp):
    draw_key = ext_module(scalp_extension(), "draw_key")
    area, main, sidebar = _viewport()
    context = _Context(area, sidebar)
    op = _operator(bpy.types.HAIR_OT_draw_key_strand)
    draw_key.HAIR_OT_draw_key_strand.invoke(op, context, None)
    assert op.modal(context, _event('LEFTMOUSE', 'PRESS', main, (5.0, 5.0))) == {'RUNNING_MODAL'}
    assert op.reports and op.reports[-1][0] == {'WARNING'}
    assert _drag_events(op, context, main, _screen_stroke(main)) == {'FINISHED'}
    assert len(key_objects()) == 1


def _comb_drag(scalp, finish):
    comb_key = ext_module(scalp_extension(), "comb_key")
    from groom import KeyStrand
    scalp.keystrand_hair.symmetry = 'X'
    area, main, sidebar = _viewport()
    draw(hanging_stroke(root=0.1 * np.array([0.6, -0.79, 0.2]) / np.linalg.norm([0.6, -0.79, 0.2])),
         view_direction=(0.0, 1.0, 0.0))
    key, twin = key_objects()
    activate(key)
    before = control_points(key), scene_snapshot()
    mid = _pixel(main, KeyStrand(before[0], kind="cubic").evaluate([0.6])[0])
    pixels = [(mid[0] + dx, mid[1]) for dx in np.linspace(0.0, 50.0, 26)]
    context = _Context(area, sidebar)
    op = _operator(bpy.types.HAIR_OT_comb_key)
    comb_key.HAIR_OT_comb_key.invoke(op, context, None)
    return _drag_events(op, context, main, pixels, finish=finish), key, twin, before, op


def test_the_modal_comb_bends_the_key_under_the_mouse_and_keeps_its_length(scalp):
    result, key, twin, (before, _), op = _comb_drag(scalp, ('LEFTMOUSE', 'RELEASE'))
    assert result == {'FINISHED'}, op.reports
    after = control_points(key)
    assert np.abs(after - before).max() > 0.005
    assert abs(length_of(after) - length_of(before)) < 1e-5 * length_of(before)
    np.testing.assert_allclose(control_points(twin), after * [-1.0, 1.0, 1.0], atol=1e-6)
    assert op.key == key.name and len(op.stroke) == 26


def test_esc_while_combing_puts_the_key_and_its_twin_back(scalp):
    result, key, twin, (_, snapshot), op = _comb_drag(scalp, ('ESC', 'PRESS'))
    assert result == {'CANCELLED'}
    assert scene_snapshot() == snapshot


# --- what the GPU draws ----------------------------------------------------------------

_GPU_SCRIPT = r"""
import importlib, json, os, bpy, bmesh, gpu
import numpy as np
from mathutils import Matrix, Vector
bpy.context.preferences.extensions.repos.new(name="t", module="t", custom_directory=os.path.join(os.environ["BLENDER_USER_RESOURCES"], "r"), source='USER')
assert bpy.ops.extensions.package_install_files(filepath=ZIP, repo="t", enable_on_install=True) == {'FINISHED'}
overlay = importlib.import_module("bl_ext.t.keystrand_hair.addon.overlay_wisps")
stroke_input = importlib.import_module("bl_ext.t.keystrand_hair.addon.stroke_input")
for o in list(bpy.data.objects):
    bpy.data.objects.remove(o)
mesh = bpy.data.meshes.new("Scalp"); bm = bmesh.new(); bmesh.ops.create_uvsphere(bm, u_segments=24, v_segments=12, radius=0.1)
bm.to_mesh(mesh); bm.free()
scalp = bpy.data.objects.new("Scalp", mesh); bpy.context.scene.collection.objects.link(scalp)
scalp.keystrand_hair.symmetry = 'NONE'
for root, side in STROKES:
    bpy.context.view_layer.objects.active = scalp
    s = np.linspace(0.0, 1.0, 60)
    p = np.stack([side * (0.05 * np.sin(np.pi * s) + 0.01 * s), np.zeros_like(s), -0.18 * s], 1) + np.asarray(root)
    assert bpy.ops.hair.draw_key_strand(stroke=[{"name": "", "location": tuple(q), "mouse": (0.0, 0.0)} for q in p],
                                        pixel_size=5e-4) == {'FINISHED'}
bpy.context.view_layer.objects.active = scalp
scalp.keystrand_hair.count = 3000
assert bpy.ops.hair.generate() == {'FINISHED'}
hair = scalp.keystrand_hair.hair_object
gpu.init()
W, H = 160, 160
eye, target = Vector((0.0, -0.7, -0.05)), Vector((0.0, 0.0, -0.05))
z = (eye - target).normalized(); x = Vector((0.0, 0.0, 1.0)).cross(z).normalized(); y = z.cross(x)
camera = Matrix(((x[0], y[0], z[0], eye[0]), (x[1], y[1], z[1], eye[1]), (x[2], y[2], z[2], eye[2]), (0, 0, 0, 1)))
f, near, far = 1.0 / np.tan(0.35), 0.01, 100.0
proj = Matrix(((f, 0, 0, 0), (0, f, 0, 0), (0, 0, (far + near) / (near - far), 2 * far * near / (near - far)), (0, 0, -1, 0)))
off = gpu.types.GPUOffScreen(W, H)

def render(draw):
    with off.bind():
        fb = gpu.state.active_framebuffer_get()
        fb.clear(color=(0.0, 0.0, 0.0, 0.0), depth=1.0)
        gpu.matrix.load_matrix(camera.inverted())
        gpu.matrix.load_projection_matrix(proj)
        draw()
        return np.array(fb.read_color(0, 0, W, H, 4, 0, 'FLOAT').to_list(), np.float32).reshape(-1, 4)

out = {"backend": gpu.platform.backend_type_get()}
for active in (None, 1):
    pixels = render(lambda: overlay.draw_hair(hair, 3, active, (W, H)))
    drawn = pixels[pixels[:, 3] > 0.2]
    expected = overlay.strand_colors(np.arange(3), 3, active)
    # Each drawn pixel's nearest wisp colour (premultiplied by nothing: blending onto black).
    rgb = drawn[:, :3] / np.maximum(drawn[:, 3:], 1e-6)
    nearest = np.argmin(np.abs(rgb[:, None, :] - expected[None, :, :3]).max(axis=2), axis=1)
    close = np.abs(rgb - expected[nearest, :3]).max(axis=1) < 0.06
    out[str(active)] = {"drawn": int(len(drawn)), "close": float(close.mean()),
                        "per_wisp": np.bincount(nearest[close], minlength=3).tolist(),
                        "shown": [float(drawn[nearest == w, :3].sum(axis=1).mean()) if (nearest == w).any() else 0.0
                                  for w in range(3)]}
line = np.array([[-0.05, 0.0, -0.05], [0.05, 0.0, -0.05]], np.float32)
pixels = render(lambda: stroke_input.draw_strips([line], (1.0, 0.5, 0.0, 1.0), (W, H)))
out["strip"] = int((pixels[:, 3] > 0.5).sum())
print("RESULT", json.dumps(out))
"""


@pytest.mark.skipif(not hasattr(__import__("gpu"), "init"),
                    reason="this Blender cannot draw without a window (its gpu module has no init())")
def test_the_overlay_and_the_preview_draw_their_colours(extension_zip, tmp_path):
    """In a fresh process with the GPU started for background use: the overlay draws the hair,
    each wisp in its own colour, the active key's opaque and the others faded; the stroke
    preview draws its line."""
    import json
    import os
    import subprocess
    import sys
    strokes = [((0.1, 0.0, 0.0), 1.0), ((-0.1, 0.0, 0.0), -1.0), ((0.0, -0.1, 0.0), 1.0)]
    code = f"ZIP = {str(extension_zip[0])!r}\nSTROKES = {strokes!r}\n" + _GPU_SCRIPT
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"), PYTHONPATH="")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300,
                          cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.split("RESULT ", 1)[1])
    plain, lit = out["None"], out["1"]
    assert plain["drawn"] > 200, out
    assert plain["close"] > 0.9, out  # the pixels are the wisps' colours
    assert min(plain["per_wisp"]) > 20, out  # every wisp is seen
    assert lit["close"] > 0.9, out
    # The active key's hairs stand out: brighter on screen than the faded others.
    assert lit["shown"][1] > 1.5 * max(lit["shown"][0], lit["shown"][2]), out
    print(f"\n[figure] overlay brightness, active wisp / brightest faded one: "
          f"{lit['shown'][1] / max(lit['shown'][0], lit['shown'][2]):.2f}")
    assert out["strip"] > 50, out


def test_an_edit_in_edit_mode_is_mirrored_as_it_happens(scalp):
    scalp.keystrand_hair.symmetry = 'X'
    draw(hanging_stroke())
    a, b = key_objects()
    for obj in bpy.context.selected_objects:
        obj.select_set(False)
    a.select_set(True)
    activate(a)
    assert bpy.ops.object.mode_set(mode='EDIT') == {'FINISHED'}
    try:
        tip = a.data.splines[0].bezier_points[-1]  # the edit curve's, in edit mode
        for v in (tip.co, tip.handle_left, tip.handle_right):
            v.x += 0.02
        a.data.update_tag()
        bpy.context.view_layer.update()
        np.testing.assert_allclose(control_points(b), control_points(a) * [-1.0, 1.0, 1.0], atol=1e-6)
    finally:
        bpy.ops.object.mode_set(mode='OBJECT')
    np.testing.assert_allclose(control_points(b)[-1], control_points(a)[-1] * [-1.0, 1.0, 1.0], atol=1e-6)
    assert control_points(a)[-1][0] > hanging_stroke()[-1][0] + 0.01, "the edit did not stay"

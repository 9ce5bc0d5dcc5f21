# SPDX-License-Identifier: GPL-3.0-or-later
"""Hair kept out of the head in Blender: the scalp's Collider (Add Head's head, another
object, or the scalp itself), read in the scalp's space and given to groom; a key strand
through the head reported as a warning; Generate's progress; and a failing Generate with a
collider leaves no trace. Depths are measured here with groom's exact signed distance on
the collider mesh read independently of the extension, carried through the objects'
world matrices."""
import importlib

import numpy as np
import pytest
import bpy
from groom import list_presets

from blender_scene import activate, make_scalp, mesh_arrays
from test_blender_errors import Boom, raise_on, run_failing


# groom starts the ramp from the root's depth in its sampled distance, which is within the
# sampling's error (some 0.02 mm near a smooth surface, collide.py) of the exact depth used
# here. A collider read in the wrong place would be off by millimetres.
RAMP_TOLERANCE = 2e-5


def ext_module(extension, name):
    return importlib.import_module(f"{extension.__name__}.addon.{name}")


def carry(points, source, target):
    """Points in `source`'s coordinates -> `target`'s, through their world matrices."""
    m = np.linalg.inv(np.array(target.matrix_world, np.float64)) @ np.array(source.matrix_world, np.float64)
    return np.asarray(points, np.float64) @ m[:3, :3].T + m[:3, 3]


def hair_arrays(hair):
    """(points (P,3) in the hair object's coordinates, radius (P,), counts (S,))."""
    c = hair.data
    n = len(c.points)
    pts, radius = np.empty(3 * n, np.float32), np.empty(n, np.float32)
    c.attributes["position"].data.foreach_get("vector", pts)
    c.attributes["radius"].data.foreach_get("value", radius)
    offsets = np.empty(len(c.curves) + 1, np.int32)
    c.curve_offset_data.foreach_get("value", offsets)
    return pts.reshape(n, 3), radius, np.diff(offsets)


def depths(hair, collider_obj):
    """For every point but the roots: (signed distance to the collider mesh, radius, the
    least distance allowed there). Distances are groom's exact ones (not the sampled ones
    the hair was moved by), positive outside, in the hair's coordinates (the collider's
    mesh carried there; its radii are in those units). The allowance is the radius plus
    half the margin; near a root that the scalp puts inside the collider, what groom's
    collision promises there: its root's depth plus RAMP_SLOPE of the distance from the
    root, less the radius and RAMP_TOLERANCE. The Collider is groom's cached one for these
    arrays when there is one: its exact distance does not depend on how it was sampled, and
    building it again costs a second."""
    from groom.collide import RAMP_SLOPE, collider_for
    pts, radius, counts = hair_arrays(hair)
    roots = np.concatenate([[0], np.cumsum(counts)[:-1]])
    strand = np.repeat(np.arange(len(counts)), counts)
    keep = np.ones(len(pts), bool)
    keep[roots] = False
    v, t = mesh_arrays(collider_obj)
    collider = collider_for(carry(v, collider_obj, hair), t, collider_obj.name)
    d = collider.signed_distance(pts[keep])
    root_depth = collider.signed_distance(pts[roots])[strand[keep]]
    from_root = np.linalg.norm(pts[keep] - pts[roots][strand[keep]], axis=1)
    margin = hair.keystrand_hair.scalp.keystrand_hair.collision_margin
    allowed = np.minimum(radius[keep] + 0.5 * margin,
                         root_depth + RAMP_SLOPE * from_root - radius[keep] - RAMP_TOLERANCE)
    return d, radius[keep], allowed


def add_head(**kwargs):
    assert bpy.ops.hair.add_head(**kwargs) == {'FINISHED'}
    scalp = bpy.context.view_layer.objects.active
    bpy.context.view_layer.update()
    return scalp.parent, scalp


def generate(scalp, count):
    scalp.keystrand_hair.count = count
    activate(scalp)
    assert bpy.ops.hair.generate() == {'FINISHED'}
    return scalp.keystrand_hair.hair_object


# --- Add Head: the bundled head is the collider ---------------------------------------------

def test_add_head_makes_its_head_the_scalp_s_collider(clean):
    head, scalp = add_head()
    assert scalp.keystrand_hair.collider == head and scalp.keystrand_hair.collision


@pytest.mark.parametrize("name", list_presets())
def test_every_preset_on_add_head_s_scalp_ends_outside_the_head(clean, name):
    # Turned and moved: the head's mesh is read in the scalp's space through the matrices.
    head, scalp = add_head(location=(0.3, -0.2, 1.1), rotation=(0.3, -0.2, 0.9))
    assert bpy.ops.hair.load_preset(preset=name) == {'FINISHED'}
    d, radius, allowed = depths(generate(scalp, 400), head)
    bad = d < allowed
    assert not bad.any(), f"{name}: {bad.sum()} points too close or inside, deepest {d.min():.4g}"
    # On the bundled head the roots lie on it: the whole margin holds, ramp or not.
    assert (d >= radius + 0.5 * scalp.keystrand_hair.collision_margin).all()


def test_a_large_groom_grows_in_a_worker_process_with_the_same_numbers(clean, monkeypatch):
    """From 2 x 2,048 strands Generate's blocks grow partly in a worker process of groom's
    (a plain Python beside Blender, groom.processes; Linux): the hair is the same, bit for
    bit, as grown on threads in Blender's process."""
    import os
    from groom import processes
    if not processes.available() or processes.parallel.cpu_threads() < 2:
        pytest.skip("worker processes need Linux's memfd and a second CPU")
    head, scalp = add_head()
    assert bpy.ops.hair.load_preset(preset="wavy") == {'FINISHED'}
    monkeypatch.setenv(processes.ENV_SWITCH, "0")
    on_threads = hair_arrays(generate(scalp, 5000))
    monkeypatch.setenv(processes.ENV_SWITCH, "1")
    before = processes.workers_cpu_seconds()
    in_processes = hair_arrays(generate(scalp, 5000))
    assert [w.alive() for w in processes._WORKERS[os.getpid()]] == [True] * (processes.parallel.cpu_threads() - 1)
    assert processes.workers_cpu_seconds() > before
    for a, b in zip(on_threads, in_processes):
        np.testing.assert_array_equal(a, b)


def test_without_collision_the_same_hair_goes_through_the_head(clean):
    """The check above can fail: the same preset grown with Collision off has points inside."""
    head, scalp = add_head()
    assert bpy.ops.hair.load_preset(preset="wavy") == {'FINISHED'}
    scalp.keystrand_hair.collision = False
    d, _, _ = depths(generate(scalp, 400), head)
    assert (d < -1e-3).sum() > 20, d.min()


# --- a user's scalp: the scalp itself, or another object -------------------------------------

def make_cap(name="Cap", location=(0.2, 0.1, 0.5), rotation=(0.0, 0.0, 0.3)):
    """The top half of a sphere of radius 0.1 (an open scalp cap), moved and turned."""
    import bmesh
    obj = make_scalp(name)
    bm = bmesh.new()
    bm.from_mesh(obj.data)
    bmesh.ops.delete(bm, geom=[v for v in bm.verts if v.co.z < -1e-6], context='VERTS')
    bm.to_mesh(obj.data)
    bm.free()
    obj.location, obj.rotation_euler = location, rotation
    bpy.context.view_layer.update()
    return obj


def make_head_for(cap):
    """A closed sphere through the cap: a mesh of radius 0.05 scaled by 2, turned otherwise
    than the cap, at the cap's place (the matrices, not the mesh, make it fit)."""
    head = make_scalp("Head", radius=0.05, segments=48, rings=24)
    head.scale = (2.0, 2.0, 2.0)
    head.rotation_euler = (0.4, 0.1, 0.7)
    head.location = cap.location
    bpy.context.view_layer.update()
    activate(cap)
    return head


def add_falling_keys(cap):
    """Straight keys on the cap's crown and upper ring, long enough to fall past its edge,
    and hairs turned at random about their roots (untidy), so many would dip into it."""
    m = np.array(cap.matrix_world)
    s = cap.keystrand_hair
    s.key_shape, s.key_length = 'STRAIGHT', 0.2
    s.tidiness, s.theta_max = 0.0, 1.0
    for local in [(0.0, 0.0, 0.1), (0.07, 0.0, 0.07), (-0.07, 0.0, 0.07), (0.0, -0.07, 0.07), (0.0, 0.07, 0.07)]:
        activate(cap)
        assert bpy.ops.hair.add_key_strand(location=tuple((m @ np.append(local, 1.0))[:3])) == {'FINISHED'}
    activate(cap)
    return sorted((o for o in bpy.data.objects if o.type == 'CURVE'), key=lambda o: o.name)


def test_an_empty_collider_is_the_scalp_itself(clean):
    from groom import generate as groom_generate
    from test_blender_workflow import curves_arrays, params_of, read_key, read_scalp_arrays
    cap = make_cap()
    head = make_head_for(cap)
    keys = add_falling_keys(cap)
    assert cap.keystrand_hair.collider is None
    hair = generate(cap, 600)
    surface = read_scalp_arrays(cap)
    up, front = ext_module(clean, "head").scalp_axes(cap)  # the scene's axes in the turned cap's mesh
    expected = groom_generate(surface, [read_key(k) for k in keys], params_of(cap, up=up, front=front),
                              collider=(surface.vertices, surface.triangles))
    got = curves_arrays(hair)
    np.testing.assert_array_equal(got["counts"], expected.strands.counts)
    np.testing.assert_array_equal(got["position"], expected.strands.points)
    assert expected.collision.strands_moved > 0, "the cap moved no hair: the comparison proves nothing"
    # An open cap keeps nothing from below its edge: there the hair falls into the head.
    d, _, _ = depths(hair, head)
    assert (d < -1e-3).any()


def test_a_collider_object_keeps_the_hair_out_of_it_through_both_objects_matrices(clean):
    """The head fits the cap only through the matrices (its mesh is half the size, turned
    otherwise): read in its own coordinates it would not lie under the scalp at all."""
    cap = make_cap()
    head = make_head_for(cap)
    add_falling_keys(cap)
    cap.keystrand_hair.collider = head
    hair = generate(cap, 600)
    d, _, allowed = depths(hair, head)
    bad = d < allowed
    assert not bad.any(), f"{bad.sum()} points too close or inside, deepest {d.min():.4g}"
    # The check can fail: grown without collision, the same hair goes into the head.
    cap.keystrand_hair.collision = False
    d, _, _ = depths(generate(cap, 600), head)
    assert (d < -1e-3).any()


# --- what the artist is told -------------------------------------------------------------------

def test_a_key_through_the_head_is_reported_as_a_warning_and_left_as_drawn(clean, capfd):
    head, scalp = add_head()
    assert bpy.ops.hair.load_preset(preset="wavy") == {'FINISHED'}
    keys = sorted((o for o in bpy.data.objects if o.keystrand_hair.role == 'KEY'), key=lambda o: o.name)
    # Key 3 drawn straight into the head, toward its middle (the head is centred on its origin).
    bp = keys[3].data.splines[0].bezier_points
    root = np.array(bp[0].co)
    s = np.linspace(0.0, 1.0, len(bp))
    line = root - 0.12 * s[:, None] * root / np.linalg.norm(root)
    for p, q in zip(bp, line):
        p.co = p.handle_left = p.handle_right = tuple(q)
    drawn = np.array([p.co for p in bp])
    capfd.readouterr()
    hair = generate(scalp, 400)
    out = "".join(capfd.readouterr())
    warnings = [line for line in out.splitlines() if line.startswith("Warning:")]
    assert len(warnings) == 1, out
    (warning,) = warnings
    assert "key 3" in warning and repr(keys[3].name) in warning and repr(head.name) in warning, warning
    np.testing.assert_array_equal(np.array([p.co for p in bp]), drawn)
    # The hair it guides is still kept out.
    d, _, allowed = depths(hair, head)
    assert not (d < allowed).any(), d.min()


def test_a_groom_with_no_key_through_the_head_gives_no_warning(clean, capfd):
    _, scalp = add_head()
    assert bpy.ops.hair.load_preset(preset="wavy") == {'FINISHED'}
    capfd.readouterr()
    generate(scalp, 300)
    out = "".join(capfd.readouterr())
    assert "Warning:" not in out and "moved out of 'Hair Head'" in out, out


def test_load_preset_lifts_its_keys_out_of_a_head_the_scalp_lies_under(clean, capfd):
    """A scalp a little inside its head (as real scans are): the preset's keys, drawn along
    the bundled head, would pass through it; Load Preset lifts them out, so Generate has no
    key to warn about."""
    from groom import generate as groom_generate, load_preset
    head_module, hair_module = ext_module(clean, "head"), ext_module(clean, "hair")
    head, scalp = add_head()
    scalp.scale = (0.985, 0.985, 0.985)  # some 1.5 mm under the head's surface
    bpy.context.view_layer.update()
    capfd.readouterr()
    assert bpy.ops.hair.load_preset(preset="wavy") == {'FINISHED'}
    out = "".join(capfd.readouterr())
    assert "lifted out of 'Hair Head'" in out, out
    generate(scalp, 300)
    out = "".join(capfd.readouterr())
    assert "Warning:" not in out, out
    # The lift is what keeps the warning away: placed as drawn, keys pass through the head.
    depsgraph = bpy.context.evaluated_depsgraph_get()
    surface = ext_module(clean, "scene_data").read_scalp(scalp, depsgraph)
    up, front = head_module.scalp_axes(scalp)
    preset = load_preset("wavy")
    drawn = preset.place_keys(surface, up=up, front=front)
    result = groom_generate(surface, drawn.keys, drawn.params.replace(count=200),
                            collider=hair_module.read_collider(scalp, depsgraph, surface))
    assert result.collision.keys_inside, "no key of the preset passes through the head: the test proves nothing"


class _Recorder:
    """Stands in for the window manager and the workspace: notes every call."""

    def __init__(self):
        self.calls = []

    def progress_begin(self, lo, hi):
        self.calls.append(("begin", lo, hi))

    def progress_update(self, value):
        self.calls.append(("update", value))

    def progress_end(self):
        self.calls.append(("end",))

    def status_text_set(self, text):
        self.calls.append(("status", text))


def test_generate_shows_groom_s_progress_and_clears_it(clean, monkeypatch):
    progress = ext_module(clean, "progress")
    shown = []
    real = progress.BlenderProgress

    class Watched(real):
        def __init__(self, window_manager, workspace, label):
            # The real window manager and workspace are driven; a recorder watches beside them.
            super().__init__(window_manager, workspace, label)
            self.watch = real(_Recorder(), _Recorder(), label)
            shown.append(self.watch)

        def __call__(self, fraction, stage):
            super().__call__(fraction, stage)
            self.watch(fraction, stage)

        def close(self):
            super().close()
            self.watch.close()

    monkeypatch.setattr(progress, "BlenderProgress", Watched)
    _, scalp = add_head()
    assert bpy.ops.hair.load_preset(preset="wavy") == {'FINISHED'}
    generate(scalp, 300)
    (watch,) = shown
    wm, status = watch.window_manager.calls, watch.workspace.calls
    assert wm[0] == ("begin", 0, 100) and wm[-1] == ("end",) and wm.count(("begin", 0, 100)) == 1
    values = [c[1] for c in wm if c[0] == "update"]
    assert values == sorted(values) and values[-1] == 100 and len(values) >= 4, values
    texts = [c[1] for c in status]
    assert texts[-1] is None
    # groom's own stages, collision among them.
    assert all(t.startswith("Generating hair: ") for t in texts[:-1]) and len(set(texts[:-1])) >= 4, texts
    assert any("collider" in t for t in texts[:-1]), texts


def test_progress_is_cleared_when_the_work_fails(clean):
    progress = ext_module(clean, "progress")
    wm, workspace = _Recorder(), _Recorder()
    with pytest.raises(Boom):
        with progress.BlenderProgress(wm, workspace, "Generating hair") as report:
            report(0.25, "growing strands")
            raise Boom("midway")
    assert wm.calls == [("begin", 0, 100), ("update", 25), ("end",)]
    assert workspace.calls == [("status", "Generating hair: growing strands (25 %)"), ("status", None)]


# --- a failing Generate with a collider leaves no trace ----------------------------------------

def test_a_collider_away_from_the_scalp_is_reported_naming_it(clean):
    cap = make_cap()
    head = make_head_for(cap)
    add_falling_keys(cap)
    cap.keystrand_hair.collider = head
    head.location.x += 1.0
    bpy.context.view_layer.update()
    activate(cap)
    message = run_failing(bpy.ops.hair.generate, "collider 'Head'")
    assert "scalp" in message


def test_a_collider_that_is_not_a_mesh_is_reported(clean):
    cap = make_cap()
    add_falling_keys(cap)
    # The setting offers meshes only; a script can still set another object.
    cap.keystrand_hair.collider = next(o for o in bpy.data.objects if o.type == 'CURVE')
    activate(cap)
    run_failing(bpy.ops.hair.generate, "is a curve, not a mesh")


def test_a_collider_without_faces_is_reported_naming_it(clean):
    cap = make_cap()
    add_falling_keys(cap)
    mesh = bpy.data.meshes.new("Points")
    mesh.from_pydata([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 1)], [])
    points = bpy.data.objects.new("Points", mesh)
    bpy.context.scene.collection.objects.link(points)
    cap.keystrand_hair.collider = points
    activate(cap)
    run_failing(bpy.ops.hair.generate, "collider 'Points': no faces")


def test_generate_again_grows_the_new_hair_in_the_memory_of_the_old(clean, spare_takes):
    from groom import parallel, processes
    if not processes.available() or parallel.cpu_threads() < 2:
        pytest.skip("the strands grow in shared memory only beside worker processes (Linux, 2 CPUs)")
    _, scalp = add_head()
    assert bpy.ops.hair.load_preset(preset="wavy") == {'FINISHED'}
    first = [a.copy() for a in hair_arrays(generate(scalp, 5000))]
    # points, radius and colour (wavy is opaque: its alpha takes no memory, groom.cylinders.ones)
    assert spare_takes == [False] * 3           # no hair to replace yet
    spare_takes.clear()
    again = hair_arrays(generate(scalp, 5000))
    # each in a file of the hair it replaced
    assert spare_takes == [True] * 3 and processes.spares() == 0
    for a, b in zip(first, again):
        np.testing.assert_array_equal(a, b)


def test_generate_failing_inside_collision_gives_the_old_hair_back(clean, monkeypatch):
    from groom.collide import StrandCollision
    _, scalp = add_head()
    assert bpy.ops.hair.load_preset(preset="wavy") == {'FINISHED'}
    generate(scalp, 300)
    scalp.keystrand_hair.count = 500
    raise_on(monkeypatch, StrandCollision, "apply", after=False)
    activate(scalp)
    run_failing(bpy.ops.hair.generate, "Boom", internal=True)
    assert len(scalp.keystrand_hair.hair_object.data.curves) == 300


def _background_builds_done():
    import threading
    for thread in threading.enumerate():
        if thread.name == "groom-collider":
            thread.join()


def test_add_head_builds_the_heads_collider_while_the_artist_picks_a_preset(clean, colliders_built):
    """...and then starts groom's worker processes and sends them the collider, which the
    first Generate would otherwise wait for."""
    import os
    from groom import collide, parallel, processes
    built = colliders_built
    _, scalp = add_head()
    _background_builds_done()
    assert built == ["groom-collider"]
    (collider,) = collide._CACHE.values()
    if processes.available() and parallel.cpu_threads() > 1:
        workers = processes._WORKERS.get(os.getpid(), [])
        assert workers and all(processes.token(collider) in w.known for w in workers)
    assert bpy.ops.hair.load_preset(preset="wavy") == {'FINISHED'}      # places its keys with it
    assert built == ["groom-collider"]


def test_load_preset_starts_the_workers_with_the_collider_it_placed_the_keys_with(clean, colliders_built, monkeypatch):
    """A scalp of the artist's own gets its collider when Load Preset places the keys; the
    workers are then started and sent it on a thread of their own, so the Generate that
    follows waits for neither (and, pressed at once, waits for that rather than growing
    on threads)."""
    import os
    import threading
    from collections import OrderedDict
    from groom import collide, parallel, processes
    _, scalp = add_head()
    _background_builds_done()
    monkeypatch.setattr(collide, "_CACHE", OrderedDict())     # as if the head were the artist's own
    assert bpy.ops.hair.load_preset(preset="wavy") == {'FINISHED'}
    (collider,) = collide._CACHE.values()
    for thread in threading.enumerate():
        if thread.name == "groom-prepare":
            thread.join()
    if processes.available() and parallel.cpu_threads() > 1:
        workers = processes._WORKERS.get(os.getpid(), [])
        assert workers and all(processes.token(collider) in w.known for w in workers)


def test_a_loaded_files_scalps_get_their_colliders_built_meanwhile(clean, request):
    live = ext_module(clean, "live")
    assert (bpy.app.handlers.load_post, live.on_loaded) in live.HANDLERS
    _, scalp = add_head()
    _background_builds_done()
    built = request.getfixturevalue("colliders_built")      # from here on
    hair = ext_module(clean, "hair")     # what on_loaded does outside background mode
    scalp.keystrand_hair.collision = False
    hair.prebuild_colliders()
    _background_builds_done()
    assert built == []                  # Collision off: nothing to build
    scalp.keystrand_hair.collision = True
    hair.prebuild_colliders()
    _background_builds_done()
    assert built == ["groom-collider"]
    assert bpy.ops.hair.load_preset(preset="wavy") == {'FINISHED'}
    assert built == ["groom-collider"]

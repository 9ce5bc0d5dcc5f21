# SPDX-License-Identifier: GPL-3.0-or-later
"""Render Preview shows what the render will: the head hides the hair behind it and shows its
own colour under the light; and the preview is progressive: a first image at once, refined
pass by pass (driven here through progressive.step, as Blender runs no timers in background
mode) towards the many-sample image, started over when the camera, a setting or the hair
changes."""
import importlib

import numpy as np
import pytest
import bpy

from blender_scene import activate, make_camera, make_scalp, mesh_arrays

HEAD_RGB = (0.2, 0.6, 0.3)       # green: no hair colour comes near it
RADIUS = 0.1
# Keys on the back of the head, growing back and up: seen from the front, the head hides
# their lower parts and their tops stand out above it.
BACK_KEYS = [(0.0, 0.07, 0.07), (0.04, 0.08, 0.04), (-0.04, 0.08, 0.04), (0.0, 0.095, 0.02)]


def ext_module(extension, name):
    return importlib.import_module(f"{extension.__name__}.addon.{name}")


def head_scene(key_points=BACK_KEYS, size=64):
    """A sphere scalp (its own collider) with a green Principled material, keys, hair, and a
    camera in front of it; returns the scalp."""
    scalp = make_scalp(radius=RADIUS)
    mat = bpy.data.materials.new("Skin")
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    next(n for n in mat.node_tree.nodes if n.type == 'BSDF_PRINCIPLED').inputs["Base Color"].default_value = (*HEAD_RGB, 1)
    scalp.data.materials.append(mat)
    # Hair grows on the back half only (the scalp's hair_density), so none lies in front of the face.
    v = np.empty(3 * len(scalp.data.vertices))
    scalp.data.vertices.foreach_get("co", v)
    density = scalp.data.attributes.new("hair_density", 'FLOAT', 'POINT')
    density.data.foreach_set("value", (v.reshape(-1, 3)[:, 1] > 0.04).astype(np.float32))
    s = scalp.keystrand_hair
    s.key_shape = 'STRAIGHT'
    for p in key_points:
        activate(scalp)
        assert bpy.ops.hair.add_key_strand(location=p) == {'FINISHED'}
    s.count, s.preview_size, s.radius = 600, size, 1.5e-3
    s.preview_scene_lights = False     # the tracer's default key light
    activate(scalp)
    assert bpy.ops.hair.generate() == {'FINISHED'}
    make_camera(location=(0.0, -0.9, 0.08))
    activate(scalp)
    return scalp


def image_pixels():
    image = bpy.data.images["Hair Preview"]
    w, h = image.size
    px = np.empty(w * h * 4, np.float32)
    image.pixels.foreach_get(px)
    return px.reshape(h, w, 4)[::-1]          # row 0 at the top, as the tracer's


def ray_distance_to_centre(preview, scene, camera_obj, size):
    """Per pixel, how close its centre ray passes to the head's centre (the origin), from the
    camera's own geometry (tracer.Camera.rays)."""
    cam = preview.camera_for(scene, camera_obj, size)
    w, h = size
    x, y = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    o, d = cam.rays(x, y)
    closest = o - np.sum(o * d, axis=-1, keepdims=True) * d
    return np.linalg.norm(closest, axis=-1)


def test_preview_of_a_scene_with_a_head_shows_the_head(clean):
    preview = ext_module(clean, "preview")
    scalp = head_scene()
    scene = bpy.context.scene
    hair = scalp.keystrand_hair.hair_object
    assert bpy.ops.hair.render_preview() == {'FINISHED'}
    got = image_pixels()
    h, w = got.shape[:2]
    # The same hair without the head: where it would show.
    alone, _ = preview.render(scene, hair, scene.camera, scalp.keystrand_hair)
    dist = ray_distance_to_centre(preview, scene, scene.camera, (w, h))
    # The UV sphere's faces lie within cos(15°) of its radius: 0.9 R is surely on the head,
    # 1.05 R surely off it.
    on_head, off_head = dist < 0.9 * RADIUS, dist > 1.05 * RADIUS
    behind = on_head & (alone[..., 3] > 0.5)
    assert behind.sum() >= 20, f"only {behind.sum()} pixels of hair behind the head: the test scene is off"
    # Where the head is, the head shows, opaque: its green times the light, the same factor in
    # every channel (white light), never the hair's brown, also where hair lies behind it.
    head = got[on_head]
    assert np.all(head[:, 3] == pytest.approx(1.0, abs=1e-6))
    light = head[:, :3] / np.array(HEAD_RGB)
    np.testing.assert_allclose(light, light[:, :1].repeat(3, axis=1), atol=2e-3)
    assert light.min() > 0.05 and light.max() <= 1.1
    # Diffuse: the side facing the default key light (which comes from the front left, above)
    # is brighter than the far side.
    cols = np.nonzero(on_head.any(axis=0))[0]
    left, right = light[:, 0][np.isin(np.nonzero(on_head)[1], cols[:len(cols) // 3])], \
        light[:, 0][np.isin(np.nonzero(on_head)[1], cols[-len(cols) // 3:])]
    assert abs(left.mean() - right.mean()) > 0.05, "the head is shaded flat: no light direction shows"
    # Off the head, the hair that stands out above it is still drawn.
    standing = off_head & (alone[..., 3] > 0.5)
    assert standing.sum() >= 10
    assert (got[standing][:, 3] > 0.5).mean() > 0.9


def test_preview_with_the_renderer_process_shows_the_head_too(clean, monkeypatch):
    preview = ext_module(clean, "preview")
    head_scene(size=40)
    assert bpy.ops.hair.render_preview() == {'FINISHED'}
    in_process = image_pixels()
    monkeypatch.setenv("KEYSTRAND_PREVIEW_IN_PROCESS", "0")
    try:
        assert bpy.ops.hair.render_preview() == {'FINISHED'}
        assert type(preview.current_renderer()).__name__ == "WorkerClient"
        np.testing.assert_allclose(image_pixels(), in_process, atol=1e-6)
    finally:
        preview.close()


def test_a_scene_past_the_triangle_budget_shows_the_scalp_and_collider(clean, monkeypatch):
    preview = ext_module(clean, "preview")
    progressive = ext_module(clean, "progressive")
    scalp = head_scene(size=32)
    import bmesh
    mesh = bpy.data.meshes.new("Floor")
    bm = bmesh.new()
    bmesh.ops.create_grid(bm, x_segments=20, y_segments=20, size=1.0)
    bm.to_mesh(mesh)
    bm.free()
    floor = bpy.data.objects.new("Floor", mesh)
    bpy.context.scene.collection.objects.link(floor)
    floor.location.z = -0.2
    scalp_triangles = len(mesh_arrays(scalp)[1])
    assert bpy.ops.hair.render_preview() == {'FINISHED'}
    # The scalp (its own collider) first, then the others.
    assert [m[3] for m in progressive.current().meshes.meshes] == ["Scalp", "Floor"]
    assert progressive.current().note is None
    monkeypatch.setattr(preview, "MESH_TRIANGLE_BUDGET", scalp_triangles + 100)
    assert bpy.ops.hair.render_preview() == {'FINISHED'}
    session = progressive.current()
    assert [m[3] for m in session.meshes.meshes] == ["Scalp"]
    assert session.meshes.skipped == sum(len(p.vertices) - 2 for p in floor.data.polygons) > 100
    assert "scalp and its collider only" in session.note


def rmse(a, b):
    return float(np.sqrt(np.mean((np.asarray(a, np.float64) - b) ** 2)))


@pytest.mark.parametrize("samples", ['1', '4'])
def test_the_preview_refines_towards_the_many_sample_image(clean, samples):
    from tracer import RenderSettings, Renderer
    preview = ext_module(clean, "preview")
    progressive = ext_module(clean, "progressive")
    scalp = head_scene(size=48)
    scalp.keystrand_hair.preview_samples = samples
    scene = bpy.context.scene
    assert bpy.ops.hair.render_preview() == {'FINISHED'}
    session = progressive.current()
    first = image_pixels()
    spp = int(scalp.keystrand_hair.preview_samples)
    assert (session.samples, session.passes) == (spp, 1)
    assert progressive.status(scalp) == f"Refining: {spp} of {progressive.TARGET_SAMPLES} samples per pixel"
    # The reference: the tracer's own stratified samples (other positions than the passes'),
    # four times as many as the refinement reaches, so its own error stays below the one measured.
    h, w = first.shape[:2]
    renderer = Renderer()
    renderer.set_strands(preview.world_strands(scalp.keystrand_hair.hair_object))
    renderer.set_meshes(session.meshes.meshes)
    rs = preview.render_settings(scene, scalp.keystrand_hair)
    reference = renderer.render(preview.camera_for(scene, scene.camera, (w, h)),
                                RenderSettings(**{**rs.__dict__, "spp": 4 * progressive.TARGET_SAMPLES}))
    states, errors = [], [rmse(first, reference)]
    while True:
        state = progressive.step()
        if state != "refined":
            break
        states.append(state)
        errors.append(rmse(image_pixels(), reference))
    assert state == "converged" and session.samples >= progressive.TARGET_SAMPLES
    # The refinement passes take the pixel sampler's 25 samples (the hair is opaque).
    refine = rs.refinement(True)
    assert (refine.sampler, refine.spp) == ("pixel", 25)
    total, passes = spp, 0
    while total < progressive.TARGET_SAMPLES:
        total, passes = total + refine.spp, passes + 1
    assert len(states) == passes and session.samples == total
    assert errors[0] > 0.01, "the first image is already the reference: nothing to refine"
    # The passes' mean approaches the reference: both estimate the same pixel areas.
    assert errors[-1] < 0.5 * errors[0], errors     # passes of the same samples again would stay at 1.0
    assert errors[len(errors) // 4] < errors[0]
    assert progressive.step() == "converged"
    assert progressive.status(scalp) == f"Refined: {session.samples} samples per pixel"


def test_the_preview_starts_over_when_the_camera_a_setting_or_the_hair_changes(clean):
    preview = ext_module(clean, "preview")
    progressive = ext_module(clean, "progressive")
    scalp = head_scene(size=32)
    scene = bpy.context.scene
    hair = scalp.keystrand_hair.hair_object
    assert bpy.ops.hair.render_preview() == {'FINISHED'}
    session = progressive.current()
    for _ in range(3):
        assert progressive.step() == "refined"
    assert session.passes == 4

    def fresh():
        pixels, _ = preview.render(scene, hair, scene.camera, scalp.keystrand_hair, meshes=session.meshes)
        return pixels

    # The camera moves: a first image from the new place.
    scene.camera.location.x += 0.02
    bpy.context.view_layer.update()
    assert progressive.step() == "restarted"
    assert session.passes == 1 and session.starts == 2
    np.testing.assert_array_equal(image_pixels(), fresh())
    assert progressive.step() == "refined"
    # A preview setting changes.
    scalp.keystrand_hair.preview_shadows = not scalp.keystrand_hair.preview_shadows
    assert progressive.step() == "restarted"
    np.testing.assert_array_equal(image_pixels(), fresh())
    # A key moves and the hair is grown again.
    assert progressive.step() == "refined"
    key = next(o for o in bpy.data.objects if o.keystrand_hair.role == 'KEY')
    key.data.splines[0].bezier_points[-1].co.z += 0.01
    activate(scalp)
    assert bpy.ops.hair.generate() == {'FINISHED'}
    assert progressive.step() == "restarted"
    np.testing.assert_array_equal(image_pixels(), fresh())
    # Nothing changes: it carries on refining.
    assert progressive.step() == "refined" and session.passes == 2
    # The image is removed: the refinement ends.
    bpy.data.images.remove(bpy.data.images["Hair Preview"])
    assert progressive.step() == "stopped" and progressive.current() is None


def test_with_the_renderer_process_a_step_does_not_wait_for_the_pass(clean, monkeypatch):
    import os
    import signal
    import time
    preview = ext_module(clean, "preview")
    progressive = ext_module(clean, "progressive")
    scalp = head_scene(size=48)
    scene = bpy.context.scene
    hair = scalp.keystrand_hair.hair_object
    monkeypatch.setenv("KEYSTRAND_PREVIEW_IN_PROCESS", "0")
    try:
        assert bpy.ops.hair.render_preview() == {'FINISHED'}
        session = progressive.current()
        assert type(preview.current_renderer()).__name__ == "WorkerClient"
        # The pass is sent and the step returns without its image: the process is held
        # stopped meanwhile, so it cannot have drawn it, however the two are scheduled (a
        # step that waited for the image would not return).
        worker = preview.current_renderer()
        os.kill(worker.pid, signal.SIGSTOP)
        try:
            assert progressive.step() == "waiting" and session.passes == 1
        finally:
            os.kill(worker.pid, signal.SIGCONT)
        deadline = time.monotonic() + 60
        state = "waiting"
        while state == "waiting" and time.monotonic() < deadline:
            time.sleep(0.02)
            state = progressive.step()
        assert state == "refined" and session.passes == 2
        # The mean of the first image and the refinement pass, each weighted by its samples.
        passes = [preview.render(scene, hair, scene.camera, scalp.keystrand_hair, meshes=session.meshes,
                                 sample_pass=k, refine=k > 0) for k in (0, 1)]
        (p0, t0), (p1, t1) = passes
        assert (t0["spp"], t1["spp"]) == (1, 25) and session.samples == 26
        np.testing.assert_allclose(image_pixels(), (p0 * t0["spp"] + p1 * t1["spp"]) / 26, atol=1e-6)
        # A change while a pass is drawn: the owed image is dropped, the new first image shown.
        os.kill(worker.pid, signal.SIGSTOP)
        try:
            assert progressive.step() == "waiting"
        finally:
            os.kill(worker.pid, signal.SIGCONT)
        scene.camera.location.x += 0.02
        bpy.context.view_layer.update()
        state = progressive.step()
        deadline = time.monotonic() + 60
        while (state == "waiting" or (state == "restarted" and session.pending is not None)) \
                and time.monotonic() < deadline:
            time.sleep(0.02)
            state = progressive.step()
        assert session.starts == 2 and session.passes == 1
        fresh, _ = preview.render(scene, hair, scene.camera, scalp.keystrand_hair, meshes=session.meshes)
        np.testing.assert_array_equal(image_pixels(), fresh)
    finally:
        progressive.stop()
        preview.close()


def test_the_preview_follows_the_world_and_the_suns_strength(clean):
    """Under the physically based shading with the scene's lights, the world's colour is the
    ambient light: a brighter world restarts the refinement and lifts every pixel the head
    covers by its base colour times the world's radiance, as a diffuse surface that nothing
    shades; a sun's strength restarts it too."""
    progressive = ext_module(clean, "progressive")
    scalp = head_scene(size=32)
    s = scalp.keystrand_hair
    s.preview_scene_lights, s.preview_shading = True, "chiang"
    scene = bpy.context.scene
    kept = scene.world
    try:
        scene.world = bpy.data.worlds.new("Studio")
        if bpy.app.version < (5, 0, 0):
            scene.world.use_nodes = True
        background = next(n for n in scene.world.node_tree.nodes if n.bl_idname == "ShaderNodeBackground")
        background.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
        background.inputs["Strength"].default_value = 0.0
        sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", 'SUN'))
        scene.collection.objects.link(sun)
        sun.data.energy = 2.0
        activate(scalp)
        assert bpy.ops.hair.render_preview() == {'FINISHED'}
        dark = image_pixels()
        assert progressive.step() == "refined"
        background.inputs["Strength"].default_value = 0.25
        assert progressive.step() == "restarted"
        lit = image_pixels()
        lift = lit[..., :3] - dark[..., :3]
        head_only = np.all(np.abs(lift - 0.25 * np.asarray(HEAD_RGB)) < 2e-3, axis=-1)
        covered = dark[..., 3] > 0.999
        assert head_only.sum() > 0.2 * covered.sum(), (head_only.sum(), covered.sum())
        assert np.all(lift[covered] > -1e-4)          # nothing darker under more light
        assert progressive.step() == "refined"
        sun.data.energy = 3.0
        assert progressive.step() == "restarted"
    finally:
        scene.world = kept

# SPDX-License-Identifier: GPL-3.0-or-later
"""Every failure is a readable report and leaves the scene exactly as it was."""
import importlib

import pytest
import bpy

from blender_scene import activate, make_camera, make_scalp, scene_snapshot


def run_failing(op, match, **kwargs):
    """Run an operator expected to fail; return its message. bpy.ops turns an ERROR report
    (or a failed poll with its message) into a RuntimeError for a script caller."""
    before = scene_snapshot()
    with pytest.raises(RuntimeError, match=match) as info:
        op(**kwargs)
    assert scene_snapshot() == before, "the failed operator changed the scene"
    return str(info.value)


def keyed_scalp():
    scalp = make_scalp()
    for p in [(0.0, 0.0, 0.1), (0.07, 0.0, 0.07)]:
        activate(scalp)
        bpy.ops.hair.add_key_strand(location=p)
    activate(scalp)
    scalp.keystrand_hair.count = 200
    return scalp


@pytest.mark.parametrize("op", ["generate", "add_key_strand", "render_preview", "load_preset"])
def test_no_scalp_is_reported(clean, op):
    cam = make_camera()
    activate(cam)  # a camera is not a scalp
    run_failing(getattr(bpy.ops.hair, op), "Select a scalp mesh")
    activate(None)
    run_failing(getattr(bpy.ops.hair, op), "Select a scalp mesh")


def test_scalp_without_faces_is_reported(clean):
    mesh = bpy.data.meshes.new("Points")
    mesh.from_pydata([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [(0, 1)], [])
    obj = bpy.data.objects.new("Points", mesh)
    bpy.context.scene.collection.objects.link(obj)
    activate(obj)
    run_failing(bpy.ops.hair.add_key_strand, "no faces", location=(0, 0, 0))
    run_failing(bpy.ops.hair.generate, "no faces")
    run_failing(bpy.ops.hair.load_preset, "no faces", preset='wavy')


def test_no_key_strands_is_reported(clean):
    make_scalp()
    run_failing(bpy.ops.hair.generate, "no key strands")


def test_no_camera_is_reported(clean):
    keyed_scalp()
    bpy.ops.hair.generate()
    run_failing(bpy.ops.hair.render_preview, "no camera")


def test_no_hair_yet_is_reported(clean):
    keyed_scalp()
    make_camera()
    activate(bpy.data.objects["Scalp"])
    run_failing(bpy.ops.hair.render_preview, "Generate")
    run_failing(bpy.ops.hair.export, "Generate", filepath="/nonexistent/x.npz")


def test_bad_settings_are_reported(clean):
    scalp = keyed_scalp()
    scalp.keystrand_hair.min_length = 0.9
    scalp.keystrand_hair.max_length = 0.5
    run_failing(bpy.ops.hair.generate, "min_length")


class _DyingRenderer:
    """Stands in for a worker whose process has died: every call fails like a broken pipe."""

    def set_strands(self, strands):
        raise BrokenPipeError("worker process exited")

    def render(self, camera, settings):
        raise BrokenPipeError("worker process exited")

    def close(self):
        pass


def test_dead_worker_is_reported_and_replaced_on_the_next_render(clean):
    preview = importlib.import_module(f"{clean.__name__}.addon.preview")
    scalp = keyed_scalp()
    scalp.keystrand_hair.preview_size = 32
    bpy.ops.hair.generate()
    make_camera()
    activate(scalp)
    in_process = preview.in_process_requested(scalp.keystrand_hair)
    preview._renderer, preview._renderer_in_process, preview._uploaded = _DyingRenderer(), in_process, None
    message = run_failing(bpy.ops.hair.render_preview, "renderer stopped")
    assert "press Render Preview again" in message
    assert preview.current_renderer() is None
    assert bpy.ops.hair.render_preview() == {'FINISHED'}
    assert "Hair Preview" in bpy.data.images

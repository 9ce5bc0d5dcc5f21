# SPDX-License-Identifier: GPL-3.0-or-later
"""Hostile input through the extension's operators: a preset file of the wrong shape, a
count that cannot fit in memory, an export path that is a folder, a preview larger than
the GPU draws. Each is reported as the user's to fix, and the scene and the files are
left as they were."""
import json

import bpy
import pytest

from blender_scene import activate, files_snapshot, make_camera, make_scalp, scene_snapshot


def _refused(op, match, folder=None, **kwargs):
    before, files = scene_snapshot(), folder and files_snapshot(folder)
    with pytest.raises(RuntimeError, match=match) as info:
        op(**kwargs)
    assert scene_snapshot() == before
    if folder is not None:
        assert files_snapshot(folder) == files
    assert "Internal error" not in str(info.value)
    return str(info.value)


def _keyed_scalp(count=200):
    scalp = make_scalp()
    for p in [(0.0, 0.0, 0.1), (0.07, 0.0, 0.07)]:
        activate(scalp)
        bpy.ops.hair.add_key_strand(location=p)
    activate(scalp)
    scalp.keystrand_hair.count = count
    return scalp


@pytest.mark.parametrize("text,match", [
    ('{"params": {}, "keys": 5}', "'keys' must be a list"),
    ('{"params": {}, "keys": ' + "[" * 100000 + "]" * 100000 + "}", "cannot read it as JSON"),
    (json.dumps({"params": {"count": 1.5}, "keys": []}), "count"),
])
def test_a_preset_file_of_the_wrong_shape_is_reported(clean, tmp_path, text, match):
    _keyed_scalp()
    path = tmp_path / "hostile.json"
    path.write_text(text)
    _refused(bpy.ops.hair.load_preset, match, folder=tmp_path, filepath=str(path))


def test_a_count_that_cannot_fit_in_memory_is_reported(clean):
    _keyed_scalp(count=10 ** 9)
    message = _refused(bpy.ops.hair.generate, "GiB of memory")
    assert "1,000,000,000" in message


def test_export_to_a_folder_is_reported_and_writes_nothing(clean, tmp_path):
    _keyed_scalp()
    assert bpy.ops.hair.generate() == {'FINISHED'}
    (tmp_path / "hair.npz").mkdir()
    _refused(bpy.ops.hair.export, "is a folder", folder=tmp_path, filepath=str(tmp_path / "hair.npz"), format='npz')


def test_a_preview_wider_than_the_gpu_draws_is_reported(clean):
    scalp = _keyed_scalp()
    assert bpy.ops.hair.generate() == {'FINISHED'}
    bpy.context.scene.camera = make_camera()
    activate(scalp)
    scalp.keystrand_hair.preview_size = 40000
    _refused(bpy.ops.hair.render_preview, "pixels a side")

# SPDX-License-Identifier: GPL-3.0-or-later
"""Render Preview: the scene camera's view of the generated hair, by the tracer.

The renderer is kept alive between renders (one per Blender session): by default a
tracer.worker.WorkerClient, whose GPU work runs in a separate process so a driver fault
cannot take Blender down; in-process (tracer.Renderer) when the scalp's settings or the
KEYSTRAND_PREVIEW_IN_PROCESS environment variable ask for it. Strands are read and
uploaded only when they changed: every write of the hair and every depsgraph update of a
hair Curves datablock bumps its revision (see `bump`), so moving the camera re-renders
without reading or re-uploading anything.
"""
import os
import time

import numpy as np
import bpy
from hairio import InputError, Strands

from . import blender_curves
from .transaction import transaction

IMAGE_NAME = "Hair Preview"


class RendererDied(Exception):
    """The preview renderer failed in a way that is not a bad-input message."""


_renderer = None
_renderer_in_process = None
_uploaded = None
_revisions = {}


def bump(curves):
    """Note that a Curves datablock's strands changed (the next preview re-uploads)."""
    _revisions[curves.session_uid] = _revisions.get(curves.session_uid, 0) + 1


def _upload_key(hair_obj):
    m = np.array(hair_obj.matrix_world, np.float64)
    return (hair_obj.data.session_uid, _revisions.get(hair_obj.data.session_uid, 0), m.tobytes())


def in_process_requested(settings):
    return settings.preview_in_process or os.environ.get("KEYSTRAND_PREVIEW_IN_PROCESS", "") not in ("", "0")


def get_renderer(in_process):
    """The cached renderer of the requested kind, started on first use."""
    global _renderer, _renderer_in_process, _uploaded
    if _renderer is not None and _renderer_in_process == in_process:
        return _renderer
    close()
    if in_process:
        from tracer import Renderer
        _renderer = Renderer()
    else:
        from tracer.worker import WorkerClient
        _renderer = WorkerClient()
    _renderer_in_process = in_process
    _uploaded = None
    return _renderer


def close():
    """Stop the renderer (the worker process exits); the next render starts a new one."""
    global _renderer, _renderer_in_process, _uploaded
    renderer, _renderer, _renderer_in_process, _uploaded = _renderer, None, None, None
    if renderer is not None:
        closer = getattr(renderer, "close", None)
        if closer is not None:
            try:
                closer()
            except Exception:
                pass  # already dead: nothing left to release


def current_renderer():
    return _renderer


def camera_for(scene, camera_obj, size):
    """tracer.Camera matching a Blender camera object's view at `size` (W, H)."""
    from tracer import Camera
    cam = camera_obj.data
    return Camera.from_blender(np.array(camera_obj.matrix_world, np.float64), size,
                               type='ORTHO' if cam.type == 'ORTHO' else 'PERSP',
                               lens=cam.lens, sensor_width=cam.sensor_width,
                               sensor_height=cam.sensor_height, sensor_fit=cam.sensor_fit,
                               shift_x=cam.shift_x, shift_y=cam.shift_y, ortho_scale=cam.ortho_scale)


def preview_size(scene, settings):
    """(W, H): the settings' width, the height following the scene's render aspect."""
    r = scene.render
    aspect = (r.resolution_y * r.pixel_aspect_y) / max(1e-9, r.resolution_x * r.pixel_aspect_x)
    w = int(settings.preview_size)
    return w, max(1, int(round(w * aspect)))


def scene_lights(scene):
    """The scene's sun and point lights as tracer.Light (at most 8), or () for none."""
    from tracer import Light
    from tracer.settings import MAX_LIGHTS
    lights = []
    for obj in scene.objects:
        if obj.type != 'LIGHT' or obj.hide_render or obj.data.type not in ('SUN', 'POINT'):
            continue
        m = np.array(obj.matrix_world, np.float64)
        if obj.data.type == 'SUN':
            lights.append(Light("directional", tuple(-m[:3, 2]), tuple(obj.data.color), 1.0))
        else:
            lights.append(Light("point", tuple(m[:3, 3]), tuple(obj.data.color), 1.0))
        if len(lights) == MAX_LIGHTS:
            break
    return tuple(lights)


def render_settings(scene, settings):
    """tracer.RenderSettings from the scalp's preview settings."""
    from tracer import RenderSettings
    kwargs = dict(spp=int(settings.preview_samples), shadows=settings.preview_shadows,
                  shadow_mode=settings.preview_shadow_mode, layers=settings.preview_layers,
                  shading=settings.preview_shading, min_pixel_width=settings.preview_min_pixel_width)
    lights = scene_lights(scene) if settings.preview_scene_lights else ()
    if lights:
        kwargs["lights"] = lights
    return RenderSettings(**kwargs)


def world_strands(hair_obj):
    """The hair object's strands in world space (points by its matrix, radii by its mean scale)."""
    s = blender_curves.curves_to_strands(hair_obj)
    m = np.array(hair_obj.matrix_world, np.float64)
    if np.allclose(m, np.eye(4)):
        return s
    points, radius = blender_curves.transform_strand_arrays(s.points, s.radius, m)
    return Strands.from_arrays(points, s.counts, radius, s.color, s.alpha, s.wisp)


def render(scene, hair_obj, camera_obj, settings):
    """Render the preview; returns ((H, W, 4) float32 linear RGBA, row 0 = top; timings).
    Raises hairio.InputError for bad settings and RendererDied when the renderer failed
    (it is then closed, so the next call starts a fresh one)."""
    global _uploaded
    t0 = time.perf_counter()
    size = preview_size(scene, settings)
    camera = camera_for(scene, camera_obj, size)
    rs = render_settings(scene, settings)
    rs.check()
    t1 = time.perf_counter()
    try:
        renderer = get_renderer(in_process_requested(settings))
        key = _upload_key(hair_obj)
        uploaded = False
        if key != _uploaded:
            renderer.set_strands(world_strands(hair_obj))
            _uploaded = key
            uploaded = True
        t2 = time.perf_counter()
        image = renderer.render(camera, rs)
    except InputError:
        raise
    except Exception as e:
        close()
        raise RendererDied(f"{type(e).__name__}: {e}") from e
    t3 = time.perf_counter()
    image = np.asarray(image, np.float32)
    if image.shape != (size[1], size[0], 4):
        close()
        raise RendererDied(f"renderer returned an image of shape {image.shape}, expected {(size[1], size[0], 4)}")
    return image, {"prepare_s": t1 - t0, "upload_s": t2 - t1, "render_s": t3 - t2, "uploaded": uploaded}


def write_image(pixels):
    """Put (H, W, 4) top-row-first linear RGBA into the image "Hair Preview" with one
    foreach_set; returns the image.

    All or nothing: an image of another size or kind is replaced by a new one only when the
    whole change commits (the new one then takes its name and users), and an image filled in
    place gets its old pixels back on rollback."""
    h, w = pixels.shape[:2]
    # Blender stores rows bottom-up.
    flat = np.ascontiguousarray(pixels[::-1], np.float32).ravel()
    with transaction() as tx:
        image = bpy.data.images.get(IMAGE_NAME)
        if image is not None and image.size[0] == w and image.size[1] == h and image.is_float:
            old = np.empty(len(image.pixels), np.float32)
            image.pixels.foreach_get(old)
            tx.undo(lambda: _fill_image(image, old))
            target = image
        else:
            target = bpy.data.images.new(IMAGE_NAME, w, h, alpha=True, float_buffer=True)
            if image is not None:
                tx.on_commit(lambda: _replace_image(image, target))
        _fill_image(target, flat)
    return target


def _fill_image(image, flat):
    image.pixels.foreach_set(flat)
    image.update()


def _replace_image(old, new):
    old.user_remap(new)
    bpy.data.images.remove(old)
    new.name = IMAGE_NAME


def show_image(context, image):
    """Show the image in an Image Editor: one of the open windows' if there is one, else a
    new window turned into an Image Editor. True when it is shown (never in background mode)."""
    wm = context.window_manager
    for window in (wm.windows if wm is not None else ()):
        for area in window.screen.areas:
            if area.type == 'IMAGE_EDITOR':
                area.spaces.active.image = image
                area.tag_redraw()
                return True
    if bpy.app.background or context.window is None:
        return False
    before = set(wm.windows[:])
    if bpy.ops.wm.window_new() != {'FINISHED'}:
        return False
    for window in wm.windows:
        if window not in before:
            area = max(window.screen.areas, key=lambda a: a.width * a.height)
            area.type = 'IMAGE_EDITOR'
            area.spaces.active.image = image
            return True
    return False

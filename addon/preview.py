# SPDX-License-Identifier: GPL-3.0-or-later
"""Render Preview: the scene camera's view of the generated hair, by the tracer.

The renderer is kept alive between renders (one per Blender session): by default a
tracer.worker.WorkerClient, whose GPU work runs in a separate process so a driver fault
cannot take Blender down; in-process (tracer.Renderer) when the scalp's settings or the
KEYSTRAND_PREVIEW_IN_PROCESS environment variable ask for it. Strands are read and
uploaded only when they changed: every write of the hair and every depsgraph update of a
hair Curves datablock bumps its revision (see `bump`), so moving the camera re-renders
without reading or re-uploading anything.

Beside the hair the preview shows the scene's meshes as a render would (the scalp, its
collider and the other visible meshes: scene_data.scene_meshes), opaque and shaded with
their base colour, so the head hides the hair behind it and shadows fall on and from it.
They are uploaded when their arrays changed; a scene of more than MESH_TRIANGLE_BUDGET
triangles shows only the scalp and collider, and the operator says so. Under the physically
based shading with the scene's lights, the world lights the preview too: a world of one
colour is the ambient term (world_radiance), so a black world gives no ambient light, as in
Cycles, and a grey one its radiance. A scene without lights keeps the tracer's default
lighting, key light and ambient term both.

One image is one pass of the settings' samples; `render(..., sample_pass=k)` shifts every
sample of pass k by the same sub-pixel offset (tracer.Camera.for_pass, a low-discrepancy
sequence over the pixel, or over one stratum of it with several samples), so the passes the
progressive preview (progressive.py) averages are new samples of the pixel's area, not the
same ones again.

The refinement passes after the first image (`refine=True`) take their samples with the
pixel sampler (tracer.RenderSettings(sampler="pixel"): a pixel's samples share one walk), as
many as it keeps without losing layers (tracer.RenderSettings.refinement): on opaque hair
5² = 25 samples a pass for about three times one sample's time, so the image has no dust
after one refinement pass instead of fifteen (docs/DECISIONS.md, "The preview refines with
the pixel sampler").
"""
import contextlib
import hashlib
import os
import time
from dataclasses import replace

import numpy as np
import bpy
from hairio import InputError, Strands

from . import blender_curves, hair_material, scene_data
from .transaction import transaction

IMAGE_NAME = "Hair Preview"
# Triangles the preview draws at most beside the hair; past it, the scalp and collider only.
# A million triangles take about a second to grid and upload on a CPU driver, and a scene
# that big (a character, a set) is rarely what the hair preview is for.
MESH_TRIANGLE_BUDGET = 1_000_000


class RendererDied(Exception):
    """The preview renderer failed in a way that is not a bad-input message."""


_renderer = None
_renderer_in_process = None
_uploaded = None
_uploaded_opaque = False     # every alpha of the uploaded strands is 1 (RenderSettings.refinement)
_uploaded_meshes = None
_revisions = {}


def bump(curves):
    """Note that a Curves datablock's strands changed (the next preview re-uploads)."""
    _revisions[curves.session_uid] = _revisions.get(curves.session_uid, 0) + 1


def upload_key(hair_obj):
    """What decides the hair's upload: its Curves, their revision and the object's matrix."""
    m = np.array(hair_obj.matrix_world, np.float64)
    return (hair_obj.data.session_uid, _revisions.get(hair_obj.data.session_uid, 0), m.tobytes())


def in_process_requested(settings):
    return settings.preview_in_process or os.environ.get("KEYSTRAND_PREVIEW_IN_PROCESS", "") not in ("", "0")


def get_renderer(in_process):
    """The cached renderer of the requested kind, started on first use."""
    global _renderer, _renderer_in_process, _uploaded, _uploaded_meshes
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
    _uploaded = _uploaded_meshes = None
    return _renderer


def close():
    """Stop the renderer (the worker process exits); the next render starts a new one."""
    global _renderer, _renderer_in_process, _uploaded, _uploaded_meshes
    renderer, _renderer, _renderer_in_process, _uploaded, _uploaded_meshes = _renderer, None, None, None, None
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


def scene_lights(scene, physical=False):
    """The scene's lights as tracer.Light (at most 8), or () for none.
    `physical` (the "chiang" shading, which then matches Cycles): each as Cycles lights with it,
    its power times 2^Exposure (Blender 5.0's Exposure): a sun's Strength is its irradiance
    (W/m²); a point light's Power P radiates P / 4 pi W/sr, a spot light's the same within its
    cone (Spot Size, Blend); an area light's P / pi along its axis, times the cosine from it
    (times its area when Normalize is off); all three falling off with the square of the
    distance. Their extent as Cycles samples it, so their shadows are soft: a sun's Angle, a
    point or spot light's Radius, an area light's Shape and Size (tracer.Light).
    Else every light at intensity 1, without fall-off or cone (the thesis's constant light).
    A light whose Cast Shadow is off casts none in the preview either."""
    from tracer import Light
    from tracer.settings import MAX_LIGHTS, blender_light
    lights = []
    for obj in scene.objects:
        if obj.type != 'LIGHT' or obj.hide_render or obj.data.type not in ('SUN', 'POINT', 'SPOT', 'AREA'):
            continue
        data, m = obj.data, np.array(obj.matrix_world, np.float64)
        along, across = _light_axes(m)
        position, axis, rgb = tuple(m[:3, 3]), tuple(along), tuple(data.color)
        power = float(data.energy) * 2.0 ** float(getattr(data, "exposure", 0.0))
        shadows = bool(data.use_shadow)
        if not physical:
            lights.append(Light("directional", axis, rgb, 1.0, shadows=shadows) if data.type == 'SUN'
                          else Light("point", position, rgb, 1.0, shadows=shadows))
        elif data.type == 'SUN':
            lights.append(blender_light('SUN', power, axis, rgb, shadows=shadows,
                                        angle=min(float(data.angle), SUN_ANGLE_MAX)))
        elif data.type in ('POINT', 'SPOT'):
            lights.append(blender_light(data.type, power, position, rgb, axis=axis, shadows=shadows,
                                        radius=float(data.shadow_soft_size),
                                        spot_size=float(getattr(data, "spot_size", np.pi)),
                                        spot_blend=float(getattr(data, "spot_blend", 0.0))))
        else:
            width, height = _area_light_size(data, m)
            ellipse = data.shape in ('DISK', 'ELLIPSE')
            if not getattr(data, "normalize", True):        # Blender 5.0: Power per square metre
                power *= width * height * (np.pi / 4.0 if ellipse else 1.0)
            lights.append(blender_light('AREA', power, position, rgb, axis=axis, shadows=shadows,
                                        size=(width, height), tangent=tuple(across),
                                        shape="ellipse" if ellipse else "rectangle"))
        if len(lights) == MAX_LIGHTS:
            break
    return tuple(lights)


# The widest sun the preview samples: Blender takes up to 180°, where the disk of directions
# (radius tan(angle / 2)) is infinite.
SUN_ANGLE_MAX = float(np.radians(179.0))


def _light_axes(m):
    """The unit directions a light shines along (its -Z) and an area light's width lies along
    (its X) from its world matrix `m`, each rebuilt from the other two axes where a scale of 0
    flattened it away."""
    x, y, z = m[:3, 0], m[:3, 1], m[:3, 2]

    def unit(v, fallback):
        n = np.linalg.norm(v)
        if n > 0.0:
            return v / n
        f = np.linalg.norm(fallback)
        return fallback / f if f > 0.0 else np.array([0.0, 0.0, 1.0])
    return -unit(z, np.cross(x, y)), unit(x, np.cross(y, z))


def _area_light_size(data, m):
    """An area light's width and height in world units: its Size (and Size Y for a rectangle
    or an ellipse) times its object's X and Y scale."""
    x = float(data.size)
    y = float(data.size_y) if data.shape in ('RECTANGLE', 'ELLIPSE') else x
    return x * float(np.linalg.norm(m[:3, 0])), y * float(np.linalg.norm(m[:3, 1]))


# Rec. 709 luminance: Blender's default scene-linear colour space.
LUMINANCE = (0.2126, 0.7152, 0.0722)


def world_radiance(scene):
    """The light the scene's world gives the physically based shading: (rgb, note). A world of
    one colour (a Background node with its Color and Strength unlinked, or a world without
    nodes) is an even environment of radiance colour × strength, whose luminance is the
    preview's ambient term (render_settings): a diffuse surface nothing shades sends base colour
    × that radiance, which is what the ambient term computes. No world, or a node tree whose
    output gets nothing, gives Cycles no light: (0, 0, 0). A world lit by more than a colour (a
    texture, a sky, a mix) is not summed here: rgb None (the tracer's default ambient stands)
    and a note that says so."""
    world = scene.world
    if world is None:
        return (0.0, 0.0, 0.0), None
    uses_nodes = world.use_nodes if bpy.app.version < (5, 0, 0) else True    # 5.0: always, and deprecated
    tree = world.node_tree if uses_nodes else None
    if tree is None:
        return tuple(max(0.0, float(c)) for c in world.color[:3]), None
    outputs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputWorld"]
    out = next((n for n in outputs if n.is_active_output), outputs[0] if outputs else None)
    surface = None if out is None else out.inputs.get("Surface")
    if surface is None or not surface.is_linked:
        return (0.0, 0.0, 0.0), None
    node = surface.links[0].from_node
    color, strength = node.inputs.get("Color"), node.inputs.get("Strength")
    if node.bl_idname != "ShaderNodeBackground" or color.is_linked or strength.is_linked:
        from tracer import RenderSettings
        return None, (f"The world {world.name!r} gives more than one colour of light ({node.name!r} feeds its "
                      f"output): the preview lights the hair with its own ambient "
                      f"{RenderSettings().ambient:g}, not the world's")
    k = max(0.0, float(strength.default_value))
    return tuple(max(0.0, float(c)) * k for c in color.default_value[:3]), None


def lights_note(scene, settings):
    """What the operator says when the scene has more lights than the preview takes, or None."""
    from tracer.settings import MAX_LIGHTS
    if not settings.preview_scene_lights:
        return None
    n = sum(1 for obj in scene.objects if obj.type == 'LIGHT' and not obj.hide_render)
    if n <= MAX_LIGHTS:
        return None
    return (f"The scene has {n} lights; the preview takes the first {MAX_LIGHTS} of them "
            "(hide the others from renders to choose which)")


def world_note(scene, settings):
    """What the operator says when the world's light cannot be the preview's ambient, or None."""
    if settings.preview_shading != "chiang" or not settings.preview_scene_lights or not scene_lights(scene):
        return None
    return world_radiance(scene)[1]


def _luminance(rgb):
    return float(sum(w * float(c) for w, c in zip(LUMINANCE, tuple(rgb)[:3])))


def render_settings(scene, settings, hair_obj=None):
    """tracer.RenderSettings from the scalp's preview settings (and, for the "chiang"
    shading, the hair object's Principled Hair BSDF, the lights' strengths and, where the
    scene's lights light the preview, the world's light as the ambient term: world_radiance)."""
    from tracer import RenderSettings
    kwargs = dict(spp=int(settings.preview_samples), shadows=settings.preview_shadows,
                  shadow_mode=settings.preview_shadow_mode, layers=settings.preview_layers,
                  shading=settings.preview_shading, min_pixel_width=settings.preview_min_pixel_width)
    physical = settings.preview_shading == "chiang"
    if physical and hair_obj is not None:
        kwargs.update(hair_material.principled_hair_settings(hair_obj))
    lights = scene_lights(scene, physical=physical) if settings.preview_scene_lights else ()
    if lights:
        kwargs["lights"] = lights
        # The world is one of the scene's lights: its radiance's luminance is the ambient term
        # (docs/DECISIONS.md says why not an environment light sampled with shadow rays); a
        # scene without lights gets the tracer's whole default lighting (key light and ambient).
        rgb = world_radiance(scene)[0] if physical else None
        if rgb is not None:
            kwargs["ambient"] = _luminance(rgb)
    return RenderSettings(**kwargs)


def world_strands(hair_obj):
    """The hair object's strands in world space (points by its matrix, radii by its mean scale)."""
    s = blender_curves.curves_to_strands(hair_obj)
    m = np.array(hair_obj.matrix_world, np.float64)
    if np.allclose(m, np.eye(4)):
        return s
    points, radius = blender_curves.transform_strand_arrays(s.points, s.radius, m)
    return Strands.from_arrays(points, s.counts, radius, s.color, s.alpha, s.wisp)


def scene_meshes(context, scalp):
    """scene_data.SceneMeshes the preview of `scalp`'s hair shows (MESH_TRIANGLE_BUDGET)."""
    return scene_data.scene_meshes(context.scene, context.view_layer, context.evaluated_depsgraph_get(),
                                   scalp, MESH_TRIANGLE_BUDGET)


def budget_note(meshes):
    """What the operator says when the budget left meshes out, or None."""
    if meshes is None or not meshes.skipped:
        return None
    return (f"The scene's meshes have {meshes.triangles + meshes.skipped:,} triangles, more than the preview's "
            f"{MESH_TRIANGLE_BUDGET:,}: it shows the scalp and its collider only "
            "(hide other meshes from renders to see them)")


def _meshes_key(meshes):
    """A digest of the meshes' arrays and colours: equal keys, nothing to upload."""
    h = hashlib.sha1()
    for vertices, triangles, rgb, name in meshes:
        for a in (vertices, triangles, np.asarray(rgb, np.float64)):
            h.update(np.ascontiguousarray(a).tobytes())
        h.update(str((vertices.shape, triangles.shape, name)).encode())
    return h.hexdigest()


def render(scene, hair_obj, camera_obj, settings, meshes=None, sample_pass=0, refine=False):
    """Render the preview; returns ((H, W, 4) float32 linear RGBA, row 0 = top; timings).
    meshes: scene_data.SceneMeshes shown beside the hair (None: the hair alone);
    sample_pass: which pass of samples (tracer.Camera.for_pass); refine: a refinement pass
    (RenderSettings.refinement; timings["spp"] says how many samples it took). Raises
    hairio.InputError for bad settings and RendererDied when the renderer failed (it is then
    closed, so the next call starts a fresh one)."""
    return begin_render(scene, hair_obj, camera_obj, settings, meshes, sample_pass, refine=refine).result()


def begin_render(scene, hair_obj, camera_obj, settings, meshes=None, sample_pass=0, wait=True, refine=False,
                 refine_to=0):
    """As render, but returns a PendingImage. With wait=False and the renderer process, the
    render runs while Blender goes on (uploads, rare, are still waited for); in process it
    is done on return either way. refine_to: the samples a pixel that refinement passes after
    this first image are to reach (RenderSettings.samples_to_come: what the first image
    builds for the scene is sized for their rays too)."""
    global _uploaded, _uploaded_meshes, _uploaded_opaque
    t0 = time.perf_counter()
    size = preview_size(scene, settings)
    rs = render_settings(scene, settings, hair_obj)
    rs.check()
    view = camera_for(scene, camera_obj, size)
    mesh_list = [] if meshes is None else meshes.meshes
    if meshes is not None and meshes.digest is None:
        meshes.digest = _meshes_key(mesh_list)     # once per reading, not once per refinement pass
    mesh_key = _meshes_key(mesh_list) if meshes is None else meshes.digest
    t1 = time.perf_counter()
    with _renderer_failures():
        renderer = get_renderer(in_process_requested(settings))
        key = upload_key(hair_obj)
        uploaded = False
        if key != _uploaded:
            strands = world_strands(hair_obj)
            renderer.set_strands(strands)
            _uploaded = key
            _uploaded_opaque = bool(strands.alpha is None or not len(strands.alpha) or strands.alpha.min() >= 1.0)
            uploaded = True
        if mesh_key != _uploaded_meshes:
            # Forgotten first: a refused mesh leaves the renderer's meshes unknown.
            _uploaded_meshes = None
            renderer.set_meshes(mesh_list or None)
            _uploaded_meshes = mesh_key
            uploaded = True
        if refine:
            rs = rs.refinement(_uploaded_opaque)
        elif refine_to > rs.spp:
            rs = replace(rs, samples_to_come=int(refine_to - rs.spp))
        camera = view.for_pass(sample_pass, rs.spp_n)
        t2 = time.perf_counter()
        timings = {"prepare_s": t1 - t0, "upload_s": t2 - t1, "uploaded": uploaded, "spp": rs.spp}
        if not wait and hasattr(renderer, "render_begin"):
            renderer.render_begin(camera, rs)
            return PendingImage(size, timings, renderer=renderer)
        t3 = time.perf_counter()
        image = renderer.render(camera, rs)
        timings["render_s"] = time.perf_counter() - t3
    return PendingImage(size, timings, image=image)


@contextlib.contextmanager
def _renderer_failures():
    """InputError passes; any other failure of the renderer closes it and is RendererDied."""
    try:
        yield
    except InputError:
        raise
    except Exception as e:
        close()
        raise RendererDied(f"{type(e).__name__}: {e}") from e


class PendingImage:
    """A preview image being drawn: ready() says, without waiting, whether result() has it;
    result() -> ((H, W, 4) float32, timings), raising as render does."""

    def __init__(self, size, timings, image=None, renderer=None):
        self.size, self.timings = size, timings
        self._image, self._renderer = image, renderer
        self._t0 = time.perf_counter()

    def ready(self):
        return self._image is not None or self._renderer.render_ready()

    def result(self):
        if self._image is None:
            with _renderer_failures():
                self._image = self._renderer.render_end()
        self.timings.setdefault("render_s", time.perf_counter() - self._t0)
        image = np.asarray(self._image, np.float32)
        w, h = self.size
        if image.shape != (h, w, 4):
            close()
            raise RendererDied(f"renderer returned an image of shape {image.shape}, expected {(h, w, 4)}")
        return image, self.timings


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

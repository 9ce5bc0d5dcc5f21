# SPDX-License-Identifier: GPL-3.0-or-later
"""The progressive preview: Render Preview shows its first image at once, then a timer adds
one pass of samples at a time (preview.begin_render with sample_pass = 1, 2, ...: new
sub-pixel positions each pass; refine=True: the pixel sampler's many samples a pass where
the settings allow, tracer.RenderSettings.refinement) and shows the running mean in the
image, each pass weighted by its samples, until TARGET_SAMPLES samples per pixel; a change
of what the image shows (the hair, a key's regrown wisps, the camera, a preview setting, the
meshes, the lights) starts it over from a first image.

With the renderer process (the default) a tick never waits for it: it sends a pass
(WorkerClient.render_begin) and returns, and a later tick collects the image once it has
come, so Blender stays responsive however long a pass takes; a new first image after a change
comes the same way. In process (Render Inside Blender) a tick draws its pass before it
returns. Only the press of Render Preview waits, for its first image. While no Image Editor
shows the preview (and a window could), the timer only watches for changes and renders
nothing.

`step()` is one tick without the timer, so the refinement can be driven and tested in
background mode, where Blender runs no timers.
"""
import numpy as np
import bpy
from bpy.app.handlers import persistent
from hairio import InputError

from . import app_handlers, hair_material, preview, scene_data
from .properties import RENDER_FIELDS
from .transaction import clear_background, report_background, transaction

# Samples per pixel the refinement stops at (the benchmark's reference counts as many).
TARGET_SAMPLES = 64
REFINE_INTERVAL_S = 0.02   # between passes: the UI's events run in between
WATCH_INTERVAL_S = 0.3     # once converged, or while hidden: how often changes are looked for
TASK = "Preview refinement"


class Session:
    """The refinement of one preview: what it shows and the samples summed so far."""

    def __init__(self, scalp, hair, camera):
        self.scalp, self.hair, self.camera = scalp, hair, camera
        self.signature = None
        self.sum = None            # (H, W, 4) float64 sum of passes, each times its samples
        self.samples = 0           # samples per pixel in `sum`
        self.passes = 0            # passes in `sum` since the last start
        self.starts = 0            # how many times it started over
        self.note = None           # the mesh budget's note of the last start, or None
        self.meshes = None         # scene_data.SceneMeshes of the last start
        self.pending = None        # preview.PendingImage of the pass being drawn
        self.pending_first = False  # whether it is a first image (the sums start over with it)

    def image(self):
        return (self.sum / self.samples).astype(np.float32)


_session = None


def current():
    """The running Session, or None."""
    return _session


def status(scalp):
    """A line for the panel while `scalp`'s preview is refined, else None."""
    session = _session
    if session is None or session.scalp != scalp:
        return None
    if session.samples >= TARGET_SAMPLES:
        return f"Refined: {session.samples} samples per pixel"
    return f"Refining: {session.samples} of {TARGET_SAMPLES} samples per pixel"


def signature(context, session):
    """Everything the preview's pixels depend on, cheaply: the preview settings, the image
    size, the camera and its lens, the hair (its revision, see preview.bump), the scene's
    lights (their strength too), the world's light and the hair material's sliders, and the
    meshes' objects, places and data with the scene's geometry edits (counted by
    on_depsgraph_update)."""
    scene, s = context.scene, session.scalp.keystrand_hair
    settings = tuple(_value(getattr(s, name)) for name in RENDER_FIELDS)
    cam = session.camera
    lens = tuple(_value(getattr(cam.data, a)) for a in
                 ("type", "lens", "sensor_width", "sensor_height", "sensor_fit", "shift_x", "shift_y", "ortho_scale"))
    r = scene.render
    size = (r.resolution_x, r.resolution_y, r.pixel_aspect_x, r.pixel_aspect_y)
    lights = preview.scene_lights(scene, physical=True)      # all a light gives the preview, any shading
    shading = (preview.world_radiance(scene), hair_material.principled_hair_settings(session.hair))
    own, others = scene_data.preview_mesh_objects(scene, context.view_layer, session.scalp)
    meshes = tuple((o.name, _matrix(o), o.data.session_uid) for o in own + others)
    return (settings, size, _matrix(cam), lens, scene.camera == cam, preview.upload_key(session.hair),
            lights, shading, meshes, _geometry_edits)


def _value(v):
    return tuple(v) if hasattr(v, "__len__") and not isinstance(v, str) else v


def _matrix(obj):
    return np.array(obj.matrix_world, np.float64).tobytes()


def start(context, scalp, hair, camera):
    """Render the first image of a new refinement and, when the press it is part of commits
    (transaction.py), let it replace the running one and start the timer; returns the
    Session. Raises what preview.render raises."""
    session = Session(scalp, hair, camera)
    with transaction() as tx:
        _restart(context, session)
        tx.on_commit(lambda: _begin(session))
    return session


def _begin(session):
    global _session
    _session = session
    if not bpy.app.background and not bpy.app.timers.is_registered(_tick):
        bpy.app.timers.register(_tick, first_interval=REFINE_INTERVAL_S)


def _restart(context, session, wait=True):
    """A first image: one pass at the settings' samples, the sums started over when it comes
    (at once with wait, else when a later step finds it ready)."""
    # The meshes first: reading them evaluates the depsgraph, whose pending updates (an edited
    # world or material) bump _geometry_edits, so the signature after them is the image's.
    session.meshes = preview.scene_meshes(context, session.scalp)
    session.signature = signature(context, session)
    s = session.scalp.keystrand_hair
    notes = (preview.budget_note(session.meshes), preview.lights_note(context.scene, s),
             preview.world_note(context.scene, s))
    session.note = ". ".join(n for n in notes if n) or None
    session.starts += 1
    session.pending, session.pending_first = _begin_pass(context, session, 0, wait), True
    if wait:
        _collect(session)


def _begin_pass(context, session, k, wait=False):
    return preview.begin_render(context.scene, session.hair, session.camera, session.scalp.keystrand_hair,
                                meshes=session.meshes, sample_pass=k, wait=wait, refine=k > 0,
                                refine_to=TARGET_SAMPLES)


def _collect(session):
    """Add the finished pass to the sums (or start them with it) and show the mean."""
    pending, first = session.pending, session.pending_first
    session.pending = None
    pixels, timings = pending.result()
    spp = timings["spp"]        # the pass's own: refinement passes may take more (RenderSettings.refinement)
    if first:
        session.sum, session.samples, session.passes = pixels.astype(np.float64) * spp, spp, 1
        preview.write_image(pixels)
    else:
        session.sum += pixels.astype(np.float64) * spp
        session.samples += spp
        session.passes += 1
        preview.write_image(session.image())


def step(context=None):
    """One tick, which never waits for the renderer process: start over when what the image
    shows changed, else add one pass of samples until TARGET_SAMPLES. Returns "restarted"
    (a new first image was asked for; shown when it is ready, at once in process), "refined"
    (a pass was added), "waiting" (a pass is being drawn), "converged", or "stopped" (no
    session, or its objects, camera or image are gone)."""
    context = context or bpy.context
    session = _session
    if session is None:
        return "stopped"
    if not _alive(context, session):
        stop()
        return "stopped"
    if signature(context, session) != session.signature:
        _restart(context, session, wait=False)
        if session.pending.ready():
            _collect(session)
        return "restarted"
    if session.pending is None:
        if session.samples >= TARGET_SAMPLES:
            return "converged"
        session.pending, session.pending_first = _begin_pass(context, session, session.passes), False
    if not session.pending.ready():
        return "waiting"
    first = session.pending_first
    _collect(session)
    return "restarted" if first else "refined"


def _alive(context, session):
    try:
        objects = (session.scalp, session.hair, session.camera)
        names = [o.name for o in objects]      # a removed object's reference fails here
    except ReferenceError:
        return False
    return (all(bpy.data.objects.get(n) == o for n, o in zip(names, objects))
            and preview.IMAGE_NAME in bpy.data.images and context.scene.camera == session.camera)


def _shown(context):
    """False only when windows exist and none has an Image Editor showing the preview."""
    wm = context.window_manager
    windows = list(wm.windows) if wm is not None else []
    if not windows:
        return True
    return any(area.type == 'IMAGE_EDITOR' and area.spaces.active.image is not None
               and area.spaces.active.image.name == preview.IMAGE_NAME
               for w in windows for area in w.screen.areas)


def _tick():
    session = _session
    if session is None:
        return None
    context = bpy.context
    if not _shown(context):
        return WATCH_INTERVAL_S
    try:
        state = step(context)
    except preview.RendererDied as e:
        stop()
        report_background(session.scalp, TASK, InputError(
            f"the preview renderer stopped ({e}); press Render Preview to start a new one"))
        return None
    except Exception as e:      # InputError: the user's to fix; anything else: a bug
        stop()
        report_background(session.scalp, TASK, e)
        return None
    if state == "stopped":
        return None
    clear_background(session.scalp, TASK)
    _redraw_image_editors(context)
    return WATCH_INTERVAL_S if state == "converged" else REFINE_INTERVAL_S


def _redraw_image_editors(context):
    wm = context.window_manager
    for window in (wm.windows if wm is not None else ()):
        for area in window.screen.areas:
            if area.type == 'IMAGE_EDITOR':
                area.tag_redraw()


def stop():
    """End the refinement (the image keeps what it has)."""
    global _session
    _session = None
    if bpy.app.timers.is_registered(_tick):
        bpy.app.timers.unregister(_tick)


# Mesh and material edits the signature cannot see from objects alone (a vertex moved in
# Edit Mode, a Base Color changed) bump this count.
_geometry_edits = 0
_WATCHED = (bpy.types.Mesh, bpy.types.Material, bpy.types.NodeTree)


@persistent
def on_depsgraph_update(scene, depsgraph):
    global _geometry_edits
    if _session is None:
        return
    for update in depsgraph.updates:
        ident = update.id.original if update.id is not None else None
        if isinstance(ident, _WATCHED) or (isinstance(ident, bpy.types.Object) and update.is_updated_geometry
                                           and ident.type == 'MESH'):
            _geometry_edits += 1
            return


@persistent
def on_load(*_args):
    stop()


HANDLERS = ((bpy.app.handlers.depsgraph_update_post, on_depsgraph_update),
            (bpy.app.handlers.load_pre, on_load))


def register():
    app_handlers.add(HANDLERS)


def unregister():
    app_handlers.remove(HANDLERS)
    stop()

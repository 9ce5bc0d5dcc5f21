# SPDX-License-Identifier: GPL-3.0-or-later
"""See the wisps: an overlay that colours the generated hair by wisp (the key strand each
hair follows) and highlights the active key's wisp, so the artist sees what a key controls.

The colours are a pure function of the strands' wisp ids (`strand_colors`, testable without
a GPU); the drawing is a `gpu` draw handler over the 3D viewport, added while the Hair tab's
Show Wisps is on (never in background mode, which has no GPU drawing). The strands' batch is
made once per change of the hair (live update and Generate note each one, see
preview.bump) and only recoloured when the active key changes.
"""
import numpy as np
import bpy
from bpy.props import BoolProperty

from . import blender_curves, preview
from .hair import existing_hair
from .scene_data import find_scalp, key_objects

# Colours are spread around the hue circle by the golden angle, so neighbouring keys (and
# any few of them) differ clearly whatever their number.
GOLDEN = 0.6180339887498949
SATURATION, VALUE = 0.65, 0.95
# With a key active, its wisp is drawn opaque and lightened toward white, the others darkened
# toward a dim grey and see-through: where hundreds of hairs overlap, alpha alone adds back up
# to opaque (docs/DECISIONS.md, "Wisp overlay").
DIM_MIX, DIM_GREY, DIM_ALPHA = 0.7, 0.15, 0.35
HIGHLIGHT_MIX = 0.35
LOST = (0.5, 0.5, 0.5, 0.5)   # a hair whose key no longer exists (deleted since Generate)


def wisp_palette(n):
    """(n, 3) float32 RGB: wisp i's colour (golden-angle hues, equal saturation and value)."""
    h = (np.arange(n) * GOLDEN) % 1.0
    i = np.floor(h * 6.0).astype(np.int64) % 6
    f = h * 6.0 - np.floor(h * 6.0)
    v, s = VALUE, SATURATION
    p, q, t = v * (1 - s), v * (1 - s * f), v * (1 - s * (1 - f))
    table = np.stack([np.stack(c, 1) for c in ((np.full(n, v), t, np.full(n, p)),
                                                (q, np.full(n, v), np.full(n, p)),
                                                (np.full(n, p), np.full(n, v), t),
                                                (np.full(n, p), q, np.full(n, v)),
                                                (t, np.full(n, p), np.full(n, v)),
                                                (np.full(n, v), np.full(n, p), q))])
    return table[i, np.arange(n)].astype(np.float32)


def strand_colors(wisp, n_keys, active=None):
    """(S, 4) float32 RGBA per strand from its wisp id (S,): the wisp's palette colour; with
    an active key index, that wisp highlighted and the others dimmed. Ids outside
    [0, n_keys) (a key deleted since) are grey."""
    wisp = np.asarray(wisp, np.int64)
    palette = np.concatenate([wisp_palette(n_keys), np.ones((n_keys, 1), np.float32)], 1)
    valid = (wisp >= 0) & (wisp < n_keys)
    out = np.empty((len(wisp), 4), np.float32)
    out[:] = LOST
    out[valid] = palette[wisp[valid]]
    if active is not None and 0 <= active < n_keys:
        mine = wisp == active
        others = ~mine & valid
        out[others, :3] = (1 - DIM_MIX) * out[others, :3] + DIM_MIX * DIM_GREY
        out[others, 3] = DIM_ALPHA
        out[mine, :3] = (1 - HIGHLIGHT_MIX) * out[mine, :3] + HIGHLIGHT_MIX
        out[mine, 3] = 1.0
    return out


def point_colors(counts, colors):
    """Per-strand colours (S, 4) repeated for each strand's points: (P, 4)."""
    return np.repeat(np.asarray(colors, np.float32), np.asarray(counts, np.int64), axis=0)


def segment_indices(counts):
    """(P - S, 2) uint32 point pairs of every strand's segments (a LINES batch)."""
    counts = np.asarray(counts, np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    first = np.arange(int(counts.sum()), dtype=np.int64)
    last_of_strand = np.zeros(len(first), bool)
    last_of_strand[starts + counts - 1] = True
    a = first[~last_of_strand]
    return np.stack([a, a + 1], 1).astype(np.uint32)


# --- drawing ---------------------------------------------------------------------------

_handle = None
_cache = {}   # "strands": (key, strands); "batch": (key, active, n_keys, batch)


def _hair_key(hair):
    return (hair.data.session_uid, preview._revisions.get(hair.data.session_uid, 0), len(hair.data.points))


def draw_hair(hair, n_keys, active, viewport_size):
    """Draw a hair object's strands in wisp colours into the current GPU frame buffer (its
    view and projection set by the caller: the viewport's, in the draw handler)."""
    import gpu
    from gpu_extras.batch import batch_for_shader
    key = _hair_key(hair)
    cached = _cache.get("strands")
    if cached is None or cached[0] != key:
        cached = _cache["strands"] = (key, blender_curves.curves_to_strands(hair))
        _cache.pop("batch", None)
    strands = cached[1]
    if strands.num_strands == 0:
        return
    shader = gpu.shader.from_builtin('POLYLINE_FLAT_COLOR')
    made = _cache.get("batch")
    if made is None or made[:3] != (key, active, n_keys):
        colors = point_colors(strands.counts, strand_colors(strands.wisp, n_keys, active))
        batch = batch_for_shader(shader, 'LINES', {"pos": strands.points, "color": colors},
                                 indices=segment_indices(strands.counts))
        made = _cache["batch"] = (key, active, n_keys, batch)
    gpu.state.blend_set('ALPHA')
    gpu.state.depth_test_set('LESS_EQUAL')
    with gpu.matrix.push_pop():
        gpu.matrix.multiply_matrix(hair.matrix_world)
        shader.bind()
        shader.uniform_float("viewportSize", tuple(viewport_size))
        shader.uniform_float("lineWidth", 1.5)
        made[3].draw(shader)
    gpu.state.depth_test_set('NONE')
    gpu.state.blend_set('NONE')


def _draw():
    context = bpy.context
    if not getattr(context.window_manager, "keystrand_show_wisps", False):
        return  # switched off with a new file (a window-manager setting is not saved)
    scalp = find_scalp(context)
    hair = existing_hair(scalp) if scalp is not None else None
    if hair is None or not hair.visible_get():
        return
    keys = key_objects(scalp)
    obj = context.active_object
    draw_hair(hair, len(keys), keys.index(obj) if obj in keys else None,
              (context.region.width, context.region.height))


def _redraw_views():
    wm = bpy.context.window_manager
    for window in (wm.windows if wm is not None else ()):
        for area in window.screen.areas:
            if area.type == 'VIEW_3D':
                area.tag_redraw()


def show(on):
    """Add or remove the overlay's draw handler (nothing to draw in background mode)."""
    global _handle
    if on and _handle is None and not bpy.app.background:
        _handle = bpy.types.SpaceView3D.draw_handler_add(_draw, (), 'WINDOW', 'POST_VIEW')
    elif not on and _handle is not None:
        bpy.types.SpaceView3D.draw_handler_remove(_handle, 'WINDOW')
        _handle = None
        _cache.clear()
    _redraw_views()


def _toggle(self, context):
    show(self.keystrand_show_wisps)


def register():
    bpy.types.WindowManager.keystrand_show_wisps = BoolProperty(
        name="Show Wisps", default=False, update=_toggle,
        description="Colour the generated hair by the key strand each hair follows, and highlight the "
                    "active key's hairs")


def unregister():
    show(False)
    del bpy.types.WindowManager.keystrand_show_wisps

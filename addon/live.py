# SPDX-License-Identifier: GPL-3.0-or-later
"""Live update: regrow only the wisps of the key strands being edited.

A depsgraph handler notes which scalps had a key strand change; a timer does the work
outside the handler (writing the hair from inside a depsgraph update would re-enter it).
While edits keep arriving, a lighter generator at the scalp's viewport count is used;
once edits have stopped for SETTLE_S, the full-count generator catches up on a worker
thread, again only for the keys that changed (groom.Generator.update_keys), and the
result is written when it is done. The timer's next interval grows with the time the last
update took, so the viewport stays responsive on 100,000 strands.

Besides the keys, two things decide the hair and change without a key edit: the head's axes
in the mesh (with Head Axes 'Scene', turning the scalp object turns them) and where the
collider is relative to the scalp. Both are compared on every scene update, and a change
regrows the hair (the collider is then read again). The scalp's mesh and the collider's
mesh themselves are read by Generate.
"""
import threading
import time

import bpy
from bpy.app.handlers import persistent

from . import app_handlers, generator_cache, hair, preview, scene_data
from .generator_cache import forget, state_of, states
from .properties import groom_params
from .transaction import clear_background, forget_background, report_background

SETTLE_S = 0.4
MIN_INTERVAL_S = 0.05
TASK = "Live update"

_pending = set()
_timer_on = False
_last_cost = 0.0


def _scalp_by_uid(uid):
    for obj in bpy.data.objects:
        if obj.session_uid == uid:
            return obj
    return None


def _update(gen, sig, old_sig, keys, scalp_data, params, collider, stale=False):
    """(generator, GroomResult or None when nothing changed). Pure groom work: no bpy, so
    it may run on a worker thread. stale: the collider changed since `gen` was built."""
    from groom import Generator
    from groom.keys import changed_keys
    changed = changed_keys(sig, old_sig)
    if gen is not None and (stale or gen.params.to_dict() != params.to_dict()):
        gen = None  # settings, axes or collider changed since it was built: start over with them
    if changed is None or gen is None:
        gen = Generator(scalp_data, keys, params, collider=collider)
        return gen, gen.generate()
    if not changed:
        return gen, None
    return gen, gen.update_keys({i: keys[i] for i in changed})


def process(now=None, settle=False):
    """Do the pending live updates now. settle=True also runs the full-count catch-up
    (used when edits have stopped, and by scripts that need the final hair at once).
    Returns the number of hair objects written. What goes wrong is noted for the panel
    (transaction.report_background) and the last good hair stays."""
    from groom.keys import keys_signature
    now = time.monotonic() if now is None else now
    written = 0
    for uid in list(_pending):
        _pending.discard(uid)
        state = state_of(uid)
        scalp = _scalp_by_uid(uid)
        if state is None or scalp is None or hair.existing_hair(scalp) is None:
            continue
        settings = scalp.keystrand_hair
        view_count = min(settings.viewport_count, settings.count)
        try:
            # Mid-edit states (a key with one point, all keys deleted) are bad input: the
            # panel says why the hair waits.
            keys = scene_data.read_keys(scalp)
            sig = keys_signature(keys)
            _refresh_scene(scalp, state)
            if view_count >= settings.count:
                if state.catchup is not None:
                    _pending.add(uid)  # the full generator is busy: come back next tick
                    continue
                state.full, result = _update(state.full, sig, state.full_sig, keys, state.scalp_data,
                                             groom_params(settings), state.collider,
                                             state.full_version != state.collider_version)
                state.full_sig, state.full_version = sig, state.collider_version
                if result is not None:
                    state.full_result = result
            else:
                state.view, result = _update(state.view, sig, state.view_sig, keys, state.scalp_data,
                                             groom_params(settings, view_count), state.collider,
                                             state.view_version != state.collider_version)
                state.view_sig, state.view_version = sig, state.collider_version
                if result is not None:
                    state.dragging = True
        except Exception as e:  # the last good hair stays
            report_background(scalp, TASK, e)
            continue
        clear_background(scalp, TASK)
        if result is not None:
            gen = state.full if view_count >= settings.count else state.view
            hair.write_hair(scalp, hair.groom_strands(gen, result), result.root_uv)
            state.last_edit = now
            written += 1
    for uid, state in states():
        if state.catchup is not None:
            written += _finish_catch_up(uid, state, wait=settle)
        if state.dragging and state.catchup is None and (settle or now - state.last_edit >= SETTLE_S):
            _start_catch_up(uid, state)
            if settle:
                written += _finish_catch_up(uid, state, wait=True)
    return written


def _refresh_scene(scalp, state):
    """Note the scene_signature the hair is about to be grown with; the collider is read
    again when its signature changed (the generators built with the old one then start
    over: see collider_version)."""
    axes, collider_sig = generator_cache.scene_signature(scalp)
    if collider_sig != state.scene_sig[1]:
        depsgraph = bpy.context.evaluated_depsgraph_get()
        state.collider = hair.read_collider(scalp, depsgraph, state.scalp_data)
        state.collider_version += 1
    state.scene_sig = (axes, collider_sig)


def _start_catch_up(uid, state):
    """Bring the full-count hair up to date with the keys after an edit, on a worker thread
    (groom is numpy and mostly releases the GIL), so the UI keeps running meanwhile. The scene
    is read here, on the main thread; the thread touches only the generator."""
    from groom.keys import keys_signature
    state.dragging = False
    scalp = _scalp_by_uid(uid)
    if scalp is None or hair.existing_hair(scalp) is None:
        return
    try:
        keys = scene_data.read_keys(scalp)
        params = groom_params(scalp.keystrand_hair)
    except Exception as e:
        report_background(scalp, TASK, e)
        return
    sig = keys_signature(keys)
    box = {}
    collider, version = state.collider, state.collider_version
    stale = state.full_version != version

    def work():
        try:
            box["gen"], box["result"] = _update(state.full, sig, state.full_sig, keys, state.scalp_data, params,
                                                collider, stale)
        except Exception as e:  # reported on the main thread
            box["error"] = e

    thread = threading.Thread(target=work, name="keystrand-hair-catch-up", daemon=True)
    state.catchup = (thread, box, sig, version)
    thread.start()


def _finish_catch_up(uid, state, wait=False):
    """Write the catch-up's result once its thread is done; returns 1 when hair was written."""
    thread, box, sig, version = state.catchup
    if wait:
        thread.join()
    if thread.is_alive():
        return 0
    state.catchup = None
    if "error" in box:
        scalp = _scalp_by_uid(uid)
        if scalp is not None:
            report_background(scalp, TASK, box["error"])
        return 0
    state.full, state.full_sig, state.full_version = box["gen"], sig, version
    # None: keys are back where they were; the view generator changed the hair object,
    # so the last full-count hair goes back.
    result = box["result"] if box["result"] is not None else state.full_result
    state.full_result = result
    scalp = _scalp_by_uid(uid)
    if state.dragging or scalp is None or hair.existing_hair(scalp) is None:
        return 0  # a newer drag is on screen; its own catch-up follows
    hair.write_hair(scalp, hair.groom_strands(state.full, result), result.root_uv)
    return 1


def _tick():
    global _timer_on, _last_cost
    start = time.monotonic()
    process(start)
    _last_cost = time.monotonic() - start
    if _pending or any(s.dragging or s.catchup is not None for _uid, s in states()):
        # Leave the UI at least as much time as the update took.
        return max(MIN_INTERVAL_S, 1.5 * _last_cost)
    _timer_on = False
    return None


def _key_scalps(depsgraph):
    """Scalps whose key strands or scene_signature changed; also notes edited hair for the
    preview."""
    uids = set()
    objects_changed = False
    for update in depsgraph.updates:
        ident = update.id.original if update.id is not None else None
        if isinstance(ident, bpy.types.Curves):
            preview.bump(ident)  # sculpted or edited hair: the next preview re-uploads
        elif isinstance(ident, bpy.types.Object):
            objects_changed = True
            s = ident.keystrand_hair
            if s.role == 'KEY' and s.scalp is not None:
                uids.add(s.scalp.session_uid)
            elif s.role == 'SCALP':
                # Moved, turned or its settings changed: process() tells what that changes.
                uids.add(ident.session_uid)
        elif isinstance(ident, bpy.types.Curve):
            for obj in bpy.data.objects:
                if obj.data == ident and obj.keystrand_hair.role == 'KEY' and obj.keystrand_hair.scalp:
                    uids.add(obj.keystrand_hair.scalp.session_uid)
    if objects_changed:
        # A collider moved (or a scalp's parent, turning its axes with Head Axes 'Scene').
        for uid, state in states():
            scalp = _scalp_by_uid(uid)
            if scalp is not None and generator_cache.scene_signature(scalp) != state.scene_sig:
                uids.add(uid)
    return uids


@persistent
def on_depsgraph_update(scene, depsgraph):
    global _timer_on
    uids = {u for u in _key_scalps(depsgraph) if state_of(u) is not None}
    if not uids:
        return
    live = set()
    for uid in uids:
        scalp = _scalp_by_uid(uid)
        if scalp is not None and scalp.keystrand_hair.live_update:
            live.add(uid)
    _pending.update(live)
    if live and not _timer_on and not bpy.app.background:
        _timer_on = True
        bpy.app.timers.register(_tick, first_interval=MIN_INTERVAL_S)


def forget_all():
    """Drop every cached generator, pending update and note (a file is loaded, the
    extension disabled)."""
    forget()
    _pending.clear()
    forget_background()


@persistent
def on_load(*_args):
    forget_all()


@persistent
def on_loaded(*_args):
    """A file is loaded: its scalps' colliders are built meanwhile (hair.prebuild_colliders),
    so its first Generate does not wait for them; not in background mode, where a script
    that wants one asks at once (and a batch render wants none)."""
    if not bpy.app.background:
        hair.prebuild_colliders()


HANDLERS = ((bpy.app.handlers.depsgraph_update_post, on_depsgraph_update),
            (bpy.app.handlers.load_pre, on_load),
            (bpy.app.handlers.load_post, on_loaded))


def register_handlers():
    app_handlers.add(HANDLERS)


def unregister_handlers():
    global _timer_on
    app_handlers.remove(HANDLERS)
    if bpy.app.timers.is_registered(_tick):
        bpy.app.timers.unregister(_tick)
    _timer_on = False
    forget_all()

# SPDX-License-Identifier: GPL-3.0-or-later
"""The groom.Generators kept per scalp between presses, so a key edit regrows only the
wisps it changed.

Generate fills the cache (hair.py), live update reads and refreshes it (live.py), and
switching Live Update off or loading a file empties it (properties.py, live.py). It is the
one state those modules share, so it lives here on its own and none of them imports another
for it.
"""
from hairio import InputError

from . import head, scene_data


class ScalpState:
    """The cached generators of one scalp (keyed by the scalp object's session_uid)."""

    def __init__(self, scalp_data, keys, full, collider, scene_sig):
        from groom.keys import keys_signature
        self.scalp_data = scalp_data
        self.collider = collider               # groom.Collider or None (Collision off)
        self.collider_version = 0              # counts the colliders read since Generate
        self.scene_sig = scene_sig             # scene_signature() the hair was last grown with
        self.full = full                       # groom.Generator at the full count
        self.full_result = None                # its last GroomResult
        self.full_sig = keys_signature(keys)
        self.full_version = 0                  # collider_version `full` was built with
        self.view = None                       # groom.Generator at the viewport count
        self.view_sig = None
        self.view_version = 0
        self.dragging = False
        self.last_edit = 0.0
        self.catchup = None                    # (thread, result box, key signature, collider version)


_states = {}


def scene_signature(scalp):
    """The hair's inputs other than the keys that can change without a key edit: the head's
    axes in the mesh (None when they cannot be read) and scene_data.collider_signature."""
    try:
        axes = head.scalp_axes(scalp)
    except InputError:
        axes = None
    return axes, scene_data.collider_signature(scalp)


def remember(scalp, scalp_data, keys, generator, result, collider=None):
    """Called after a full Generate: cache its generator (grown with `collider`) for live
    updates."""
    state = ScalpState(scalp_data, keys, generator, collider, scene_signature(scalp))
    state.full_result = result
    _states[scalp.session_uid] = state


def state_of(uid):
    """The ScalpState of the scalp with this session_uid, or None."""
    return _states.get(uid)


def states():
    """(session_uid, ScalpState) of every cached scalp."""
    return list(_states.items())


def forget(scalp=None):
    """Drop one scalp's generators (every scalp's when None), once any catch-up thread that
    holds one has finished."""
    for state in (list(_states.values()) if scalp is None else [_states.get(scalp.session_uid)]):
        if state is not None and state.catchup is not None:
            state.catchup[0].join()  # the thread holds the generator; let it finish first
    if scalp is None:
        _states.clear()
    else:
        _states.pop(scalp.session_uid, None)

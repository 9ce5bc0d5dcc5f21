# SPDX-License-Identifier: GPL-3.0-or-later
"""The head a hairstyle sits on, as Blender holds it: its up and front directions in the
scalp's own space (where groom works), and presets placed on the scalp with them.

One source for the axes: Generate and live update (properties.groom_params) and Load Preset
(place_preset) both read scalp_axes, so the hairs' root frames and the keys' anchors agree.
"""
import numpy as np
from hairio import InputError


def _linear_part(obj):
    """The 3x3 of the object's world matrix; InputError when it has no inverse (a flattened
    object: no direction in its mesh points up in the scene)."""
    m = np.array(obj.matrix_world, np.float64)[:3, :3]
    size = float(np.abs(m).max())
    if not size > 0 or abs(np.linalg.det(m)) <= 1e-12 * size ** 3:
        raise InputError(f"Scalp {obj.name!r} has a zero scale on some axis, so the scene's up "
                         "and front cannot be found in its mesh: give it a non-zero scale, or "
                         "set Head Axes to Mesh and give Up and Front in the mesh's coordinates")
    return m


def scene_to_mesh(obj, directions):
    """Directions in the scene -> the same directions in the object's mesh coordinates.

    A direction d in the scene is M⁻¹d in the mesh (not Rᵀd): hair grown 'down' in the mesh
    then falls down in the scene under any scale, and an object without rotation or scale
    gets d back bit for bit (solving with the identity is exact)."""
    local = np.linalg.solve(_linear_part(obj), np.array(directions, np.float64).T)
    return tuple(tuple(float(x) for x in column) for column in local.T)


def mesh_to_scene(obj, directions):
    """Directions in the object's mesh coordinates -> the same directions in the scene."""
    world = _linear_part(obj) @ np.array(directions, np.float64).T
    return tuple(tuple(float(x) for x in column) for column in world.T)


def scalp_axes(obj):
    """(up, front) of a scalp object's head in the object's mesh coordinates, as float
    tuples: the Up and Front settings, carried from the scene into the mesh when Head Axes
    is 'WORLD', as they are when it is 'LOCAL'."""
    s = obj.keystrand_hair
    up, front = tuple(s.up), tuple(s.front)
    if s.head_axes == 'LOCAL':
        return up, front
    return scene_to_mesh(obj, (up, front))


def place_preset(preset, scalp_obj, scalp_data, collider=None):
    """A groom.Preset's keys on a scalp (groom.Placement: keys, frame, collapsed, lifted,
    warning()): the preset's anchors go through the head frame fitted to `scalp_data` (the
    groom.Scalp read from `scalp_obj`) with the scalp's own axes, the ones Generate grows
    hair with; keys that would lie inside `collider` (a groom.Collider or None: a scalp
    under its head's surface) are lifted out of it."""
    up, front = scalp_axes(scalp_obj)
    return preset.place_keys(scalp_data, up=up, front=front, collider=collider)

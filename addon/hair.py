# SPDX-License-Identifier: GPL-3.0-or-later
"""Generate: scalp + key strands -> groom -> the scalp's hair Curves object.

All model logic is groom's; this module reads the scene (scene_data), builds a
groom.Generator and writes its strands with blender_curves. The generators stay cached
per scalp (generator_cache.py) so a key edit regenerates only the affected wisps.
"""
import threading
import time

import bpy

from . import blender_curves, generator_cache, preview, scene_data
from .properties import groom_params
from .transaction import transaction


def hair_name(scalp):
    return f"{scalp.name} Hair"


def existing_hair(scalp):
    """The scalp's hair Curves object if it still exists in this file, else None."""
    hair = scalp.keystrand_hair.hair_object
    if hair is None or hair.type != 'CURVES' or hair.name not in bpy.data.objects:
        return None
    return hair


def read_inputs(scalp, depsgraph=None):
    """(groom.Scalp, [KeyStrand]) of a scalp object; InputError on bad input."""
    return scene_data.read_scalp(scalp, depsgraph), scene_data.read_keys(scalp)


def read_collider(scalp, depsgraph=None, scalp_data=None, collision=None):
    """The groom.Collider of the scalp's Collider object in the scalp's space, named after
    the object, or None when Collision is off. Made once per mesh and place (groom caches
    it: building one takes a second or two), so Generate pressed again reuses it; groom
    widens it for the hair's clearance as it does for the command line, so both grow the
    same hair. collision: as scene_data.read_collider's."""
    from groom.collide import collider_for
    mesh = scene_data.read_collider(scalp, depsgraph, scalp_data, collision)
    if mesh is None:
        return None
    vertices, triangles, name = mesh
    return collider_for(vertices, triangles, name)


def prebuild_collider(scalp, depsgraph=None, collision=None):
    """Starts building the scalp's collider on a thread of its own (groom.collide's
    prebuild_collider), so the Load Preset or Generate that follows finds it made (about a
    second on the bundled head) rather than building it then; the same thread then starts
    groom's worker processes and sends them the collider (generate.prepare_workers), which
    the first Generate would otherwise wait for. The mesh is read here, as
    read_collider reads it (Blender's data stays on this thread); nothing where collision is
    off or the collider cannot be read: the operator that needs it says why. Returns the
    thread or None."""
    from groom.collide import prebuild_collider as start
    from groom.generate import prepare_workers
    from hairio import InputError
    try:
        mesh = scene_data.read_collider(scalp, depsgraph, None, collision)
    except InputError:
        return None
    return None if mesh is None else start(*mesh, then=prepare_workers)


def prepare_workers_meanwhile(collider):
    """groom.generate.prepare_workers(collider) on a thread of its own (Load Preset has just
    made the scalp's collider: the Generate that follows then finds groom's workers started
    with it). Returns the thread, or None without a collider."""
    if collider is None:
        return None
    from groom.generate import prepare_workers

    def prepare():
        try:
            prepare_workers(collider)
        except Exception:   # noqa: BLE001 -- the Generate to come does it again, and says why
            pass
    thread = threading.Thread(target=prepare, name="groom-prepare", daemon=True)
    thread.start()
    return thread


def prebuild_colliders():
    """prebuild_collider for every scalp of the file with Collision on (a file just loaded)."""
    try:
        depsgraph = bpy.context.evaluated_depsgraph_get()
    except (AttributeError, RuntimeError):    # no context to evaluate in: the meshes as stored
        depsgraph = None
    return [prebuild_collider(obj, depsgraph) for obj in bpy.data.objects
            if obj.type == 'MESH' and obj.keystrand_hair.role == 'SCALP' and obj.keystrand_hair.collision]


def build_generator(scalp_data, keys, settings, count=None, collider=None, progress=None, replacing=None):
    """A groom.Generator and its first GroomResult; collider: a groom.Collider (read_collider)
    or None; progress: groom's progress callback or None; replacing: the scalp whose cached
    hair this result replaces, or None. That hair's generators go once the new inputs have
    passed groom's checks, before the strands grow, so the new result takes the memory of
    the old (groom.processes.recycling) rather than fresh pages beside it."""
    from groom import Generator, processes
    gen = Generator(scalp_data, keys, groom_params(settings, count), collider=collider, progress=progress)
    with processes.recycling():
        if replacing is not None:
            generator_cache.forget(replacing)
        return gen, gen.generate()


def groom_strands(generator, result):
    """The strands of a GroomResult with the guides they were interpolated with (the key
    strands, each strand's three keys and weights), which write_hair stores on the hair
    object so its exports carry them."""
    from groom.generate import strands_with_guides
    return strands_with_guides(result, generator.keys, generator.params)


def write_hair(scalp, strands, root_uv=None):
    """Write strands (scalp space) into the scalp's hair object, creating it on first use;
    root_uv: the roots' UVs on the scalp's UV map (GroomResult.root_uv), or None.
    All or nothing: a failure midway leaves the scalp, its hair and the file as they were."""
    with transaction() as tx:
        hair = existing_hair(scalp)
        tx.keep_settings(scalp)
        collection = None
        if hair is None and scalp.users_collection:
            collection = scalp.users_collection[0]
        new = hair is None
        if not new:
            tx.keep_settings(hair)
            tx.keep_transform(hair)
            tx.keep_curves(hair)
            # Its arrays are shared now (with the backup, and with the depsgraph's evaluated
            # copy): written in place, each would be copied first only to be overwritten.
            blender_curves.drop_written_attributes(hair.data)
        hair = blender_curves.strands_to_curves(hair_name(scalp), strands, collection=collection,
                                                parent=scalp, obj=hair, root_uv=root_uv)
        if new:
            blender_curves.ensure_hair_material(hair)
        hair.keystrand_hair.role = 'HAIR'
        hair.keystrand_hair.scalp = scalp
        if scalp.keystrand_hair.hair_object != hair:
            scalp.keystrand_hair.hair_object = hair
    preview.bump(hair.data)
    return hair


def generate(scalp, depsgraph=None, count=None, progress=None):
    """Full generation for a scalp object, kept out of its collider. Returns (hair object,
    GroomResult, timings dict); progress: groom's progress callback or None.

    Reads and computes everything before the first write, so an error (hairio.InputError)
    leaves the file untouched; the writes are one transaction, so an unexpected error among
    them leaves it untouched too.
    """
    settings = scalp.keystrand_hair
    t0 = time.perf_counter()
    scalp_data, keys = read_inputs(scalp, depsgraph)
    t1 = time.perf_counter()
    if progress is not None and settings.collision:
        progress(0.0, "preparing the collider")
    collider = read_collider(scalp, depsgraph, scalp_data)
    t_collider = time.perf_counter()
    gen, result = build_generator(scalp_data, keys, settings, count, collider, progress, replacing=scalp)
    gen.progress = None  # the live updates that reuse it report nothing
    t2 = time.perf_counter()
    with transaction() as tx:
        tx.keep_settings(scalp)
        if settings.role != 'SCALP':
            settings.role = 'SCALP'
        hair = write_hair(scalp, groom_strands(gen, result), result.root_uv)
    t3 = time.perf_counter()
    generator_cache.remember(scalp, scalp_data, keys, gen, result, collider)
    return hair, result, {"read_s": t1 - t0, "collider_s": t_collider - t1, "groom_s": t2 - t_collider,
                          "write_s": t3 - t2, "total_s": t3 - t0}

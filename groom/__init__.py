# SPDX-License-Identifier: GPL-3.0-or-later
"""The key-strand hair model (SPEC §1–6): numpy only, no Blender, no GL.

    from groom import default_scalp, load_preset, generate
    scalp = default_scalp()
    preset = load_preset("wavy")
    result = generate(scalp, preset.keys_on(scalp), preset.params)
    result.strands.save_npz("wavy.npz")

On a mesh of your own (here a Y-up .obj facing +Z), give the head's axes in its space:

    scalp = load_obj("scalp.obj")
    placement = preset.place_keys(scalp, up=(0, 1, 0), front=(0, 0, 1))
    print(placement.warning() or "every key has its own root")
    result = generate(scalp, placement.keys, placement.params)

Keep the hair out of the head: give the closed head mesh (the bundled scalp lies on
default_collider(), the bundled head) and read what it did:

    head = load_obj("head.obj")
    result = generate(scalp, placement.keys, placement.params,
                      collider=Collider(head.vertices, head.triangles, name="head"))
    print(result.collision.warning() or f"{result.collision.strands_moved} strands moved out")

A head too large to hold (ten million strands) grows a block at a time straight into its
file, in the memory of one block:

    summary = generate_to_npz("head.npz", scalp, placement.keys, placement.params.replace(count=10_000_000))
"""
from .scalp import Scalp, default_head, default_scalp, load_obj
from .keys import KeyStrand, place_key
from .params import GroomParams
from .generate import BlockGenerator, GroomResult, Generator, generate, generate_to_npz
from .head import HeadFrame, fit_head_frame
from .collide import Collider, default_collider
from .presets import Placement, Preset, list_presets, load_preset, save_preset

__all__ = ["Scalp", "default_head", "default_scalp", "load_obj", "KeyStrand", "place_key", "GroomParams",
           "GroomResult", "Generator", "generate", "BlockGenerator", "generate_to_npz", "HeadFrame", "fit_head_frame",
           "Collider", "default_collider",
           "Placement", "Preset", "list_presets", "load_preset", "save_preset"]

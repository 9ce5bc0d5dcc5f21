# SPDX-License-Identifier: GPL-3.0-or-later
"""The key-strand hair model (SPEC §1–6): numpy only, no Blender, no GL.

    from groom import default_scalp, load_preset, generate
    scalp = default_scalp()
    preset = load_preset("wavy")
    result = generate(scalp, preset.keys_on(scalp), preset.params)
    result.strands.save_npz("wavy.npz")
"""
from .scalp import Scalp, default_scalp, load_obj
from .keys import KeyStrand, place_key
from .params import GroomParams
from .generate import GroomResult, Generator, generate
from .presets import Preset, list_presets, load_preset, save_preset

__all__ = ["Scalp", "default_scalp", "load_obj", "KeyStrand", "place_key", "GroomParams",
           "GroomResult", "Generator", "generate", "Preset", "list_presets", "load_preset", "save_preset"]

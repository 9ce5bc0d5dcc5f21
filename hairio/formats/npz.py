# SPDX-License-Identifier: GPL-3.0-or-later
"""The interchange .npz (exactly the SPEC §0 arrays) and its JSON sidecar.

The sidecar `NAME.npz.json` says what the arrays alone cannot: units, axes, counts, the
tool and its version, and where the strands came from. Readers that only want arrays
ignore it; `read_sidecar` returns it as a dict.
"""
import json
import os

import numpy as np

from ..atomic import atomic_write
from ..strands import Strands
from ..validate import InputError
from ._common import TOOL_NAME, TOOL_VERSION, check_strands


def sidecar_path(path):
    return os.fspath(path) + ".json"


def sidecar(strands, units="m", up="Z", front="-Y", source=None, extra=None, handedness="right"):
    """The sidecar's content as a dict (JSON-ready)."""
    meta = {
        "format": "keystrand-hair strands npz",
        "arrays": list(strands.arrays()),
        "units": units,
        "axes": {"up": up, "front": front, "handedness": handedness},
        "counts": {"strands": int(strands.num_strands), "points": int(strands.num_points),
                   "segments": int(strands.num_segments)},
        "tool": {"name": TOOL_NAME, "version": TOOL_VERSION},
        "source": source,
    }
    if extra:
        meta.update(extra)
    return meta


def write_npz(path, strands, units="m", up="Z", front="-Y", source=None, extra=None, write_sidecar=True,
              handedness="right"):
    """Write the SPEC §0 arrays to `path` and the sidecar to `path`.json, atomically: both
    are complete on their temporary names before either replaces a file."""
    s = check_strands(strands)
    text = json.dumps(sidecar(s, units, up, front, source, extra, handedness), indent=2) + "\n"
    if not write_sidecar:
        s.save_npz(path)
        return
    with atomic_write(sidecar_path(path), "w") as fj, atomic_write(path) as fn:
        np.savez(fn, **s.arrays())
        fj.write(text)


# What the sidecar says of each target frame (axes.AXES) and of common scales.
FRAME_NAMES = {"none": ("Z", "-Y", "right"), "y-up": ("Y", "+Z", "right"), "unreal": ("Z", "+Y", "left"),
               "directx": ("Y", "-Z", "left")}
UNIT_NAMES = {1.0: "m", 100.0: "cm", 1000.0: "mm"}


def export_npz(path, strands, axis="none", scale=1.0, root_uv=None, units=None, source=None):
    """Write `strands` turned to `axis` and multiplied by `scale` (axes.convert_strands), with
    a sidecar naming that frame and the units (default from the scale: m, cm, mm), and
    `root_uv` (S, 2) joining the arrays when given. Returns [path, its sidecar]."""
    from .axes import convert_strands
    if root_uv is not None:
        strands = check_strands(strands).with_guides(strands.guides, root_uv)
    strands = convert_strands(check_strands(strands), axis, scale)
    scale = float(scale)
    up, front, handedness = FRAME_NAMES[axis]
    write_npz(path, strands, units=units or UNIT_NAMES.get(scale, f"{1 / scale:g} m"), up=up, front=front,
              source=source, handedness=handedness)
    return [os.fspath(path), sidecar_path(path)]


def read_npz(path):
    return Strands.load_npz(path)


def read_sidecar(path):
    """The sidecar of `path` as a dict, or None when there is none."""
    p = sidecar_path(path)
    if not os.path.exists(p):
        return None
    try:
        with open(p, encoding="utf-8") as f:
            return json.load(f)
    except (OSError, ValueError, RecursionError) as e:     # RecursionError: JSON nested too deep
        raise InputError(f"{p}: unreadable sidecar ({e}); delete or rewrite it") from e

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

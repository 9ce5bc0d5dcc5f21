# SPDX-License-Identifier: GPL-3.0-or-later
"""Strand files: read and write by extension.

    .npz   SPEC §0 arrays + NAME.npz.json sidecar    (npz.py)
    .hair  Cem Yuksel's HAIR format                  (cyhair.py)
    .tfx   AMD TressFX binary v4                     (tressfx.py)
    .data  USC-HairSalon strands                     (usc.py)
    .abc   Alembic groom for Unreal (alembic3d)      (alembic.py)
    .usd   USD groom: BasisCurves + GroomAPI (pxr)   (usd.py; also .usda, .usdc)

Every writer is atomic (hairio.atomic_write): a failed export leaves no file.
"""
import os

from ..validate import InputError
from .axes import AXES, convert_points, convert_strands
from .cyhair import read_hair, write_hair
from .npz import read_npz, read_sidecar, write_npz
from .tressfx import (VERTICES_PER_STRAND, load_tfx, loaded_strand_count, read_tfx,
                      resample_strands, resampling_error, resampling_errors, spherical_root_uv,
                      write_tfx, write_tfx_pair)
from .usc import read_usc, write_usc
from .alembic import read_abc, write_abc
from .usd import read_usd, write_usd

READERS = {"npz": read_npz, "hair": read_hair, "tfx": read_tfx, "data": read_usc, "abc": read_abc,
           "usd": read_usd}
WRITERS = {"npz": write_npz, "hair": write_hair, "tfx": write_tfx, "data": write_usc, "abc": write_abc,
           "usd": write_usd}
# Extensions that name a format other than their own.
ALIASES = {"usda": "usd", "usdc": "usd"}


def format_of(path, format=None):
    """The format name for `path`: `format` when given, else the file's extension."""
    if format is None:
        format = os.path.splitext(os.fspath(path))[1].lstrip(".")
    name = str(format).lower().lstrip(".")
    name = ALIASES.get(name, name)
    if name not in READERS:
        known = ", ".join("." + k for k in READERS)
        raise InputError(f"{path}: unknown strand file format {format!r}; use one of {known}")
    return name


def read_strands(path, format=None, **opts):
    """Strands from a .npz, .hair, .tfx, .data, .abc or .usd file (by extension or `format`)."""
    name = format_of(path, format)
    if not os.path.isfile(path):
        raise InputError(f"{path}: no such file")
    return READERS[name](path, **opts)


def write_strands(path, strands, format=None, **opts):
    """Write `strands` to `path` in `format` (default: by extension), atomically.
    Options go to the format's writer (write_npz, write_hair, write_tfx, write_usc, write_abc,
    write_usd)."""
    name = format_of(path, format)
    return WRITERS[name](path, strands, **opts)


__all__ = ["read_strands", "write_strands", "format_of", "READERS", "WRITERS", "ALIASES",
           "read_npz", "write_npz", "read_sidecar", "read_hair", "write_hair",
           "read_tfx", "write_tfx", "write_tfx_pair", "load_tfx", "loaded_strand_count",
           "resample_strands", "resampling_error", "resampling_errors", "spherical_root_uv",
           "VERTICES_PER_STRAND", "read_usc", "write_usc", "read_abc", "write_abc", "read_usd", "write_usd",
           "AXES", "convert_points", "convert_strands"]

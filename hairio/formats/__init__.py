# SPDX-License-Identifier: GPL-3.0-or-later
"""Strand files: read and write by extension. The formats are one table, `FORMATS`
(registry.py), which the command line and the Blender extension read too:

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
from .tressfx import (VERTICES_PER_STRAND, follow_hair_guides, load_tfx, loaded_strand_count,
                      padding_strands, read_tfx, resample_strands, resampling_error, resampling_errors,
                      spherical_root_uv, write_tfx, write_tfx_pair)
from .usc import read_usc, write_usc
from .alembic import read_abc, write_abc
from .usd import read_usd, write_usd
from .registry import BY_EXTENSION, BY_NAME, FORMATS, Format, format_of, get_format, with_extension


def read_strands(path, format=None, **opts):
    """Strands from a file of any format in FORMATS (by extension or `format`)."""
    fmt = format_of(path, format)
    if not os.path.isfile(path):
        raise InputError(f"{path}: no such file")
    return fmt.read(path, **opts)


def write_strands(path, strands, format=None, **opts):
    """Write `strands` to `path` in `format` (default: by extension), atomically; returns the
    files written. Options are the format's export options (registry.py), each checked."""
    fmt = format_of(path, format)
    fmt.check_options(opts)
    return fmt.export(path, strands, **opts)


__all__ = ["read_strands", "write_strands", "format_of", "get_format", "with_extension", "FORMATS", "Format",
           "BY_NAME", "BY_EXTENSION",
           "read_npz", "write_npz", "read_sidecar", "read_hair", "write_hair",
           "read_tfx", "write_tfx", "write_tfx_pair", "load_tfx", "loaded_strand_count", "padding_strands",
           "follow_hair_guides", "resample_strands", "resampling_error", "resampling_errors",
           "spherical_root_uv", "VERTICES_PER_STRAND", "read_usc", "write_usc", "read_abc", "write_abc",
           "read_usd", "write_usd", "AXES", "convert_points", "convert_strands"]

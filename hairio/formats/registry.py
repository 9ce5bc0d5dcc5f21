# SPDX-License-Identifier: GPL-3.0-or-later
"""The one table of strand file formats.

Every list of formats reads `FORMATS`: `read_strands`/`write_strands`, the command line
(`python -m groom export`: its --format choices, its option checks, its help), and the
Blender extension (the Export operator's format list, its file filter and extension, the
File > Export menu). A format is added here and nowhere else.

Each entry says what a format is (name, file extensions, label, description), how it is
read and written (`read`, `export`), which export options it takes (`options`, with the
axes its `axis` option accepts), and the library it needs beyond numpy (`library`, with the
import that tells whether it is here: `available()`).

`export(path, strands, **options)` writes the file(s) and returns the paths written. The
options are keyword arguments of the same names everywhere (the command line's --flags
with - for _):

    axis, scale              the target frame (axes.AXES, or the groom formats' y-up/z-up)
                             and a factor on points and widths (100: metres to centimetres)
    root_uv                  (S, 2) root UVs on the scalp's UV map (else those the strands carry)
    units, source            .npz sidecar: the units' name, where the strands came from
    vertices_per_strand, pinned, pin_tip, flip_v, pad_strands, shuffle_seed,
    guides, guides_out, follow_hairs   .tfx (tressfx.export_tfx)

A format refuses an option it does not take (`check_options`), so no option is silently
dropped.
"""
import math
import os
from dataclasses import dataclass, field
from typing import Callable

from ..validate import InputError
from . import alembic, cyhair, npz, tressfx, usc, usd
from ._common import check_strands
from .axes import AXES, convert_strands


@dataclass(frozen=True)
class Format:
    """One strand file format: what it is, how it is read and written, what it needs."""
    name: str                       # the --format value, e.g. "abc"
    extensions: tuple               # file extensions, the one written by default first
    label: str                      # short name for menus, e.g. "Alembic groom (.abc)"
    description: str                # one sentence for tooltips and --help
    read: Callable                  # read(path, **opts) -> Strands
    export: Callable                # export(path, strands, **options) -> [paths written]
    options: tuple = ()             # the export options it takes (names as above)
    axes: tuple = tuple(AXES)       # the values its `axis` option takes, the default first
    library: str = None             # the pip requirement it needs beyond numpy, if any
    probe: Callable = field(default=None, repr=False)   # raises InputError when `library` is missing
    frame: str = "none"             # the frame (axes.AXES) its files are in as others write
                                    # them: what `--up auto` reads them as (up_axis.py)

    @property
    def extension(self):
        """The extension a new file of this format gets (with the dot)."""
        return self.extensions[0]

    @property
    def file_filter(self):
        """Blender's filter_glob / a file dialog's pattern for this format: "*.usd;*.usda"."""
        return ";".join("*" + ext for ext in self.extensions)

    def available(self):
        """Whether its library imports here (always true for the numpy formats)."""
        if self.probe is None:
            return True
        try:
            self.probe()
        except InputError:
            return False
        return True

    def require(self):
        """Raise the InputError that says what to install when its library is missing."""
        if self.probe is not None:
            self.probe()

    def check_options(self, options):
        """Refuse options this format does not take (InputError naming each and what it takes)."""
        extra = sorted(set(options) - set(self.options))
        if extra:
            takes = ", ".join(flag(o) for o in self.options) or "no options"
            raise InputError(f"{', '.join(flag(o) for o in extra)}: .{self.name} files take no "
                             f"{'such option' if len(extra) == 1 else 'such options'}; {self.name} takes {takes}")
        axis = options.get("axis")
        if axis is not None and axis not in self.axes:
            raise InputError(f"--axis {axis}: for {self.name} choose one of {', '.join(self.axes)}")
        scale = options.get("scale")
        if scale is not None:
            try:
                value = float(scale)
            except (TypeError, ValueError):
                value = math.nan
            if not (math.isfinite(value) and value > 0):
                raise InputError(f"--scale {scale}: must be a positive number")


def flag(option):
    """The command line's flag for an export option (flip_v is turned off by --no-flip-v)."""
    return "--no-flip-v" if option == "flip_v" else "--" + option.replace("_", "-")


def _convert_then(write):
    """An export for a format that stores points as given: axis and scale applied first."""
    def export(path, strands, axis="none", scale=1.0):
        write(path, convert_strands(check_strands(strands), axis, scale))
        return [os.fspath(path)]
    export.__doc__ = f"{write.__name__} after turning the strands to `axis` and multiplying by `scale`."
    return export


def _groom_export(write):
    """An export for the groom formats: root UVs, when given, join the strands' own arrays."""
    def export(path, strands, axis=None, scale=1.0, root_uv=None):
        if root_uv is not None:
            strands = check_strands(strands).with_guides(strands.guides, root_uv)
        return write(path, strands, scale=scale, **({} if axis is None else {"axis": axis}))
    export.__doc__ = f"{write.__name__}, with `root_uv` (S, 2) as the groom's groom_root_uv."
    return export


_PLAIN = ("axis", "scale")
_GROOM = ("axis", "scale", "root_uv")

FORMATS = (
    Format("npz", (".npz",), "NumPy arrays (.npz)",
           "The strand arrays (SPEC §0) with guides and root UVs when present, and a JSON sidecar "
           "with units and axes",
           npz.read_npz, npz.export_npz, _PLAIN + ("root_uv", "units", "source")),
    Format("hair", (".hair",), "Cem Yuksel HAIR (.hair)",
           "The HAIR file of many hair renderers: points, thickness, transparency, colour",
           cyhair.read_hair, _convert_then(cyhair.write_hair), _PLAIN),
    # TressFX samples (AMD's, TressFX-OpenGL's) and USC-HairSalon's files are right-handed Y up.
    Format("tfx", (".tfx",), "AMD TressFX (.tfx)",
           "TressFX 4 binary for game engines: strands resampled to equal chords, optional guide file",
           tressfx.read_tfx, tressfx.export_tfx,
           _PLAIN + ("root_uv", "vertices_per_strand", "pinned", "pin_tip", "flip_v", "pad_strands",
                     "shuffle_seed", "guides", "guides_out", "follow_hairs"), frame="y-up"),
    Format("data", (".data",), "USC-HairSalon (.data)",
           "The USC-HairSalon strand file: points only",
           usc.read_usc, _convert_then(usc.write_usc), _PLAIN, frame="y-up"),
    Format("abc", (".abc",), "Alembic groom (.abc)",
           "Unreal's Alembic groom: widths, colours, groups, root UVs, guides and their weights",
           alembic.read_abc, _groom_export(alembic.write_abc), _GROOM, alembic.AXES,
           "alembic3d==1.8.12.1", alembic.alembic_modules),
    Format("usd", (".usd", ".usda", ".usdc"), "USD groom (.usd)",
           "USD BasisCurves under a GroomAPI prim, with the same attributes and guides as Alembic",
           usd.read_usd, _groom_export(usd.write_usd), _GROOM, usd.AXES,
           "usd-core==26.11", usd.pxr_modules),
)

BY_NAME = {f.name: f for f in FORMATS}
BY_EXTENSION = {ext: f for f in FORMATS for ext in f.extensions}


def get_format(name):
    """The Format called `name` (case and a leading dot ignored); InputError naming the choices."""
    key = str(name).lower().lstrip(".")
    fmt = BY_NAME.get(key) or BY_EXTENSION.get("." + key)
    if fmt is None:
        raise InputError(f"--format {name}: choose one of {', '.join(BY_NAME)}")
    return fmt


def format_of(path, format=None):
    """The Format of `path`: `format` (a name) when given, else the file's extension."""
    if format is not None:
        return get_format(format)
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext not in BY_EXTENSION:
        known = ", ".join(BY_EXTENSION)
        raise InputError(f"{path}: cannot tell the strand file format from {ext or 'no extension'!r}; "
                         f"use one of {known} (or pass --format)")
    return BY_EXTENSION[ext]


def with_extension(path, fmt):
    """`path` ending in one of `fmt`'s extensions: kept when it does, else the default one put in place."""
    path = os.fspath(path)
    if path.lower().endswith(fmt.extensions):
        return path
    return os.path.splitext(path)[0] + fmt.extension

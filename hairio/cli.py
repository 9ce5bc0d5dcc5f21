# SPDX-License-Identifier: GPL-3.0-or-later
"""`python -m groom export`: strands to the files game engines read.

    python -m groom export INPUT --format hair|tfx|npz|data|abc|usd --out FILE
        [--vertices-per-strand N] [--pinned K] [--pin-tip] [--guides KEYS.npz]
        [--root-uv UV.npy] [--scale S] [--axis AXIS] [--no-flip-v] [--pad-strands]
        [--shuffle-seed N] [--units U]

INPUT is any strand file we read (.npz, .hair, .tfx, .data, .abc, .usd). The .hair/.tfx/.npz/.data
writers are numpy; .abc is written with the Alembic library (alembic3d) and .usd with Pixar's
(usd-core), both as Unreal's groom schema with the guides and weights the strands carry. Where
that library is missing and Blender's Python module is here, Blender's exporter runs instead,
in a subprocess (this module never imports bpy), and writes geometry and widths only. Bad input
prints one line naming the problem, exits 2 and writes nothing.
Also runnable as `python -m hairio.cli export ...` or `python -m hairio.cli ...`.
"""
import argparse
import importlib.util
import os
import pathlib
import subprocess
import sys
import time

import numpy as np

from .atomic import check_destination
from .npyfile import read_npy
from .validate import InputError

NUMPY_FORMATS = ("hair", "tfx", "npz", "data")
# Grooms: our own writers (alembic3d, pxr), Blender's exporters where the library is missing.
BLENDER_FORMATS = ("abc", "usd")
EXTENSIONS = {".hair": "hair", ".tfx": "tfx", ".npz": "npz", ".data": "data", ".abc": "abc",
              ".usd": "usd", ".usda": "usd", ".usdc": "usd"}
BLENDER_AXES = {"abc": ("y-up", "z-up"), "usd": ("z-up", "y-up")}
UNITS = {1.0: "m", 100.0: "cm", 1000.0: "mm"}
EXPORT_SCRIPT = pathlib.Path(__file__).resolve().parents[1] / "addon" / "export_blender.py"


def export_file(input_path, out, format=None, vertices_per_strand=32, pinned=2, pin_tip=False,
                guides=None, root_uv=None, scale=1.0, axis=None, flip_v=True, pad_strands=False,
                shuffle_seed=None, units=None, guides_out=None, up="z"):
    """Export the strands in `input_path` to `out`; returns the list of files written.
    The command line's engine, callable from benchmarks. Raises InputError for bad input.
    guides and root_uv are file names here (KEYS strand file, UV.npy). `up`: z|y|auto, which
    way is up in the input (hairio/formats/up_axis.py); it is turned into our Z-up frame first."""
    from .formats import read_strands
    from .formats.up_axis import file_frame, strands_to_z_up

    out = os.fspath(out)
    format, scale, axis = _check_request(out, format, scale, axis, guides is not None)
    turned = file_frame(input_path, up) != "none"
    if format in BLENDER_FORMATS and not groom_library_available(format):
        if turned:
            raise InputError(f"--up {up}: Blender's {format} exporter reads the input as it is; export to .npz "
                             "with --up first, then from that file")
        return _export_with_blender(input_path, out, format, scale, axis, root_uv)
    strands = read_strands(input_path)
    if turned:
        strands = strands_to_z_up(strands, input_path, up)
    # Root UVs mean something to TressFX files and grooms; the others have no place for them.
    uv = _load_root_uv(root_uv, strands.num_strands) if format in ("tfx",) + BLENDER_FORMATS else None
    return export_strands(strands, out, format, vertices_per_strand, pinned, pin_tip,
                          guides=None if guides is None else read_strands(guides), root_uv=uv,
                          scale=scale, axis=axis, flip_v=flip_v, pad_strands=pad_strands,
                          shuffle_seed=shuffle_seed, units=units, guides_out=guides_out,
                          source=os.path.basename(os.fspath(input_path)))


def groom_library_available(format):
    """Whether the library that writes `format` (abc: alembic3d, usd: pxr) imports here."""
    from .formats import alembic, usd
    try:
        (alembic.alembic_modules if format == "abc" else usd.pxr_modules)()
    except InputError:
        if importlib.util.find_spec("bpy") is None:
            raise
        return False
    return True


def _check_request(out, format, scale, axis, with_guides=False):
    """(format, scale, axis) of an export request, checked; InputError names what is wrong."""
    if format is None:
        ext = os.path.splitext(out)[1].lower()
        if ext not in EXTENSIONS:
            raise InputError(f"--out {out}: cannot tell the format from {ext or 'no extension'!r}; "
                             f"pass --format {'|'.join(NUMPY_FORMATS + BLENDER_FORMATS)}")
        format = EXTENSIONS[ext]
    if format not in NUMPY_FORMATS + BLENDER_FORMATS:
        raise InputError(f"--format {format}: choose one of {', '.join(NUMPY_FORMATS + BLENDER_FORMATS)}")
    if with_guides and format != "tfx":
        raise InputError("--guides: separate guide files are a TressFX convention; use it with --format tfx "
                         "(.abc and .usd take the guides the strands carry, from groom generate)")
    # Before the work: a folder, a missing or unwritable place would fail only at the end.
    check_destination(out, f"--out {out}")
    scale = float(scale)
    if not np.isfinite(scale) or scale <= 0:
        raise InputError(f"--scale {scale}: must be a positive number")
    if format in BLENDER_FORMATS:
        axis = BLENDER_AXES[format][0] if axis is None else axis
        if axis not in BLENDER_AXES[format]:
            raise InputError(f"--axis {axis}: for {format} choose one of {', '.join(BLENDER_AXES[format])}")
    return format, scale, axis


def export_strands(strands, out, format=None, vertices_per_strand=32, pinned=2, pin_tip=False,
                   guides=None, root_uv=None, scale=1.0, axis=None, flip_v=True, pad_strands=False,
                   shuffle_seed=None, units=None, guides_out=None, source=None):
    """Write hairio.Strands to `out` (hair, tfx, npz, data, abc, usd); returns the list of
    files written. What `export_file` runs once it has read its input, and what
    Blender's Export runs on the hair it holds, so both write the same files.
    guides: key strands (tfx); root_uv: (S, 2) array or None (tfx: a spherical projection
    then; abc/usd: the groom's groom_root_uv); source: where the strands came from (the npz
    sidecar). Raises InputError."""
    from .formats import (AXES, convert_strands, spherical_root_uv, write_abc, write_hair, write_npz,
                          write_tfx, write_tfx_pair, write_usc, write_usd)
    from .formats.tressfx import guides_path_for

    out = os.fspath(out)
    format, scale, axis = _check_request(out, format, scale, axis, guides is not None)
    if format in BLENDER_FORMATS:
        if root_uv is not None:
            strands = strands.with_guides(strands.guides, root_uv)
        return (write_abc if format == "abc" else write_usd)(out, strands, axis=axis, scale=scale)
    axis = "none" if axis is None else axis
    if axis not in AXES:
        raise InputError(f"--axis {axis}: choose one of {', '.join(AXES)}")
    if format == "tfx":
        uv = root_uv
        # The projection needs the head's own up/front, so it runs before any axis change.
        if uv is None:
            uv = spherical_root_uv(strands.points[strands.offsets])
        opts = dict(vertices_per_strand=vertices_per_strand, pinned=pinned, pin_tip=pin_tip,
                    root_uv=uv, flip_v=flip_v, pad_strands=pad_strands, shuffle_seed=shuffle_seed)
        strands = convert_strands(strands, axis, scale)
        if guides is None:
            write_tfx(out, strands, **opts)
            return [out]
        key_uv = spherical_root_uv(guides.points[guides.offsets])
        keys = convert_strands(guides, axis, scale)
        return list(write_tfx_pair(out, strands, keys, guides_out or guides_path_for(out),
                                   guide_root_uv=key_uv, **opts))
    strands = convert_strands(strands, axis, scale)
    if format == "hair":
        write_hair(out, strands)
    elif format == "data":
        write_usc(out, strands)
    else:
        up = {"none": "Z", "y-up": "Y", "unreal": "Z", "directx": "Y"}[axis]
        handed = "left" if axis in ("unreal", "directx") else "right"
        write_npz(out, strands, units=units or UNITS.get(scale, f"{1 / scale:g} m"), up=up,
                  front={"none": "-Y", "y-up": "+Z", "unreal": "+Y", "directx": "-Z"}[axis],
                  source=source, handedness=handed)
        return [out, out + ".json"]
    return [out]


def _load_root_uv(path, num_strands):
    if path is None:
        return None
    uv = read_npy(path, f"--root-uv {path}")      # its header's shape checked against the file first
    if uv.shape != (num_strands, 2):
        raise InputError(f"--root-uv {path}: shape {uv.shape}, expected ({num_strands}, 2), one UV per strand")
    return uv


def _export_with_blender(input_path, out, format, scale, axis, root_uv):
    """Run addon/export_blender.py under this Python (which has the bpy module)."""
    if not os.path.isfile(input_path):
        raise InputError(f"{input_path}: no such file")
    if importlib.util.find_spec("bpy") is None:
        raise InputError(f"--format {format} needs Blender's Python module (pip install bpy) in "
                         f"{sys.executable}; or export from Blender with File > Export")
    if not EXPORT_SCRIPT.is_file():
        raise InputError(f"--format {format}: {EXPORT_SCRIPT} is missing; run from a full checkout")
    cmd = [sys.executable, str(EXPORT_SCRIPT), os.fspath(input_path), out, "--format", format,
           "--scale", repr(scale), "--axis", axis]
    if root_uv is not None:
        cmd += ["--root-uv", os.fspath(root_uv)]
    run = subprocess.run(cmd, capture_output=True, text=True)
    if run.returncode != 0:
        lines = [ln for ln in run.stderr.strip().splitlines() if ln.strip()]
        message = lines[-1] if lines else f"exit status {run.returncode}"
        raise InputError(f"{format} export failed: {message.removeprefix('error: ')}")
    return [out]


def build_parser(prog="groom export"):
    ap = argparse.ArgumentParser(prog=prog, description="Export strands for game engines and DCC tools.")
    ap.add_argument("input", help="strands: .npz (SPEC §0), .hair, .tfx, .data, .abc or .usd")
    ap.add_argument("--out", required=True, help="output file")
    ap.add_argument("--format", choices=NUMPY_FORMATS + BLENDER_FORMATS,
                    help="default: from the --out extension")
    ap.add_argument("--vertices-per-strand", type=int, default=32, metavar="N",
                    help="tfx: 4, 8, 16, 32 or 64 vertices per strand (arc-length resampling)")
    ap.add_argument("--pinned", type=int, default=2, metavar="K", help="tfx: root vertices pinned (inverse mass 0)")
    ap.add_argument("--pin-tip", action="store_true", help="tfx: also pin each tip")
    ap.add_argument("--guides", metavar="KEYS", help="tfx: key strands, written to OUT_guides.tfx")
    ap.add_argument("--guides-out", metavar="FILE", help="tfx: where the guides go")
    ap.add_argument("--root-uv", metavar="UV.npy", help="(S, 2) root UVs from the scalp's UV map")
    ap.add_argument("--scale", type=float, default=1.0, help="multiply points and widths (100: metres to cm)")
    ap.add_argument("--axis", help="hair/tfx/npz/data: none|y-up|unreal|directx (default none); "
                                   "abc: y-up|z-up (default y-up); usd: z-up|y-up (default z-up)")
    ap.add_argument("--up", choices=("z", "y", "auto"), default="z",
                    help="which way is up in INPUT: z keeps it as it is (the default), y turns a Y-up file into "
                         "our Z up first, auto does so for the formats that are Y up (TressFX .tfx, USC .data)")
    ap.add_argument("--no-flip-v", action="store_true", help="tfx: keep V as is (default flips it for DirectX)")
    ap.add_argument("--pad-strands", action="store_true", help="tfx: pad the strand count to a multiple of 64")
    ap.add_argument("--shuffle-seed", type=int, help="tfx: shuffle strands for TressFX's LOD")
    ap.add_argument("--units", help="npz sidecar: units name (default from --scale: m, cm, mm)")
    return ap


def export_main(argv=None, prog="groom export"):
    """The `export` command; returns the exit status (0 done, 2 bad input, nothing written)."""
    args = build_parser(prog).parse_args(argv)
    t0 = time.perf_counter()
    try:
        written = export_file(args.input, args.out, args.format, args.vertices_per_strand, args.pinned,
                              args.pin_tip, args.guides, args.root_uv, args.scale, args.axis,
                              not args.no_flip_v, args.pad_strands, args.shuffle_seed, args.units,
                              args.guides_out, args.up)
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        print(f"error: {args.out}: cannot write ({e})", file=sys.stderr)
        return 2
    dt = time.perf_counter() - t0
    for path in written:
        print(f"wrote {path} ({os.path.getsize(path)} bytes)")
    print(f"export took {dt:.3f} s")
    return 0


if __name__ == "__main__":
    argv = sys.argv[1:]
    if argv[:1] == ["export"]:
        argv = argv[1:]
    sys.exit(export_main(argv, prog="python -m hairio.cli export"))

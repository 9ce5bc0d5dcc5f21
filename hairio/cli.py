# SPDX-License-Identifier: GPL-3.0-or-later
"""`python -m groom export`: strands to the files game engines read.

    python -m groom export INPUT --out FILE [--format NAME] [options]

INPUT is any strand file we read; the formats, their extensions, the options each takes and
the library each needs are the one table of hairio.formats.registry (`--help` lists them).
Every format is written by hairio itself: .hair/.tfx/.npz/.data with numpy, .abc with the
Alembic library (alembic3d) and .usd with Pixar's (usd-core), both as Unreal's groom schema
with the guides and weights the strands carry; where such a library is missing the command
says what to install. Bad input (including an option the format does not take) prints one
line naming the problem, exits 2 and writes nothing.
Also runnable as `python -m hairio.cli export ...` or `python -m hairio.cli ...`.
"""
import argparse
import os
import sys
import textwrap
import time

from .atomic import check_destination
from .formats.registry import FORMATS, flag, format_of
from .formats.up_axis import UP_CHOICES
from .npyfile import read_npy
from .validate import InputError


def export_file(input_path, out, format=None, up="z", **options):
    """Export the strands in `input_path` to `out`; returns the list of files written.
    The command line's engine, callable from benchmarks. Raises InputError for bad input.
    `up`: z|y|auto, which way is up in the input (hairio/formats/up_axis.py); it is turned
    into our Z-up frame first. Options are the format's export options (registry.py);
    guides and root_uv are file names here (a KEYS strand file, a UV.npy)."""
    from .formats import read_strands
    from .formats.up_axis import file_frame, strands_to_z_up

    out = os.fspath(out)
    file_frame(input_path, up)      # a bad --up is refused before the work
    fmt = _checked(out, format, options)
    strands = strands_to_z_up(read_strands(input_path), input_path, up)
    if options.get("root_uv") is not None:
        options["root_uv"] = _load_root_uv(options["root_uv"], strands.num_strands)
    if options.get("guides") is not None:
        options["guides"] = strands_to_z_up(read_strands(options["guides"]), options["guides"], up)
    if "source" in fmt.options and options.get("source") is None:
        options["source"] = os.path.basename(os.fspath(input_path))
    return fmt.export(out, strands, **options)


def export_strands(strands, out, format=None, **options):
    """Write hairio.Strands to `out` in `format` (default: by its extension) with the
    format's export options; returns the list of files written. The same checks and writer
    as `export_file` once it has read its input: what the extension's Export runs on the
    hair it holds, so both write the same files. Raises InputError."""
    out = os.fspath(out)
    fmt = _checked(out, format, options)
    return fmt.export(out, strands, **options)


def _checked(out, format, options):
    """The Format for `out`, after refusing what it would fail on only after the work: an
    option it does not take, a missing library, a destination that cannot be written."""
    fmt = format_of(out, format)
    fmt.check_options(options)
    fmt.require()
    # Before the work: a folder, a missing or unwritable place would fail only at the end.
    check_destination(out, f"--out {out}")
    return fmt


def _load_root_uv(path, num_strands):
    uv = read_npy(path, f"--root-uv {path}")      # its header's shape checked against the file first
    if uv.shape != (num_strands, 2):
        raise InputError(f"--root-uv {path}: shape {uv.shape}, expected ({num_strands}, 2), one UV per strand")
    return uv


def _formats_epilog():
    lines = ["formats (the options each takes; the library it needs):"]
    for f in FORMATS:
        # Named, not probed: importing a groom library only to print help costs seconds.
        need = "" if f.library is None else f" Needs {f.library}."
        opts = ", ".join(flag(o) for o in f.options if o != "source")
        text = (f"{f.description}. Options: {opts} (--axis {'|'.join(f.axes)}, default {f.axes[0]}).{need}")
        lines.append(f"  {f.name:5} {', '.join(f.extensions)}:")
        lines += textwrap.wrap(text, width=88, initial_indent=" " * 8, subsequent_indent=" " * 8)
    return "\n".join(lines)


def build_parser(prog="groom export"):
    """Each export option once; which format takes which is the registry's. Options left out
    stay None, so only those given reach the format (and are checked against it)."""
    ap = argparse.ArgumentParser(prog=prog, description="Export strands for game engines and DCC tools.",
                                 epilog=_formats_epilog(), formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("input", help="strands: " + ", ".join(ext for f in FORMATS for ext in f.extensions))
    ap.add_argument("--out", required=True, help="output file")
    ap.add_argument("--format", choices=[f.name for f in FORMATS], help="default: from the --out extension")
    ap.add_argument("--vertices-per-strand", type=int, metavar="N",
                    help="tfx: 4, 8, 16, 32 (default) or 64 vertices per strand, equal chords apart")
    ap.add_argument("--pinned", type=int, metavar="K", help="tfx: root vertices pinned (inverse mass 0; default 2)")
    ap.add_argument("--pin-tip", action="store_const", const=True, help="tfx: also pin each tip")
    ap.add_argument("--guides", metavar="KEYS", help="tfx: key strands, written as guides to OUT_guides.tfx")
    ap.add_argument("--follow-hairs", type=int, metavar="F",
                    help="tfx: guides taken from the wisps to OUT_guides.tfx, F follow hairs each for TressFX "
                         "to make, with the loader's parameters in OUT_guides.tfx.json")
    ap.add_argument("--guides-out", metavar="FILE", help="tfx: where the guides go")
    ap.add_argument("--root-uv", metavar="UV.npy", help="(S, 2) root UVs from the scalp's UV map")
    ap.add_argument("--scale", type=float, help="multiply points and widths (100: metres to cm; default 1)")
    ap.add_argument("--axis", help="the target frame: " + "; ".join(
        f"{f.name}: {'|'.join(f.axes)}" for f in FORMATS))
    ap.add_argument("--up", choices=UP_CHOICES, default="z",
                    help="which way is up in INPUT: z keeps it as it is (the default), y turns a Y-up file into "
                         "our Z up first, auto does so for the formats that are Y up (TressFX .tfx, USC .data)")
    ap.add_argument("--no-flip-v", dest="flip_v", action="store_const", const=False,
                    help="tfx: keep V as is (default flips it for DirectX)")
    ap.add_argument("--pad-strands", action="store_const", const=True,
                    help="tfx: pad the strand count to a multiple of 64")
    ap.add_argument("--shuffle-seed", type=int, help="tfx: shuffle strands for TressFX's LOD")
    ap.add_argument("--units", help="npz sidecar: units name (default from --scale: m, cm, mm)")
    return ap


def export_main(argv=None, prog="groom export"):
    """The `export` command; returns the exit status (0 done, 2 bad input, nothing written)."""
    args = vars(build_parser(prog).parse_args(argv))
    input_path, out, format, up = args.pop("input"), args.pop("out"), args.pop("format"), args.pop("up")
    options = {name: value for name, value in args.items() if value is not None}
    t0 = time.perf_counter()
    try:
        written = export_file(input_path, out, format, up, **options)
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        print(f"error: {out}: cannot write ({e})", file=sys.stderr)
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

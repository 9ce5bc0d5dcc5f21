# SPDX-License-Identifier: GPL-3.0-or-later
"""Command line: grow a preset hairstyle, or export strands to another format.

    python -m groom generate --preset NAME [--scalp MESH.obj [--up X,Y,Z] [--front X,Y,Z]]
                             [--collider MESH.obj | --collider none]
                             [--count N] [--seed S] --out FILE.npz
    python -m groom export ...   (see `python -m groom export --help`)
    python -m groom head --out HEAD.obj   (the bundled head the bundled scalp lies on)

Bad input exits 2 with a message naming it; no partial output file is ever written. Keys
that cannot each find a root of their own on the scalp, and keys that pass through the
collider, are named on stderr; so is the progress of work that takes more than a second.
`generate` grows the strands a block at a time straight into the file
(groom.generate.generate_to_npz), so its memory does not grow with --count; only a file the
disk cannot take is refused (with the size it would need).
"""
import argparse
import os
import re
import sys
import time

from hairio import InputError


def _parser():
    p = argparse.ArgumentParser(prog="python -m groom", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    g = sub.add_parser("generate", help="grow a preset hairstyle and write the strands as .npz")
    g.add_argument("--preset", required=True, help="preset name (see --list) or a preset .json file")
    g.add_argument("--scalp", help="scalp mesh (.obj); default: the bundled head")
    g.add_argument("--up", metavar="X,Y,Z",
                   help="the head's up direction in the mesh's own space, e.g. 0,1,0 for a Y-up .obj "
                        "(default: the preset's, 0,0,1)")
    g.add_argument("--front", metavar="X,Y,Z",
                   help="the direction the face looks, in the mesh's own space, e.g. 0,0,1 for a Y-up .obj "
                        "(default: the preset's, 0,-1,0)")
    g.add_argument("--collider", metavar="MESH.obj",
                   help="closed mesh the hair must stay out of, in the scalp's space (the head), or 'none'; "
                        "default: the bundled head for the bundled scalp, none for a scalp of your own")
    g.add_argument("--count", type=int, help="number of strands (overrides the preset)")
    g.add_argument("--seed", type=int, help="random seed (overrides the preset)")
    g.add_argument("--out", required=True, help="output .npz file (SPEC §0 arrays, the key strands, guides and weights)")
    sub.add_parser("export", help="convert strands between formats", add_help=False)
    sub.add_parser("list", help="list the bundled presets")
    h = sub.add_parser("head", help="write the bundled head (the bundled scalp lies on it) as .obj, "
                                    "e.g. for `python -m tracer render --mesh`")
    h.add_argument("--out", required=True, help="output .obj file (metres, Z up, face toward -Y)")
    return p


def head_main(args):
    from hairio.atomic import check_destination
    from hairio.obj import write_obj
    from .scalp import default_head
    check_destination(args.out, f"--out {args.out!r}")
    head = default_head()
    write_obj(args.out, head.vertices, head.triangles,
              comment="The bundled head of keystrand hair (metres, Z up, face toward -Y).")
    print(f"head: {len(head.vertices)} vertices, {len(head.triangles)} triangles -> {args.out}")
    return 0


# Options whose value may start with a minus sign ("--front -1,0,0"), which argparse would
# otherwise take for an option of its own.
_VECTOR_OPTIONS = ("--up", "--front")


def _vector_option(option, text):
    """'X,Y,Z' -> 3 floats, or InputError naming the option."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 3:
        raise InputError(f"{option} {text!r}: expected three numbers X,Y,Z, e.g. 0,1,0")
    return values


def _head_axes(args, params):
    """(up, front) for the scalp from --up/--front, each defaulting to the preset's, checked."""
    from .head import head_axes
    up = params.up if args.up is None else _vector_option("--up", args.up)
    front = params.front if args.front is None else _vector_option("--front", args.front)
    names = ("--up" if args.up is not None else "the preset's up",
             "--front" if args.front is not None else "the preset's front")
    head_axes(up, front, names)
    return up, front


def _collider(args):
    """The collider for --collider: a mesh read from the file, none, or by default the
    bundled head when the scalp is the bundled one."""
    from .collide import Collider, default_collider
    if args.collider is None:
        return None if args.scalp else default_collider()
    if args.collider.lower() == "none":
        return None
    from .scalp import load_obj
    try:
        mesh = load_obj(args.collider)
    except InputError as e:
        raise InputError(f"--collider: {e}") from None
    return Collider(mesh.vertices, mesh.triangles, name=os.path.basename(args.collider))


# Work that takes longer than this (seconds) shows its progress on stderr.
PROGRESS_AFTER = 1.0


class _Progress:
    """A progress line on stderr, once the work has taken PROGRESS_AFTER seconds: redrawn in
    place on a terminal, a line per stage otherwise (a log)."""

    def __init__(self, stream=None):
        self.stream = stream or sys.stderr
        self.start = time.perf_counter()
        self.shown = False
        self.last = None
        self.stages = set()
        self.last_line = self.start
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())

    def __call__(self, fraction, stage):
        now = time.perf_counter()
        text = f"{100 * fraction:3.0f}% {stage}"
        if now - self.start < PROGRESS_AFTER or text == self.last:
            return
        # A log gets a line for each new stage and at most one a second otherwise (the blocks
        # of a large head repeat their stages); a terminal redraws its one line.
        if not self.tty and stage in self.stages and now - self.last_line < PROGRESS_AFTER and fraction < 1:
            return
        self.last, self.last_line = text, now
        self.stages.add(stage)
        if self.tty:
            self.stream.write("\r" + text.ljust(56))
        else:
            self.stream.write(f"progress: {text}\n")
        self.stream.flush()
        self.shown = True

    def close(self):
        if self.shown and self.tty:
            self.stream.write("\n")
            self.stream.flush()


def generate_main(args):
    from . import default_scalp, load_obj, load_preset
    if not args.out.lower().endswith(".npz"):
        raise InputError(f"--out {args.out!r}: the output must be a .npz file")
    from hairio.atomic import check_destination
    check_destination(args.out, f"--out {args.out!r}")    # before the work, not after it
    if args.count is not None and args.count < 1:
        raise InputError(f"--count {args.count}: must be at least 1")
    if args.seed is not None and args.seed < 0:
        raise InputError(f"--seed {args.seed}: must be >= 0")
    preset = load_preset(args.preset)
    changes = {k: v for k, v in (("count", args.count), ("seed", args.seed)) if v is not None}
    from .generate import check_npz_room, generate_to_npz
    # A file the disk cannot take is refused before the scalp, keys and collider are made.
    check_npz_room(args.out, preset.params.replace(**changes), f"--out {args.out!r}")
    up, front = _head_axes(args, preset.params)
    scalp = load_obj(args.scalp) if args.scalp else default_scalp()
    collider = _collider(args)
    start = time.perf_counter()
    placement = preset.place_keys(scalp, up, front, collider)
    warning = placement.warning()
    if warning:
        print(f"warning: {warning}", file=sys.stderr)
    params = placement.params.replace(**changes) if changes else placement.params
    progress = _Progress()
    # The key strands, guides and weights travel in the .npz, so `export` can hand them to an
    # engine's simulation later.
    try:
        result = generate_to_npz(args.out, scalp, placement.keys, params, collider=collider, progress=progress,
                                 what=f"--out {args.out!r}")
    except OSError as e:
        raise InputError(f"--out {args.out!r}: cannot write it ({e})") from e
    finally:
        progress.close()
    elapsed = time.perf_counter() - start
    inside = result.collision.warning() if result.collision is not None else None
    if inside:
        print(f"warning: {inside}", file=sys.stderr)
    moved = ("" if result.collision is None else
             f", {result.collision.strands_moved} moved out of {result.collision.collider}")
    print(f"{preset.name}: {result.num_strands} strands, {result.num_points} points, {result.num_segments} "
          f"cylinders{moved} in {elapsed:.3f} s -> {args.out}")
    return 0


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "export":
        # Imported only here, so `generate` works without the exporter installed.
        try:
            from hairio.cli import export_main
        except ModuleNotFoundError as e:
            if e.name != "hairio.cli":
                raise
            print("error: export: this installation has no hairio.cli exporter", file=sys.stderr)
            return 2
        return export_main(argv[1:])
    joined = []
    for a in argv:
        if joined and joined[-1] in _VECTOR_OPTIONS and re.match(r"-[\d.]", a):
            joined[-1] = f"{joined[-1]}={a}"
        else:
            joined.append(a)
    args = _parser().parse_args(joined)
    try:
        if args.command == "list":
            from .presets import list_presets
            print("\n".join(list_presets()))
            return 0
        if args.command == "head":
            return head_main(args)
        return generate_main(args)
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())

# SPDX-License-Identifier: GPL-3.0-or-later
"""python -m tracer render INPUT --out IMAGE.png [--size 512x512] [--spp N]
[--shadows|--no-shadows] [--layers K] [--shading phong|kajiya-kay]
[--camera auto|x,y,z:tx,ty,tz:fov]"""
import argparse
import os
import sys
import time

from hairio import InputError


def read_any(path):
    """Strands from any readable format; .npz works even without hairio.formats."""
    if not os.path.isfile(path):
        raise InputError(f"{path}: no such file")
    try:
        from hairio.formats import read_strands
    except ImportError:
        read_strands = None
    if read_strands is not None:
        try:
            return read_strands(path)
        except InputError:
            raise
        except Exception as e:   # a reader tripping over a malformed file is still bad input
            raise InputError(f"{path}: cannot read ({type(e).__name__}: {e})") from e
    if path.lower().endswith(".npz"):
        from hairio import Strands
        return Strands.load_npz(path)
    raise InputError(f"{path}: cannot read this format here (only .npz without hairio.formats)")


def parse_size(text):
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise InputError(f"--size {text!r}: expected WIDTHxHEIGHT, e.g. 512x512") from None
    if not (1 <= w <= 16384 and 1 <= h <= 16384):
        raise InputError(f"--size {text!r}: width and height must lie in 1..16384")
    return w, h


def parse_camera(text, strands, size):
    from .camera import Camera
    if text == "auto":
        lo, hi = strands.bounds()
        return Camera.frame_bounds(lo, hi, size)
    try:
        eye, target, fov = text.split(":")
        eye = [float(x) for x in eye.split(",")]
        target = [float(x) for x in target.split(",")]
        fov = float(fov)
        if len(eye) != 3 or len(target) != 3:
            raise ValueError
    except ValueError:
        raise InputError(f"--camera {text!r}: expected auto or x,y,z:tx,ty,tz:fov") from None
    return Camera.look_at(eye, target, fov_deg=fov, size=size)


def build_parser():
    parser = argparse.ArgumentParser(prog="python -m tracer", description="Render strands with the GPU ray tracer.")
    sub = parser.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render", help="render a strand file to a PNG")
    r.add_argument("input", help="strand file to render (.npz, or any format hairio.formats reads)")
    r.add_argument("--out", required=True, help="PNG image to write (RGBA, transparent background); "
                   "its folder must exist")
    r.add_argument("--size", default="512x512", help="image size WIDTHxHEIGHT in pixels, each 1..16384 (default %(default)s)")
    r.add_argument("--spp", type=int, default=1,
                   help="samples per pixel, a square number (1, 4, 9, ...) for stratified sampling (default %(default)s)")
    r.add_argument("--shadows", dest="shadows", action="store_true", default=True,
                   help="trace shadow rays toward the lights (the default)")
    r.add_argument("--no-shadows", dest="shadows", action="store_false", help="no shadow rays: faster, flatter")
    r.add_argument("--layers", type=int, default=4,
                   help="semi-transparent hits composited front to back per ray, 1..64 (default %(default)s)")
    r.add_argument("--shading", choices=("phong", "kajiya-kay"), default="kajiya-kay",
                   help="shading model (default %(default)s)")
    r.add_argument("--camera", default="auto",
                   help="auto (frame the strands' bounds from the front) or EYE:TARGET:FOV as "
                        "x,y,z:tx,ty,tz:degrees, e.g. 0,-3,1:0,0,1:40 (default %(default)s)")
    return parser


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        size = parse_size(args.size)
        folder = os.path.dirname(os.path.abspath(args.out))
        if not os.path.isdir(folder):
            raise InputError(f"--out {args.out}: folder {folder} does not exist; create it first")
        from .settings import RenderSettings
        settings = RenderSettings(spp=args.spp, shadows=args.shadows, layers=args.layers,
                                  shading=args.shading, background=(0.0, 0.0, 0.0, 0.0))
        settings.check()
        t0 = time.perf_counter()
        strands = read_any(args.input)
        t1 = time.perf_counter()
        camera = parse_camera(args.camera, strands, size)
        from .renderer import Renderer
        from .png import write_png
        renderer = Renderer()
        renderer.set_strands(strands)
        img = renderer.render(camera, settings)
        st = renderer.stats
        write_png(args.out, img)
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"read {t1 - t0:.3f} s: {strands.num_strands} strands, {st['num_cylinders']} cylinders")
    print(f"upload {st['upload_s']:.3f} s (cylinders {st['cylinders_s']:.3f} s)")
    print(f"grid build {st['grid_s']:.3f} s: {st['grid_dims']} cells, {st['grid_refs']} references")
    print(f"render {st['render_s']:.3f} s at {size[0]}x{size[1]}, {args.spp} spp")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

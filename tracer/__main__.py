# SPDX-License-Identifier: GPL-3.0-or-later
"""python -m tracer render INPUT --out IMAGE.png [--size 512x512] [--spp N]
[--sampler independent|pixel] [--shadows|--no-shadows] [--layers K] [--shading MODEL]
[--min-pixel-width|--no-min-pixel-width]
[--camera auto|x,y,z:tx,ty,tz:fov] [--up auto|z|y] [--mesh MESH.obj [--mesh-color R,G,B]]...
[--light TYPE:...]... [--ambient X]

Bad input exits 2 with one line naming it and writes nothing. What can be known before the
render is checked before it: the size, the memory of one band of tiles at that width, the
samples, the destination (a folder, a missing or read-only place). The image is rendered in tiles of at most TILE_PIXELS and written to
the PNG band by band as they finish, so a 16384 x 16384 image takes the memory of one band
of tiles, not of the image (a whole 8192² image in float64 needs 2 GiB per copy). A disk
that fills up while the PNG is written is an exit 2 too, and leaves no file.
"""
import argparse
import os
import sys
import time

import numpy as np

from hairio import InputError

from .settings import ACCELS, DEFAULT_ACCEL, MAX_LIGHTS

# Samples are placed in float32 pixel coordinates of the whole image: below 16384 they
# round to within 1/2048 of a pixel (a 32nd of the finest stratum, 64 per side at MAX_SPP);
# each doubling of the size doubles that error.
MAX_SIZE = 16384
# Pixels per tile: 4 MiB of float32 RGBA from the GPU; tiles are at most TILE_SIDE wide, so
# a band of them is at most 16384 x 128 pixels (8 MiB of 8-bit rows). Smaller tiles cost
# more in per-draw overhead than they save (docs/DECISIONS.md, "Tiles of 2^18 pixels").
TILE_PIXELS = 1 << 18
TILE_SIDE = 2048
# Rows converted to 8-bit sRGB at once: the conversion works in float64 (~10 MiB at 2048 wide).
CONVERT_ROWS = 32
# A mesh without --mesh-color: a light neutral grey, like skin in a clay render.
DEFAULT_MESH_COLOR = (0.7, 0.7, 0.7)


def read_any(path):
    """Strands from any readable format; .npz works even without hairio.formats. The
    readers report every malformed file as an InputError naming it: anything else is a
    bug and surfaces as one."""
    try:
        from hairio.formats import read_strands
    except ImportError:
        read_strands = None
    if read_strands is not None:
        return read_strands(path)
    if not os.path.isfile(path):
        raise InputError(f"{path}: no such file")
    if path.lower().endswith(".npz"):
        from hairio import Strands
        return Strands.load_npz(path)
    raise InputError(f"{path}: cannot read this format here (only .npz without hairio.formats)")


def parse_size(text):
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise InputError(f"--size {text!r}: expected WIDTHxHEIGHT, e.g. 512x512") from None
    if min(w, h) < 1:
        raise InputError(f"--size {text!r}: width and height must lie in 1..{MAX_SIZE}")
    if max(w, h) > MAX_SIZE:
        raise InputError(f"--size {text!r}: width and height must lie in 1..{MAX_SIZE}; the tracer places samples "
                         f"in float32 pixel coordinates, which {max(w, h)} pixels across round to "
                         f"1/{1 / position_error(max(w, h)):.0f} of a pixel (1/{1 / position_error(MAX_SIZE):.0f} "
                         f"at {MAX_SIZE})")
    return w, h


def position_error(side):
    """The largest rounding of a float32 sample position (0 <= x < side) in an image `side`
    pixels across, in pixels: half the float32 spacing just below `side`."""
    below = np.nextafter(np.float32(side), np.float32(0))
    return float(np.spacing(below)) / 2


def render_memory(size, tile_pixels=TILE_PIXELS, tile_side=TILE_SIDE):
    """Bytes of host memory render_png takes for an image of `size` (W, H), whatever its
    height: one band of 8-bit rows and its PNG scanlines twice (the filtered rows and their
    bytes), one tile's float32 copies (tracer.draw.RENDER_COPIES), the float64 temporaries
    of converting CONVERT_ROWS rows of a tile (about four), and 1 MiB for zlib."""
    from .draw import RENDER_COPIES
    W, _ = size
    _, h, row = tiles(size, tile_pixels, tile_side)[0]
    tw = row[0][1]
    return (h * W * 4 + 2 * h * (1 + 4 * W) + RENDER_COPIES * tw * h * 16
            + 4 * min(h, CONVERT_ROWS) * tw * 4 * 8 + (1 << 20))


def parse_camera(text, strands, size, meshes=None):
    """The camera of --camera; `auto` frames the strands and the meshes (a MeshSet) together."""
    from .camera import Camera
    if text == "auto":
        lo, hi = strands.bounds()
        if meshes is not None:
            mlo, mhi = meshes.bounds()
            lo, hi = (mlo, mhi) if not strands.num_points else (np.minimum(lo, mlo), np.maximum(hi, mhi))
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


# --light: a Blender light's type, place and power, as the add-on reads them from a scene.
LIGHT_FORMS = {
    "sun": "sun:DX,DY,DZ[:STRENGTH[:ANGLE]] (the way it shines, irradiance in W/m², angular diameter "
           "in degrees)",
    "point": "point:X,Y,Z:POWER[:RADIUS] (watts, metres)",
    "spot": "spot:X,Y,Z:TX,TY,TZ:POWER[:SIZE[:BLEND]] (aimed at TX,TY,TZ; cone angle in degrees, blend 0..1)",
    "area": "area:X,Y,Z:TX,TY,TZ:POWER[:WIDTH[:HEIGHT]] (facing TX,TY,TZ; a rectangle, metres)",
}


def parse_light(text):
    """A tracer Light from --light's TYPE:... (LIGHT_FORMS), as Cycles lights with the Blender
    light of those settings (settings.blender_light). Every number must be finite."""
    from .settings import blender_light
    kind, _, rest = text.partition(":")
    form = LIGHT_FORMS.get(kind.lower())
    if form is None:
        raise InputError(f"--light {text!r}: unknown type {kind!r}; use one of: " + "; ".join(LIGHT_FORMS.values()))
    kind = kind.lower()
    places = 1 if kind in ("sun", "point") else 2       # points (or the sun's direction) first
    # The numbers after them with their defaults (None: required).
    tail = {"sun": [1.0, 0.0], "point": [None, 0.0], "spot": [None, 180.0, 0.0], "area": [None, 0.0, None]}[kind]
    try:
        parts = [[float(x) for x in p.split(",")] for p in rest.split(":")]
        numbers = [p[0] for p in parts[places:]]
        if (len(parts) < places or any(len(p) != 3 for p in parts[:places]) or any(len(p) != 1 for p in parts[places:])
                or len(numbers) > len(tail) or not all(np.all(np.isfinite(p)) for p in parts)):
            raise ValueError
        values = numbers + tail[len(numbers):]
        if values[0] is None:
            raise ValueError
        if kind == "sun":
            light = blender_light("SUN", values[0], parts[0], angle=np.radians(values[1]))
        elif kind == "point":
            light = blender_light("POINT", values[0], parts[0], radius=values[1])
        else:
            axis = np.asarray(parts[1]) - np.asarray(parts[0])
            if kind == "spot":
                light = blender_light("SPOT", values[0], parts[0], axis=axis, spot_size=np.radians(values[1]),
                                      spot_blend=values[2])
            else:
                width, height = values[1], values[1] if values[2] is None else values[2]
                across = np.cross(axis, (0.0, 0.0, 1.0))        # its width level, where it can be
                tangent = across if np.linalg.norm(across) > 1e-9 * np.linalg.norm(axis) else (1.0, 0.0, 0.0)
                light = blender_light("AREA", values[0], parts[0], axis=axis, size=(width, height), tangent=tangent)
        light.check()
    except (ValueError, InputError) as e:
        detail = f" ({e})" if isinstance(e, InputError) else ""
        raise InputError(f"--light {text!r}: expected {form}{detail}") from None
    return light


def parse_color(text, option="--mesh-color"):
    """R,G,B of three finite numbers >= 0 (linear)."""
    try:
        rgb = tuple(float(x) for x in text.split(","))
    except ValueError:
        rgb = ()
    if len(rgb) != 3 or not all(np.isfinite(rgb)) or min(rgb) < 0:
        raise InputError(f"{option} {text!r}: expected R,G,B, three numbers >= 0, e.g. 0.8,0.6,0.5")
    return rgb


def read_meshes(paths, colors, frame_of):
    """The --mesh files as a tracer.meshes.MeshSet (None for none): each .obj read, turned
    into our frame by `frame_of(points, path)`, with the --mesh-color of the same position
    (DEFAULT_MESH_COLOR where fewer colours than meshes are given)."""
    from hairio.obj import read_obj
    from .meshes import mesh_set
    if len(colors) > len(paths):
        raise InputError(f"--mesh-color: {len(colors)} colours for {len(paths)} meshes; give one --mesh-color "
                         "after each --mesh it colours")
    meshes = []
    for k, path in enumerate(paths):
        verts, tris = read_obj(path)
        rgb = parse_color(colors[k]) if k < len(colors) else DEFAULT_MESH_COLOR
        meshes.append((frame_of(verts, path), tris, rgb, path))
    return mesh_set(meshes)


def tiles(size, tile_pixels=TILE_PIXELS, tile_side=TILE_SIDE):
    """Row bands of tiles covering a (W, H) image: [(y0, h, [(x0, w), ...]), ...]."""
    W, H = size
    tw = min(W, tile_side)
    th = min(H, max(1, tile_pixels // tw))
    return [(y0, min(th, H - y0), [(x0, min(tw, W - x0)) for x0 in range(0, W, tw)]) for y0 in range(0, H, th)]


def render_png(renderer, camera, settings, out, tile_pixels=TILE_PIXELS, tile_side=TILE_SIDE):
    """Render `camera`'s image tile by tile and write it to the PNG `out` band by band;
    returns the seconds spent tracing (the renderer's render_s summed over tiles)."""
    from .png import to_srgb8, write_png_bands
    W, H = camera.size
    spent = [0.0]

    def bands():
        for y0, h, row in tiles(camera.size, tile_pixels, tile_side):
            band = np.empty((h, W, 4), np.uint8)
            for x0, w in row:
                img = renderer.render(camera.window(x0, y0, w, h), settings)
                spent[0] += renderer.stats.render_s
                for r in range(0, h, CONVERT_ROWS):    # float64 temporaries of a few rows at a time
                    band[r:r + CONVERT_ROWS, x0:x0 + w] = to_srgb8(img[r:r + CONVERT_ROWS])
            yield band

    write_png_bands(out, W, H, bands())
    return spent[0]


HAIR_SLIDERS = (("--melanin", "hair_melanin", "melanin 0..1"),
                ("--melanin-redness", "hair_melanin_redness", "pheomelanin share of the melanin, 0..1"),
                ("--roughness", "hair_roughness", "longitudinal roughness 0..1"),
                ("--radial-roughness", "hair_radial_roughness", "azimuthal roughness 0..1"),
                ("--coat", "hair_coat", "lowers the surface reflection's roughness, 0..1"),
                ("--ior", "hair_ior", "index of refraction 1..3"),
                ("--cuticle-tilt", "hair_cuticle_tilt", "cuticle tilt in degrees, -90..90"))


def build_parser():
    from hairio.formats.up_axis import UP_CHOICES
    from .layout import PIXEL_MAX_SPP
    from .settings import HAIR_COLORS, MAX_SPP, SAMPLERS, RenderSettings
    from .shading import DEFAULT_SHADING, SHADING_MODELS
    parser = argparse.ArgumentParser(prog="python -m tracer", description="Render strands with the GPU ray tracer.")
    sub = parser.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render", help="render a strand file to a PNG")
    r.add_argument("input", help="strand file to render (.npz, or any format hairio.formats reads)")
    r.add_argument("--out", required=True, help="PNG image to write (RGBA, transparent background); "
                   "its folder must exist")
    r.add_argument("--size", default="512x512",
                   help=f"image size WIDTHxHEIGHT in pixels, each 1..{MAX_SIZE}; large images are rendered "
                        f"and written in tiles (default %(default)s)")
    r.add_argument("--spp", type=int, default=1,
                   help=f"samples per pixel, a square number (1, 4, 9, ...) up to {MAX_SPP}, for stratified "
                        f"sampling (default %(default)s)")
    r.add_argument("--sampler", choices=SAMPLERS, default=RenderSettings().sampler,
                   help="how a pixel's samples are taken: independent (each its own ray, one pass per sample) "
                        f"or pixel (up to {PIXEL_MAX_SPP} of them in one walk, each strand shaded once a walk: "
                        f"16 samples for a fraction of 16 passes' time) (default %(default)s)")
    r.add_argument("--shadows", dest="shadows", action="store_true", default=True,
                   help="trace shadow rays toward the lights (the default)")
    r.add_argument("--no-shadows", dest="shadows", action="store_false", help="no shadow rays: faster, flatter")
    r.add_argument("--layers", type=int, default=4,
                   help="semi-transparent hits composited front to back per ray, 1..64 (default %(default)s)")
    defaults = RenderSettings()     # the options' defaults are the library's
    on_off = {True: "on", False: "off"}
    r.add_argument("--min-pixel-width", dest="min_pixel_width", action="store_true",
                   default=defaults.min_pixel_width,
                   help="widen hairs thinner than half a pixel (up to "
                        f"{defaults.min_pixel_width_cap:g}x their radius) and make them fainter to match, so thin "
                        "hair shows as strands, not dust; hair far thinner than a pixel stays faint "
                        f"(default {on_off[defaults.min_pixel_width]})")
    r.add_argument("--no-min-pixel-width", dest="min_pixel_width", action="store_false",
                   help="trace every hair at its own radius")
    r.add_argument("--shading", choices=[m.name for m in SHADING_MODELS], default=DEFAULT_SHADING,
                   help="shading model: " + "; ".join(f"{m.name}: {m.description}" for m in SHADING_MODELS)
                        + " (default %(default)s)")
    # The "chiang" model's sliders (RenderSettings.hair_*, Cycles' Principled Hair names).
    defaults = RenderSettings()
    r.add_argument("--hair-color", choices=HAIR_COLORS, default=defaults.hair_color,
                   help="what a strand's colour means to the chiang model: strand = the hair's colour (Cycles' "
                        "Direct Coloring), melanin = a tint over --melanin (default %(default)s)")
    for flag, field, what in HAIR_SLIDERS:
        r.add_argument(flag, type=float, dest=field, metavar="X", default=getattr(defaults, field),
                       help=f"chiang model: {what} (default %(default)s)")
    r.add_argument("--accel", choices=ACCELS, default=DEFAULT_ACCEL,
                   help="what rays walk: beams (camera rays and shadow rays toward suns look up lists made "
                        "for them; the grid for the rest), the uniform grid, or the BVH over cylinders; same "
                        "image (default %(default)s)")
    r.add_argument("--camera", default="auto",
                   help="auto (frame the strands' and meshes' bounds from the front) or EYE:TARGET:FOV as "
                        "x,y,z:tx,ty,tz:degrees, e.g. 0,-3,1:0,0,1:40 (default %(default)s)")
    r.add_argument("--up", choices=UP_CHOICES, default="auto",
                   help="which way is up in INPUT (and in the meshes, which come in its frame): z keeps the "
                        "coordinates, y turns a Y-up file into Z up, auto does so for the formats that are "
                        "Y up (TressFX .tfx, USC .data) (default %(default)s)")
    r.add_argument("--light", action="append", default=[], metavar="TYPE:...",
                   help="a light as Cycles lights with the Blender light of those settings, in the picture's "
                        "frame (Z up, after --up); repeatable, up to 8; without any, the tracer's default sun. "
                        "Forms: " + "; ".join(LIGHT_FORMS.values()))
    r.add_argument("--ambient", type=float, default=defaults.ambient, metavar="X",
                   help="light from everywhere, the radiance of an even grey world (0: none, as Cycles under "
                        "a black world) (default %(default)s)")
    r.add_argument("--mesh", action="append", default=[], metavar="MESH.obj",
                   help="an opaque mesh beside the strands (a head, a body); repeatable")
    r.add_argument("--mesh-color", action="append", default=[], metavar="R,G,B",
                   help="linear base colour of the --mesh before it, 0..1 each "
                        f"(default {','.join(str(c) for c in DEFAULT_MESH_COLOR)}); repeatable")
    return parser


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        size = parse_size(args.size)
        from hairio.validate import check_memory
        check_memory(f"--size {args.size}", render_memory(size),
                     "render a narrower image (it is rendered in bands of tiles, each the image's width)")
        from hairio.atomic import check_destination
        check_destination(args.out, f"--out {args.out}")
        from .settings import RenderSettings
        lights = tuple(parse_light(text) for text in args.light)
        if len(lights) > MAX_LIGHTS:
            raise InputError(f"--light: {len(lights)} given; use at most {MAX_LIGHTS}")
        if not np.isfinite(args.ambient) or args.ambient < 0:
            raise InputError(f"--ambient {args.ambient}: use a finite number >= 0")
        settings = RenderSettings(spp=args.spp, sampler=args.sampler, shadows=args.shadows, layers=args.layers,
                                  shading=args.shading, min_pixel_width=args.min_pixel_width,
                                  background=(0.0, 0.0, 0.0, 0.0), hair_color=args.hair_color,
                                  ambient=args.ambient, **({"lights": lights} if lights else {}),
                                  **{field: getattr(args, field) for _, field, _ in HAIR_SLIDERS})
        settings.check()
        from hairio.formats.up_axis import file_frame
        from hairio.formats.axes import unconvert_points
        frame = file_frame(args.input, args.up)

        def to_our_frame(points, path):
            return points if frame == "none" else unconvert_points(points, frame)

        t0 = time.perf_counter()
        strands = read_any(args.input)
        if frame != "none":
            from hairio.formats.up_axis import strands_to_z_up
            strands = strands_to_z_up(strands, args.input, args.up)
        meshes = read_meshes(args.mesh, args.mesh_color, to_our_frame)
        t1 = time.perf_counter()
        from .renderer import Renderer
        renderer = Renderer(accel=args.accel)
        try:
            renderer.set_strands(strands)
        except InputError as e:     # strands the tracer cannot resolve: name the file they came from
            raise InputError(f"{args.input}: {e}") from None
        renderer.set_meshes(meshes)
        camera = parse_camera(args.camera, strands, size, meshes)
        st = renderer.stats.as_dict()
        try:
            render_s = render_png(renderer, camera, settings, args.out)
        except OSError as e:     # the disk filled up, or the place changed, while rendering
            raise InputError(f"--out {args.out}: cannot write it ({e.strerror or e}); nothing was written") from None
        except InputError as e:  # tiles are within every image limit: what is left is the camera's
            raise InputError(f"--camera {args.camera}: {e}") from None
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"read {t1 - t0:.3f} s: {strands.num_strands} strands, {st['num_cylinders']} cylinders"
          + (f", {st['num_triangles']} mesh triangles" if st["num_triangles"] else ""))
    print(f"upload {st['upload_s']:.3f} s (cylinders {st['cylinders_s']:.3f} s)")
    after = renderer.stats.as_dict()
    if renderer.accel == "beams" and after["beams_s"] is not None:
        print(f"beams {after['beams_s']:.3f} s (last tile): camera {after['camera_beams']}, "
              f"{after['beam_refs']} references")
    if after["grid_refs"] is not None:
        print(f"grid build {after['grid_s']:.3f} s: {after['grid_dims']} cells, {after['grid_refs']} references")
    if renderer.accel == "bvh":
        print(f"BVH build {st['accel_s']:.3f} s: {st['bvh_pieces']} pieces, {st['bvh_entries']} nodes and leaves")
    print(f"render {render_s:.3f} s at {size[0]}x{size[1]}, {args.spp} spp"
          + (" in one walk a pixel (sampler pixel)" if settings.sampler == "pixel" else "")
          + (", minimum pixel width" if settings.min_pixel_width else ""))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

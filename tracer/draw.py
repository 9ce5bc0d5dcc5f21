# SPDX-License-Identifier: GPL-3.0-or-later
"""Drawing: the trace program for a set of compile-time switches, the float framebuffers,
the checks of what the GPU can draw, and the draw calls (tile by tile, one sample per
draw) that turn a camera and settings into an image. Reads the scene's buffers and grid;
uploads nothing but uniforms.
"""
import numpy as np

from hairio import InputError
from hairio.validate import check_memory

from . import layout
from .gl_buffers import set_samplers
from .gpu_build import set_uniforms
from .beams import anchored
from .grid import Grid
from .mesh_upload import MESH_BUFFERS
from .scene_buffers import split_part_names
from .scene_beams import CAMERA_BUFFERS, SUN_BUFFERS
from .scene_grid import WIDE
from .shader_source import shader_source
from .settings import pixel_group
from .shading import shading_model

# Host memory of one render: the framebuffer (a driver like llvmpipe keeps it in host memory),
# its read-back bytes and the flipped image, RGBA float32 each.
RENDER_COPIES = 3
# The trace program's buffers per accelerator, on texture units 0, 1, 2, and with meshes 3, 4, 5.
TRACE_BUFFERS = {"grid": ("tex_cyl", "tex_idx", "tex_cell"), "bvh": ("tex_cyl", "tex_node", "tex_order")}
TRACE_BUFFERS["beams"] = TRACE_BUFFERS["grid"]
# Then, on units 6, 7, ..., the parts past the first of buffers split over the driver's limit
# (tracer/scene_buffers.py); a scene within it binds none of them.
SPLIT_PARTS = split_part_names()
# Then the pixel sampler's wide grid (tracer/scene_grid.py, build_wide_grid), when it walks
# one beside the scene's grid.
WIDE_BUFFERS = WIDE
# Then the beams (tracer/scene_beams.py): the camera's, then each sun slot's.
BEAM_BUFFERS = CAMERA_BUFFERS + tuple(n for pair in SUN_BUFFERS for n in pair)


def sun_slots_within(units):
    """How many sun slots' buffers (each two units, after every other buffer's) lie within a
    driver's `units` texture units (GL_MAX_TEXTURE_IMAGE_UNITS: 32 on llvmpipe and desktop
    GPUs, 16 on some): the lights past them walk the grid."""
    first = len(TRACE_BUFFERS["grid"] + MESH_BUFFERS + SPLIT_PARTS + WIDE_BUFFERS + CAMERA_BUFFERS)
    return max(0, min(len(SUN_BUFFERS), (int(units) - first) // 2))


_VERTEX = """#version 330 core
void main() {   // one triangle that covers the screen; the scissor picks the pixels
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
"""


def trace_files(settings, meshes=False, accel="grid", walk=True):
    """The trace program's files in dependency order (tracer/shaders/trace_scene.glsl lists
    them): the scene, the shape, the accelerator interface and the structure that implements
    it (`accel`: "grid" or "bvh"; "beams": the beams, after the grid when some ray walks it,
    `walk`), with `meshes` the triangles and their grid, the shading model of `settings`, the
    tracer's main."""
    mesh_files = ["shapes_triangle.glsl", "accel_mesh_grid.glsl"] if meshes else []
    if accel == "beams":
        structure = (["accel_grid.glsl"] if walk else []) + ["accel_beams.glsl"]
    else:
        structure = [f"accel_{accel}.glsl"]
    return (["trace_scene.glsl", "shapes_cylinder.glsl", "capsule.glsl", "accel.glsl", "sampler_pixel.glsl"] + structure
            + mesh_files
            + [shading_model(settings.shading).glsl, "trace_main.glsl"])


class Drawer:
    """Programs and framebuffers of one renderer (compiled and made on first use, kept)."""

    def __init__(self, ctx):
        self.ctx = ctx
        self._programs = {}
        self._fbos = {}

    def program(self, settings, camera, layers, meshes=False, accel="grid", parts=(1, 1), wide=False, group=1,
                beams=(False, 0, True, False)):
        """`parts`: buffer textures holding the cylinders and the cell lists (tracer/scene_buffers.py);
        `wide`: the pixel sampler walks a grid of its own (WIDE_BUFFERS); `group`: the pixel
        sampler's samples a walk (settings.pixel_group); `beams` (accel "beams"): whether the
        camera has beams, how many sun slots are used, whether some ray walks the grid, whether
        the camera's entries come with their marks (Beams.reach)."""
        key = (layers, settings.shadows and (1 if settings.shadow_mode == "hard" else 2),
               settings.shading, len(settings.lights), settings.spp_n, settings.min_pixel_width,
               camera.type, settings.count, bool(meshes), layout.glsl_header(), accel, settings.sampler,
               tuple(parts), bool(wide), group, tuple(beams))
        prog = self._programs.get(key)
        if prog is None:
            defines = {
                "LAYERS": layers,
                "SHADOWS": int(key[1] or 0),
                "NUM_LIGHTS": len(settings.lights),
                "SPP_N": settings.spp_n,
                "MIN_PX": int(settings.min_pixel_width),
                "ORTHO": int(camera.type == "ORTHO"),
                "COUNT": int(settings.count),
                "MESHES": int(bool(meshes)),
                "PIXEL": int(settings.sampler == "pixel"),
                "PIX_GROUP": group,
                "CYL_PARTS": parts[0],
                "IDX_PARTS": parts[1],
                "WIDE_GRID": int(bool(wide)),
                "CAMERA_BEAMS": int(beams[0]),
                "SUN_BEAMS": int(beams[1]),
                "WALK": int(beams[2]),
                "CAMERA_MARKS": int(beams[3]),
            }
            program = self.ctx.program(vertex_shader=_VERTEX,
                                       fragment_shader=shader_source(
                                           330, trace_files(settings, meshes, accel, beams[2]), defines))
            set_samplers(program, **{name: unit for unit, name in enumerate(
                TRACE_BUFFERS[accel] + MESH_BUFFERS + SPLIT_PARTS + WIDE_BUFFERS + BEAM_BUFFERS)})
            prog = (program, self.ctx.vertex_array(program, []))
            self._programs[key] = prog
        return prog

    def framebuffer(self, w, h, count):
        key = (w, h, count)
        fbo = self._fbos.get(key)
        if fbo is None:
            import moderngl
            atts = []
            try:
                atts.append(self.ctx.texture((w, h), 4, dtype="f4"))
                if count:
                    atts.append(self.ctx.texture((w, h), 4, dtype="f4"))
                fbo = self.ctx.framebuffer(color_attachments=atts)
            except moderngl.Error as e:
                # Drivers have limits of their own below GL_MAX_TEXTURE_SIZE (llvmpipe refuses
                # a float framebuffer past 2 GiB: 12000² is INCOMPLETE_ATTACHMENT).
                for t in atts:
                    t.release()
                raise InputError(f"camera size {w}x{h}: the GPU driver cannot make a float framebuffer of "
                                 f"{w * h * 16 / 2**30:.2f} GiB ({e}); render a smaller image, or in tiles "
                                 "(python -m tracer render does)") from None
            self._fbos[key] = fbo
        return fbo

    def check_camera(self, camera, settings):
        """What the GPU cannot draw is refused before the framebuffer is made: a camera so far
        out that squared distances overflow, an image wider than the driver draws, or one
        whose copies need more memory than there is."""
        far = float(np.abs(camera.position).max())
        if not far <= layout.MAX_CAMERA_COORDINATE:
            raise InputError(f"camera: position {far:.3g} from the origin; the GPU tracer squares distances in "
                             f"float32, so it takes cameras within ±{layout.MAX_CAMERA_COORDINATE:.0e}: move it closer "
                             "or scale the scene down")
        w, h = camera.size
        side = min(int(self.ctx.info["GL_MAX_TEXTURE_SIZE"]), *(int(d) for d in self.ctx.info["GL_MAX_VIEWPORT_DIMS"]))
        if max(w, h) > side:
            raise InputError(f"camera size {w}x{h}: this GPU draws at most {side} pixels a side in one image; "
                             "render a larger image in tiles (python -m tracer render does)")
        check_memory(f"camera size {w}x{h}", (RENDER_COPIES + settings.count) * w * h * 16,
                     "render a smaller image, or in tiles (python -m tracer render writes any size band by band)")

    def draw(self, buffers, structure, camera, settings, layers, box, mesh_grid=None, mesh_offset=0.0, wide=None,
             beams=None):
        """The image (H, W, 4) float32, row 0 = top, and the summed work counters (4,):
        pixels in `box` (x0, y0, x1, y1; None: none) traced, the rest background.
        `structure`: the scene's Grid, or its BVH (tracer/bvh.py); None with `beams` when no
        ray walks one. With `mesh_grid` the meshes uploaded with it are traced too. `wide`:
        the Grid the pixel sampler walks, in WIDE_BUFFERS unless it is `structure` itself.
        `beams`: tracer.scene_beams.BeamPlan (accel "beams")."""
        import moderngl
        w, h = camera.size
        fbo = self.framebuffer(w, h, settings.count)
        fbo.use()
        self.ctx.scissor = None
        fbo.clear(*settings.premultiplied_background())
        counts = np.zeros(4)
        if box is not None:
            meshes = mesh_grid is not None
            walk = structure is not None
            accel = "beams" if beams is not None else ("grid" if isinstance(structure, Grid) else "bvh")
            suns = 0 if beams is None else max([k + 1 for k in beams.light_sun if k >= 0], default=0)
            switches = ((False, 0, True, False) if beams is None else
                        (beams.camera is not None, suns, walk, beams.camera is not None and beams.camera.reach is not None))
            parts = (buffers.parts("tex_cyl"), buffers.parts("tex_idx") if accel != "bvh" and walk else 1)
            pixel = settings.sampler == "pixel"
            own = pixel and wide is not None and wide is not structure
            # The pixel sampler takes a group of a pixel's samples a draw, the other one sample.
            group = pixel_group(settings.spp, layers) if pixel else 1
            draws = settings.spp // group
            prog, vao = self.program(settings, camera, layers, meshes, accel, parts, own, group, switches)
            buffers.bind(TRACE_BUFFERS[accel] + (MESH_BUFFERS if meshes else ("",) * len(MESH_BUFFERS))
                         + SPLIT_PARTS + (WIDE_BUFFERS if own else ("",) * len(WIDE_BUFFERS))
                         + (BEAM_BUFFERS if beams is not None else ()))
            if beams is not None:
                _set_beam_uniforms(prog, beams)
            if own:
                set_uniforms(prog, wide_lo=tuple(float(x) for x in wide.lo),
                             wide_cell_size=tuple(float(x) for x in wide.cell_size),
                             wide_dims=tuple(int(x) for x in wide.dims))
            set_uniforms(prog, cyl_split=buffers.part_size("tex_cyl"), idx_split=buffers.part_size("tex_idx"))
            if accel != "bvh" and walk:
                set_uniforms(prog, grid_lo=tuple(float(x) for x in structure.lo),
                             cell_size=tuple(float(x) for x in structure.cell_size),
                             dims=tuple(int(x) for x in structure.dims))
            elif accel == "bvh":
                set_uniforms(prog, bvh_entries=int(buffers.stats.bvh_entries))
            _set_uniforms(prog, camera, settings)
            if meshes:
                set_uniforms(prog, mesh_lo=tuple(float(x) for x in mesh_grid.lo),
                             mesh_cell_size=tuple(float(x) for x in mesh_grid.cell_size),
                             mesh_dims=tuple(int(x) for x in mesh_grid.dims), mesh_offset=float(mesh_offset),
                             mesh_brdf=float(shading_model(settings.shading).mesh_brdf))
            self.ctx.blend_func = moderngl.ONE, moderngl.ONE
            self.ctx.blend_equation = moderngl.FUNC_ADD
            x0, y0, x1, y1 = box
            step = settings.tile
            for ty in range(y0, y1, step):
                for tx in range(x0, x1, step):
                    tw, th = min(step, x1 - tx), min(step, y1 - ty)
                    # GL's window origin is the bottom-left corner.
                    self.ctx.scissor = (tx, h - ty - th, tw, th)
                    # One sample per draw (the shader's main says why): the first replaces the
                    # cleared background, the others add to it (colour and counters alike).
                    # The pixel sampler takes a group of a pixel's samples a draw.
                    for s in range(draws):
                        set_uniforms(prog, sample_index=s)
                        if s == 1:
                            self.ctx.enable(moderngl.BLEND)
                        vao.render(vertices=3)
                    self.ctx.disable(moderngl.BLEND)
                    if (x1 - x0) * (y1 - y0) > step * step:
                        self.ctx.finish()
            self.ctx.scissor = None
            if settings.count:
                raw = fbo.read(viewport=(x0, h - y1, x1 - x0, y1 - y0), components=4, dtype="f4", attachment=1)
                counts = np.frombuffer(raw, np.float32).reshape(-1, 4).sum(axis=0, dtype=np.float64)
        raw = fbo.read(components=4, dtype="f4", attachment=0)
        return np.frombuffer(raw, np.float32).reshape(h, w, 4)[::-1].copy(), counts


def screen_bounds(lo, hi, camera):
    """Pixel rectangle (x0, y0, x1, y1), y from the top, that the box lo..hi can cover;
    None when nothing can be seen."""
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    w, h = camera.size
    x, y, depth = camera.project(corners)
    if camera.type == "PERSP" and np.any(depth <= 1e-9 * (1 + np.abs(corners).max())):
        return 0, 0, w, h         # the box reaches behind the camera: no projection bound
    if camera.type == "ORTHO" and np.all(depth < 0):
        return None
    x0 = int(np.clip(np.floor(x.min()) - 1, 0, w))
    x1 = int(np.clip(np.ceil(x.max()) + 1, 0, w))
    y0 = int(np.clip(np.floor(y.min()) - 1, 0, h))
    y1 = int(np.clip(np.ceil(y.max()) + 1, 0, h))
    if x0 >= x1 or y0 >= y1:
        return None
    return x0, y0, x1, y1


def _set_uniforms(prog, camera, settings):
    set_uniforms(prog, cam_pos=tuple(float(x) for x in camera.position),
                 cam_rot=tuple(float(x) for x in camera.rotation.T.ravel()),
                 pixel_size=float(camera.pixel_size),
                 centre_px=tuple(float(x) for x in camera.centre_px),
                 pixel_origin=tuple(int(x) for x in camera.pixel_origin),
                 image_size=(float(camera.size[0]), float(camera.size[1])))
    packed = [light.packed() for light in settings.lights]
    if "light_vec" in prog:
        prog["light_vec"].write(np.array([p[0] for p in packed], np.float32).tobytes())
    if "light_col" in prog:
        prog["light_col"].write(np.array([p[1] for p in packed], np.float32).tobytes())
    cones = [light.cone() for light in settings.lights]
    if "light_axis" in prog:
        prog["light_axis"].write(np.array([c[0] for c in cones], np.float32).tobytes())
    if "light_blend" in prog:
        prog["light_blend"].write(np.array([c[1] for c in cones], np.float32).tobytes())
    extents = [light.extent() for light in settings.lights]
    if "light_u" in prog:
        prog["light_u"].write(np.array([e[0] for e in extents], np.float32).tobytes())
    if "light_v" in prog:
        prog["light_v"].write(np.array([e[1] for e in extents], np.float32).tobytes())
    if "light_shadow" in prog:
        prog["light_shadow"].write(np.array([float(light.shadows) for light in settings.lights], np.float32).tobytes())
    set_uniforms(prog, background=settings.premultiplied_background(),
                 material=(settings.ambient, settings.diffuse, settings.specular, settings.shininess),
                 mpw_cap=float(settings.min_pixel_width_cap), t_eps=float(settings.transmittance_eps))
    set_uniforms(prog, **shading_model(settings.shading).uniforms(settings))


def _set_origin(frame):
    """A shadow set's origin as accel_beams.glsl's sun_origin: a light's position and extent,
    or w = -1 for a sun."""
    if frame.kind == "sun":
        return (0.0, 0.0, 0.0, -1.0)
    return (*(float(x) for x in frame.origin), float(frame.extent))


def _set_beam_uniforms(prog, beams):
    """The camera's and the suns' beams (tracer/scene_beams.py, BeamPlan) as the trace shader
    reads them (shaders/accel_beams.glsl)."""
    cam = beams.camera
    if cam is not None:
        f = cam.frame
        set_uniforms(prog, beam_box=(int(f.box[0]), int(f.box[1]), int(f.bin_px), int(f.dims[0])),
                     beam_rows=int(f.dims[1]), beam_keys=(float(f.key0), float(cam.fine_step)),
                     beam_sub=int(cam.sub),
                     beam_shift=tuple(float(x) for x in beams.camera_shift))
        if cam.reach is not None:
            set_uniforms(prog, beam_axis_reach=float(cam.reach))
    used = max([k + 1 for k in beams.light_sun if k >= 0], default=0)
    if used:
        sets = list(beams.suns)[:used]
        pick = lambda fn, dtype: np.array([fn(b) for b in sets], dtype)  # noqa: E731
        zero3 = (0.0, 0.0, 0.0)
        for name, fn, dtype in (
                ("sun_u", lambda b: b.frame.axes[0] if b else zero3, np.float32),
                ("sun_v", lambda b: b.frame.axes[1] if b else zero3, np.float32),
                ("sun_w", lambda b: b.frame.axes[2] if b else zero3, np.float32),
                ("sun_frame", lambda b: (b.frame.offset[0], b.frame.offset[1], b.frame.key0, b.fine_step) if b
                 else (0.0,) * 4, np.float32),
                ("sun_dims", lambda b: tuple(int(d) for d in b.frame.dims) if b else (0, 0), np.int32),
                ("sun_sub", lambda b: int(b.sub) if b else 0, np.int32),
                ("sun_reach", lambda b: float(b.reach) if b else 0.0, np.float32),
                ("sun_origin", lambda b: _set_origin(b.frame) if b else (0.0, 0.0, 0.0, -1.0), np.float32),
                ("sun_far", lambda b: float(b.frame.far_depth) if b else 0.0, np.float32),
                ("sun_anchor", lambda b: (*anchored(b.frame)[0], 0.0) if b else (0.0,) * 4, np.float32),
                ("sun_anchor_frame", lambda b: (*anchored(b.frame)[1], 0.0) if b else (0.0,) * 4, np.float32)):
            if name in prog:
                prog[name].write(pick(fn, dtype).tobytes())
    if "light_sun" in prog:
        prog["light_sun"].write(np.array(beams.light_sun, np.int32).tobytes())

# SPDX-License-Identifier: GPL-3.0-or-later
"""GPU ray tracer of continual cylinders (SPEC §6–7) in a standalone OpenGL context (EGL or
GLX on Linux, WGL on Windows, CGL on macOS; KEYSTRAND_GL_BACKEND picks one), with a float64
reference tracer of the same model. numpy + moderngl + hairio only.

    from tracer import Camera, Light, RenderSettings, Renderer, reference_render
    r = Renderer()                          # one GL context per process, reused
    r.set_strands(strands)                  # hairio.Strands -> cylinders, textures, grid
    cam = Camera.frame_bounds(*strands.bounds(), size=(512, 512))
    img = r.render(cam, RenderSettings(spp=4, shadows=True))   # (H, W, 4) float32
    ref = reference_render(strands, cam, RenderSettings(spp=4, shadows=True))  # float64

Images are linear, premultiplied RGBA with row 0 at the top. Modules: layout (the constants
and buffer layouts both builds and every shader share), cylinders (strands to cut
cylinders), grid (uniform grid, CSR lists, the frame both builds use), bvh (the BVH over
cylinder pieces, Renderer(accel="bvh")), camera
(Blender-exact projection), settings (lights, render settings), shading (the registry of
shading models), renderer and the modules it delegates to (gl_state, scene_buffers,
strand_upload, scene_grid, scene_bvh, draw; shaders/ for the GLSL), stats, gl_context (which backend
makes the context, where raw GL entry points come from), reference (float64 CPU tracer,
split as the shaders are), png, worker (out-of-process renderer), scenes (synthetic strands
for tests and benchmarks), __main__ (python -m tracer render). docs/ARCHITECTURE.md maps
them.
"""
from . import layout
from .camera import Camera
from .settings import Light, RenderSettings
from .cylinders import Cylinders, strands_to_cylinders
from .grid import Grid, build_grid


def __getattr__(name):
    # moderngl and the reference load on first use, so importing tracer stays cheap.
    if name == "Renderer":
        from .renderer import Renderer
        return Renderer
    if name == "reference_render":
        from .reference import reference_render
        return reference_render
    raise AttributeError(name)


__all__ = ["Camera", "Light", "RenderSettings", "Renderer", "reference_render",
           "Cylinders", "strands_to_cylinders", "Grid", "build_grid"]

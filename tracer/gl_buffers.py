# SPDX-License-Identifier: GPL-3.0-or-later
"""Buffer textures: a GL buffer read by shaders as a 1-D array of texels (GL 3.1 core:
samplerBuffer in GLSL, imageBuffer for compute writes), which moderngl does not wrap.

The scene's arrays live in them rather than in 2-D textures: a texel is found by its index
alone (no row/column split, no rows padded to a power of two), partial updates are byte
ranges, and on llvmpipe a texelFetch from a buffer costs less than a 2-D texture read
(docs/DECISIONS.md, "Scene data in buffer textures").

The few GL entry points moderngl lacks are called through ctypes, loaded through the
context's own glcontext loader (tracer/gl_context.py), so they come from the library that
made the context: libEGL, libGL (GLX), opengl32.dll (WGL) or the OpenGL framework (CGL).
"""
import ctypes
import weakref

from .gl_context import current_system, function_type, proc_loader

GL_TEXTURE_BUFFER = 0x8C2A
GL_TEXTURE0 = 0x84C0
GL_READ_ONLY, GL_WRITE_ONLY, GL_READ_WRITE = 0x88B8, 0x88B9, 0x88BA
# (dtype, components) -> sized internal format. RGB32F buffers need GL 4.0; only the
# compute passes (GL 4.3) use them.
FORMATS = {("f4", 1): 0x822E, ("f4", 3): 0x8815, ("f4", 4): 0x8814, ("i4", 1): 0x8235, ("i4", 2): 0x823B,
           ("i4", 4): 0x8D82, ("u4", 1): 0x8236, ("u4", 2): 0x823C}

# One set of entry points per context: on Windows a pointer is only valid for contexts like
# the one it was looked up in, so none outlives its context.
_ENTRIES = weakref.WeakKeyDictionary()


class Entries:
    """The GL functions used here, looked up once per context through `load` (name ->
    address)."""

    def __init__(self, load, version_code, system=None):
        prototype = getattr(ctypes, function_type(system or current_system()))

        def fn(fname, restype, *args):
            address = load(fname)
            if not address:
                raise RuntimeError(f"tracer: the OpenGL driver has no {fname}")
            return prototype(restype, *args)(address)

        u, i = ctypes.c_uint, ctypes.c_int
        self.gen_textures = fn("glGenTextures", None, i, ctypes.POINTER(u))
        self.delete_textures = fn("glDeleteTextures", None, i, ctypes.POINTER(u))
        self.active_texture = fn("glActiveTexture", None, u)
        self.bind_texture = fn("glBindTexture", None, u, u)
        self.tex_buffer = fn("glTexBuffer", None, u, u, u)
        self.use_program = fn("glUseProgram", None, u)
        self.uniform1i = fn("glUniform1i", None, i, i)
        self.get_integerv = fn("glGetIntegerv", None, u, ctypes.POINTER(i))
        # GL 4.2, for the compute passes only; macOS (4.1) has none. Asked by version, not by
        # a null pointer: Linux's dispatch libraries hand out a stub for any name.
        self.bind_image_texture = None
        if version_code >= 420:
            self.bind_image_texture = fn("glBindImageTexture", None, u, u, i, ctypes.c_ubyte, i, u, u)


def gl(ctx):
    """The entry points of `ctx` (looked up on first use)."""
    entries = _ENTRIES.get(ctx)
    if entries is None:
        entries = _ENTRIES[ctx] = Entries(proc_loader(ctx), ctx.version_code)
    return entries


class BufferTexture:
    """`capacity` texels of `components` x `dtype` ("f4" or "i4") in one buffer, seen by
    shaders as a buffer texture. The caller checks the driver's texel limit."""

    def __init__(self, ctx, capacity, components, dtype):
        self.format = FORMATS[(dtype, components)]
        self.components, self.dtype, self.capacity = components, dtype, int(capacity)
        self.texel_bytes = 4 * components
        self.ctx = ctx
        self.buffer = ctx.buffer(reserve=max(1, self.capacity) * self.texel_bytes)
        g = gl(ctx)
        name = ctypes.c_uint(0)
        g.gen_textures(1, ctypes.byref(name))
        self.glo = name.value
        self.use(0)
        g.tex_buffer(GL_TEXTURE_BUFFER, self.format, self.buffer.glo)

    def fits(self, texels, components, dtype):
        return (components, dtype) == (self.components, self.dtype) and texels <= self.capacity

    def use(self, unit):
        g = gl(self.ctx)
        g.active_texture(GL_TEXTURE0 + unit)
        g.bind_texture(GL_TEXTURE_BUFFER, self.glo)
        g.active_texture(GL_TEXTURE0)

    def bind_to_image(self, unit, read=False, write=True):
        access = GL_READ_WRITE if read and write else (GL_WRITE_ONLY if write else GL_READ_ONLY)
        bind = gl(self.ctx).bind_image_texture
        if bind is None:
            v = self.ctx.version_code
            raise RuntimeError(f"tracer: image buffers need OpenGL 4.2; this context has "
                               f"{v // 100}.{v // 10 % 10}; build with 'numpy'")
        bind(unit, self.glo, 0, 0, 0, access, self.format)

    def write(self, data, first=0):
        """Writes `data` (bytes-like) from texel `first` on."""
        self.buffer.write(data, offset=int(first) * self.texel_bytes)

    def read(self, texels=None, first=0):
        """Bytes of texels first..first+texels (to the end by default)."""
        texels = self.capacity - first if texels is None else texels
        return self.buffer.read(size=int(texels) * self.texel_bytes, offset=int(first) * self.texel_bytes)

    def release(self):
        if self.glo:
            name = ctypes.c_uint(self.glo)
            gl(self.ctx).delete_textures(1, ctypes.byref(name))
            self.glo = 0
            self.buffer.release()


def set_samplers(prog, **units):
    """Points the sampler uniforms of `prog` at texture units (moderngl ignores uniforms of
    buffer sampler types). Names the compiler dropped are skipped."""
    g = gl(prog.ctx)
    g.use_program(prog.glo)
    for name, unit in units.items():
        if name in prog:
            g.uniform1i(prog[name].location, int(unit))
    g.use_program(0)


GL_SHADER_STORAGE_BUFFER_OFFSET_ALIGNMENT = 0x90DF


def storage_limits(ctx):
    """(the largest storage buffer range a shader may bind, the alignment of a bound range's
    offset), in bytes: GL_MAX_SHADER_STORAGE_BLOCK_SIZE (128 MB on llvmpipe; a buffer bound
    whole past it may be cut short) and GL_SHADER_STORAGE_BUFFER_OFFSET_ALIGNMENT."""
    align = ctypes.c_int(0)
    gl(ctx).get_integerv(GL_SHADER_STORAGE_BUFFER_OFFSET_ALIGNMENT, ctypes.byref(align))
    return int(ctx.info["GL_MAX_SHADER_STORAGE_BLOCK_SIZE"]), max(int(align.value), 4)

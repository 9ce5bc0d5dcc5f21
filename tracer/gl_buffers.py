# SPDX-License-Identifier: GPL-3.0-or-later
"""Buffer textures: a GL buffer read by shaders as a 1-D array of texels (GL 3.1 core:
samplerBuffer in GLSL, imageBuffer for compute writes), which moderngl does not wrap.

The scene's arrays live in them rather than in 2-D textures: a texel is found by its index
alone (no row/column split, no rows padded to a power of two), partial updates are byte
ranges, and on llvmpipe a texelFetch from a buffer costs less than a 2-D texture read
(100,000 strands, 512x512: the whole render 14 % faster, same image).

The few GL entry points moderngl lacks are called through ctypes, from the EGL library the
headless context was made with (glcontext finds it the same way).
"""
import ctypes
import ctypes.util
import os

GL_TEXTURE_BUFFER = 0x8C2A
GL_TEXTURE0 = 0x84C0
GL_READ_ONLY, GL_WRITE_ONLY, GL_READ_WRITE = 0x88B8, 0x88B9, 0x88BA
# (dtype, components) -> sized internal format. RGB32F buffers need GL 4.0; only the
# compute passes (GL 4.3) use them.
FORMATS = {("f4", 1): 0x822E, ("f4", 3): 0x8815, ("f4", 4): 0x8814, ("i4", 1): 0x8235, ("i4", 2): 0x823B}

_GL = None


class _Entry:
    """The GL functions used here, looked up once through eglGetProcAddress."""

    def __init__(self):
        name = os.environ.get("GLCONTEXT_LINUX_LIBEGL") or ctypes.util.find_library("EGL") or "libEGL.so.1"
        egl = ctypes.CDLL(name)
        egl.eglGetProcAddress.restype = ctypes.c_void_p
        egl.eglGetProcAddress.argtypes = [ctypes.c_char_p]

        def fn(fname, restype, *args):
            ptr = egl.eglGetProcAddress(fname.encode())
            if not ptr:
                raise RuntimeError(f"tracer: the OpenGL driver has no {fname}")
            return ctypes.CFUNCTYPE(restype, *args)(ptr)

        u, i = ctypes.c_uint, ctypes.c_int
        self.gen_textures = fn("glGenTextures", None, i, ctypes.POINTER(u))
        self.delete_textures = fn("glDeleteTextures", None, i, ctypes.POINTER(u))
        self.active_texture = fn("glActiveTexture", None, u)
        self.bind_texture = fn("glBindTexture", None, u, u)
        self.tex_buffer = fn("glTexBuffer", None, u, u, u)
        self.use_program = fn("glUseProgram", None, u)
        self.uniform1i = fn("glUniform1i", None, i, i)
        self.bind_image_texture = None
        try:        # GL 4.2: only the compute passes need it
            self.bind_image_texture = fn("glBindImageTexture", None, u, u, i, ctypes.c_ubyte, i, u, u)
        except RuntimeError:
            pass


def gl():
    global _GL
    if _GL is None:
        _GL = _Entry()
    return _GL


class BufferTexture:
    """`capacity` texels of `components` x `dtype` ("f4" or "i4") in one buffer, seen by
    shaders as a buffer texture. The caller checks the driver's texel limit."""

    def __init__(self, ctx, capacity, components, dtype):
        self.format = FORMATS[(dtype, components)]
        self.components, self.dtype, self.capacity = components, dtype, int(capacity)
        self.texel_bytes = 4 * components
        self.buffer = ctx.buffer(reserve=max(1, self.capacity) * self.texel_bytes)
        g = gl()
        name = ctypes.c_uint(0)
        g.gen_textures(1, ctypes.byref(name))
        self.glo = name.value
        self.use(0)
        g.tex_buffer(GL_TEXTURE_BUFFER, self.format, self.buffer.glo)

    def fits(self, texels, components, dtype):
        return (components, dtype) == (self.components, self.dtype) and texels <= self.capacity

    def use(self, unit):
        g = gl()
        g.active_texture(GL_TEXTURE0 + unit)
        g.bind_texture(GL_TEXTURE_BUFFER, self.glo)
        g.active_texture(GL_TEXTURE0)

    def bind_to_image(self, unit, read=False, write=True):
        access = GL_READ_WRITE if read and write else (GL_WRITE_ONLY if write else GL_READ_ONLY)
        gl().bind_image_texture(unit, self.glo, 0, 0, 0, access, self.format)

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
            gl().delete_textures(1, ctypes.byref(name))
            self.glo = 0
            self.buffer.release()


def set_samplers(prog, **units):
    """Points the sampler uniforms of `prog` at texture units (moderngl ignores uniforms of
    buffer sampler types). Names the compiler dropped are skipped."""
    g = gl()
    g.use_program(prog.glo)
    for name, unit in units.items():
        if name in prog:
            g.uniform1i(prog[name].location, int(unit))
    g.use_program(0)

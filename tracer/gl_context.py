# SPDX-License-Identifier: GPL-3.0-or-later
"""The tracer's OpenGL context: which of glcontext's backends makes it, and where the raw GL
entry points moderngl does not wrap come from.

`KEYSTRAND_GL_BACKEND` picks the backend: `auto` (the default), `egl`, `glx`, `wgl` or `cgl`.
auto tries, on Linux, headless EGL and then GLX when an X display is set; on Windows WGL; on
macOS CGL (OpenGL 4.1 core there: no compute shaders, so the tracer builds in numpy).

Entry points come from the loader of the context in use (`ctx.mglo._context.load`, the
library glcontext itself made the context with), so a GLX context is never fed pointers from
libEGL, nor a WGL one pointers looked up before it existed. Only when moderngl stops exposing
that loader does `ctypes_loader` look them up by platform.

Every decision that depends on the platform takes it as an argument (`system`: "linux",
"windows" or "macos"), so it can be checked on any machine.
"""
import ctypes
import ctypes.util
import os
import sys
import weakref

from hairio import InputError

ENV = "KEYSTRAND_GL_BACKEND"
BACKENDS = ("auto", "egl", "glx", "wgl", "cgl")
PLATFORM_OF = {"egl": "linux", "glx": "linux", "wgl": "windows", "cgl": "macos"}
# glcontext's backend modules by the type of the loader they make; glcontext calls GLX "x11"
# and CGL "darwin".
_MODULE_TO_BACKEND = {"egl": "egl", "x11": "glx", "wgl": "wgl", "darwin": "cgl"}
_FIXES = {
    "egl": "install Mesa's EGL and drivers (Debian: libegl1 libegl-mesa0 libgl1-mesa-dri) or a GPU "
           "driver with EGL",
    "glx": "GLX needs an X display in DISPLAY (headless: run Xvfb, Debian package xvfb) and Mesa's "
           "GLX (Debian: libgl1 libglx-mesa0 libgl1-mesa-dri) or a GPU driver",
    "wgl": "install the graphics card maker's driver: Windows' own display driver and most remote "
           "desktops offer no OpenGL 3.3",
    "cgl": "macOS brings OpenGL 4.1 itself; a virtual machine without graphics acceleration has none",
}
# How each backend's entry points are found without glcontext's loader: (library, the
# library's lookup function or None for a plain symbol lookup, whether names the lookup
# refuses are the library's own exports). wglGetProcAddress refuses the GL 1.1 names
# (glBindTexture, glGenTextures) that opengl32.dll exports itself; macOS has no lookup
# function, its framework exports every name.
LOADERS = {
    "egl": ("EGL", "eglGetProcAddress", False),
    "glx": ("GL", "glXGetProcAddressARB", False),
    "wgl": ("opengl32", "wglGetProcAddress", True),
    "cgl": ("/System/Library/Frameworks/OpenGL.framework/OpenGL", None, True),
}
_MADE = weakref.WeakKeyDictionary()      # context -> backend, for contexts made here


def current_system(platform=None):
    """"linux", "windows" or "macos" for a sys.platform value (glcontext, too, treats every
    other Unix as Linux)."""
    platform = sys.platform if platform is None else platform
    if platform.startswith("win"):
        return "windows"
    if platform == "darwin":
        return "macos"
    return "linux"


def requested_backend(value=None):
    """The backend asked for: `value`, else KEYSTRAND_GL_BACKEND, else auto."""
    raw = os.environ.get(ENV, "") if value is None else value
    name = raw.strip().lower() or "auto"
    if name not in BACKENDS:
        raise InputError(f"{ENV}={raw!r}: expected one of {', '.join(BACKENDS)}; unset it or use "
                         "auto to let the tracer pick its platform's backend")
    return name


def candidates(requested, system, display=None):
    """The backends to try, in order, for `requested` on `system`; `display` is DISPLAY."""
    if requested == "auto":
        if system == "linux":
            # EGL needs no X server and survives a lost one, so it comes first.
            return ("egl", "glx") if display else ("egl",)
        return ("wgl",) if system == "windows" else ("cgl",)
    if PLATFORM_OF[requested] != system:
        here = [b for b in BACKENDS if b == "auto" or PLATFORM_OF[b] == system]
        raise InputError(f"{ENV}={requested}: {requested} exists on {PLATFORM_OF[requested]} only; "
                         f"on {system} use one of {', '.join(here)}")
    return (requested,)


def create_args(backend):
    """moderngl.create_standalone_context's arguments for `backend`. glcontext names only EGL;
    GLX, WGL and CGL are its default backend on their own platform."""
    return {"backend": "egl"} if backend == "egl" else {}


def create_context(value=None, system=None, display=None):
    """(a standalone OpenGL 3.3+ moderngl context, the backend that made it), trying the
    candidates for `value` (default: KEYSTRAND_GL_BACKEND) in order. A RuntimeError names each
    backend tried, why it failed and what to install."""
    import moderngl
    system = system or current_system()
    display = os.environ.get("DISPLAY") if display is None else display
    requested = requested_backend(value)
    failures = []
    for backend in candidates(requested, system, display):
        if backend == "glx" and not display:
            failures.append((backend, "no X display (DISPLAY is not set)"))
            continue
        try:
            ctx = moderngl.create_standalone_context(require=330, **create_args(backend))
        except Exception as e:   # glcontext raises a bare Exception for a missing library or driver
            failures.append((backend, str(e) or type(e).__name__))
            continue
        made = backend_of(ctx)
        if made not in (None, backend):
            ctx.release()
            failures.append((backend, f"glcontext made a {made} context instead"))
            continue
        _MADE[ctx] = backend
        return ctx, backend
    tried = "; ".join(f"{b}: {why}" for b, why in failures)
    fixes = " ".join(f"For {b}: {_FIXES[b]}." for b, _ in failures)
    raise RuntimeError(f"tracer: cannot create an OpenGL 3.3 context ({ENV}={requested}; tried {tried}). "
                       f"{fixes} {ENV} picks the backend ({', '.join(BACKENDS)}).")


def own_loader(ctx):
    """glcontext's loader object of `ctx` (None where moderngl does not expose it)."""
    loader = getattr(getattr(ctx, "mglo", None), "_context", None)
    return loader if callable(getattr(loader, "load", None)) else None


def backend_of(ctx):
    """The backend that made `ctx`: read from its glcontext loader's type, else as recorded
    when it was made here, else None."""
    loader = own_loader(ctx)
    if loader is not None:
        return _MODULE_TO_BACKEND.get(type(loader).__module__.rpartition(".")[2])
    return _MADE.get(ctx)


def proc_loader(ctx):
    """A function name -> address (0 when unknown) for the entry points of `ctx`."""
    loader = own_loader(ctx)
    if loader is not None:
        return loader.load
    backend = backend_of(ctx)
    if backend is None:
        raise RuntimeError("tracer: cannot tell which backend made this OpenGL context, so not "
                           "where its entry points are; make it with tracer.gl_context.create_context")
    return ctypes_loader(backend)


def function_type(system):
    """The ctypes prototype factory for GL functions: GL's APIENTRY is __stdcall on Windows."""
    return "WINFUNCTYPE" if system == "windows" else "CFUNCTYPE"


def _open_library(name):
    if name.startswith("/"):
        return ctypes.CDLL(name)
    if name == "EGL" and os.environ.get("GLCONTEXT_LINUX_LIBEGL"):   # the one glcontext used
        return ctypes.CDLL(os.environ["GLCONTEXT_LINUX_LIBEGL"])
    if name == "GL" and os.environ.get("GLCONTEXT_LINUX_LIBGL"):
        return ctypes.CDLL(os.environ["GLCONTEXT_LINUX_LIBGL"])
    if name == "opengl32":
        return ctypes.WinDLL("opengl32")
    return ctypes.CDLL(ctypes.util.find_library(name) or f"lib{name}.so.1")


def ctypes_loader(backend):
    """A name -> address (0 when unknown) lookup for `backend` through ctypes (LOADERS says
    where)."""
    library, lookup, own_exports = LOADERS[backend]
    lib = _open_library(library)
    get = None
    if lookup is not None:
        get = getattr(lib, lookup)
        get.restype, get.argtypes = ctypes.c_void_p, [ctypes.c_char_p]

    def load(name):
        address = get(name.encode()) if get is not None else None
        if backend == "wgl" and address in (1, 2, 3, 2 ** 64 - 1):   # wglGetProcAddress's other "no"
            address = None
        if not address and own_exports:
            try:
                address = ctypes.cast(getattr(lib, name), ctypes.c_void_p).value
            except AttributeError:
                address = None
        return address or 0

    load.backend = backend
    return load

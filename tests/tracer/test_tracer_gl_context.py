# SPDX-License-Identifier: GPL-3.0-or-later
"""The GL context: the backend each platform tries, the one in use is the one asked for, the
raw entry points come from the context's own loader (or, without it, from the platform's
library), and a driver without compute shaders (macOS's GL 4.1) renders with the numpy build."""
import ctypes
import gc
import json
import os
import subprocess
import sys
import weakref

import numpy as np
import pytest

from hairio import InputError
from tracer import Camera, Renderer, RenderSettings
from tracer import gl_buffers, gl_context
from tracer.gl_context import ENV, candidates, current_system, requested_backend
from tracer.gl_state import context_backend, shared_context

from tracer_scenes import curls

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
ENTRY_POINTS = {"gen_textures": "glGenTextures", "delete_textures": "glDeleteTextures",
                "active_texture": "glActiveTexture", "bind_texture": "glBindTexture",
                "tex_buffer": "glTexBuffer", "use_program": "glUseProgram", "uniform1i": "glUniform1i",
                "get_integerv": "glGetIntegerv",
                "bind_image_texture": "glBindImageTexture"}


# --- which backend, on which platform ---------------------------------------------------
def test_auto_tries_egl_then_glx_on_linux_and_glx_only_with_a_display():
    assert candidates("auto", "linux", display=":1") == ("egl", "glx")
    assert candidates("auto", "linux", display=None) == ("egl",)
    assert candidates("auto", "linux", display="") == ("egl",)


def test_auto_is_wgl_on_windows_and_cgl_on_macos():
    assert candidates("auto", "windows", display=":1") == ("wgl",)
    assert candidates("auto", "macos") == ("cgl",)


@pytest.mark.parametrize("backend,system", [("egl", "linux"), ("glx", "linux"), ("wgl", "windows"), ("cgl", "macos")])
def test_a_named_backend_is_the_only_one_tried(backend, system):
    assert candidates(backend, system, display=":1") == (backend,)


@pytest.mark.parametrize("backend,system,offered", [("wgl", "linux", "auto, egl, glx"), ("egl", "windows", "auto, wgl"),
                                                    ("glx", "macos", "auto, cgl")])
def test_a_backend_of_another_platform_is_refused_naming_those_that_exist(backend, system, offered):
    with pytest.raises(InputError, match=f"{ENV}={backend}: .* on {system} use one of {offered}$"):
        candidates(backend, system)


def test_unknown_backend_values_are_refused_and_case_and_blanks_do_not_matter():
    with pytest.raises(InputError, match=f"{ENV}='vulkan': expected one of auto, egl, glx, wgl, cgl"):
        requested_backend("vulkan")
    assert requested_backend(" GLX ") == "glx"
    assert requested_backend("") == "auto"


def test_the_environment_names_the_backend(monkeypatch):
    monkeypatch.setenv(ENV, "cgl")
    assert requested_backend() == "cgl"
    monkeypatch.delenv(ENV)
    assert requested_backend() == "auto"
    monkeypatch.setenv(ENV, "opengl")
    with pytest.raises(InputError, match=ENV):
        gl_context.create_context()


@pytest.mark.parametrize("platform,system", [("linux", "linux"), ("win32", "windows"), ("darwin", "macos"),
                                             ("freebsd14", "linux")])
def test_platforms_map_to_the_three_systems(platform, system):
    assert current_system(platform) == system


def test_glx_without_a_display_fails_naming_what_was_tried_and_what_to_install():
    with pytest.raises(RuntimeError) as e:
        gl_context.create_context("glx", system="linux", display="")
    message = str(e.value)
    assert f"{ENV}=glx; tried glx: no X display (DISPLAY is not set)" in message
    assert "xvfb" in message and "libglx-mesa0" in message


def test_a_backend_that_fails_is_named_with_its_error(monkeypatch):
    import moderngl

    def broken(**kwargs):
        raise Exception("libEGL.so.1: cannot open shared object file")
    monkeypatch.setattr(moderngl, "create_standalone_context", broken)
    with pytest.raises(RuntimeError, match=r"tried egl: libEGL.so.1: cannot open.*; glx: libEGL.*For egl: install "
                                           r"Mesa's EGL.*For glx: GLX needs"):
        gl_context.create_context("auto", system="linux", display=":1")


# --- the context in use -----------------------------------------------------------------
def test_the_context_in_use_is_made_by_the_backend_asked_for():
    # Read from the type of glcontext's loader, not from what was asked: a GLX run that fell
    # back to EGL fails here.
    used = gl_context.backend_of(shared_context())
    assert used == context_backend() == Renderer(build="numpy").stats.gl_backend
    asked = requested_backend()
    if asked == "auto":
        assert used in candidates("auto", current_system(), os.environ.get("DISPLAY"))
    else:
        assert used == asked


def test_raw_entry_points_come_from_the_contexts_own_loader():
    ctx = shared_context()
    own = ctx.mglo._context
    g = gl_buffers.gl(ctx)
    for attr, name in ENTRY_POINTS.items():
        fn = getattr(g, attr)
        if fn is None:       # glBindImageTexture below GL 4.2
            assert attr == "bind_image_texture" and ctx.version_code < 420
            continue
        assert ctypes.cast(fn, ctypes.c_void_p).value == own.load(name) != 0, name


class _FakeContext:
    """What gl() reads of a context: its loader and version."""

    def __init__(self, addresses, version_code=330):
        self.asked = []
        loader = type("GLContext", (), {"load": lambda _, name: self.asked.append(name) or addresses[name]})()
        self.mglo = type("Mglo", (), {"_context": loader})()
        self.version_code = version_code


def test_entry_points_are_looked_up_once_per_context_and_die_with_it():
    real = shared_context().mglo._context
    addresses = {name: real.load(name) for name in ENTRY_POINTS.values()}
    a, b = _FakeContext(addresses), _FakeContext(addresses)
    ga = gl_buffers.gl(a)
    assert gl_buffers.gl(a) is ga and a.asked.count("glTexBuffer") == 1
    assert gl_buffers.gl(b) is not ga and b.asked.count("glTexBuffer") == 1
    assert "glBindImageTexture" not in a.asked and ga.bind_image_texture is None     # GL 3.3: not asked
    alive, gone = len(gl_buffers._ENTRIES), weakref.ref(b)
    del b
    gc.collect()
    assert gone() is None and len(gl_buffers._ENTRIES) == alive - 1      # no entry outlives its context


def test_windows_entry_points_use_the_stdcall_prototype(monkeypatch):
    made = []

    def winfunctype(restype, *args):
        made.append(args)
        return ctypes.CFUNCTYPE(restype, *args)
    monkeypatch.setattr(ctypes, "WINFUNCTYPE", winfunctype, raising=False)
    real = shared_context().mglo._context
    gl_buffers.Entries(real.load, 450, system="windows")
    assert len(made) == len(ENTRY_POINTS)
    made.clear()
    gl_buffers.Entries(real.load, 450, system="linux")
    assert made == []


# --- the ctypes loaders, used only where moderngl hides glcontext's ------------------------
class _FakeLibrary:
    """A shared library: its exports, and a lookup function answering `lookup_answers`."""

    def __init__(self, exports, lookup=None, lookup_answers=None):
        for name, address in exports.items():
            setattr(self, name, ctypes.c_void_p(address))
        if lookup:
            answers = lookup_answers or {}
            setattr(self, lookup, type("Lookup", (), {"__call__": lambda _, name: answers.get(name.decode())})())


def test_wgl_takes_gl_1_1_names_from_opengl32s_own_exports(monkeypatch):
    # wglGetProcAddress answers 0 or one of its small error codes for what opengl32 exports.
    lib = _FakeLibrary({"glBindTexture": 0x1000, "glGenTextures": 0x2000}, "wglGetProcAddress",
                       {"glTexBuffer": 0x3000, "glBindTexture": 2, "glGenTextures": None})
    opened = []
    monkeypatch.setattr(gl_context, "_open_library", lambda name: opened.append(name) or lib)
    load = gl_context.ctypes_loader("wgl")
    assert opened == ["opengl32"]
    assert (load("glTexBuffer"), load("glBindTexture"), load("glGenTextures"), load("glNoSuch")) == (0x3000, 0x1000, 0x2000, 0)


def test_cgl_looks_names_up_in_the_opengl_framework(monkeypatch):
    lib = _FakeLibrary({"glTexBuffer": 0x4000})
    opened = []
    monkeypatch.setattr(gl_context, "_open_library", lambda name: opened.append(name) or lib)
    load = gl_context.ctypes_loader("cgl")
    assert opened == ["/System/Library/Frameworks/OpenGL.framework/OpenGL"]
    assert (load("glTexBuffer"), load("glBindImageTexture")) == (0x4000, 0)


@pytest.mark.parametrize("backend,library,lookup", [("egl", "EGL", "eglGetProcAddress"), ("glx", "GL", "glXGetProcAddressARB")])
def test_linux_backends_ask_their_own_library(monkeypatch, backend, library, lookup):
    lib = _FakeLibrary({"glTexBuffer": 0x5000}, lookup, {"glTexBuffer": 0x6000})
    opened = []
    monkeypatch.setattr(gl_context, "_open_library", lambda name: opened.append(name) or lib)
    assert gl_context.ctypes_loader(backend)("glTexBuffer") == 0x6000    # the lookup, not an export
    assert opened == [library]


def test_without_glcontexts_loader_the_backends_library_is_asked():
    class Hidden:        # a moderngl that no longer exposes mglo._context
        mglo = object()
    ctx = shared_context()
    gl_context._MADE[Hidden] = context_backend()
    load = gl_context.proc_loader(Hidden)
    assert load.backend == context_backend()
    with pytest.raises(RuntimeError, match="cannot tell which backend"):
        gl_context.proc_loader(type("Unknown", (), {"mglo": object()}))
    # The pointers it finds draw: a buffer texture read back through a samplerBuffer.
    g = gl_buffers.Entries(load, ctx.version_code)
    data = np.array([1.5, -2.0, 7.25, 0.5], np.float32)
    buf = ctx.buffer(data.tobytes())
    name = ctypes.c_uint(0)
    g.gen_textures(1, ctypes.byref(name))
    g.active_texture(gl_buffers.GL_TEXTURE0 + 3)
    g.bind_texture(gl_buffers.GL_TEXTURE_BUFFER, name.value)
    g.tex_buffer(gl_buffers.GL_TEXTURE_BUFFER, gl_buffers.FORMATS[("f4", 1)], buf.glo)
    g.active_texture(gl_buffers.GL_TEXTURE0)
    prog = ctx.program(vertex_shader="#version 330 core\nvoid main() { vec2 p = vec2((gl_VertexID << 1) & 2, "
                                     "gl_VertexID & 2); gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0); }",
                       fragment_shader="#version 330 core\nuniform samplerBuffer data; out float value;\n"
                                       "void main() { value = texelFetch(data, int(gl_FragCoord.x)).r; }")
    g.use_program(prog.glo)
    g.uniform1i(prog["data"].location, 3)
    g.use_program(0)
    fbo = ctx.framebuffer(color_attachments=[ctx.renderbuffer((4, 1), components=1, dtype="f4")])
    fbo.use()
    ctx.vertex_array(prog, []).render(vertices=3)
    got = np.frombuffer(fbo.read(components=1, dtype="f4"), np.float32)
    g.delete_textures(1, ctypes.byref(name))
    for obj in (fbo, prog, buf):
        obj.release()
    np.testing.assert_array_equal(got, data)


# --- without compute shaders (macOS: CGL, GL 4.1 core) --------------------------------------
_GL41 = r"""
import json, sys
import numpy as np
from tracer import Camera, Renderer, RenderSettings
from tracer.gl_buffers import gl
from tracer.gpu_build import compute_available
from tracer.gl_state import context_backend, shared_context
from tracer_scenes import curls
from hairio import InputError
ctx = shared_context()
report = {"version": ctx.version_code, "backend": context_backend(), "compute": compute_available(ctx),
          "bind_image_texture": gl(ctx).bind_image_texture is not None}
r = Renderer()
report["build"] = r.build
try:
    Renderer(build="gpu")
except InputError as e:
    report["gpu_refused"] = str(e)
s = curls(8, 8, seed=4, alpha=0.7)
r.set_strands(s)
np.save(sys.argv[1], r.render(Camera.frame_bounds(*s.bounds(), (32, 32)), RenderSettings(shadows=True, layers=4)))
print(json.dumps(report))
"""


def test_a_gl_4_1_driver_renders_with_the_numpy_build_and_no_image_binding(tmp_path):
    # Mesa's version override turns this machine's driver into one like macOS's: GL 4.1
    # core, no compute shaders, no glBindImageTexture.
    env = dict(os.environ, MESA_GL_VERSION_OVERRIDE="4.1", MESA_GLSL_VERSION_OVERRIDE="410",
               PYTHONPATH=os.pathsep.join([ROOT, os.path.dirname(os.path.abspath(__file__))]))
    out = tmp_path / "gl41.npy"
    run = subprocess.run([sys.executable, "-c", _GL41, str(out)], capture_output=True, text=True, env=env, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    report = json.loads(run.stdout.strip().splitlines()[-1])
    if report["version"] != 410:
        pytest.skip(f"this driver ignores Mesa's version override (reports {report['version']}); "
                    "it is not Mesa")
    assert report["backend"] == context_backend()
    assert report["compute"] is False and report["bind_image_texture"] is False
    assert report["build"] == "numpy" and "needs compute shaders" in report["gpu_refused"]
    s = curls(8, 8, seed=4, alpha=0.7)
    here = Renderer(build="numpy")
    here.set_strands(s)
    want = here.render(Camera.frame_bounds(*s.bounds(), (32, 32)), RenderSettings(shadows=True, layers=4))
    got = np.load(out)
    assert (got[..., 3] > 0).mean() > 0.05
    np.testing.assert_array_equal(got, want)


def test_binding_an_image_without_gl_4_2_says_so():
    fake = _FakeContext({name: shared_context().mglo._context.load(name) for name in ENTRY_POINTS.values()},
                        version_code=410)
    tex = object.__new__(gl_buffers.BufferTexture)
    tex.ctx, tex.glo, tex.format = fake, 1, gl_buffers.FORMATS[("f4", 4)]
    with pytest.raises(RuntimeError, match="image buffers need OpenGL 4.2; this context has 4.1; build with 'numpy'"):
        tex.bind_to_image(0)

# SPDX-License-Identifier: GPL-3.0-or-later
import os

import pytest


def pytest_configure(config):
    """KEYSTRAND_GL_BACKEND=glx without a DISPLAY: the tests get a private Xvfb, started
    before any test module makes the context and stopped when the session ends."""
    from hairio import InputError
    from tracer.gl_context import requested_backend
    try:
        backend = requested_backend()
    except InputError as e:
        raise pytest.UsageError(str(e)) from None
    if backend != "glx" or os.environ.get("DISPLAY"):
        return
    from xvfb_display import Xvfb, XvfbError
    try:
        server = Xvfb()
    except XvfbError as e:
        raise pytest.UsageError(f"KEYSTRAND_GL_BACKEND=glx: {e}") from None
    os.environ["DISPLAY"] = server.display

    def stop():
        os.environ.pop("DISPLAY", None)
        server.stop()

    config.add_cleanup(stop)


def _session_renderer(build, accel=None):
    from tracer import Renderer
    from tracer.gpu_build import compute_available
    from tracer.gl_state import shared_context
    if build == "gpu" and not compute_available(shared_context()):
        pytest.skip("this driver has no compute shaders (OpenGL 4.3); the numpy build covers it")
    return Renderer(build=build) if accel is None else Renderer(build=build, accel=accel)


@pytest.fixture(scope="session", params=["gpu", "numpy"])
def renderer(request):
    """One renderer per build (one GL context for all) for the whole session, as in
    production: every renderer test runs with cylinders and structures made by the compute
    shaders and by numpy, with the default accelerator (beams: with the GPU build the
    camera's and the suns', with the numpy build the suns'; the grid for the rest). Drivers
    without compute shaders (macOS) have only the numpy build."""
    return _session_renderer(request.param)


@pytest.fixture(scope="session", params=["gpu", "numpy"])
def grid_renderer(request):
    """The session's renderer per build with the uniform grid as its accelerator (tests of the
    grid itself)."""
    return _session_renderer(request.param, "grid")

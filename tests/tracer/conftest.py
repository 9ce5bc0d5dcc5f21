# SPDX-License-Identifier: GPL-3.0-or-later
import pytest


@pytest.fixture(scope="session", params=["gpu", "numpy"])
def renderer(request):
    """One renderer per build (one EGL context for all) for the whole session, as in
    production: every renderer test runs with cylinders and grid made by the compute
    shaders and by numpy. Drivers without compute shaders (macOS) have only the numpy build."""
    from tracer import Renderer
    from tracer.gpu_build import compute_available
    from tracer.renderer import shared_context
    if request.param == "gpu" and not compute_available(shared_context()):
        pytest.skip("this driver has no compute shaders (OpenGL 4.3); the numpy build covers it")
    return Renderer(build=request.param)

# SPDX-License-Identifier: GPL-3.0-or-later
"""The process's GL state: one standalone OpenGL context, made on first use by the backend
KEYSTRAND_GL_BACKEND asks for (tracer/gl_context.py), and the compute passes compiled in it.
Every Renderer of the process shares them."""
from .gl_context import create_context
from .gpu_beams import BeamBuilder
from .gpu_build import GpuBuilder

_CONTEXT = None
_BACKEND = None
_BUILDER = None
_BEAM_BUILDER = None


def shared_context():
    """The process's one standalone OpenGL context (created on first use)."""
    global _CONTEXT, _BACKEND
    if _CONTEXT is None:
        _CONTEXT, _BACKEND = create_context()
    return _CONTEXT


def context_backend():
    """The backend of the shared context ("egl", "glx", "wgl" or "cgl"), creating it first."""
    shared_context()
    return _BACKEND


def gpu_builder():
    """The compute passes of the shared context (compiled on first use)."""
    global _BUILDER
    if _BUILDER is None:
        _BUILDER = GpuBuilder(shared_context())
    return _BUILDER


def beam_builder():
    """The beams' compute passes of the shared context (tracer/gpu_beams.py)."""
    global _BEAM_BUILDER
    if _BEAM_BUILDER is None:
        _BEAM_BUILDER = BeamBuilder(shared_context())
    return _BEAM_BUILDER

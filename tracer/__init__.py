# SPDX-License-Identifier: GPL-3.0-or-later
"""GPU ray tracer of continual cylinders (SPEC §6–7), headless through EGL, with a float64
reference tracer of the same model. numpy + moderngl + hairio only."""
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

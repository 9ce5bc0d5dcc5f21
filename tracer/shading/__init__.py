# SPDX-License-Identifier: GPL-3.0-or-later
"""The registry of shading models: every list of models (RenderSettings, the command line,
the float64 references, the add-on's menu) reads SHADING_MODELS, so a model plugs in here
and nowhere else.

A model is two functions of the same shape, one per side:

* GLSL, in tracer/shaders/<glsl>: `vec3 shade_light(Surface s, vec3 L)`, the light the
  surface sends toward the eye per unit of light colour arriving from the unit direction
  L (toward the light). `Surface` (tracer/shaders/trace_main.glsl): p (hit point), T (unit
  tangent), N (unit normal of the surface entered, facing the ray), V (unit ray
  direction, from the eye), color (base colour); the uniform `material` holds (ambient,
  diffuse, specular, shininess).
* float64, in tracer/shading/<module>.py: `shade_light(s, L, settings)` on (n,) arrays
  of the same fields (tracer.shading.Surface), returning (n, 3).

A model with settings of its own gives `uniforms(settings)`: the uniforms its GLSL reads
(name -> value), set on every draw.

The ambient term, the lights, their colours and the shadows are the tracer's (the same for
every model).
"""
import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from hairio import InputError

from . import chiang, kajiya_kay, phong


@dataclass(frozen=True)
class Surface:
    """Float64 arrays of the hit points to shade, each (n,3) but `color` (n,3) too."""
    p: np.ndarray
    T: np.ndarray
    N: np.ndarray
    V: np.ndarray
    color: np.ndarray


@dataclass(frozen=True)
class ShadingModel:
    name: str               # what settings, the command line and files say
    label: str              # what a menu shows
    description: str        # a tooltip
    glsl: str               # file in tracer/shaders defining shade_light
    reference: Callable     # float64 shade_light(surface, L, settings) -> (n, 3)
    needs_normal: bool      # whether shade_light reads s.N (the references skip it otherwise)
    uniforms: Callable = field(default=lambda settings: {})   # settings -> {uniform: value}
    # The meshes beside the hair reflect light as Lambertian surfaces of their base colour:
    # base colour / pi times the light's irradiance times cos. A model in radiometric units
    # (its lights are irradiance, as Cycles' sun strength is) takes the 1/pi; the models
    # with lights in their own units take the base colour as is, as their hair does.
    mesh_brdf: float = 1.0


SHADING_MODELS = (
    ShadingModel("chiang", "Principled hair (Chiang)",
                 "Physically based fibre scattering, the model of Cycles' Principled Hair BSDF (Chiang)",
                 "shading_chiang.glsl", chiang.shade_light, needs_normal=True, uniforms=chiang.uniforms,
                 mesh_brdf=1.0 / math.pi),
    ShadingModel("kajiya-kay", "Kajiya-Kay", "The classic hair shading, with a highlight along the strand",
                 "shading_kajiya_kay.glsl", kajiya_kay.shade_light, needs_normal=False),
    ShadingModel("phong", "Phong", "Plastic-like shading, as in the thesis",
                 "shading_phong.glsl", phong.shade_light, needs_normal=True),
)
DEFAULT_SHADING = SHADING_MODELS[0].name


def shading_names():
    return tuple(m.name for m in SHADING_MODELS)


def shading_model(name):
    """The model called `name`; InputError naming the choices otherwise."""
    for m in SHADING_MODELS:
        if m.name == name:
            return m
    raise InputError(f"shading: {name!r}; use one of {', '.join(repr(n) for n in shading_names())}")


def enum_items():
    """(identifier, label, description) per model, for a menu (Blender's EnumProperty)."""
    return tuple((m.name, m.label, m.description) for m in SHADING_MODELS)

# SPDX-License-Identifier: GPL-3.0-or-later
"""Kajiya-Kay (1989) in float64: the mirror of tracer/shaders/shading_kajiya_kay.glsl.
A strand is a thin cylinder seen from afar: diffuse by the sine of the angle between
tangent and light, a highlight on the cone of directions mirroring the light about the
tangent."""
import numpy as np


def shade_light(s, L, settings):
    dot = lambda x, y: np.einsum("ij,ij->i", x, y)  # noqa: E731
    tl, tv = dot(s.T, L), dot(s.T, s.V)
    sl = np.sqrt(np.maximum(0, 1 - tl * tl))
    sv = np.sqrt(np.maximum(0, 1 - tv * tv))
    diff = sl
    spec = np.maximum(0, tl * tv + sl * sv) ** settings.shininess
    return settings.diffuse * diff[:, None] * s.color + settings.specular * spec[:, None]

# SPDX-License-Identifier: GPL-3.0-or-later
"""Phong, as the thesis shades cylinders (SPEC §7), in float64: the mirror of
tracer/shaders/shading_phong.glsl. Diffuse by the normal of the surface entered, a
highlight around the light mirrored about that normal."""
import numpy as np


def shade_light(s, L, settings):
    dot = lambda x, y: np.einsum("ij,ij->i", x, y)  # noqa: E731
    nl = dot(s.N, L)
    diff = np.maximum(nl, 0)
    R = 2 * nl[:, None] * s.N - L
    spec = np.where(diff > 0, np.maximum(dot(R, -s.V), 0) ** settings.shininess, 0)
    return settings.diffuse * diff[:, None] * s.color + settings.specular * spec[:, None]

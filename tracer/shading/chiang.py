# SPDX-License-Identifier: GPL-3.0-or-later
"""Principled hair (Chiang et al. 2016, the model of Cycles' Principled Hair BSDF) as a
shading model of the registry: the float64 mirror of shade_light in
tracer/shaders/shading_chiang.glsl; the fibre model itself is tracer/hair_bsdf.py.

What a strand's colour means (RenderSettings.hair_color):

* "strand" (the default): the colour is the hair's colour, as Cycles' "Direct Coloring"
  shows it: absorption sigma_a = (log(colour) / f(radial roughness))^2, the inverse of the
  fit of Chiang et al. eq. 9 from absorption to the colour a fibre shows after multiple
  scattering. The add-on's hair material is this node set-up (Principled Hair, Direct
  Coloring, fed the strands' colour attribute), so the preview predicts what Cycles renders
  in Blender out of the box.
* "melanin": absorption from the settings' melanin and melanin redness, plus the strand
  colour as Cycles' Tint (the same colour-to-absorption mapping, added): white strands
  show the melanin alone, a coloured strand is dyed that colour over it.

The light's part is radiance = irradiance * sum_p Mp Ap Np (the cosine is in the model, as
in Cycles' evaluation); `diffuse`, `specular` and `shininess` play no part. h, where the ray
meets the fibre across its width, comes from the normal of the surface entered (-N.Y in
the fibre frame, Cycles' dot(cross(Ng, X), Z)); on a cut plane (a strand end, the exposed
crescent of a bend) the normal runs along the strand and h comes out near 0.
"""
import numpy as np

from .. import hair_bsdf as hb


def lobes(settings):
    """FibreLobes of the settings (the node's sliders, Cycles' mapping)."""
    return hb.fibre_lobes(settings.hair_roughness, settings.hair_radial_roughness, settings.hair_coat,
                          settings.hair_ior, np.radians(settings.hair_cuticle_tilt))


def base_absorption(settings):
    """Absorption (3,) every strand has before its colour's: the melanin's, or none when the
    colour is the hair's colour."""
    if settings.hair_color == "strand":
        return np.zeros(3)
    return hb.sigma_a_from_melanin(settings.hair_melanin, settings.hair_melanin_redness)


def absorption(color, settings):
    """Absorption (n, 3) of strands of colour `color` (n, 3)."""
    return base_absorption(settings) + hb.sigma_a_from_color(color, settings.hair_radial_roughness)


def shade_light(s, L, settings):
    wo = -s.V
    _, Y, _ = hb.fibre_frame(s.T, wo)
    h = np.clip(-np.einsum("ij,ij->i", s.N, Y), -1.0, 1.0)
    return hb.hair_bsdf(L, wo, s.T, h, absorption(s.color, settings), lobes(settings))


def uniforms(settings):
    """The uniforms shading_chiang.glsl's shade_light reads."""
    f = lobes(settings)
    return {"hair_lobes": (f.v, f.v_r, f.s, f.alpha), "hair_eta": f.eta,
            "hair_base_sigma": tuple(float(x) for x in base_absorption(settings)),
            "hair_radial_roughness": float(settings.hair_radial_roughness)}

# SPDX-License-Identifier: GPL-3.0-or-later
"""The fibre scattering model of Chiang, Bitterli, Tappan and Burley (2016), "A practical and
controllable hair and fur model for production path tracing", as Cycles' Principled Hair BSDF
("Chiang" model) evaluates it for direct light; float64 numpy, vectorised over hits.

shaders/shading_chiang.glsl is the same model, function for function (same names, same order
of operations), so the GPU preview and this reference can be compared number by number.

A fibre is a dielectric cylinder (index of refraction eta) whose interior absorbs with
coefficient sigma_a per unit radius. Light leaving toward the viewer is the sum of lobes p:
p = 0 reflects at the surface (R), p = 1 goes through (TT), p = 2 reflects once inside (TRT),
and p = 3 stands for every longer path (TRRT+). Each lobe is

    Mp(theta_i, theta_o)   longitudinal spread (a von Mises-Fisher-like lobe, variance v)
  * Ap(theta_o, h)         attenuation: Fresnel and absorption along the p-th path
  * Np(phi, h)             azimuthal spread (a logistic trimmed to [-pi, pi], scale s)

and the radiance from a light of irradiance E (along its direction) is E * sum_p Mp Ap Np:
like pbrt-v4's HairBxDF times |cos theta_i|, and like Cycles' bsdf_hair_chiang_eval, whose
result already holds the cosine.

Angles (pbrt's and Cycles' frame): X is the fibre tangent, root to tip; Y = X x wo
normalised (so wo lies in the X-Z plane); Z = X x Y. theta is the angle to the normal plane
(sin theta = w.X), phi the angle in it. h in [-1, 1] is where the ray meets the fibre across
its width (0: through the axis, +-1: grazing), h = -(p - axis).Y / r for a hit point p.

Where Cycles and pbrt-v4 differ, this follows Cycles (the render it must predict): the cuticle
tilt rotates theta_i (pbrt rotates theta_o), the TRRT+ lobe is not tilted, the R lobe's
roughness is scaled by (1 - coat), and I0 is Cycles' (and pbrt's) 10-term series, with the
asymptotic form of log I0 past 12. Both fall short of the true I0 by up to 2 % near x = 12,
where the R and TT lobes of a roughness-0.3 fibre peak; matching them keeps the preview
within reach of Cycles' figures rather than of the textbook's.

The model is not reciprocal in general: Ap and gamma_t are taken at the outgoing angle only
(as in the paper, pbrt and Cycles). It is where |theta_i| = |theta_o|, at h = 0 and no tilt.
"""
from dataclasses import dataclass

import numpy as np

# Absorption of one unit of eumelanin and of pheomelanin per unit radius, linear RGB
# (Donner and Jensen's measured spectra reduced to RGB, as in pbrt-v4 and Cycles).
EUMELANIN_SIGMA_A = np.array([0.506, 0.841, 1.653])
PHEOMELANIN_SIGMA_A = np.array([0.343, 0.733, 1.924])
# Cycles' Principled Hair BSDF defaults (melanin parametrisation).
DEFAULT_MELANIN = 0.8
DEFAULT_MELANIN_REDNESS = 1.0
DEFAULT_ROUGHNESS = 0.3
DEFAULT_RADIAL_ROUGHNESS = 0.3
DEFAULT_COAT = 0.0
DEFAULT_IOR = 1.55
DEFAULT_OFFSET = np.radians(2.0)      # cuticle tilt alpha, radians
# Below this variance Mp is evaluated in log space (the I0 series would overflow float32).
LOG_MP_BELOW = 0.1
LOG_I0_ABOVE = 12.0


@dataclass(frozen=True)
class FibreLobes:
    """A fibre's lobe parameters, precomputed once (Cycles' bsdf_hair_chiang_setup):
    v the longitudinal variance (TT uses v/4, TRT and TRRT+ 4v), v_r the R lobe's, s the
    logistic scale of Np, alpha the cuticle tilt (radians), eta the index of refraction."""
    v: float
    v_r: float
    s: float
    alpha: float
    eta: float


def _unit_clamp(x):
    return float(np.clip(x, 0.001, 1.0))


def longitudinal_variance(roughness):
    """beta_m in [0, 1] -> v: the fit of Chiang et al. (eq. 7) that makes the lobe's width
    grow roughly linearly with the slider."""
    b = _unit_clamp(roughness)
    return (0.726 * b + 0.812 * b ** 2 + 3.7 * b ** 20) ** 2


def logistic_scale(radial_roughness):
    """beta_n in [0, 1] -> s (eq. 8)."""
    b = _unit_clamp(radial_roughness)
    return (0.265 * b + 1.194 * b ** 2 + 5.372 * b ** 22) * np.sqrt(np.pi / 8.0)


def fibre_lobes(roughness=DEFAULT_ROUGHNESS, radial_roughness=DEFAULT_RADIAL_ROUGHNESS,
                coat=DEFAULT_COAT, ior=DEFAULT_IOR, offset=DEFAULT_OFFSET):
    """The Principled Hair node's sliders -> FibreLobes, as Cycles maps them (coat lowers
    the R lobe's roughness only: Cycles' "primary reflection roughness")."""
    b = _unit_clamp(roughness)
    return FibreLobes(v=longitudinal_variance(b),
                      v_r=longitudinal_variance((1.0 - float(np.clip(coat, 0.0, 1.0))) * b),
                      s=logistic_scale(radial_roughness), alpha=float(offset), eta=float(ior))


def sigma_a_from_melanin(melanin, redness):
    """Absorption (..., 3) for the node's Melanin and Melanin Redness in [0, 1]: the slider
    maps to a concentration by -log(1 - m) (perceptually even steps), which redness splits
    between pheomelanin and eumelanin."""
    m = np.asarray(melanin, np.float64)
    r = np.asarray(redness, np.float64)
    c = -np.log(np.maximum(1.0 - m, 1e-4))
    return ((c * (1.0 - r))[..., None] * EUMELANIN_SIGMA_A + (c * r)[..., None] * PHEOMELANIN_SIGMA_A)


def albedo_roughness_scale(radial_roughness):
    """The polynomial of Chiang et al. (eq. 9) relating absorption to the colour a fibre of
    that azimuthal roughness shows after multiple scattering."""
    x = radial_roughness
    return (((((0.245 * x) + 5.574) * x - 10.73) * x + 2.532) * x - 0.215) * x + 5.969


def sigma_a_from_color(color, radial_roughness=DEFAULT_RADIAL_ROUGHNESS):
    """Absorption (..., 3) whose hair shows `color` (linear RGB, in (0, 1]): Cycles' "Direct
    Coloring" and its Tint. The radial roughness is used unclamped, as Cycles passes it."""
    c = np.clip(np.asarray(color, np.float64), 1e-5, 1.0)
    return (np.log(c) / albedo_roughness_scale(float(radial_roughness))) ** 2


# --- the lobes' functions ------------------------------------------------------------------

def i0(x):
    """Modified Bessel function I0 by its first 10 series terms (Cycles' and pbrt's)."""
    x2 = np.asarray(x, np.float64) ** 2
    val = 1.0 + 0.25 * x2
    power = x2 * x2
    fact2 = 1.0
    pow4 = 16.0
    for i in range(2, 10):
        fact2 *= i * i
        val = val + power / (pow4 * fact2)
        power = power * x2
        pow4 *= 4.0
    return val


def log_i0(x):
    """log I0(x): the series below LOG_I0_ABOVE, the asymptotic form above (x >= 0)."""
    x = np.asarray(x, np.float64)
    xs = np.maximum(x, 1e-30)
    big = x + 0.5 * (1.0 / (8.0 * xs) - np.log(2.0 * np.pi) - np.log(xs))
    return np.where(x > LOG_I0_ABOVE, big, np.log(i0(np.minimum(x, LOG_I0_ABOVE))))


def mp(sin_i, cos_i, sin_o, cos_o, v):
    """Longitudinal scattering Mp (Chiang et al. eq. 4), normalised over theta_i."""
    a = cos_i * cos_o / v
    b = sin_i * sin_o / v
    if v <= LOG_MP_BELOW:
        # 1/sinh(1/v) = 2 exp(-1/v) to float precision here; log space keeps I0 finite.
        return np.exp(log_i0(a) - b - 1.0 / v + 0.6931 + np.log(0.5 / v))
    return np.exp(-b) * i0(a) / (np.sinh(1.0 / v) * 2.0 * v)


def logistic(x, s):
    e = np.exp(-np.abs(x) / s)
    return e / (s * (1.0 + e) ** 2)


def logistic_cdf(x, s):
    arg = -np.asarray(x, np.float64) / s
    return np.where(arg > 88.0, 0.0, 1.0 / (1.0 + np.exp(np.minimum(arg, 88.0))))


def trimmed_logistic(x, s):
    """The logistic restricted to [-pi, pi] and renormalised there."""
    return logistic(x, s) / (1.0 - 2.0 * logistic_cdf(-np.pi, s))


def delta_phi(p, gamma_o, gamma_t):
    """Azimuthal change of direction of the p-th path (eq. 3 of d'Eon et al. 2011)."""
    return 2.0 * p * gamma_t - 2.0 * gamma_o + p * np.pi


def wrap_angle(a):
    """a mapped to [-pi, pi)."""
    return (a + np.pi) - 2.0 * np.pi * np.floor((a + np.pi) / (2.0 * np.pi)) - np.pi


def np_lobe(phi, p, s, gamma_o, gamma_t):
    """Azimuthal scattering Np of lobe p (p < 3)."""
    return trimmed_logistic(wrap_angle(phi - delta_phi(p, gamma_o, gamma_t)), s)


def fresnel_dielectric(cos_i, eta):
    """Unpolarised Fresnel reflectance entering a dielectric of index eta at cos_i."""
    c = np.abs(cos_i)
    g2 = eta * eta - 1.0 + c * c
    g = np.sqrt(np.maximum(g2, 0.0))
    a = (g - c) / (g + c)
    b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    return np.where(g2 > 0.0, 0.5 * a * a * (1.0 + b * b), 1.0)


def ap(f, T):
    """Attenuation (4, N, 3) of R, TT, TRT and TRRT+ from the Fresnel reflectance f (N,) and
    the transmittance T (N, 3) of one pass through the fibre."""
    f = f[:, None]
    a0 = np.broadcast_to(f, T.shape)
    a1 = (1.0 - f) ** 2 * T
    a2 = a1 * T * f
    tf = T * f
    a3 = a2 * np.where(tf < 1.0, tf / np.where(tf < 1.0, 1.0 - tf, 1.0), 0.0)
    return np.stack([a0, a1, a2, a3])


def tilted_angles(sin_i, cos_i, alpha):
    """(sin, cos) of theta_i turned by the cuticle tilt for R (+2 alpha), TT (-alpha) and
    TRT (-4 alpha): three pairs, Cycles' hair_alpha_angles."""
    s1, c1 = np.sin(alpha), np.cos(alpha)
    s2, c2 = 2.0 * s1 * c1, c1 * c1 - s1 * s1
    s4, c4 = 2.0 * s2 * c2, c2 * c2 - s2 * s2
    return ((sin_i * c2 + cos_i * s2, np.abs(cos_i * c2 - sin_i * s2)),
            (sin_i * c1 - cos_i * s1, np.abs(cos_i * c1 + sin_i * s1)),
            (sin_i * c4 - cos_i * s4, np.abs(cos_i * c4 + sin_i * s4)))


def safe_asin(x):
    """asin of x clamped to [-1, 1] (the shader computes it through atan, see there)."""
    return np.arcsin(np.clip(x, -1.0, 1.0))


def _dot(a, b):
    return np.einsum("ij,ij->i", a, b)


def _normalize(a):
    n = np.linalg.norm(a, axis=1, keepdims=True)
    return a / np.maximum(n, 1e-300)


def fibre_frame(tangent, wo):
    """(X, Y, Z), each (N, 3): X the unit tangent, Y = X x wo and Z = X x Y, normalised."""
    X = _normalize(tangent)
    Y = _normalize(np.cross(X, wo))
    Z = _normalize(np.cross(X, Y))
    return X, Y, Z


def fibre_offset(p, axis_point, tangent, wo, radius):
    """h in [-1, 1] of hits p on fibres through axis_point along tangent seen from wo:
    -(p - axis).Y / r (Cycles' dot(cross(Ng, X), Z) for a hit on the side). The offset
    across Y is the same for every point of the ray, so a hit on a cut plane gets the h a
    hit on the side at that offset would."""
    X, Y, _ = fibre_frame(tangent, wo)
    return np.clip(-_dot(p - axis_point, Y) / radius, -1.0, 1.0)


def hair_bsdf(wi, wo, tangent, h, sigma_a, lobes):
    """sum_p Mp Ap Np (N, 3) for light arriving from wi (unit, toward the light) and leaving
    toward wo (unit, toward the viewer) at fibre offsets h (N,), absorption sigma_a (N, 3)
    and one FibreLobes. Radiance = irradiance along wi times this."""
    wi = np.asarray(wi, np.float64)
    wo = np.asarray(wo, np.float64)
    X, Y, Z = fibre_frame(np.asarray(tangent, np.float64), wo)
    h = np.asarray(h, np.float64)
    sigma_a = np.asarray(sigma_a, np.float64)
    eta = lobes.eta

    sin_o = _dot(wo, X)
    cos_o = np.sqrt(np.maximum(1.0 - sin_o * sin_o, 0.0))
    phi_o = np.arctan2(_dot(wo, Z), _dot(wo, Y))
    sin_t = sin_o / eta
    cos_t = np.sqrt(np.maximum(1.0 - sin_t * sin_t, 0.0))
    sin_gamma_o = h
    cos_gamma_o = np.sqrt(np.maximum(1.0 - h * h, 0.0))
    gamma_o = safe_asin(h)
    # Snell's law in the normal plane with the modified index sqrt(eta^2 - sin^2)/cos.
    sin_gamma_t = sin_gamma_o * cos_o / np.sqrt(eta * eta - sin_o * sin_o)
    cos_gamma_t = np.sqrt(np.maximum(1.0 - sin_gamma_t * sin_gamma_t, 0.0))
    gamma_t = safe_asin(sin_gamma_t)
    T = np.exp(-sigma_a * (2.0 * cos_gamma_t / cos_t)[:, None])
    A = ap(fresnel_dielectric(cos_o * cos_gamma_o, eta), T)

    sin_i = _dot(wi, X)
    cos_i = np.sqrt(np.maximum(1.0 - sin_i * sin_i, 0.0))
    phi = np.arctan2(_dot(wi, Z), _dot(wi, Y)) - phi_o

    out = np.zeros_like(T)
    for p, ((s_i, c_i), v) in enumerate(zip(tilted_angles(sin_i, cos_i, lobes.alpha),
                                           (lobes.v_r, 0.25 * lobes.v, 4.0 * lobes.v))):
        out += A[p] * (mp(s_i, c_i, sin_o, cos_o, v) * np_lobe(phi, p, lobes.s, gamma_o, gamma_t))[:, None]
    out += A[3] * (mp(sin_i, cos_i, sin_o, cos_o, 4.0 * lobes.v) / (2.0 * np.pi))[:, None]
    return out

// SPDX-License-Identifier: GPL-3.0-or-later
// The fibre scattering model of Chiang, Bitterli, Tappan and Burley (2016) as Cycles'
// Principled Hair BSDF ("Chiang") evaluates it for direct light. tracer/hair_bsdf.py is the
// float64 reference of this file, function for function (its docstring gives the frame, the
// symbols and where Cycles and pbrt-v4 differ); keep the two in step.
// A shading model of tracer/shading (float64 mirror of shade_light: tracer/shading/chiang.py);
// everything above shade_light needs nothing from the other shader files.

const float CHIANG_PI = 3.14159265358979;
const float LOG_MP_BELOW = 0.1;
const float LOG_I0_ABOVE = 12.0;

// A fibre's lobes, precomputed once on the host (hair_bsdf.fibre_lobes).
struct FibreLobes {
    float v;        // longitudinal variance; TT uses v/4, TRT and TRRT+ 4v
    float v_r;      // the R lobe's variance (roughness scaled by 1 - coat)
    float s;        // logistic scale of the azimuthal lobes
    float alpha;    // cuticle tilt, radians
    float eta;      // index of refraction
};

// Absorption per unit radius for the node's Melanin and Melanin Redness.
vec3 sigma_a_from_melanin(float melanin, float redness) {
    float c = -log(max(1.0 - melanin, 1e-4));
    return (c * (1.0 - redness)) * vec3(0.506, 0.841, 1.653) + (c * redness) * vec3(0.343, 0.733, 1.924);
}

float albedo_roughness_scale(float x) {
    return (((((0.245 * x) + 5.574) * x - 10.73) * x + 2.532) * x - 0.215) * x + 5.969;
}

// Absorption whose hair shows `color` (Cycles' Direct Coloring and Tint).
vec3 sigma_a_from_color(vec3 color, float radial_roughness) {
    vec3 l = log(clamp(color, vec3(1e-5), vec3(1.0))) / albedo_roughness_scale(radial_roughness);
    return l * l;
}

// I0 by its first 10 series terms, as Cycles and pbrt compute it.
float i0(float x) {
    float x2 = x * x;
    float val = 1.0 + 0.25 * x2;
    float power = x2 * x2;
    float fact2 = 1.0;
    float pow4 = 16.0;
    for (int i = 2; i < 10; ++i) {
        fact2 *= float(i * i);
        val += power / (pow4 * fact2);
        power *= x2;
        pow4 *= 4.0;
    }
    return val;
}

float log_i0(float x) {
    if (x > LOG_I0_ABOVE) {
        return x + 0.5 * (1.0 / (8.0 * x) - log(2.0 * CHIANG_PI) - log(x));
    }
    return log(i0(x));
}

// Longitudinal scattering; in log space for narrow lobes, where I0 alone would overflow.
float mp(float sin_i, float cos_i, float sin_o, float cos_o, float v) {
    float a = cos_i * cos_o / v;
    float b = sin_i * sin_o / v;
    if (v <= LOG_MP_BELOW) {
        return exp(log_i0(a) - b - 1.0 / v + 0.6931 + log(0.5 / v));
    }
    return exp(-b) * i0(a) / (sinh(1.0 / v) * 2.0 * v);
}

float logistic(float x, float s) {
    float e = exp(-abs(x) / s);
    return e / (s * (1.0 + e) * (1.0 + e));
}

float logistic_cdf(float x, float s) {
    float arg = -x / s;
    return arg > 88.0 ? 0.0 : 1.0 / (1.0 + exp(arg));   // exp overflows float32 past 88
}

float trimmed_logistic(float x, float s) {
    return logistic(x, s) / (1.0 - 2.0 * logistic_cdf(-CHIANG_PI, s));
}

float delta_phi(float p, float gamma_o, float gamma_t) {
    return 2.0 * p * gamma_t - 2.0 * gamma_o + p * CHIANG_PI;
}

float wrap_angle(float a) {
    return (a + CHIANG_PI) - 2.0 * CHIANG_PI * floor((a + CHIANG_PI) / (2.0 * CHIANG_PI)) - CHIANG_PI;
}

float np_lobe(float phi, float p, float s, float gamma_o, float gamma_t) {
    return trimmed_logistic(wrap_angle(phi - delta_phi(p, gamma_o, gamma_t)), s);
}

float fresnel_dielectric(float cos_i, float eta) {
    float c = abs(cos_i);
    float g2 = eta * eta - 1.0 + c * c;
    if (g2 <= 0.0) return 1.0;
    float g = sqrt(g2);
    float a = (g - c) / (g + c);
    float b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0);
    return 0.5 * a * a * (1.0 + b * b);
}

// Attenuation of R, TT, TRT and TRRT+.
void ap(float f, vec3 T, out vec3 a0, out vec3 a1, out vec3 a2, out vec3 a3) {
    a0 = vec3(f);
    a1 = (1.0 - f) * (1.0 - f) * T;
    a2 = a1 * T * f;
    vec3 tf = T * f;
    a3 = a2 * mix(vec3(0.0), tf / max(1.0 - tf, vec3(1e-30)), lessThan(tf, vec3(1.0)));
}

// (sin, cos) of theta_i turned by the cuticle tilt for R, TT and TRT.
void tilted_angles(float sin_i, float cos_i, float alpha, out vec2 r, out vec2 tt, out vec2 trt) {
    float s1 = sin(alpha), c1 = cos(alpha);
    float s2 = 2.0 * s1 * c1, c2 = c1 * c1 - s1 * s1;
    float s4 = 2.0 * s2 * c2, c4 = c2 * c2 - s2 * s2;
    r = vec2(sin_i * c2 + cos_i * s2, abs(cos_i * c2 - sin_i * s2));
    tt = vec2(sin_i * c1 - cos_i * s1, abs(cos_i * c1 + sin_i * s1));
    trt = vec2(sin_i * c4 - cos_i * s4, abs(cos_i * c4 + sin_i * s4));
}

// asin through atan: Mesa's asin is off by up to 4e-4 rad, which moves a narrow azimuthal
// lobe (s = 0.02) by 8 % of its height; atan is good to 3e-6.
float safe_asin(float x) {
    x = clamp(x, -1.0, 1.0);
    return atan(x, sqrt(max(1.0 - x * x, 0.0)));
}

void fibre_frame(vec3 tangent, vec3 wo, out vec3 X, out vec3 Y, out vec3 Z) {
    X = normalize(tangent);
    Y = normalize(cross(X, wo));
    Z = normalize(cross(X, Y));
}

// h in [-1, 1] of a hit p on the fibre through axis_point along tangent, seen from wo.
float fibre_offset(vec3 p, vec3 axis_point, vec3 tangent, vec3 wo, float radius) {
    vec3 X, Y, Z;
    fibre_frame(tangent, wo, X, Y, Z);
    return clamp(-dot(p - axis_point, Y) / radius, -1.0, 1.0);
}

// sum_p Mp Ap Np for light from wi (toward the light) leaving toward wo (toward the viewer).
vec3 hair_bsdf(vec3 wi, vec3 wo, vec3 tangent, float h, vec3 sigma_a, FibreLobes lobes) {
    vec3 X, Y, Z;
    fibre_frame(tangent, wo, X, Y, Z);
    float eta = lobes.eta;

    float sin_o = dot(wo, X);
    float cos_o = sqrt(max(1.0 - sin_o * sin_o, 0.0));
    float phi_o = atan(dot(wo, Z), dot(wo, Y));
    float sin_t = sin_o / eta;
    float cos_t = sqrt(max(1.0 - sin_t * sin_t, 0.0));
    float sin_gamma_o = h;
    float cos_gamma_o = sqrt(max(1.0 - h * h, 0.0));
    float gamma_o = safe_asin(h);
    float sin_gamma_t = sin_gamma_o * cos_o / sqrt(eta * eta - sin_o * sin_o);
    float cos_gamma_t = sqrt(max(1.0 - sin_gamma_t * sin_gamma_t, 0.0));
    float gamma_t = safe_asin(sin_gamma_t);
    vec3 T = exp(-sigma_a * (2.0 * cos_gamma_t / cos_t));
    vec3 a0, a1, a2, a3;
    ap(fresnel_dielectric(cos_o * cos_gamma_o, eta), T, a0, a1, a2, a3);

    float sin_i = dot(wi, X);
    float cos_i = sqrt(max(1.0 - sin_i * sin_i, 0.0));
    float phi = atan(dot(wi, Z), dot(wi, Y)) - phi_o;

    vec2 r, tt, trt;
    tilted_angles(sin_i, cos_i, lobes.alpha, r, tt, trt);
    vec3 f = a0 * (mp(r.x, r.y, sin_o, cos_o, lobes.v_r) * np_lobe(phi, 0.0, lobes.s, gamma_o, gamma_t));
    f += a1 * (mp(tt.x, tt.y, sin_o, cos_o, 0.25 * lobes.v) * np_lobe(phi, 1.0, lobes.s, gamma_o, gamma_t));
    f += a2 * (mp(trt.x, trt.y, sin_o, cos_o, 4.0 * lobes.v) * np_lobe(phi, 2.0, lobes.s, gamma_o, gamma_t));
    f += a3 * (mp(sin_i, cos_i, sin_o, cos_o, 4.0 * lobes.v) / (2.0 * CHIANG_PI));
    return f;
}

// The registry's interface (tracer/shading/chiang.py says what the strand colour means).
uniform vec4 hair_lobes;              // v, v_r, s, alpha of FibreLobes
uniform float hair_eta;
uniform vec3 hair_base_sigma;         // the melanin's absorption; 0 when the colour is the hair's
uniform float hair_radial_roughness;  // for the colour's absorption

vec3 shade_light(Surface s, vec3 L) {
    vec3 wo = -s.V;
    vec3 X, Y, Z;
    fibre_frame(s.T, wo, X, Y, Z);
    float h = clamp(-dot(s.N, Y), -1.0, 1.0);
    vec3 sigma_a = hair_base_sigma + sigma_a_from_color(s.color, hair_radial_roughness);
    FibreLobes lobes = FibreLobes(hair_lobes.x, hair_lobes.y, hair_lobes.z, hair_lobes.w, hair_eta);
    return hair_bsdf(L, wo, s.T, h, sigma_a, lobes);
}

// SPDX-License-Identifier: GPL-3.0-or-later
// Kajiya-Kay (1989), a shading model of tracer/shading (float64 mirror:
// tracer/shading/kajiya_kay.py). A strand is a thin cylinder seen from afar: diffuse by
// the sine of the angle between tangent and light, a highlight on the cone of directions
// that mirror the light about the tangent. Reads no normal.
vec3 shade_light(Surface s, vec3 L) {
    float tl = dot(s.T, L), tv = dot(s.T, s.V);
    float sl = sqrt(max(0.0, 1.0 - tl * tl)), sv = sqrt(max(0.0, 1.0 - tv * tv));
    float diff = sl;
    float spec = pow(max(0.0, tl * tv + sl * sv), material.w);
    return material.y * diff * s.color + material.z * spec;
}

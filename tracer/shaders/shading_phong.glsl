// SPDX-License-Identifier: GPL-3.0-or-later
// Phong, as the thesis shades cylinders (SPEC §7), a shading model of tracer/shading
// (float64 mirror: tracer/shading/phong.py): diffuse by the normal of the surface entered,
// a highlight around the light mirrored about that normal.
vec3 shade_light(Surface s, vec3 L) {
    float diff = max(dot(s.N, L), 0.0);
    vec3 R = reflect(-L, s.N);
    float spec = diff > 0.0 ? pow(max(dot(R, -s.V), 0.0), material.w) : 0.0;
    return material.y * diff * s.color + material.z * spec;
}

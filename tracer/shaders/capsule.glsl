// SPDX-License-Identifier: GPL-3.0-or-later
// The capsule a cut cylinder lies in, shared by the structures' builds (grid_build.glsl,
// beams_build.glsl) and the pixel sampler (sampler_pixel.glsl): the axis from `top` past
// `tip` by the bend's reach, radius r. Past the tip, on the outer side of a bend, the cut
// cylinder reaches r·tan(angle) further along its axis (tracer/cylinders.py: extension).
vec3 capsule_far(vec3 top, vec3 tip, vec3 n2, float r) {
    vec3 axis = tip - top;
    float len = length(axis);
    float c = clamp(dot(axis, n2) / max(len, 1e-30), COS_SHARP, 1.0);
    float ext = r * sqrt(max(0.0, 1.0 - c * c)) / c;
    return tip + axis * (ext / max(len, 1e-30));
}

// SPDX-License-Identifier: GPL-3.0-or-later
// Continual cylinders made on the GPU (GL 4.3 compute) from the strand points, written
// straight into the cylinder texture the trace shader reads: the same TEXELS_PER_CYL texels
// per cylinder (CYL_TOP, CYL_TIP, CYL_N2, CYL_COL: tracer/layout.py), by the same rules, as
// tracer/cylinders.py (which the reference tracer uses).
// Cylinder k runs from point p = cyl_point[k] to p + 1 of the same strand; plane 2 is
// square to the next axis unless the strand ends there or bends sharper than
// SHARP_BEND_DEG (then square to its own axis, and a cap). The host prepends
// "#version 430 core" and the generated header of tracer/layout.py.
layout(local_size_x = GROUP) in;

uniform int n_items;        // cylinders to make in this dispatch
uniform int first_item;     // index of the first of them
uniform int n_cyl;          // cylinders in the scene
uniform int out_first;      // the cylinder whose texels start the range bound to Cylinders
                            // (the host binds ranges within the driver's block size, within
                            // one part of the buffer: tracer/scene_buffers.py)
uniform float repeat2;      // squared distance below which a point repeats its predecessor
                            // (0: the host dropped repeats already)

// Per point, the arrays of SPEC §0 as they are (no packing on the host), in buffer textures.
layout(binding = 0) uniform samplerBuffer tex_pos;      // xyz
layout(binding = 1) uniform samplerBuffer tex_rad;      // radius
layout(binding = 2) uniform samplerBuffer tex_col;      // rgb
layout(binding = 3) uniform samplerBuffer tex_alpha;    // alpha
layout(binding = 4) uniform isamplerBuffer tex_cp;      // per cylinder: index of its top point
// TEXELS_PER_CYL per cylinder, the buffer texture's storage bound as a storage buffer: on
// llvmpipe a store there costs a third of an imageStore to the same texels (docs/DECISIONS.md).
layout(std430, binding = 0) writeonly buffer Cylinders { vec4 cyl_out[]; };
// Segments no longer than the repeat distance (the host passes twice the numpy build's, so
// float32 rounding cannot hide one): repeats[0] counts them, repeats[1..] list the first
// MAX_REPEATS of their top points. The host checks each by the numpy rule, drops the repeated
// points (tracer/cylinders.py) and makes the cylinders again: one rule for both builds.
layout(std430, binding = 1) buffer Repeats { int repeats[]; };

vec3 pos(int p) { return texelFetch(tex_pos, p).xyz; }
int top_point(int k) { return texelFetch(tex_cp, k).x; }
// As numpy: the axis divided by its float32 length.
vec3 unit(vec3 v) { return v / sqrt(v.x * v.x + v.y * v.y + v.z * v.z); }

void main() {
    int k = first_item + int(gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * GROUP
            + int(gl_LocalInvocationID.x);
    if (k >= first_item + n_items || k >= n_cyl) return;
    int p = top_point(k);
    // Consecutive cylinders of a strand have consecutive top points.
    bool first = k == 0 || top_point(k - 1) != p - 1;
    bool has_next = k + 1 < n_cyl && top_point(k + 1) == p + 1;
    vec3 A = pos(p), B = pos(p + 1);
    vec3 ax = B - A;
    if (ax.x * ax.x + ax.y * ax.y + ax.z * ax.z <= repeat2) {
        int i = atomicAdd(repeats[0], 1);
        if (i < MAX_REPEATS) repeats[i + 1] = p;
    }
    vec3 u1 = unit(ax);
    vec3 u2 = u1;
    bool sharp = false;
    if (has_next) {
        u2 = unit(pos(p + 2) - B);
        sharp = u1.x * u2.x + u1.y * u2.y + u1.z * u2.z < COS_SHARP;
        if (sharp) u2 = u1;
    }
    bool cap1 = first;
    if (!first) {
        vec3 u0 = unit(A - pos(p - 1));
        cap1 = u0.x * u1.x + u0.y * u1.y + u0.z * u1.z < COS_SHARP;
    }
    int flags = (cap1 ? CAP_PLANE1 : 0) | (!has_next || sharp ? CAP_PLANE2 : 0);
    int base = TEXELS_PER_CYL * (k - out_first);
    // The mean of the two points' radii, as tracer/cylinders.py's segment_radius: (a + b)·0.5.
    float r = (texelFetch(tex_rad, p).x + texelFetch(tex_rad, p + 1).x) * 0.5;
    cyl_out[base + CYL_TOP] = vec4(A, r);
    cyl_out[base + CYL_TIP] = vec4(B, texelFetch(tex_alpha, p).x);
    cyl_out[base + CYL_N2] = vec4(u2, float(flags));
    cyl_out[base + CYL_COL] = vec4(texelFetch(tex_col, p).rgb, 0.0);
}

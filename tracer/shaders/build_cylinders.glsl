// SPDX-License-Identifier: GPL-3.0-or-later
// What the compute passes that read the cylinders share (grid_build.glsl, beams_build.glsl;
// compiled in front of them): the workgroup size, the cylinder buffer (TEXELS_PER_CYL texels
// per cylinder; past the driver's limit the cylinders continue in further buffers, cyl_split
// in each but the last: tracer/scene_buffers.py) and the invocation's item.
layout(local_size_x = GROUP) in;

layout(binding = 0) uniform samplerBuffer tex_cyl;
#if CYL_PARTS > 1
layout(binding = 1) uniform samplerBuffer tex_cyl1;
#endif
#if CYL_PARTS > 2
layout(binding = 2) uniform samplerBuffer tex_cyl2;
#endif
#if CYL_PARTS > 3
layout(binding = 3) uniform samplerBuffer tex_cyl3;
#endif
uniform int cyl_split;

vec4 cyl(int id, int j) {
#if CYL_PARTS > 3
    if (id >= 3 * cyl_split) return texelFetch(tex_cyl3, TEXELS_PER_CYL * (id - 3 * cyl_split) + j);
#endif
#if CYL_PARTS > 2
    if (id >= 2 * cyl_split) return texelFetch(tex_cyl2, TEXELS_PER_CYL * (id - 2 * cyl_split) + j);
#endif
#if CYL_PARTS > 1
    if (id >= cyl_split) return texelFetch(tex_cyl1, TEXELS_PER_CYL * (id - cyl_split) + j);
#endif
    return texelFetch(tex_cyl, TEXELS_PER_CYL * id + j);
}

int item_index() {
    return int(gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * GROUP + int(gl_LocalInvocationID.x);
}

// SPDX-License-Identifier: GPL-3.0-or-later
// What every part of the trace program reads: the cylinder buffer, the material, the work
// counters, the sentinels, and the Surface a shading model shades. The trace program is
// these files in order (tracer/draw.py: trace_files), after "#version 330 core", its
// compile-time switches and the header generated from tracer/layout.py:
//   trace_scene.glsl      this file
//   shapes_cylinder.glsl  ray vs one cut cylinder, its normal
//   capsule.glsl          the capsule a cut cylinder lies in (shared with the builds)
//   accel.glsl            the accelerator interface and the hit list it fills
//   sampler_pixel.glsl    the pixel sampler's list of distinct cylinders and coverage masks
//                         (PIXEL 1; empty otherwise)
//   accel_grid.glsl       the uniform grid (or accel_bvh.glsl, the BVH), implementing that
//                         interface, and the pixel sampler's walk
//   accel_beams.glsl      with beams (after the grid's file where some ray walks it): the
//                         camera's and the suns' lists
//   shapes_triangle.glsl, accel_mesh_grid.glsl   opaque meshes and their own grid (MESHES 1)
//   shading_<model>.glsl  shade_light of the chosen model (tracer/shading: the registry)
//   trace_main.glsl       camera rays, layers, shadows, samples: main
// Compile-time switches (tracer/draw.py):
//   LAYERS        hits composited front to back (1 when every alpha is 1)
//   SHADOWS       0: no shadow code at all; 1: hard (any hit); 2: transmittance
//   NUM_LIGHTS    1..MAX
//   SPP_N         samples per pixel = SPP_N * SPP_N (stratified, jittered by a fixed hash;
//                 one sample per draw, see main)
//   MIN_PX        1: widen radii to half a pixel (alpha scaled by r / r')
//   ORTHO         1: orthographic camera
//   COUNT         1: write per-pixel work counters to a second target
//   MESHES        1: opaque triangle meshes beside the strands
//   PIXEL         1: the pixel sampler: a pixel's SPP_N² samples in one walk, each distinct
//                 cylinder shaded once (docs/DECISIONS.md, "Samples of one pixel share the walk")
//   CYL_PARTS, IDX_PARTS  buffer textures the cylinders and the grid's cell lists are split over

// Per cylinder, TEXELS_PER_CYL consecutive texels (one 64-byte cache line on a CPU driver),
// CYL_TOP: xyz top, w radius; CYL_TIP: xyz tip, w alpha; CYL_N2: xyz unit normal of plane
// 2, w cap flags (CAP_PLANE1, CAP_PLANE2); CYL_COL: rgb colour. Buffer textures
// (tracer/gl_buffers.py): texel i is found by its index alone.
// Past the driver's texel limit (CYL_PARTS > 1, tracer/scene_buffers.py) cylinder id lives
// in tex_cyl<id / cyl_split>, at id % cyl_split; within it (CYL_PARTS 1) there is no compare.
uniform samplerBuffer tex_cyl;
#if CYL_PARTS > 1
uniform samplerBuffer tex_cyl1;
uniform int cyl_split;                // cylinders in each part but the last
#endif
#if CYL_PARTS > 2
uniform samplerBuffer tex_cyl2;
#endif
#if CYL_PARTS > 3
uniform samplerBuffer tex_cyl3;
#endif

uniform vec4 material;                // ambient, diffuse, specular, shininess
uniform float mpw_cap;                // largest widening factor r'/r
uniform float t_eps;                  // stop compositing once transmittance drops below this

#if COUNT
vec4 counter = vec4(0.0);             // shadow rays, layers, cells visited, cylinder tests
#endif

const float BIG = 1e30;
const int NO_ID = 0x7fffffff;

// Texel `j` of cylinder `id`.
vec4 cyl(int id, int j) {
#if CYL_PARTS > 1
    if (id >= cyl_split) {
#if CYL_PARTS > 2
        if (id >= 2 * cyl_split) {
#if CYL_PARTS > 3
            if (id >= 3 * cyl_split) return texelFetch(tex_cyl3, (id - 3 * cyl_split) * TEXELS_PER_CYL + j);
#endif
            return texelFetch(tex_cyl2, (id - 2 * cyl_split) * TEXELS_PER_CYL + j);
        }
#endif
        return texelFetch(tex_cyl1, (id - cyl_split) * TEXELS_PER_CYL + j);
    }
#endif
    return texelFetch(tex_cyl, id * TEXELS_PER_CYL + j);
}

// A hit to shade (tracer/shading: the shading model interface): the point, the unit
// tangent, the unit normal of the surface entered (facing the ray), the unit ray direction
// (from the eye) and the base colour.
struct Surface {
    vec3 p;
    vec3 T;
    vec3 N;
    vec3 V;
    vec3 color;
};

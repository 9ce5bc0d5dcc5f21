// SPDX-License-Identifier: GPL-3.0-or-later
// Grid build on the GPU (GL 4.3 compute), the same listing as tracer/grid.py's numpy build:
// every cylinder in every cell its padded capsule may touch, cut slab by slab along its
// dominant axis. The host prepends "#version 430 core" and PASS:
//   PASS 0  count: cells[cell] += 1 for every (cylinder, cell)
//   PASS 1  fill:  slot = cells[cell]++ (cells holds each cell's first slot on entry),
//                  idx_img[slot] = cylinder id
// The counters are a storage buffer, not an image: llvmpipe's buffer atomics take ~60 % of
// the time of its image atomics (measured on 43 M references). The lists themselves go
// straight into the index texture: writing them to a buffer and copying measured the same.
// The order of a cell's list depends on the order the atomics of PASS 1 ran in; the trace
// shader breaks ties between equal distances by id, so images do not depend on it.
// A cylinder whose listing would take more than MAX_VISITS loop steps is not listed at all
// but counted in overflow_img: llvmpipe silently cuts any invocation off after 65,535 loop
// steps, so the host builds such a grid in numpy instead of trusting a truncated one.
layout(local_size_x = 64) in;

uniform int n_items;          // cylinders
uniform int cyl_shift;        // log2 cylinders per row of tex_cyl
uniform int idx_shift;        // log2 texels per row of the index image
uniform vec3 grid_lo;
uniform vec3 inv_cell;        // 1 / cell size per axis
uniform ivec3 dims;
uniform float pad_factor;

uniform sampler2D tex_cyl;
layout(std430, binding = 0) buffer Cells { int cells[]; };
#if PASS == 0
layout(r32i, binding = 2) uniform iimage3D overflow_img;
#endif
#if PASS == 1
layout(r32i, binding = 1) uniform writeonly iimage2D idx_img;
#endif

ivec2 slot_texel(int i) { return ivec2(i & ((1 << idx_shift) - 1), i >> idx_shift); }
vec4 cyl(int id, int j) { return texelFetch(tex_cyl, ivec2(((id & ((1 << cyl_shift) - 1)) << 2) | j, id >> cyl_shift), 0); }

int item_index() {
    return int(gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * 64 + int(gl_LocalInvocationID.x);
}

void visit(ivec3 c, int id) {
#if PASS == 0
    atomicAdd(cells[c.x + dims.x * (c.y + dims.y * c.z)], 1);
#else
    int slot = atomicAdd(cells[c.x + dims.x * (c.y + dims.y * c.z)], 1);
    imageStore(idx_img, slot_texel(slot), ivec4(id));
#endif
}

void main() {
    int id = item_index();
    if (id >= n_items) return;
    vec4 top = cyl(id, 0), tip = cyl(id, 1), n2 = cyl(id, 2);
    vec3 axis = tip.xyz - top.xyz;
    float len = length(axis);
    // Past the tip, on the outer side of a bend, the cut cylinder reaches r·tan(angle)
    // further along its axis (tracer/cylinders.py: extension); the same bound as there.
    float c = clamp(dot(axis, n2.xyz) / max(len, 1e-30), 0.17364817766693041, 1.0);
    float ext = top.w * sqrt(max(0.0, 1.0 - c * c)) / c;
    vec3 far = tip.xyz + axis * (ext / max(len, 1e-30));
    vec3 g0 = (top.xyz - grid_lo) * inv_cell;
    vec3 dg = (far - grid_lo) * inv_cell - g0;
    // A thousandth of a cell more than the radius covers float32 rounding, as in numpy.
    vec3 pad = vec3(top.w * pad_factor) * inv_cell + 1e-3;
    vec3 adg = abs(dg);
    int k = adg.x >= adg.y && adg.x >= adg.z ? 0 : (adg.y >= adg.z ? 1 : 2);
    int a = (k + 1) % 3, b = (k + 2) % 3;
    int i0 = clamp(int(floor(min(g0[k], g0[k] + dg[k]) - pad[k])), 0, dims[k] - 1);
    int i1 = clamp(int(floor(max(g0[k], g0[k] + dg[k]) + pad[k])), 0, dims[k] - 1);
    bool no_dir = abs(dg[k]) < 1e-12;
    float inv = no_dir ? 1.0 : 1.0 / dg[k];
    // Upper bound of the steps below: slabs times the cells of the whole box's other sides.
    float ba = abs(dg[a]) + 2.0 * pad[a] + 2.0, bb = abs(dg[b]) + 2.0 * pad[b] + 2.0;
    if (float(i1 - i0 + 1) * min(ba, float(dims[a])) * min(bb, float(dims[b])) > float(MAX_VISITS)) {
#if PASS == 0
        imageAtomicAdd(overflow_img, ivec3(0), 1);
#endif
        return;
    }
    for (int slab = i0; slab <= i1; ++slab) {
        // Part of the segment (s in [0, 1]) whose dominant coordinate lies within pad of
        // this slab; a segment too short to have a dominant direction is taken whole.
        float s0 = 0.0, s1 = 1.0;
        if (!no_dir) {
            float sa = (float(slab) - pad[k] - g0[k]) * inv;
            float sb = (float(slab + 1) + pad[k] - g0[k]) * inv;
            s0 = clamp(min(sa, sb), 0.0, 1.0);
            s1 = clamp(max(sa, sb), 0.0, 1.0);
        }
        float ea0 = g0[a] + s0 * dg[a], ea1 = g0[a] + s1 * dg[a];
        float eb0 = g0[b] + s0 * dg[b], eb1 = g0[b] + s1 * dg[b];
        int ja0 = clamp(int(floor(min(ea0, ea1) - pad[a])), 0, dims[a] - 1);
        int ja1 = clamp(int(floor(max(ea0, ea1) + pad[a])), 0, dims[a] - 1);
        int jb0 = clamp(int(floor(min(eb0, eb1) - pad[b])), 0, dims[b] - 1);
        int jb1 = clamp(int(floor(max(eb0, eb1) + pad[b])), 0, dims[b] - 1);
        for (int jb = jb0; jb <= jb1; ++jb)
            for (int ja = ja0; ja <= ja1; ++ja) {
                ivec3 cell;
                cell[k] = slab; cell[a] = ja; cell[b] = jb;
                visit(cell, id);
            }
    }
}

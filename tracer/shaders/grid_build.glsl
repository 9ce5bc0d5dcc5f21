// SPDX-License-Identifier: GPL-3.0-or-later
// Grid build on the GPU (GL 4.3 compute), the same listing as tracer/grid.py's numpy build:
// every cylinder in every cell its padded capsule may touch, cut slab by slab along its
// dominant axis. The host prepends "#version 430 core", PASS and the generated header of
// tracer/layout.py, then build_cylinders.glsl and capsule.glsl:
//   PASS 0  count: cells[cell] += 1 for every (cylinder, cell)
//   PASS 1  fill:  slot = cells[cell]++ (cells holds each cell's first slot on entry),
//                  idx_img[slot] = cylinder id
// The counters are a storage buffer, not an image: its atomics are the cheaper kind
// (docs/DECISIONS.md, "Grid build counters in a storage buffer"). The lists go straight
// into the index buffer texture the trace shader reads.
// The order of a cell's list depends on the order the atomics of PASS 1 ran in; the trace
// shader breaks ties between equal distances by id, so images do not depend on it.
// A cylinder whose listing would take more than MAX_VISITS loop steps is not listed at all
// but counted in `overflow`: llvmpipe silently cuts any invocation off after 65,535 loop
// steps, so the host builds such a grid in numpy instead of trusting a truncated one.
uniform int n_items;          // cylinders
uniform vec3 grid_lo;
uniform vec3 inv_cell;        // 1 / cell size per axis
uniform ivec3 dims;
uniform float pad_factor;

// Past the driver's limit the lists continue in further buffers, idx_split entries in each
// but the last (tracer/scene_buffers.py).
uniform int idx_split;
layout(std430, binding = 0) buffer Cells { int cells[]; };
#if PASS == 0
layout(std430, binding = 1) buffer Overflow { int overflow; };
#endif
#if PASS == 1
layout(r32i, binding = 1) uniform writeonly iimageBuffer idx_img;
#if IDX_PARTS > 1
layout(r32i, binding = 2) uniform writeonly iimageBuffer idx_img1;
#endif
#if IDX_PARTS > 2
layout(r32i, binding = 3) uniform writeonly iimageBuffer idx_img2;
#endif
#if IDX_PARTS > 3
layout(r32i, binding = 4) uniform writeonly iimageBuffer idx_img3;
#endif
#endif

void visit(int cell, int id) {
#if PASS == 0
    atomicAdd(cells[cell], 1);
#else
    int slot = atomicAdd(cells[cell], 1);
#if IDX_PARTS > 3
    if (slot >= 3 * idx_split) { imageStore(idx_img3, slot - 3 * idx_split, ivec4(id)); return; }
#endif
#if IDX_PARTS > 2
    if (slot >= 2 * idx_split) { imageStore(idx_img2, slot - 2 * idx_split, ivec4(id)); return; }
#endif
#if IDX_PARTS > 1
    if (slot >= idx_split) { imageStore(idx_img1, slot - idx_split, ivec4(id)); return; }
#endif
    imageStore(idx_img, slot, ivec4(id));
#endif
}

// Cells of slab `slab` (along the dominant axis) that the padded segment may touch: rows
// ja0..ja1 and columns jb0..jb1 of the other two axes. G, DG, P are the segment's start,
// direction and pad in cell units, ordered (dominant, a, b); D the grid's cells likewise.
void ranges(int slab, bool no_dir, float inv, vec3 G, vec3 DG, vec3 P, ivec3 D,
            out int ja0, out int ja1, out int jb0, out int jb1) {
    // Part of the segment (s in [0, 1]) whose dominant coordinate lies within pad of this
    // slab; a segment too short to have a dominant direction is taken whole.
    float s0 = 0.0, s1 = 1.0;
    if (!no_dir) {
        float sa = (float(slab) - P.x - G.x) * inv;
        float sb = (float(slab + 1) + P.x - G.x) * inv;
        s0 = clamp(min(sa, sb), 0.0, 1.0);
        s1 = clamp(max(sa, sb), 0.0, 1.0);
    }
    vec2 e0 = G.yz + s0 * DG.yz, e1 = G.yz + s1 * DG.yz;
    ivec2 j0 = clamp(ivec2(floor(min(e0, e1) - P.yz)), ivec2(0), D.yz - 1);
    ivec2 j1 = clamp(ivec2(floor(max(e0, e1) + P.yz)), ivec2(0), D.yz - 1);
    ja0 = j0.x; jb0 = j0.y; ja1 = j1.x; jb1 = j1.y;
}

void main() {
    int id = item_index();
    if (id >= n_items) return;
    vec4 top = cyl(id, CYL_TOP), tip = cyl(id, CYL_TIP), n2 = cyl(id, CYL_N2);
    vec3 far = capsule_far(top.xyz, tip.xyz, n2.xyz, top.w);
    vec3 g0 = (top.xyz - grid_lo) * inv_cell;
    vec3 dg = (far - grid_lo) * inv_cell - g0;
    // A thousandth of a cell more than the radius covers float32 rounding, as in numpy.
    vec3 pad = vec3(top.w * pad_factor) * inv_cell + 1e-3;
    // Everything below in the order (dominant axis, a, b), once: constant components in
    // the loop (llvmpipe turns a computed component index into selects at every use).
    vec3 adg = abs(dg);
    ivec3 stride = ivec3(1, dims.x, dims.x * dims.y);
    vec3 G = g0, DG = dg, P = pad;
    ivec3 D = dims, S = stride;
    if (adg.y > adg.x && adg.y >= adg.z) { G = g0.yzx; DG = dg.yzx; P = pad.yzx; D = dims.yzx; S = stride.yzx; }
    else if (adg.z > adg.x && adg.z > adg.y) { G = g0.zxy; DG = dg.zxy; P = pad.zxy; D = dims.zxy; S = stride.zxy; }
    int i0 = clamp(int(floor(min(G.x, G.x + DG.x) - P.x)), 0, D.x - 1);
    int i1 = clamp(int(floor(max(G.x, G.x + DG.x) + P.x)), 0, D.x - 1);
    bool no_dir = abs(DG.x) < 1e-12;
    float inv = no_dir ? 1.0 : 1.0 / DG.x;
    // Upper bound of the steps below: slabs times the cells of the whole box's other sides.
    vec2 bound = min(abs(DG.yz) + 2.0 * P.yz + 2.0, vec2(D.yz));
    if (float(i1 - i0 + 1) * bound.x * bound.y > float(MAX_VISITS)) {
#if PASS == 0
        atomicAdd(overflow, 1);
#endif
        return;
    }
    // One loop over every listed cell, slab by slab, row by row: nested loops make every
    // lane wait for the longest inner loop of its neighbours (docs/DECISIONS.md, "One loop
    // over the grid build's cells").
    int slab = i0;
    int ja0, ja1, jb0, jb1;
    ranges(slab, no_dir, inv, G, DG, P, D, ja0, ja1, jb0, jb1);
    int ja = ja0, jb = jb0;
    for (;;) {
        visit(slab * S.x + ja * S.y + jb * S.z, id);
        ja++;
        if (ja > ja1) { ja = ja0; jb++; }
        if (jb > jb1) {
            slab++;
            if (slab > i1) break;
            ranges(slab, no_dir, inv, G, DG, P, D, ja0, ja1, jb0, jb1);
            ja = ja0; jb = jb0;
        }
    }
}

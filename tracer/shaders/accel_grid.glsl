// SPDX-License-Identifier: GPL-3.0-or-later
// The uniform grid (tracer/grid.py, tracer/scene_grid.py) as the accelerator of accel.glsl:
// a 3-D DDA over cells (id x + nx*(y + ny*z)), each with a compact list of the cylinders
// its padded capsules may touch, and whole empty BLOCK³ blocks jumped in one step.

uniform isamplerBuffer tex_idx;   // cell lists (CSR), cylinder ids
#if IDX_PARTS > 1                 // past the driver's limit: entry i in tex_idx<i / idx_split>
uniform isamplerBuffer tex_idx1;
uniform int idx_split;
#endif
#if IDX_PARTS > 2
uniform isamplerBuffer tex_idx2;
#endif
#if IDX_PARTS > 3
uniform isamplerBuffer tex_idx3;
#endif
uniform isamplerBuffer tex_cell;  // per cell: x = first slot (EMPTY_BLOCK: the whole
                                  // BLOCK^3 block of this cell is empty), y = count
uniform vec3 grid_lo;
uniform vec3 cell_size;
uniform ivec3 dims;
#if PIXEL && WIDE_GRID
// The pixel sampler's own grid (tracer/scene_grid.py, build_wide_grid): its cylinders listed
// wherever their capsule widened GRID_WIDEN_CAP times reaches, its lists in one buffer.
uniform isamplerBuffer tex_idx_w;
uniform isamplerBuffer tex_cell_w;
uniform vec3 wide_lo;
uniform vec3 wide_cell_size;
uniform ivec3 wide_dims;
#endif

// The frame of the scene's grid, or with `wide` of the pixel sampler's (callers pass a
// constant, so a build without the wide grid compiles to the scene's alone).
vec3 frame_lo(bool wide) {
#if PIXEL && WIDE_GRID
    if (wide) return wide_lo;
#endif
    return grid_lo;
}
vec3 frame_cell(bool wide) {
#if PIXEL && WIDE_GRID
    if (wide) return wide_cell_size;
#endif
    return cell_size;
}
ivec3 frame_dims(bool wide) {
#if PIXEL && WIDE_GRID
    if (wide) return wide_dims;
#endif
    return dims;
}

int list_entry(int i, bool wide) {
#if PIXEL && WIDE_GRID
    if (wide) return texelFetch(tex_idx_w, i).x;
#endif
#if IDX_PARTS > 1
    if (i >= idx_split) {
#if IDX_PARTS > 2
        if (i >= 2 * idx_split) {
#if IDX_PARTS > 3
            if (i >= 3 * idx_split) return texelFetch(tex_idx3, i - 3 * idx_split).x;
#endif
            return texelFetch(tex_idx2, i - 2 * idx_split).x;
        }
#endif
        return texelFetch(tex_idx1, i - idx_split).x;
    }
#endif
    return texelFetch(tex_idx, i).x;
}
ivec2 cell_entry(ivec3 c, bool wide) {
    ivec3 n = frame_dims(wide);
    int i = c.x + n.x * (c.y + n.y * c.z);
#if PIXEL && WIDE_GRID
    if (wide) return texelFetch(tex_cell_w, i).xy;
#endif
    return texelFetch(tex_cell, i).xy;
}

// Most cells a ray crosses are empty (hair is a thin shell with air inside and around).
// When the whole block of BLOCK^3 cells around `cell` is empty, move the DDA state to
// where the ray leaves that block in one go instead of stepping cell by cell. Every cell
// skipped lies in the empty block, so nothing can be missed; at exact ties of two faces
// the cell we land in may differ from the step-by-step walk by one index, but then the
// ray is on that shared edge and the next steps put it right. False when the ray ends or
// leaves the grid inside the block. Nothing coarser pays for its fetch on every step
// (docs/DECISIONS.md, "No empty-space skipping beyond one block of cells").
bool skip_empty_block(inout ivec3 cell, inout vec3 tnext, inout float tcur, vec3 tdelta,
                      ivec3 stp, float t1, bool wide) {
    ivec3 b0 = (cell / BLOCK) * BLOCK;
    ivec3 lastc = b0 + ivec3(greaterThan(stp, ivec3(0))) * (BLOCK - 1);
    ivec3 nsteps = abs(lastc - cell);
    vec3 tleave = tnext + vec3(nsteps) * tdelta;
    float tb = min(min(tleave.x, tleave.y), tleave.z);
    if (tb >= t1) return false;
    int exit_axis = tleave.x <= tleave.y && tleave.x <= tleave.z ? 0 : (tleave.y <= tleave.z ? 1 : 2);
    for (int i = 0; i < 3; ++i) {
        int k;
        if (i == exit_axis) k = nsteps[i] + 1;
        else k = tnext[i] < tb ? min(int(floor((tb - tnext[i]) / tdelta[i])) + 1, nsteps[i]) : 0;
        cell[i] += stp[i] * k;
        tnext[i] += float(k) * tdelta[i];
    }
    tcur = tb;
    return all(greaterThanEqual(cell, ivec3(0))) && all(lessThan(cell, frame_dims(wide)));
}

// A grid walk (primary and shadow rays alike): the current cell, where the ray leaves it
// along each axis (tnext), where it entered it (tcur), and what is read ahead: the cell's
// entry, its next candidate's id and TOP/TIP texels, and the list entry after that one.
struct Walk {
    ivec3 cell;
    vec3 tnext;
    float tcur;
    ivec2 sc;       // the cell's first slot (-1: empty block) and count
    int id, id2;
    vec4 A, B;
    bool wide;      // the pixel sampler's wide grid (a constant of each walk)
};

// The cell's entry, its first two list entries and the first candidate's texels, read before
// they are needed (the walks read one cell and one candidate ahead, so that their cache
// misses overlap the tests of the cell before). The reads ahead stay inside tex_idx: an
// empty block's cell (start EMPTY_BLOCK) reads from 0, and the host gives the lists two texels of
// zeros past their end.
void read_cell(inout Walk w) {
    w.sc = cell_entry(clamp(w.cell, ivec3(0), frame_dims(w.wide) - 1), w.wide);
    int first = max(w.sc.x, 0);
    w.id = list_entry(first, w.wide);
    w.id2 = list_entry(first + 1, w.wide);
    w.A = cyl(w.id, CYL_TOP);
    w.B = cyl(w.id, CYL_TIP);
}

// The walk from o along d where it enters the grid (`wide`: the pixel sampler's) at t0; stp
// and tdelta stay fixed.
Walk begin_walk(vec3 o, vec3 d, vec3 inv, float t0, out ivec3 stp, out vec3 tdelta, bool wide) {
    Walk w;
    w.wide = wide;
    vec3 lo = frame_lo(wide), cs = frame_cell(wide);
    vec3 pe = (o + t0 * d - lo) / cs;
    w.cell = clamp(ivec3(floor(pe)), ivec3(0), frame_dims(wide) - 1);
    stp = ivec3(sign(d));
    tdelta = abs(cs * inv);
    w.tnext = (lo + (vec3(w.cell) + step(0.0, d)) * cs - o) * inv;
    w.tcur = t0;
    read_cell(w);
    return w;
}

// Where the walk goes after w's cell (after its empty block when `empty`), with that cell
// read ahead, in `next`. False when the ray ends or leaves the grid there.
bool next_cell(Walk w, bool empty, bool last, float texit, vec3 tdelta, ivec3 stp, float t1,
               out Walk next) {
    next = w;
    next.tcur = texit;
    bool inside;
    if (empty) {
        inside = skip_empty_block(next.cell, next.tnext, next.tcur, tdelta, stp, t1, w.wide);
    } else {
        if (w.tnext.x <= w.tnext.y && w.tnext.x <= w.tnext.z) { next.cell.x += stp.x; next.tnext.x += tdelta.x; }
        else if (w.tnext.y <= w.tnext.z) { next.cell.y += stp.y; next.tnext.y += tdelta.y; }
        else { next.cell.z += stp.z; next.tnext.z += tdelta.z; }
        inside = !last && all(greaterThanEqual(next.cell, ivec3(0))) && all(lessThan(next.cell, frame_dims(w.wide)));
    }
    read_cell(next);
    return inside;
}

// Candidate k of w's cell (read a pass ahead): its id and texels; reads the one after it.
int take_candidate(inout Walk w, int k, out vec4 A, out vec4 B) {
    int id = w.id;
    A = w.A;
    B = w.B;
    w.id = w.id2;
    w.A = cyl(w.id, CYL_TOP);
    w.B = cyl(w.id, CYL_TIP);
    w.id2 = list_entry(w.sc.x + k + 2, w.wide);
    return id;
}

// Slab test against the grid box (`wide`: the pixel sampler's); false when the ray misses it
// within [tmin, tmax].
bool enter_grid(vec3 o, vec3 inv, inout float t0, inout float t1, bool wide) {
    vec3 lo = frame_lo(wide);
    vec3 hi = lo + frame_cell(wide) * vec3(frame_dims(wide));
    vec3 ta = (lo - o) * inv, tb = (hi - o) * inv;
    vec3 tn = min(ta, tb), tf = max(ta, tb);
    t0 = max(t0, max(tn.x, max(tn.y, tn.z)));
    t1 = min(t1, min(tf.x, min(tf.y, tf.z)));
    return t0 <= t1;
}

// Cells come in ray order, so once the hit list is settled after a full cell, no later
// cell can change it.
void accel_nearest(vec3 o, vec3 d, float tmax, float widen_per_t, float widen_const) {
    vec3 inv = safe_inverse(d);
    float t0 = 0.0, t1 = tmax;
    if (enter_grid(o, inv, t0, t1, false)) {
        ivec3 stp; vec3 tdelta;
        Walk w = begin_walk(o, d, inv, t0, stp, tdelta, false);
        int guard = dims.x + dims.y + dims.z + 3;
        for (int it = 0; it < guard; ++it) {
            bool empty = w.sc.x < 0;
            float texit = min(min(w.tnext.x, w.tnext.y), min(w.tnext.z, t1));
            bool last = texit >= t1;
            // Where the ray goes after this cell (or after its empty block), that cell's
            // entry and its first candidate, read before this cell's tests so that their
            // cache misses overlap the tests: the render is memory-bound on a CPU. Inside
            // a cell the next candidate's texels and the list entry after it are read a
            // pass ahead for the same reason, and no further (docs/DECISIONS.md, "Read one
            // cell and one candidate ahead").
            Walk next;
            bool inside = next_cell(w, empty, last, texit, tdelta, stp, t1, next);
            int count = empty ? 0 : w.sc.y;
#if COUNT
            counter.z += 1.0; counter.w += float(count);
#endif
            for (int k = 0; k < count; ++k) {
                vec4 A4, B4;
                int id = take_candidate(w, k, A4, B4);
                int surf; float asc, alpha;
                float t = hit_cylinder_ab(id, A4, B4, o, d, widen_per_t, widen_const, surf, asc, alpha);
                // A hit outside this cell's [tcur, texit) belongs to another cell the
                // cylinder is also listed in (half-open, so a hit on a face counts once).
                // Equal distances are ordered by id, so the result does not depend on the
                // order of the cell's list (the GPU grid build fills lists with atomics).
                bool ok = t > 0.0 && t < tmax && t >= w.tcur && (t < texit || last);
                hits_offer(ok ? t : BIG, ok ? id : NO_ID, surf, alpha * asc);
            }
            if (!empty && hits_settled()) break;
            if (!inside) break;
            w = next;
        }
    }
}

#if SHADOWS
// Transmittance mode counts each cylinder once, in the cell that holds its entry point.
float accel_transmittance(vec3 p, vec3 d, float tmax, int own, float tmin, inout int hint) {
    vec3 inv = safe_inverse(d);
    float t0 = 0.0, t1 = tmax;
    if (!enter_grid(p, inv, t0, t1, false)) return 1.0;
    ivec3 stp; vec3 tdelta;
    Walk w = begin_walk(p, d, inv, t0, stp, tdelta, false);
    float trans = 1.0;
    int guard = dims.x + dims.y + dims.z + 3;
    // The walk of accel_nearest: the next cell and the next candidate read one step ahead.
    for (int it = 0; it < guard; ++it) {
        bool empty = w.sc.x < 0;
        float texit = min(min(w.tnext.x, w.tnext.y), min(w.tnext.z, t1));
        bool last = texit >= t1;
        Walk next;
        bool inside = next_cell(w, empty, last, texit, tdelta, stp, t1, next);
        int count = empty ? 0 : w.sc.y;
#if COUNT
        if (!empty) { counter.z += 1.0; counter.w += float(count); }
#endif
        for (int k = 0; k < count; ++k) {
            vec4 A4, B4;
            int id = take_candidate(w, k, A4, B4);
            if (id == own) continue;
            int surf; float asc, alpha;
            float t = hit_cylinder_ab(id, A4, B4, p, d, 0.0, 0.0, surf, asc, alpha);
#if SHADOWS == 1
            if (t > tmin && t < tmax) { hint = id; return 0.0; }
#else
            if (t > tmin && t >= w.tcur && (t < texit || last) && t < tmax) {
                trans *= 1.0 - alpha;
                if (trans < t_eps) return 0.0;
            }
#endif
        }
        if (!inside) break;
        w = next;
    }
    return trans;
}
#endif

#if PIXEL
// The pixel sampler's walk (sampler_pixel.glsl): the cells of the pixel's central ray, every
// candidate offered to pixel_offer, which tests all the pixel's samples. A sample ray lies
// within a pixel of the central one, and the grid it walks (with WIDE_GRID its own, else the
// scene's, padded then) lists each cylinder in every cell its capsule widened GRID_WIDEN_CAP
// times touches, so where a cylinder is as wide as an eighth of a pixel or more, the cells of
// the central ray list every cylinder a sample hits. No cell range decides where a hit counts
// (the list takes a cylinder once, by id): a sample's hit need not lie in a cell of the
// central ray. (Walking the scene's unpadded lists
// instead, through every cell within the samples' reach of the central ray, visited 8 times
// the cells: docs/DECISIONS.md.)
void accel_pixel_nearest(vec3 o, vec3 d, float tmax) {
    vec3 inv = safe_inverse(d);
    float t0 = 0.0, t1 = tmax;
    const bool wide = WIDE_GRID != 0;
    if (enter_grid(o, inv, t0, t1, wide)) {
        ivec3 stp; vec3 tdelta;
        Walk w = begin_walk(o, d, inv, t0, stp, tdelta, wide);
        ivec3 n = frame_dims(wide);
        int guard = n.x + n.y + n.z + 3;
        for (int it = 0; it < guard; ++it) {
            bool empty = w.sc.x < 0;
            float texit = min(min(w.tnext.x, w.tnext.y), min(w.tnext.z, t1));
            bool last = texit >= t1;
            Walk next;
            bool inside = next_cell(w, empty, last, texit, tdelta, stp, t1, next);
            int count = empty ? 0 : w.sc.y;
#if COUNT
            counter.z += 1.0; counter.w += float(count);
#endif
            for (int k = 0; k < count; ++k) {
                vec4 A4, B4;
                int id = take_candidate(w, k, A4, B4);
                pixel_offer(id, A4, B4, o, d);
            }
            if (!empty && pixel_settled()) break;
            if (!inside) break;
            w = next;
        }
    }
}
#endif

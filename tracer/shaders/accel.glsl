// SPDX-License-Identifier: GPL-3.0-or-later
// The accelerator interface: all trace_main.glsl asks of an acceleration structure. An
// accelerator (accel_grid.glsl, accel_bvh.glsl) implements two functions and
// uses the hit list below:
//
//   void accel_nearest(vec3 o, vec3 d, float tmax, float widen_per_t, float widen_const)
//       Offers every cylinder the ray o + t·d (unit d) enters at 0 < t < tmax (tmax: where
//       an opaque mesh hides what lies behind, else BIG) to the hit list with
//       hits_offer(t, id, surf, alpha · ascale), each entry once (hit_cylinder_ab of
//       shapes_cylinder.glsl gives t, surf, ascale and alpha; widen_* are its minimum
//       pixel width arguments). Offers may come in any order: the list keeps the LAYERS
//       nearest, ties by id. It may stop early once hits_settled() holds, provided every
//       hit nearer than those it has not offered yet was offered (cells in ray order).
//
//   float accel_transmittance(vec3 p, vec3 d, float tmax, int own, float tmin, inout int hint)
//       Shadow rays from p along unit d, cylinder `own` (the one shaded) left out.
//       SHADOWS == 1: 0 at any hit in (tmin, tmax), writing the blocker's id to `hint`
//       (the caller tries it first next time), else 1. SHADOWS == 2: the product of
//       (1 - alpha) of every cylinder entered in (tmin, tmax), each counted once; 0 once
//       it drops below t_eps.
//
// With COUNT it adds to counter.z the cells (or nodes; beams: its bin and the list entries
// it reads) it visits and to counter.w the cylinders it tests. Its buffers and uniforms are
// its own (the host binds them: tracer/draw.py TRACE_BUFFERS).

// The pixel (whole-image coordinates) whose samples this invocation's camera rays go
// through, and the independent sampler's sample point in it (pixels), set by main: the
// camera beams (accel_beams.glsl) look their bin up by them.
ivec2 camera_pixel;
vec2 camera_point;

// Axis zero components get a tiny same-sign stand-in so 1/d stays finite (no inf - inf).
vec3 safe_inverse(vec3 d) {
    vec3 s = mix(vec3(1.0), sign(d), notEqual(d, vec3(0.0)));
    return 1.0 / (s * max(abs(d), vec3(1e-30)));
}

// The nearest LAYERS hits of the ray being traced, sorted by (distance, id); empty slots
// are (BIG, NO_ID). Globals, read and written with constant indices only: llvmpipe then
// keeps them in registers, where an insertion at a computed index is a per-lane scatter
// through memory on every test (docs/DECISIONS.md, "The hit list is indexed by constants").
float ht[LAYERS]; float ha[LAYERS]; int hid[LAYERS]; int hs[LAYERS];

void hits_clear() {
    for (int i = 0; i < LAYERS; ++i) { ht[i] = BIG; ha[i] = 0.0; hid[i] = NO_ID; hs[i] = 0; }
}

// The order of hits everywhere (this list, the pixel sampler's, the meshes'): nearer first,
// equal distances by id, so that the order cylinders come in never changes the image.
bool precedes(float ta, int ia, float tb, int ib) {
    return ta < tb || (ta == tb && ia < ib);
}

// Entry (t, id, surface, alpha) goes in by one pass of compare-and-swap; a miss (BIG,
// NO_ID) changes nothing, so callers offer branch-free.
void hits_offer(float ct, int cid, int cs, float ca) {
    for (int i = 0; i < LAYERS; ++i) {
        bool sw = precedes(ct, cid, ht[i], hid[i]);
        float ft = ht[i], fa = ha[i]; int fi = hid[i], fs = hs[i];
        ht[i] = sw ? ct : ft; ha[i] = sw ? ca : fa; hid[i] = sw ? cid : fi; hs[i] = sw ? cs : fs;
        ct = sw ? ft : ct; ca = sw ? fa : ca; cid = sw ? fi : cid; cs = sw ? fs : cs;
    }
}

// No farther hit can change the image: the list is full, or its layers let less than
// t_eps through.
bool hits_settled() {
    if (ht[LAYERS - 1] < BIG) return true;
#if LAYERS > 1
    float Tl = 1.0;
    for (int i = 0; i < LAYERS; ++i) Tl *= 1.0 - ha[i];
    if (Tl < t_eps) return true;
#endif
    return false;
}

// Past this distance no hit can change the image: the farthest of a full list, or the hit
// after which the layers let less than t_eps through (compositing stops there); BIG while
// neither holds. (The BVH's near-first walk and the beams' walks stop there.)
float hits_horizon() {
    float h = ht[LAYERS - 1];
#if LAYERS > 1
    float Tl = 1.0;
    for (int i = 0; i < LAYERS; ++i) {
        Tl *= 1.0 - ha[i];
        h = Tl < t_eps ? min(h, ht[i]) : h;
    }
#endif
    return h;
}

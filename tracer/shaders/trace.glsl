// SPDX-License-Identifier: GPL-3.0-or-later
// Ray tracer of continual cylinders (SPEC §7), one fragment per pixel.
// The host prepends "#version 330 core" and these compile-time switches:
//   LAYERS        hits composited front to back (1 when every alpha is 1)
//   SHADOWS       0: no shadow code at all; 1: hard (any hit); 2: transmittance
//   SHADING_KK    1: Kajiya-Kay, 0: Phong
//   NUM_LIGHTS    1..MAX
//   SPP_N         samples per pixel = SPP_N * SPP_N (stratified, jittered by a fixed hash;
//                 one sample per draw, see main)
//   MIN_PX        1: widen radii to half a pixel (alpha scaled by r / r')
//   ORTHO         1: orthographic camera
//   COUNT         1: write per-pixel work counters to a second target
//   BLOCK         cells per side of the blocks whose emptiness lets the DDA jump ahead
//   ACCEL_BVH     1: walk the BVH (accel_bvh.glsl) instead of the grid

// Per cylinder, 4 consecutive texels (one 64-byte cache line on a CPU driver):
//   TOP: xyz top, w radius   TIP: xyz tip, w alpha   N2: xyz unit normal of plane 2, w cap
//   flags   COL: rgb colour
// Buffer textures (tracer/gl_buffers.py): texel i of each is found by its index alone.
uniform samplerBuffer tex_cyl;    // TEXELS_PER_CYL texels per cylinder
uniform isamplerBuffer tex_idx;   // cell lists (CSR), cylinder ids
uniform isamplerBuffer tex_cell;  // per cell (id x + nx*(y + ny*z)): x = first slot (-1: the
                                  // whole BLOCK^3 block of this cell is empty), y = count

uniform vec3 grid_lo;
uniform vec3 cell_size;
uniform ivec3 dims;

uniform vec3 cam_pos;
uniform mat3 cam_rot;
uniform float pixel_size;
uniform vec2 shift_px;
uniform vec2 image_size;

uniform vec4 light_vec[NUM_LIGHTS];   // w = 0: xyz is the direction light travels; w = 1: position
uniform vec3 light_col[NUM_LIGHTS];
uniform vec4 background;              // premultiplied
uniform vec4 material;                // ambient, diffuse, specular, shininess
uniform float mpw_cap;                // largest widening factor r'/r
uniform float t_eps;                  // stop compositing once transmittance drops below this

layout(location = 0) out vec4 frag_color;
#if COUNT
layout(location = 1) out vec4 frag_count;   // shadow rays, layers, cells visited, cylinder tests
vec4 counter = vec4(0.0);
#endif

const float BIG = 1e30;
const int NO_ID = 0x7fffffff;

const int TOP = 0, TIP = 1, N2 = 2, COL = 3;
// Texel `j` of cylinder `id`.
vec4 cyl(int id, int j) { return texelFetch(tex_cyl, (id << 2) | j); }
int list_entry(int i) { return texelFetch(tex_idx, i).x; }
ivec2 cell_entry(ivec3 c) { return texelFetch(tex_cell, c.x + dims.x * (c.y + dims.y * c.z)).xy; }

// Fixed per-sample hash (lowbias32); the reference tracer computes the same integers.
uint hash32(uint x) {
    x ^= x >> 16; x *= 0x7feb352du;
    x ^= x >> 15; x *= 0x846ca68bu;
    x ^= x >> 16; return x;
}

// Ray vs one cut cylinder, treated as a solid: the infinite solid cylinder intersected with
// the two half-spaces of its planes. Returns the entry distance along the ray (or -1), the
// surface it enters through (0 side, 1 plane 1, 2 plane 2), and the alpha scale of the
// minimum pixel width. An entry through a plane shared with the neighbouring cylinder is no
// surface where the neighbour's section covers the entry point (the ray was inside the
// strand already), and a surface elsewhere: at a bend of θ one section is an ellipse of
// semi-axes r and r/cos θ, the other a circle of radius r, and the crescents between them
// are exposed (SPEC §6). Rejecting every shared-plane entry left holes of width
// r(1/cos θ - 1) on the outside of every bend.
float hit_cylinder_ab(int id, vec4 A4, vec4 B4, vec3 o, vec3 d, float widen_per_t, float widen_const,
                      out int surf, out float ascale, out float alpha) {
    // No cheaper pre-test (bounding sphere, distance to the axis line) pays off: cells are
    // shorter than the cylinders, so nearly every candidate passes such a test, and the
    // extra fetch costs more than the quadratic below, which rejects misses at disc < 0
    // (measured on llvmpipe: 25 % slower with a sphere test, 45 % with a line test).
    // Nor does an early return: llvmpipe runs a branch as masked straight-line code for
    // all 8 lanes (only loops jump, and a loop body runs at least once), so every test
    // pays for all of this function; what saves time is fewer tests or fewer fetches.
    alpha = B4.w;
    vec3 A = A4.xyz, ax = B4.xyz - A4.xyz;
    // Move the origin to the point of the ray nearest the cylinder's middle: the quadratic
    // then works with lengths of the cylinder's size, not the camera distance, so float32
    // keeps its digits for thin, distant hair. The shift is added back at the end.
    float tc = dot(A + 0.5 * ax - o, d);
    vec3 w = o + tc * d - A;
    float r = A4.w;
    ascale = 1.0;
#if MIN_PX
    // Decided once per ray and cylinder, at the shift point's distance.
    float want = widen_const + widen_per_t * abs(tc);
    float rw = clamp(want, r, r * mpw_cap);
    ascale = r / max(rw, 1e-30);
    r = rw;
#endif
    float L2 = dot(ax, ax);
    float dn = dot(d, ax), wn = dot(w, ax);
    vec3 dp = d - ax * (dn / L2);
    vec3 wp = w - ax * (wn / L2);
    float a = dot(dp, dp), b = dot(dp, wp), c = dot(wp, wp) - r * r;
    float tin, tout;
    surf = 0;
    if (a < 1e-12) {            // parallel to the axis: inside the tube everywhere or nowhere
        if (c > 0.0) return -1.0;
        tin = -BIG; tout = BIG;
    } else {
        float disc = b * b - a * c;
        if (disc < 0.0) return -1.0;   // also every grazing miss: no sqrt of a negative
        float s = sqrt(disc);
        tin = (-b - s) / a; tout = (-b + s) / a;
    }
    // (Same cache line as TOP and TIP, so this fetch costs instructions, not a miss.)
    vec4 N4 = cyl(id, N2);
    // Plane 1 keeps (p - A)·ax >= 0, i.e. t·dn >= -wn.
    if (dn > 0.0) { float t1 = -wn / dn; if (t1 > tin) { tin = t1; surf = 1; } }
    else if (dn < 0.0) tout = min(tout, -wn / dn);
    else if (wn < 0.0) return -1.0;
    // Plane 2 keeps (p - B)·n2 <= 0, i.e. t·(d·n2) <= (ax - w)·n2.
    float d2 = dot(d, N4.xyz), w2 = dot(ax - w, N4.xyz);
    if (d2 < 0.0) { float t2 = w2 / d2; if (t2 > tin) { tin = t2; surf = 2; } }
    else if (d2 > 0.0) tout = min(tout, w2 / d2);
    else if (w2 < 0.0) return -1.0;
    if (tin > tout) return -1.0;
    int flags = int(N4.w + 0.5);
    // The neighbour across a shared plane is the next or the previous cylinder (a strand's
    // cylinders are consecutive); its section there is the set of points within its radius
    // of its axis: the next cylinder's axis is N2, the previous one's runs into A. A cap
    // (or the side) has no neighbour: nb = id, and the test below cannot reject.
    bool shared = (surf == 1 && (flags & 1) == 0) || (surf == 2 && (flags & 2) == 0);
    int nb = shared ? (surf == 2 ? id + 1 : id - 1) : id;
    vec4 P4 = cyl(nb, TOP);
    vec3 q = w + tin * d - (surf == 2 ? ax : vec3(0.0));     // entry point - the plane's point
    vec3 na = surf == 2 ? N4.xyz : A - P4.xyz;
    float rn = P4.w;
#if MIN_PX
    rn = clamp(want, rn, rn * mpw_cap);     // widened as this cylinder was, for this ray
#endif
    float qa = dot(q, na), aa = dot(na, na);
    if (shared && dot(q, q) * aa - qa * qa < rn * rn * aa) return -1.0;
    return tc + tin;
}

float hit_cylinder(int id, vec3 o, vec3 d, float widen_per_t, float widen_const,
                   out int surf, out float ascale, out float alpha) {
    return hit_cylinder_ab(id, cyl(id, TOP), cyl(id, TIP), o, d, widen_per_t, widen_const, surf, ascale, alpha);
}

// Most cells a ray crosses are empty (hair is a thin shell with air inside and around).
// When the whole block of BLOCK^3 cells around `cell` is empty, move the DDA state to
// where the ray leaves that block in one go instead of stepping cell by cell. Every cell
// skipped lies in the empty block, so nothing can be missed; at exact ties of two faces
// the cell we land in may differ from the step-by-step walk by one index, but then the
// ray is on that shared edge and the next steps put it right. False when the ray ends or
// leaves the grid inside the block.
// Measured and dropped: a per-block distance to the nearest full block (a coarser level,
// made from the cell counts) to jump whole cubes of empty blocks at once. It cut the cell
// steps by 8-20 %, but the extra fetch runs on every step (see hit_cylinder on branches):
// 3 % faster on 10k wavy strands, 6 % slower on 1k, no change on the real hair.
bool skip_empty_block(inout ivec3 cell, inout vec3 tnext, inout float tcur, vec3 tdelta,
                      ivec3 stp, float t1) {
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
    return all(greaterThanEqual(cell, ivec3(0))) && all(lessThan(cell, dims));
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
};

// The cell's entry, its first two list entries and the first candidate's texels, read before
// they are needed (the walks read one cell and one candidate ahead, so that their cache
// misses overlap the tests of the cell before). The reads ahead stay inside tex_idx: an
// empty block's cell (start -1) reads from 0, and the host gives the lists two texels of
// zeros past their end.
void read_cell(inout Walk w) {
    w.sc = cell_entry(clamp(w.cell, ivec3(0), dims - 1));
    int first = max(w.sc.x, 0);
    w.id = list_entry(first);
    w.id2 = list_entry(first + 1);
    w.A = cyl(w.id, TOP);
    w.B = cyl(w.id, TIP);
}

// The walk from o along d where it enters the grid at t0; stp and tdelta stay fixed.
Walk begin_walk(vec3 o, vec3 d, vec3 inv, float t0, out ivec3 stp, out vec3 tdelta) {
    Walk w;
    vec3 pe = (o + t0 * d - grid_lo) / cell_size;
    w.cell = clamp(ivec3(floor(pe)), ivec3(0), dims - 1);
    stp = ivec3(sign(d));
    tdelta = abs(cell_size * inv);
    w.tnext = (grid_lo + (vec3(w.cell) + step(0.0, d)) * cell_size - o) * inv;
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
        inside = skip_empty_block(next.cell, next.tnext, next.tcur, tdelta, stp, t1);
    } else {
        if (w.tnext.x <= w.tnext.y && w.tnext.x <= w.tnext.z) { next.cell.x += stp.x; next.tnext.x += tdelta.x; }
        else if (w.tnext.y <= w.tnext.z) { next.cell.y += stp.y; next.tnext.y += tdelta.y; }
        else { next.cell.z += stp.z; next.tnext.z += tdelta.z; }
        inside = !last && all(greaterThanEqual(next.cell, ivec3(0))) && all(lessThan(next.cell, dims));
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
    w.A = cyl(w.id, TOP);
    w.B = cyl(w.id, TIP);
    w.id2 = list_entry(w.sc.x + k + 2);
    return id;
}

// Slab test against the grid box; false when the ray misses it within [tmin, tmax].
bool enter_grid(vec3 o, vec3 inv, inout float t0, inout float t1) {
    vec3 hi = grid_lo + cell_size * vec3(dims);
    vec3 ta = (grid_lo - o) * inv, tb = (hi - o) * inv;
    vec3 tn = min(ta, tb), tf = max(ta, tb);
    t0 = max(t0, max(tn.x, max(tn.y, tn.z)));
    t1 = min(t1, min(tf.x, min(tf.y, tf.z)));
    return t0 <= t1;
}

// Axis zero components get a tiny same-sign stand-in so 1/d stays finite (no inf - inf).
vec3 safe_inverse(vec3 d) {
    vec3 s = mix(vec3(1.0), sign(d), notEqual(d, vec3(0.0)));
    return 1.0 / (s * max(abs(d), vec3(1e-30)));
}

#if ACCEL_BVH
#include "accel_bvh.glsl"
#endif

#if SHADOWS
// Transmittance toward a light from p (1 = lit). Hard mode stops at the first hit anywhere;
// transmittance mode multiplies (1 - alpha) of every cylinder hit, each counted once (in the
// cell that holds its entry point).
float shadow_ray(vec3 p, vec3 d, float tmax, int own, float tmin, inout int hint) {
#if COUNT
    counter.x += 1.0;
#endif
#if SHADOWS == 1 && LAYERS > 1
    // The cylinder that shadowed this pixel's previous (nearer) layer often shadows this
    // one too: one test that can end the walk before it starts (5 % off the 4-layer
    // real-hair scene). Any hit in (tmin, tmax) darkens, so which one is found first
    // does not change the result.
    {
        int h = max(hint, 0), hsurf; float hasc, halpha;
        float th = hit_cylinder(h, p, d, 0.0, 0.0, hsurf, hasc, halpha);
#if COUNT
        if (hint >= 0) counter.w += 1.0;
#endif
        if (hint >= 0 && h != own && th > tmin && th < tmax) return 0.0;
    }
#endif
#if ACCEL_BVH
    return bvh_shadow(p, d, tmax, own, tmin, hint);
#else
    vec3 inv = safe_inverse(d);
    float t0 = 0.0, t1 = tmax;
    if (!enter_grid(p, inv, t0, t1)) return 1.0;
    ivec3 stp; vec3 tdelta;
    Walk w = begin_walk(p, d, inv, t0, stp, tdelta);
    float trans = 1.0;
    int guard = dims.x + dims.y + dims.z + 3;
    // The walk of trace: the next cell and the next candidate read one step ahead.
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
#endif
}
#endif

#if SHADOWS
int occluder[NUM_LIGHTS];   // per light, the last cylinder that blocked a shadow ray
#endif

vec3 shade(int id, int surf, vec3 o, vec3 d, float t) {
    vec4 A4 = cyl(id, TOP);
    vec4 B4 = cyl(id, TIP);
    vec3 col = cyl(id, COL).rgb;
    vec3 ax = B4.xyz - A4.xyz;
    vec3 T = normalize(ax);
    vec3 p = o + t * d;
#if !SHADING_KK
    vec3 N;
    if (surf == 0) {
        // SPEC §7: N = ((top - tip) x (p - tip)) x (top - tip), i.e. the part of p - tip
        // square to the axis.
        vec3 q = p - B4.xyz;
        N = q - T * dot(q, T);
    } else if (surf == 1) {
        N = -T;
    } else {
        N = cyl(id, N2).xyz;
    }
    float nl = length(N);
    N = nl > 0.0 ? N / nl : -d;
    if (dot(N, d) > 0.0) N = -N;
#endif
    vec3 result = material.x * col;
    for (int l = 0; l < NUM_LIGHTS; ++l) {
        vec3 L; float dist;
        if (light_vec[l].w > 0.5) { L = light_vec[l].xyz - p; dist = length(L); L /= max(dist, 1e-30); }
        else { L = -light_vec[l].xyz; dist = BIG; }
        float lit = 1.0;
#if SHADOWS
        lit = shadow_ray(p, L, dist, id, 1e-3 * A4.w, occluder[l]);
        if (lit <= 0.0) continue;
#endif
#if SHADING_KK
        float tl = dot(T, L), tv = dot(T, d);
        float sl = sqrt(max(0.0, 1.0 - tl * tl)), sv = sqrt(max(0.0, 1.0 - tv * tv));
        float diff = sl;
        float spec = pow(max(0.0, tl * tv + sl * sv), material.w);
#else
        float diff = max(dot(N, L), 0.0);
        vec3 R = reflect(-L, N);
        float spec = diff > 0.0 ? pow(max(dot(R, -d), 0.0), material.w) : 0.0;
#endif
        result += lit * light_col[l] * (material.y * diff * col + material.z * spec);
    }
    return result;
}

// One primary ray: first find its LAYERS nearest hits without shading (a small sorted list;
// cells come in ray order, so once the list is full, or its layers already let less than
// t_eps through, no later cell can change it), then shade them front to back. Keeping the
// shadow rays out of the traversal loop matters on SIMD hardware (llvmpipe included):
// nested in it, one lane's shadow ray stalls all the lanes still traversing.
// Measured and dropped (llvmpipe, 2 cores, 512x512, CPU time against this loop): one flat
// loop in which each pass either tests one candidate or steps one cell, so lanes with
// short cell lists need not wait for their neighbours' long ones: every pass then pays for
// both halves; 0 % on the real straight hair, 3-4 % slower on 10k and 100k wavy strands
// (it won 5-12 % on wavy hair with the older, finer grids). The same for shadow rays (all
// layers' shadow rays of a pixel walked in one loop, a lane starting its next ray when
// one ends): 13 % slower on the real hair, as every pass pays for setting a ray up. Two
// candidates per pass, to overlap their cache misses: 5 % faster on the real hair and on
// 100k wavy strands, 12 % slower on 10k wavy strands, whose cells hold fewer candidates.
vec4 trace(vec3 o, vec3 d, float widen_per_t, float widen_const) {
    vec3 inv = safe_inverse(d);
    float t0 = 0.0, t1 = BIG;
    // The nearest LAYERS hits, sorted by (distance, id); empty slots are (BIG, NO_ID).
    // A candidate goes in by one pass of compare-and-swap with constant indices: llvmpipe
    // then keeps the arrays in registers, where an insertion at a computed index was a
    // per-lane scatter through memory on every test (10 % of the 4-layer scene's time).
    // Every array index in this function is a constant for that reason.
    float ht[LAYERS]; float ha[LAYERS]; int hid[LAYERS]; int hs[LAYERS];
    for (int i = 0; i < LAYERS; ++i) { ht[i] = BIG; ha[i] = 0.0; hid[i] = NO_ID; hs[i] = 0; }
#if ACCEL_BVH
    bvh_nearest(o, d, widen_per_t, widen_const, ht, ha, hid, hs);
#else
    if (enter_grid(o, inv, t0, t1)) {
        ivec3 stp; vec3 tdelta;
        Walk w = begin_walk(o, d, inv, t0, stp, tdelta);
        int guard = dims.x + dims.y + dims.z + 3;
        for (int it = 0; it < guard; ++it) {
            bool empty = w.sc.x < 0;
            float texit = min(min(w.tnext.x, w.tnext.y), min(w.tnext.z, t1));
            bool last = texit >= t1;
            // Where the ray goes after this cell (or after its empty block), that cell's
            // entry and its first candidate, read before this cell's tests so that their
            // cache misses overlap the tests: the render is memory-bound on a CPU. Inside
            // a cell the next candidate's texels and the list entry after it are read a
            // pass ahead for the same reason (together 15-20 % less time; reading two
            // candidates ahead lost 2-5 % to the extra reads at each cell's end).
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
                bool ok = t > 0.0 && t >= w.tcur && (t < texit || last);
                float ct = ok ? t : BIG, ca = alpha * asc;
                int cid = ok ? id : NO_ID, cs = surf;
                for (int i = 0; i < LAYERS; ++i) {
                    bool sw = ct < ht[i] || (ct == ht[i] && cid < hid[i]);
                    float ft = ht[i], fa = ha[i]; int fi = hid[i], fs = hs[i];
                    ht[i] = sw ? ct : ft; ha[i] = sw ? ca : fa; hid[i] = sw ? cid : fi; hs[i] = sw ? cs : fs;
                    ct = sw ? ft : ct; ca = sw ? fa : ca; cid = sw ? fi : cid; cs = sw ? fs : cs;
                }
            }
            if (!empty) {
                if (ht[LAYERS - 1] < BIG) break;
#if LAYERS > 1
                float Tl = 1.0;
                for (int i = 0; i < LAYERS; ++i) Tl *= 1.0 - ha[i];
                if (Tl < t_eps) break;
#endif
            }
            if (!inside) break;
            w = next;
        }
    }
#endif
    int n = 0;
    for (int i = 0; i < LAYERS; ++i) n += ht[i] < BIG ? 1 : 0;
    vec3 C = vec3(0.0);
    float T = 1.0;
#if SHADOWS
    for (int l = 0; l < NUM_LIGHTS; ++l) occluder[l] = -1;
#endif
    for (int i = 0; i < n; ++i) {
        if (i > 0 && T < t_eps) break;
        // Entry i by constant indices (see above: a computed index would move the arrays
        // to memory for the whole traversal).
        float et = 0.0, ea = 0.0; int eid = 0, es = 0;
        for (int j = 0; j < LAYERS; ++j) if (j == i) { et = ht[j]; ea = ha[j]; eid = hid[j]; es = hs[j]; }
        C += T * ea * shade(eid, es, o, d, et);
        T *= 1.0 - ea;
#if COUNT
        counter.y += 1.0;
#endif
    }
    return vec4(C + T * background.rgb, 1.0 - T + T * background.a);
}

// One sample per draw: the host draws every pixel SPP_N² times, sample_index = 0, 1, ...,
// and adds the passes with blending. Mesa's llvmpipe caps the loop iterations of one
// shader invocation (65535 back-edges over all loops together, then every loop exits
// early, silently); all samples in one invocation with several layers and shadow rays ran
// past it and dropped hits, so the work of one invocation is kept to one sample.
uniform int sample_index;

void main() {
    int px = int(gl_FragCoord.x);
    int py = int(image_size.y) - 1 - int(gl_FragCoord.y);   // row 0 = top
    int s = sample_index;
    vec2 jit = vec2(0.5);
#if SPP_N > 1
    uint h = hash32(hash32(hash32(uint(s)) ^ uint(py)) ^ uint(px));
    vec2 rnd = vec2(float(h >> 8u), float(hash32(h ^ 0x68bc21ebu) >> 8u)) * (1.0 / 16777216.0);
    jit = (vec2(s % SPP_N, s / SPP_N) + rnd) / float(SPP_N);
#endif
    float x = float(px) + jit.x, y = float(py) + jit.y;
    float u = (x - 0.5 * image_size.x + shift_px.x) * pixel_size;
    float v = (0.5 * image_size.y - y + shift_px.y) * pixel_size;
    vec3 o, d;
    float widen_per_t = 0.0, widen_const = 0.0;
#if ORTHO
    o = cam_pos + cam_rot * vec3(u, v, 0.0);
    d = -cam_rot[2];
    widen_const = 0.5 * pixel_size;
#else
    o = cam_pos;
    vec3 dc = cam_rot * vec3(u, v, -1.0);
    float len = length(dc);
    d = dc / len;
    // At distance t along this ray the depth is t / len and a pixel spans pixel_size times
    // that; the minimum width is half of it.
    widen_per_t = 0.5 * pixel_size / len;
#endif
    frag_color = trace(o, d, widen_per_t, widen_const) / float(SPP_N * SPP_N);
#if COUNT
    frag_count = counter;
#endif
}

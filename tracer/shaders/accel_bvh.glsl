// SPDX-License-Identifier: GPL-3.0-or-later
// The BVH's walks (tracer/bvh.py builds the tree and lays it out), implementing the
// accelerator interface of accel.glsl.
//
// Entry i (a node or a leaf, depth-first): texels WALK_TEXELS*i, +1 of tex_node (RGBA32I),
// (lo, skip) (hi, code), box corners as float bits (an integer buffer keeps every bit).
// `code` is BVH_NODE for a node, else a leaf's first << LEAF_BITS | count: its pieces are
// tex_order[first .. first + count), each (cylinder id, k | K << PIECE_BITS), piece k of K
// of the cylinder's axis (tracer/bvh.py cuts long cylinders). `skip` is the entry after the
// subtree, so a node's children are entries i + 1 and skip(i + 1). The tree has bvh_entries
// entries.
//
// Two walks. Shadow rays (and a primary ray whose stack overflowed) go in tree order: on to
// i + 1 into a node the ray enters, else to skip; no stack. Primary rays go near child
// first with a short stack in registers (accel_nearest says how), so that the hit list's
// horizon prunes early. Measured on llvmpipe (2 cores, 256², primary rays, CPU time): on
// 100,000 wavy strands the near-first walk tests 136 boxes and 53 pieces per ray where the
// tree-order walk tests 327 and 146 (0.50 s against 0.78 s; with 10 slots it overflowed
// often enough to take 0.62 s); on 10,000 strands it costs 12 % more (184 -> 114 boxes do
// not pay for shifting the stack).
// Measured and dropped: a stack indexed per lane (it lives in memory on llvmpipe; 1.08 s
// against 0.91 s for the tree-order walk at 10,000 strands before pieces); testing a leaf in
// the same pass as a box (every lane pays for a leaf whenever one lane has one: 1.74 s);
// leaves of at most 2 or 7 pieces (1.17, 1.30 s against 0.91 s with 4); reading both
// possible next entries ahead (6-20 % slower).
uniform isamplerBuffer tex_node;
uniform isamplerBuffer tex_order;
uniform int bvh_entries;

// Whether the ray enters the box within [t0, t1]; `oi` is o * inv, so each slab distance
// is one multiply-add (lo * inv - oi). The far side gets a little slack: the boxes are
// padded (tracer/bvh.py BOX_EPS), and this only keeps float32 rounding of a far camera from
// losing a box whose hit lies at its edge.
float box_entry(vec3 lo, vec3 hi, vec3 inv, vec3 oi, float t0, float t1) {
    vec3 ta = lo * inv - oi, tb = hi * inv - oi;
    vec3 tn = min(ta, tb), tf = max(ta, tb);
    float en = max(t0, max(tn.x, max(tn.y, tn.z)));
    float ex = min(t1, min(tf.x, min(tf.y, tf.z)));
    return en <= ex + 1e-6 * abs(ex) ? en : BIG;
}

bool box_entered(vec3 lo, vec3 hi, vec3 inv, vec3 oi, float t0, float t1) {
    return box_entry(lo, hi, inv, oi, t0, t1) < BIG;
}

// The next leaf the ray enters within [0, t1] from entry i on: its code (i left on it), or
// -1 at the end. Boxes are walked until a leaf is reached, and only then is a leaf tested:
// llvmpipe runs 8 pixels in lock-step, so a loop that tests a leaf in the same pass as a
// node step makes every lane pay for a leaf whenever any lane is at one. `wide` (the pixel
// sampler's walk): every box grown by how far a sample ray strays from this one at the box's
// far side, reach.x + reach.y · distance; callers pass a constant, so a plain walk compiles
// without it.
int next_leaf(inout int i, vec3 o, vec3 inv, float t1, bool wide, vec2 reach) {
    int code = -1;
    vec3 oi = o * inv;
    for (int it = 0; it < bvh_entries && i < bvh_entries; ++it) {
        ivec4 a = texelFetch(tex_node, WALK_TEXELS * i), b = texelFetch(tex_node, WALK_TEXELS * i + 1);
        vec3 lo = intBitsToFloat(a.xyz), hi = intBitsToFloat(b.xyz);
        float pad = wide ? reach.x + reach.y * (length(0.5 * (lo + hi) - o) + 0.5 * length(hi - lo)) : 0.0;
        bool enter = box_entered(lo - pad, hi + pad, inv, oi, 0.0, t1);
#if COUNT
        counter.z += 1.0;
#endif
        if (enter && b.w != BVH_NODE) { code = b.w; break; }
        i = enter ? i + 1 : a.w;
    }
    return code;
}

// Whether piece k of K (part = k | K << PIECE_BITS) holds the entry point at t: its axis
// parameter u (0 at the top, 1 at the tip) in [k/K, (k+1)/K), open-ended for the first and
// the last piece. All pieces of a cylinder compute the same u from the same numbers, so a
// hit counts in exactly one of them.
bool piece_holds(int part, vec3 o, vec3 d, float t, vec4 A4, vec4 B4) {
    int k = part & ((1 << PIECE_BITS) - 1), K = part >> PIECE_BITS;
    vec3 ax = B4.xyz - A4.xyz;
    float u = dot(o + t * d - A4.xyz, ax) / dot(ax, ax);
    float lo = k == 0 ? -BIG : float(k) / float(K);
    float hi = k == K - 1 ? BIG : float(k + 1) / float(K);
    return K == 1 || (u >= lo && u < hi);
}

// Offers the pieces of leaf `code` hit at 0 < t < tmax to the hit list (a hit counts in the
// piece that holds it).
void offer_leaf(int code, vec3 o, vec3 d, float tmax, float widen_per_t, float widen_const) {
    int count = code & ((1 << LEAF_BITS) - 1), first = code >> LEAF_BITS;
#if COUNT
    counter.w += float(count);
#endif
    for (int k = 0; k < count; ++k) {
        ivec2 piece = texelFetch(tex_order, first + k).xy;
        int id = piece.x;
        vec4 A4 = cyl(id, CYL_TOP), B4 = cyl(id, CYL_TIP);
        int surf; float asc, alpha;
        float t = hit_cylinder_ab(id, A4, B4, o, d, widen_per_t, widen_const, surf, asc, alpha);
        bool ok = t > 0.0 && t < tmax && piece_holds(piece.y, o, d, t, A4, B4);
        hits_offer(ok ? t : BIG, ok ? id : NO_ID, surf, alpha * asc);
    }
}

// The walk in tree order, boxes that start beyond `cut` (or the list's horizon) skipped.
void nearest_in_order(vec3 o, vec3 d, float tmax, float widen_per_t, float widen_const, float cut) {
    vec3 inv = safe_inverse(d);
    int i = 0;
    for (int it = 0; it < bvh_entries; ++it) {
        int code = next_leaf(i, o, inv, cut, false, vec2(0.0));
        if (code < 0) break;
        ++i;     // a leaf's subtree is itself
        offer_leaf(code, o, d, tmax, widen_per_t, widen_const);
        cut = min(cut, hits_horizon());
    }
}

// Near child first: at node `cur` both children are tested; the nearer one entered is taken
// and the farther pushed with its entry distance, popped only while it starts before the
// hit list's horizon. The stack's slots are read and written with constant indices only
// (a push shifts them down), so llvmpipe keeps them in registers. When it overflows, the
// deepest slot is lost: the walk in tree order then runs again from a cleared list with
// boxes past the horizon found so far skipped (no nearer hit can lie beyond it), so the
// list ends as if nothing had been lost.
void accel_nearest(vec3 o, vec3 d, float tmax, float widen_per_t, float widen_const) {
    vec3 inv = safe_inverse(d), oi = o * inv;
    float cut = tmax;
    int st_i[BVH_SHORT_STACK]; int st_c[BVH_SHORT_STACK]; float st_t[BVH_SHORT_STACK];
    for (int j = 0; j < BVH_SHORT_STACK; ++j) { st_i[j] = 0; st_c[j] = BVH_NODE; st_t[j] = BIG; }
    int depth = 0;
    bool lost = false;
    int cur = 0, code = BVH_NODE;
    for (int it = 0; it < 2 * bvh_entries; ++it) {
        if (cur < 0) {
            for (int p = 0; p < BVH_SHORT_STACK && depth > 0 && cur < 0; ++p) {
                int ti = st_i[0], tc = st_c[0]; float tt = st_t[0];
                for (int j = 0; j < BVH_SHORT_STACK - 1; ++j) {
                    st_i[j] = st_i[j + 1]; st_c[j] = st_c[j + 1]; st_t[j] = st_t[j + 1];
                }
                --depth;
                if (tt <= cut) { cur = ti; code = tc; }
            }
            if (cur < 0) break;
        }
        if (code != BVH_NODE) {
            offer_leaf(code, o, d, tmax, widen_per_t, widen_const);
            cut = min(tmax, hits_horizon());
            cur = -1;
            continue;
        }
        int li = cur + 1;
        ivec4 la = texelFetch(tex_node, WALK_TEXELS * li), lb = texelFetch(tex_node, WALK_TEXELS * li + 1);
        int ri = la.w;
        ivec4 ra = texelFetch(tex_node, WALK_TEXELS * ri), rb = texelFetch(tex_node, WALK_TEXELS * ri + 1);
        float tl = box_entry(intBitsToFloat(la.xyz), intBitsToFloat(lb.xyz), inv, oi, 0.0, cut);
        float tr = box_entry(intBitsToFloat(ra.xyz), intBitsToFloat(rb.xyz), inv, oi, 0.0, cut);
#if COUNT
        counter.z += 2.0;
#endif
        bool gl = tl < BIG, gr = tr < BIG;
        bool left_first = tl <= tr;
        if (gl && gr) {
            lost = lost || depth == BVH_SHORT_STACK;
            for (int j = BVH_SHORT_STACK - 1; j > 0; --j) {
                st_i[j] = st_i[j - 1]; st_c[j] = st_c[j - 1]; st_t[j] = st_t[j - 1];
            }
            st_i[0] = left_first ? ri : li; st_c[0] = left_first ? rb.w : lb.w; st_t[0] = left_first ? tr : tl;
            depth = min(depth + 1, BVH_SHORT_STACK);
        }
        bool take_left = gl && (left_first || !gr);
        cur = take_left ? li : (gr ? ri : -1);
        code = take_left ? lb.w : rb.w;
    }
    if (lost) {
        hits_clear();
        nearest_in_order(o, d, tmax, widen_per_t, widen_const, cut);
    }
}

#if SHADOWS
float accel_transmittance(vec3 p, vec3 d, float tmax, int own, float tmin, inout int hint) {
    vec3 inv = safe_inverse(d);
    float trans = 1.0;
    int i = 0;
    for (int it = 0; it < bvh_entries; ++it) {
        int code = next_leaf(i, p, inv, tmax, false, vec2(0.0));
        if (code < 0) break;
        int count = code & ((1 << LEAF_BITS) - 1), first = code >> LEAF_BITS;
        ++i;
#if COUNT
        counter.w += float(count);
#endif
        for (int k = 0; k < count; ++k) {
            ivec2 piece = texelFetch(tex_order, first + k).xy;
            int id = piece.x;
            if (id == own) continue;
            vec4 A4 = cyl(id, CYL_TOP), B4 = cyl(id, CYL_TIP);
            int surf; float asc, alpha;
            float t = hit_cylinder_ab(id, A4, B4, p, d, 0.0, 0.0, surf, asc, alpha);
            if (t > tmin && t < tmax && piece_holds(piece.y, p, d, t, A4, B4)) {
#if SHADOWS == 1
                hint = id;
                return 0.0;
#else
                trans *= 1.0 - alpha;
                if (trans < t_eps) return 0.0;
#endif
            }
        }
    }
    return trans;
}
#endif

#if PIXEL
// The pixel sampler's walk (sampler_pixel.glsl): the tree in order along the pixel's central
// ray, every box grown by how far a sample ray strays from that ray at the box's far side,
// so that every cylinder a sample hits is offered (pixel_offer takes each once, whichever of
// its pieces comes first). Once every sample has its LAYERS hits, boxes starting past the
// farthest of them are skipped (next_leaf's wide walk).
void accel_pixel_nearest(vec3 o, vec3 d, float tmax) {
    vec3 inv = safe_inverse(d);
    float cut = tmax;
    int i = 0;
    for (int it = 0; it < bvh_entries; ++it) {
        int code = next_leaf(i, o, inv, cut, true, vec2(px_reach_c, px_reach_t));
        if (code < 0) break;
        ++i;
        int count = code & ((1 << LEAF_BITS) - 1), first = code >> LEAF_BITS;
#if COUNT
        counter.w += float(count);
#endif
        for (int k = 0; k < count; ++k) {
            int id = texelFetch(tex_order, first + k).x;
            pixel_offer(id, cyl(id, CYL_TOP), cyl(id, CYL_TIP), o, d);
        }
        if (pixel_settled()) cut = min(cut, list_far());
    }
}
#endif

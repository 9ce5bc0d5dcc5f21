// SPDX-License-Identifier: GPL-3.0-or-later
// The BVH's walks (tracer/bvh.py builds the tree and lays it out), implementing the
// accelerator interface of accel.glsl.
//
// Entry i (a node or a leaf, depth-first): texels WALK_TEXELS*i, +1 of tex_node (RGBA32I),
// (lo, skip) (hi, code), box corners as float bits (an integer buffer keeps every bit).
// `code` is BVH_NODE for a node, else a leaf's first << LEAF_BITS | count: its pieces are
// tex_order[first .. first + count), each (cylinder id, k | K << PIECE_BITS), piece k of K
// of the cylinder's axis (tracer/bvh.py cuts long cylinders). `skip` is the entry after the
// subtree. The walk goes on to i + 1 into a node the ray enters, else to skip: no stack.
// The tree has bvh_entries entries.
//
// Measured and dropped (llvmpipe, 2 cores, 10,000 wavy strands, 256², 4 layers, 1 sun,
// before pieces): an ordered walk with a stack (each node holding both children's boxes,
// the near child first, the far one pushed with its entry distance) visits 65 boxes per
// primary ray where this walk visits 207, yet took 1.08 s against 0.91 s: its stack, an
// array indexed per lane, lives in memory on llvmpipe. Testing a leaf in the same pass as a
// node step took 1.74 s (every lane pays for a leaf whenever one lane has one). Leaves of at
// most 2 or 7 pieces: 1.17 and 1.30 s against 0.91 s with LEAF_MAX 4.
// With pieces, near child first again, its stack in registers (a push shifts the
// slots with constant indices; overflow lost the deepest slot and reran this walk): 16
// slots cut boxes per primary ray from 184 to 114 and cylinder tests from 55 to 32, yet
// cost 4 % more CPU time than this walk (shifting the slots); 4 to 8 slots overflowed too
// often to gain anything. Reading both possible next entries ahead: 6-20 % slower.
uniform isamplerBuffer tex_node;
uniform isamplerBuffer tex_order;
uniform int bvh_entries;

// Whether the ray enters the box within [t0, t1]; `oi` is o * inv, so each slab distance
// is one multiply-add (lo * inv - oi). The far side gets a little slack: the boxes are
// padded (tracer/bvh.py BOX_EPS), and this only keeps float32 rounding of a far camera from
// losing a box whose hit lies at its edge.
bool box_entered(vec3 lo, vec3 hi, vec3 inv, vec3 oi, float t0, float t1) {
    vec3 ta = lo * inv - oi, tb = hi * inv - oi;
    vec3 tn = min(ta, tb), tf = max(ta, tb);
    float en = max(t0, max(tn.x, max(tn.y, tn.z)));
    float ex = min(t1, min(tf.x, min(tf.y, tf.z)));
    return en <= ex + 1e-6 * abs(ex);
}

// The next leaf the ray enters within [0, t1] from entry i on: its code (i left on it), or
// -1 at the end. Boxes are walked until a leaf is reached, and only then is a leaf tested:
// llvmpipe runs 8 pixels in lock-step, so a loop that tests a leaf in the same pass as a
// node step makes every lane pay for a leaf whenever any lane is at one.
int next_leaf(inout int i, vec3 o, vec3 inv, float t1) {
    int code = -1;
    vec3 oi = o * inv;
    for (int it = 0; it < bvh_entries && i < bvh_entries; ++it) {
        ivec4 a = texelFetch(tex_node, WALK_TEXELS * i), b = texelFetch(tex_node, WALK_TEXELS * i + 1);
        bool enter = box_entered(intBitsToFloat(a.xyz), intBitsToFloat(b.xyz), inv, oi, 0.0, t1);
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

// The distance past which no hit can change the image: the last slot's when the list is
// full, or the first hit at which the layers before let less than t_eps through.
float hits_horizon() {
    float cut = ht[LAYERS - 1];
#if LAYERS > 1
    float Tl = 1.0;
    for (int i = 0; i < LAYERS; ++i) {
        Tl *= 1.0 - ha[i];
        if (Tl < t_eps) cut = min(cut, ht[i]);
    }
#endif
    return cut;
}

// Boxes beyond the hit list's horizon are skipped (a box that starts at it exactly is
// walked: a hit there may still win its tie by id).
void accel_nearest(vec3 o, vec3 d, float widen_per_t, float widen_const) {
    vec3 inv = safe_inverse(d);
    float cut = BIG;
    int i = 0;
    for (int it = 0; it < bvh_entries; ++it) {
        int code = next_leaf(i, o, inv, cut);
        if (code < 0) break;
        int count = code & ((1 << LEAF_BITS) - 1), first = code >> LEAF_BITS;
        ++i;     // a leaf's subtree is itself
#if COUNT
        counter.w += float(count);
#endif
        for (int k = 0; k < count; ++k) {
            ivec2 piece = texelFetch(tex_order, first + k).xy;
            int id = piece.x;
            vec4 A4 = cyl(id, CYL_TOP), B4 = cyl(id, CYL_TIP);
            int surf; float asc, alpha;
            float t = hit_cylinder_ab(id, A4, B4, o, d, widen_per_t, widen_const, surf, asc, alpha);
            bool ok = t > 0.0 && piece_holds(piece.y, o, d, t, A4, B4);
            hits_offer(ok ? t : BIG, ok ? id : NO_ID, surf, alpha * asc);
        }
        cut = hits_horizon();
    }
}

#if SHADOWS
float accel_transmittance(vec3 p, vec3 d, float tmax, int own, float tmin, inout int hint) {
    vec3 inv = safe_inverse(d);
    float trans = 1.0;
    int i = 0;
    for (int it = 0; it < bvh_entries; ++it) {
        int code = next_leaf(i, p, inv, tmax);
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

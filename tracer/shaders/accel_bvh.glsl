// SPDX-License-Identifier: GPL-3.0-or-later
// BVH walks for primary and shadow rays (tracer/bvh.py builds the tree, walk_texels lays it
// out). Needs from the shader that includes it: cyl(), TOP, TIP, hit_cylinder_ab(),
// safe_inverse(), BIG, NO_ID, LAYERS, t_eps and, with COUNT, `counter` (z: boxes tested,
// w: cylinders tested).
//
// Entry i (a node or a leaf, depth-first): texels 2i, 2i+1 of tex_node (RGBA32I), (lo, skip)
// (hi, leaf), box corners as float bits (an integer buffer keeps every bit). `leaf` is -1 for
// a node, else first * 8 + count: the leaf's pieces are tex_order[first .. first + count),
// each (cylinder id, k | K << 8): piece k of K of the cylinder's axis (tracer/bvh.py cuts long
// cylinders). `skip` is the entry after the subtree. The tree has bvh_nodes entries.
//
// Measured and dropped (llvmpipe, 2 cores, 10,000 wavy strands, 256², 4 layers, 1 sun):
// an ordered walk with a stack (each node holding both children's boxes, the near child
// first, the far one pushed with its entry distance) visits 65 boxes per primary ray where
// this walk visits 207, yet took 1.08 s against 0.91 s here: its stack, an array indexed
// per lane, lives in memory on llvmpipe. Testing a leaf in the same pass as a node step
// took 1.74 s (every lane pays for a leaf whenever one lane has one). Leaves of at most 2
// or 7 cylinders: 1.17 and 1.30 s against 0.91 s with 4.
uniform isamplerBuffer tex_node;
uniform isamplerBuffer tex_order;
uniform int bvh_nodes;

// Where the ray enters the box within [t0, t1], or BIG when it misses it there. The far
// side gets a few ulps of slack: the boxes are padded (tracer/bvh.py BOX_EPS), and this only
// keeps float32 rounding of a far camera from losing a box whose hit lies at its edge.
float box_entry(vec3 lo, vec3 hi, vec3 o, vec3 inv, float t0, float t1) {
    vec3 ta = (lo - o) * inv, tb = (hi - o) * inv;
    vec3 tn = min(ta, tb), tf = max(ta, tb);
    float en = max(t0, max(tn.x, max(tn.y, tn.z)));
    float ex = min(t1, min(tf.x, min(tf.y, tf.z)));
    ex += 1e-6 * abs(ex);
    return en <= ex ? en : BIG;
}

// Whether piece k of K (part = k | K << 8) holds the entry point at t: its axis parameter u
// (0 at the top, 1 at the tip) in [k/K, (k+1)/K), open-ended for the first and last piece.
// All pieces of a cylinder compute the same u from the same numbers, so a hit counts in
// exactly one of them.
bool piece_holds(int part, vec3 o, vec3 d, float t, vec4 A4, vec4 B4) {
    int k = part & 255, K = part >> 8;
    vec3 ax = B4.xyz - A4.xyz;
    float u = dot(o + t * d - A4.xyz, ax) / dot(ax, ax);
    float lo = k == 0 ? -BIG : float(k) / float(K);
    float hi = k == K - 1 ? BIG : float(k + 1) / float(K);
    return K == 1 || (u >= lo && u < hi);
}

// The walk goes on to i + 1 into an entered node, else to skip (past the subtree): no stack.
// Boxes are walked until the ray enters a leaf (or ends), and only then is a leaf tested:
// llvmpipe runs 8 pixels in lock-step, so a loop that tests a leaf in the same pass as a
// node step makes every lane pay for a leaf whenever any lane is at one.
// The next leaf the ray enters from entry i on (its entry in `i`, its code returned; -1:
// none before the end), boxes clipped to [0, t1].
int next_leaf(inout int i, vec3 o, vec3 inv, float t1) {
    int code = -1;
    for (int it = 0; it < bvh_nodes && i < bvh_nodes; ++it) {
        ivec4 a = texelFetch(tex_node, 2 * i), b = texelFetch(tex_node, 2 * i + 1);
        float en = box_entry(intBitsToFloat(a.xyz), intBitsToFloat(b.xyz), o, inv, 0.0, t1);
        bool enter = en < BIG;
#if COUNT
        counter.z += 1.0;
#endif
        if (enter && b.w >= 0) { code = b.w; break; }
        i = enter ? i + 1 : a.w;
    }
    return code;
}

void bvh_nearest(vec3 o, vec3 d, float widen_per_t, float widen_const,
                 inout float ht[LAYERS], inout float ha[LAYERS], inout int hid[LAYERS], inout int hs[LAYERS]) {
    vec3 inv = safe_inverse(d);
    float cut = BIG;
    int i = 0;
    for (int it = 0; it < bvh_nodes; ++it) {
        int code = next_leaf(i, o, inv, cut);
        if (code < 0) break;
        int cnt = code & 7, first = code >> 3;
        ++i;     // a leaf's skip is the next entry
#if COUNT
        counter.w += float(cnt);
#endif
        for (int k = 0; k < cnt; ++k) {
            ivec2 ref = texelFetch(tex_order, first + k).xy;
            int id = ref.x;
            vec4 A4 = cyl(id, TOP), B4 = cyl(id, TIP);
            int surf; float asc, alpha;
            float t = hit_cylinder_ab(id, A4, B4, o, d, widen_per_t, widen_const, surf, asc, alpha);
            bool ok = t > 0.0 && piece_holds(ref.y, o, d, t, A4, B4);
            float ct = ok ? t : BIG, ca = alpha * asc;
            int cid = ok ? id : NO_ID, cs = surf;
            for (int j = 0; j < LAYERS; ++j) {
                bool sw = ct < ht[j] || (ct == ht[j] && cid < hid[j]);
                float ft = ht[j], fa = ha[j]; int fi = hid[j], fs = hs[j];
                ht[j] = sw ? ct : ft; ha[j] = sw ? ca : fa; hid[j] = sw ? cid : fi; hs[j] = sw ? cs : fs;
                ct = sw ? ft : ct; ca = sw ? fa : ca; cid = sw ? fi : cid; cs = sw ? fs : cs;
            }
        }
        cut = ht[LAYERS - 1];
#if LAYERS > 1
        float Tl = 1.0;
        for (int j = 0; j < LAYERS; ++j) {
            Tl *= 1.0 - ha[j];
            if (Tl < t_eps) cut = min(cut, ht[j]);
        }
#endif
    }
}

#if SHADOWS
float bvh_shadow(vec3 p, vec3 d, float tmax, int own, float tmin, inout int hint) {
    vec3 inv = safe_inverse(d);
    float trans = 1.0;
    int i = 0;
    for (int it = 0; it < bvh_nodes; ++it) {
        int code = next_leaf(i, p, inv, tmax);
        if (code < 0) break;
        int cnt = code & 7, first = code >> 3;
        ++i;
#if COUNT
        counter.w += float(cnt);
#endif
        for (int k = 0; k < cnt; ++k) {
            ivec2 ref = texelFetch(tex_order, first + k).xy;
            int id = ref.x;
            if (id == own) continue;
            vec4 A4 = cyl(id, TOP), B4 = cyl(id, TIP);
            int surf; float asc, alpha;
            float t = hit_cylinder_ab(id, A4, B4, p, d, 0.0, 0.0, surf, asc, alpha);
            if (t > tmin && t < tmax && piece_holds(ref.y, p, d, t, A4, B4)) {
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

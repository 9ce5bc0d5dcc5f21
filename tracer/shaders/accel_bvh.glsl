// SPDX-License-Identifier: GPL-3.0-or-later
// BVH walks for primary and shadow rays (tracer/bvh.py builds the tree).
// Needs from the shader that includes it: cyl(), TOP, TIP, hit_cylinder_ab(), safe_inverse(),
// BIG, NO_ID, LAYERS, t_eps and, with COUNT, `counter`. Compile-time switches:
//   BVH_STACK     slots of the walk's stack (the tree's depth; tracer/bvh.py says why enough)
//   BVH_LEAF_MAX  cylinders per leaf at most (tracer/bvh.py LEAF_MAX)
//
// Node i: texels 4i..4i+3 of tex_node (RGBA32I): (lo_L, link_L) (hi_L, link_R) (lo_R, -)
// (hi_R, -), box corners as float bits. A link >= 0 is a node; < 0 a leaf,
// -(first * 8 + count) - 1, whose cylinder ids are tex_order[first .. first + count).
// Node 0 is the root; the tree has bvh_nodes nodes.
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

#if !BVH_THREADED
// One node: both children's entry distances (BIG: missed) and links.
struct BvhNode { float tL, tR; int lL, lR; };

BvhNode visit(int node, vec3 o, vec3 inv, float t0, float t1) {
    ivec4 a = texelFetch(tex_node, node * 4);
    ivec4 b = texelFetch(tex_node, node * 4 + 1);
    ivec4 c = texelFetch(tex_node, node * 4 + 2);
    ivec4 e = texelFetch(tex_node, node * 4 + 3);
    BvhNode n;
    n.tL = box_entry(intBitsToFloat(a.xyz), intBitsToFloat(b.xyz), o, inv, t0, t1);
    n.tR = box_entry(intBitsToFloat(c.xyz), intBitsToFloat(e.xyz), o, inv, t0, t1);
    n.lL = a.w;
    n.lR = b.w;
#if COUNT
    counter.z += 1.0;
#endif
    return n;
}

// The leaves among a node's children that the ray enters: cylinders to test, and the slot in
// tex_order of test k (the left leaf's cylinders first).
int leaf_tests(BvhNode n, out int firstL, out int nL, out int firstR) {
    int vL = -n.lL - 1, vR = -n.lR - 1;
    nL = (n.lL < 0 && n.tL < BIG) ? (vL & 7) : 0;
    int nR = (n.lR < 0 && n.tR < BIG) ? (vR & 7) : 0;
    firstL = vL >> 3;
    firstR = (vR >> 3) - nL;
#if COUNT
    counter.w += float(nL + nR);
#endif
    return nL + nR;
}

// The next node after `n`: the nearer inner child that starts before t1 (the farther one
// pushed), else the nearest pushed node that still starts before t1; -1 when none is left.
int next_node(BvhNode n, float t1, inout int sp, inout int st_node[BVH_STACK], inout float st_t[BVH_STACK]) {
    // (A missed child's entry is BIG, which t1 may equal: the test against BIG comes first.)
    bool gL = n.lL >= 0 && n.tL < BIG && n.tL <= t1, gR = n.lR >= 0 && n.tR < BIG && n.tR <= t1;
    if (gL && gR) {
        bool left_first = n.tL <= n.tR;
        st_node[sp] = left_first ? n.lR : n.lL;
        st_t[sp] = left_first ? n.tR : n.tL;
        ++sp;
        return left_first ? n.lL : n.lR;
    }
    if (gL) return n.lL;
    if (gR) return n.lR;
    while (sp > 0) {
        --sp;
        if (st_t[sp] <= t1) return st_node[sp];
    }
    return -1;
}

// The nearest LAYERS hits of a primary ray, sorted by (distance, id), into the caller's list
// (see trace: constant indices only). Subtrees are skipped once they start beyond the
// distance past which no hit can change the image: the last slot's when the list is full,
// or the first hit at which the layers before let less than t_eps through.
void bvh_nearest(vec3 o, vec3 d, float widen_per_t, float widen_const,
                 inout float ht[LAYERS], inout float ha[LAYERS], inout int hid[LAYERS], inout int hs[LAYERS]) {
    vec3 inv = safe_inverse(d);
    int st_node[BVH_STACK]; float st_t[BVH_STACK];
    int sp = 0, node = 0;
    float cut = BIG;
    for (int it = 0; it < bvh_nodes && node >= 0; ++it) {
        BvhNode n = visit(node, o, inv, 0.0, cut);
        int firstL, nL, firstR;
        int tests = leaf_tests(n, firstL, nL, firstR);
        for (int k = 0; k < tests; ++k) {
            int id = texelFetch(tex_order, (k < nL ? firstL : firstR) + k).x;
            int surf; float asc, alpha;
            float t = hit_cylinder_ab(id, cyl(id, TOP), cyl(id, TIP), o, d, widen_per_t, widen_const,
                                      surf, asc, alpha);
            bool ok = t > 0.0;
            float ct = ok ? t : BIG, ca = alpha * asc;
            int cid = ok ? id : NO_ID, cs = surf;
            for (int i = 0; i < LAYERS; ++i) {
                bool sw = ct < ht[i] || (ct == ht[i] && cid < hid[i]);
                float ft = ht[i], fa = ha[i]; int fi = hid[i], fs = hs[i];
                ht[i] = sw ? ct : ft; ha[i] = sw ? ca : fa; hid[i] = sw ? cid : fi; hs[i] = sw ? cs : fs;
                ct = sw ? ft : ct; ca = sw ? fa : ca; cid = sw ? fi : cid; cs = sw ? fs : cs;
            }
        }
        if (tests > 0) {
            cut = ht[LAYERS - 1];
#if LAYERS > 1
            float Tl = 1.0;
            for (int i = 0; i < LAYERS; ++i) {
                Tl *= 1.0 - ha[i];
                if (Tl < t_eps) cut = min(cut, ht[i]);
            }
#endif
        }
        node = next_node(n, cut, sp, st_node, st_t);
    }
}

#endif  // !BVH_THREADED

#if SHADOWS && !BVH_THREADED
// Transmittance from p toward a light at distance tmax (1 = lit), without cylinder `own`:
// hard mode ends at the first hit (`hint` keeps it for the next layer's ray); transmittance
// mode multiplies (1 - alpha) of every cylinder hit (each lies in one leaf: counted once).
float bvh_shadow(vec3 p, vec3 d, float tmax, int own, float tmin, inout int hint) {
    vec3 inv = safe_inverse(d);
    int st_node[BVH_STACK]; float st_t[BVH_STACK];
    int sp = 0, node = 0;
    float trans = 1.0;
    for (int it = 0; it < bvh_nodes && node >= 0; ++it) {
        BvhNode n = visit(node, p, inv, 0.0, tmax);
        int firstL, nL, firstR;
        int tests = leaf_tests(n, firstL, nL, firstR);
        for (int k = 0; k < tests; ++k) {
            int id = texelFetch(tex_order, (k < nL ? firstL : firstR) + k).x;
            if (id == own) continue;
            int surf; float asc, alpha;
            float t = hit_cylinder_ab(id, cyl(id, TOP), cyl(id, TIP), p, d, 0.0, 0.0, surf, asc, alpha);
            if (t > tmin && t < tmax) {
#if SHADOWS == 1
                hint = id;
                return 0.0;
#else
                trans *= 1.0 - alpha;
                if (trans < t_eps) return 0.0;
#endif
            }
        }
        node = next_node(n, tmax, sp, st_node, st_t);
    }
    return trans;
}
#endif

#if BVH_THREADED
// The stackless walk: entries in depth-first order, 2 texels each, (lo, skip) (hi, leaf):
// leaf -1 for a node, else first * 8 + count. Go on to i + 1 into an entered node, else to
// skip (past the subtree). No near-first order, but no stack either (a per-lane array with
// computed indices lives in memory on llvmpipe).
void bvh_nearest(vec3 o, vec3 d, float widen_per_t, float widen_const,
                 inout float ht[LAYERS], inout float ha[LAYERS], inout int hid[LAYERS], inout int hs[LAYERS]) {
    vec3 inv = safe_inverse(d);
    float cut = BIG;
    int i = 0;
    for (int it = 0; it < bvh_nodes && i < bvh_nodes; ++it) {
        ivec4 a = texelFetch(tex_node, 2 * i), b = texelFetch(tex_node, 2 * i + 1);
        float en = box_entry(intBitsToFloat(a.xyz), intBitsToFloat(b.xyz), o, inv, 0.0, cut);
        bool enter = en < BIG;
        int cnt = (enter && b.w >= 0) ? (b.w & 7) : 0;
        int first = b.w >> 3;
#if COUNT
        counter.z += 1.0; counter.w += float(cnt);
#endif
        for (int k = 0; k < cnt; ++k) {
            int id = texelFetch(tex_order, first + k).x;
            int surf; float asc, alpha;
            float t = hit_cylinder_ab(id, cyl(id, TOP), cyl(id, TIP), o, d, widen_per_t, widen_const,
                                      surf, asc, alpha);
            bool ok = t > 0.0;
            float ct = ok ? t : BIG, ca = alpha * asc;
            int cid = ok ? id : NO_ID, cs = surf;
            for (int j = 0; j < LAYERS; ++j) {
                bool sw = ct < ht[j] || (ct == ht[j] && cid < hid[j]);
                float ft = ht[j], fa = ha[j]; int fi = hid[j], fs = hs[j];
                ht[j] = sw ? ct : ft; ha[j] = sw ? ca : fa; hid[j] = sw ? cid : fi; hs[j] = sw ? cs : fs;
                ct = sw ? ft : ct; ca = sw ? fa : ca; cid = sw ? fi : cid; cs = sw ? fs : cs;
            }
        }
        if (cnt > 0) {
            cut = ht[LAYERS - 1];
#if LAYERS > 1
            float Tl = 1.0;
            for (int j = 0; j < LAYERS; ++j) {
                Tl *= 1.0 - ha[j];
                if (Tl < t_eps) cut = min(cut, ht[j]);
            }
#endif
        }
        i = (enter && b.w < 0) ? i + 1 : a.w;
    }
}

#if SHADOWS
float bvh_shadow(vec3 p, vec3 d, float tmax, int own, float tmin, inout int hint) {
    vec3 inv = safe_inverse(d);
    float trans = 1.0;
    int i = 0;
    for (int it = 0; it < bvh_nodes && i < bvh_nodes; ++it) {
        ivec4 a = texelFetch(tex_node, 2 * i), b = texelFetch(tex_node, 2 * i + 1);
        float en = box_entry(intBitsToFloat(a.xyz), intBitsToFloat(b.xyz), p, inv, 0.0, tmax);
        bool enter = en < BIG;
        int cnt = (enter && b.w >= 0) ? (b.w & 7) : 0;
        int first = b.w >> 3;
#if COUNT
        counter.z += 1.0; counter.w += float(cnt);
#endif
        for (int k = 0; k < cnt; ++k) {
            int id = texelFetch(tex_order, first + k).x;
            if (id == own) continue;
            int surf; float asc, alpha;
            float t = hit_cylinder_ab(id, cyl(id, TOP), cyl(id, TIP), p, d, 0.0, 0.0, surf, asc, alpha);
            if (t > tmin && t < tmax) {
#if SHADOWS == 1
                hint = id;
                return 0.0;
#else
                trans *= 1.0 - alpha;
                if (trans < t_eps) return 0.0;
#endif
            }
        }
        i = (enter && b.w < 0) ? i + 1 : a.w;
    }
    return trans;
}
#endif
#endif  // BVH_THREADED

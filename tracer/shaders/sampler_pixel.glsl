// SPDX-License-Identifier: GPL-3.0-or-later
// The pixel sampler (RenderSettings.sampler "pixel", PIXEL 1): the samples of one pixel
// share one walk, PIX_GROUP of its SPP_N² at a time (one draw each, sample_index the group:
// settings.pixel_group keeps a group's layers within the list). The accelerator walks the
// pixel's central ray and hands every candidate to pixel_offer (accel_pixel_nearest of
// accel_grid.glsl / accel_bvh.glsl), which tests all the group's sample rays against it at
// once (footprint_mask) and keeps the distinct cylinders a sample hits and may see (at most
// PIX_M = PIX_GROUP × LAYERS), each with the mask of the samples it covers (with one layer,
// each sample's own nearest cylinder instead). trace_main.glsl then composites each
// sample's own hits (at most LAYERS per sample, as the independent sampler does) and shades distinct cylinders once each, on
// the ray of a sample drawn among those that meet it: with layers the PIX_SHADE heaviest;
// with one layer the PIX_SHADE_ONE heaviest (so every strand of a walk of up to that many
// samples), with one set of shadow rays a pixel, cast from a strand drawn by its light; and
// one more, drawn by weight, standing for the rest ("The pixel sampler is unbiased").
// docs/DECISIONS.md, "Samples of one pixel share the walk".
#if PIXEL
const int PN = PIX_GROUP;                   // samples per walk (settings: at most 25)
const int GROUPS = SPP_N * SPP_N / PN;      // walks (draws) per pixel
const uint FULL = PN >= 32 ? 0xffffffffu : (1u << uint(PN)) - 1u;

// Per pixel (set by trace_main.glsl's main): each sample's offset from the pixel's centre
// in pixels (x right, y down, the same stratified jitter as the independent sampler), and
// what one pixel of offset changes: with a perspective camera the unit central direction
// (the sample's direction is d + ox·px_du + oy·px_dv), with an orthographic one the origin.
vec2 px_off[PN];
vec3 px_du, px_dv;
// How far a sample ray strays from the central one at distance t: px_reach_c + px_reach_t·t.
float px_reach_c, px_reach_t;
#if MESHES
float px_tm[PN];                            // each sample's nearest mesh hit (BIG: none)
#endif

// The point of the line w + s·D nearest the line through the origin along ax (L2 = ax·ax).
vec3 nearest_on_ray(vec3 w, vec3 D, vec3 ax, float L2) {
    float a = dot(D, D), b = dot(D, ax), dd = dot(D, w), e = dot(ax, w);
    float den = a * L2 - b * b;
    return w + ((b * e - L2 * dd) / max(den, 1e-30 * a * L2)) * D;
}

// How near a camera ray from o (along d for the orthographic camera) can meet the capsule of
// the cylinder (A, axis ax, plane-2 normal n2, radius r; capsule.glsl): perspective, the
// distance from o to its axis less r; orthographic, its nearest depth less r (tracer/beams.py,
// the camera's keys).
float capsule_near(vec3 A, vec3 ax, vec3 n2, float r, vec3 o, vec3 d) {
    vec3 far = capsule_far(A, A + ax, n2, r);
#if ORTHO
    return min(dot(A - o, d), dot(far - o, d)) - r;
#else
    vec3 af = far - A;
    float s = clamp(dot(o - A, af) / max(dot(af, af), 1e-30), 0.0, 1.0);
    return length(A + s * af - o) - r;
#endif
}

// Which of the pixel's samples hit the cut cylinder (A4, B4, plane-2 normal n2) of the
// central ray o + t·d: bit i for sample i. A sample hits where its ray passes within r of
// the axis and its chord through the infinite cylinder (the point of the ray nearest the
// axis ± the half chord) reaches between the two planes. Within one pixel the distance
// between the lines and the plane values at the nearest point are linear in the sample's
// offset (the distance exactly so for a perspective camera: w·(D × ax) has no second-order
// terms when w moves by t·δD), so each sample costs a few multiply-adds, one square root and
// compares; what is shared is worked out once, around the point of the central ray nearest
// the cylinder's middle (the shift of hit_cylinder_ab, for float32's sake). `trep`: where the
// central ray enters the infinite cylinder (or passes nearest it), which orders the
// cylinders of the pixel.
uint footprint_mask(vec4 A4, vec4 B4, vec3 n2, vec3 o, vec3 d, out float trep) {
    vec3 A = A4.xyz, ax = B4.xyz - A4.xyz;
    float r = A4.w, L2 = dot(ax, ax);
    float tc = dot(A + 0.5 * ax - o, d);
    vec3 w = o + tc * d - A;
    // Most candidates of a cell pass far from the pixel. First the cheapest test: a sample
    // ray strays from the central one by at most px_reach at its distance (taken half again,
    // for the normalised directions' sake), so none can come within the cylinder's bounding
    // sphere when the central ray passes farther than the sphere's radius plus that.
    float half_len = 0.5 * sqrt(L2);
    vec3 e = w - 0.5 * ax;
    float R = half_len + r + 1.5 * (px_reach_c + px_reach_t * (abs(tc) + half_len + r));
    trep = BIG;
    if (dot(e, e) > R * R) return 0u;
#if ORTHO
    vec3 wu = px_du, wv = px_dv, Du = vec3(0.0), Dv = vec3(0.0);
#else
    vec3 wu = tc * px_du, wv = tc * px_dv, Du = px_du, Dv = px_dv;
#endif
    vec3 c = cross(d, ax), cu = cross(Du, ax), cv = cross(Dv, ax);
    float s2 = max(dot(c, c), 1e-30 * L2);
    float n0 = dot(w, c);
    float nu = dot(wu, c) + dot(w, cu);
    float nv = dot(wv, c) + dot(w, cv);
    float lim = r * r * s2;
    bool along = dot(c, c) < 1e-10 * L2 * dot(d, d);
    // Then the line's: no sample's ray comes within r of the axis when even the nearest
    // offset (|q.x|, |q.y| <= 1/2) leaves |n| above the largest r·|D × ax| of any sample.
    // (On llvmpipe these two tests measured neutral: a group of pixels shaded together
    // skips the work only when every one of them is rejected.)
    float nmin = abs(n0) - 0.5 * (abs(nu) + abs(nv));
    float spread = 0.5 * (length(cu) + length(cv));     // how far |D × ax| can move
    float rmax = r * (sqrt(s2) + spread);
    if (!along && nmin > rmax) return 0u;
    vec3 p0 = nearest_on_ray(w, d, ax, L2);
    vec3 pu = nearest_on_ray(w + wu, d + Du, ax, L2) - p0;
    vec3 pv = nearest_on_ray(w + wv, d + Dv, ax, L2) - p0;
    // Along the ray the plane values change by d·ax and d·n2 per unit: over the half chord
    // h = sqrt(r²s2 - n²)·|ax| / s2 plane 1's value can grow by hk1 = |d·ax|·|ax| / s2 times
    // the root, plane 2's fall by hk2.
    float chord = sqrt(L2) / s2;
    float hk1 = abs(dot(d, ax)) * chord, hk2 = abs(dot(d, n2)) * chord;
    float f10 = dot(p0, ax), f1u = dot(pu, ax), f1v = dot(pv, ax);
    float f20 = dot(p0 - ax, n2), f2u = dot(pu, n2), f2v = dot(pv, n2);
    trep = tc + dot(p0 - w, d) - sqrt(max(lim - n0 * n0, 0.0)) * chord;
    // Looking exactly along the axis the lines are parallel and the nearest point undefined:
    // then every sample hits where the central ray lies within r of the axis (the entry is a
    // plane, at the middle's distance less half the length), none where it does not.
    vec3 q0 = w - ax * (dot(w, ax) / L2);
    if (along) {
        trep = tc - 0.5 * sqrt(L2);
        n0 = dot(q0, q0) <= r * r ? 0.0 : BIG; nu = 0.0; nv = 0.0;
        f10 = 0.0; f1u = 0.0; f1v = 0.0; f20 = 0.0; f2u = 0.0; f2v = 0.0; hk1 = 0.0; hk2 = 0.0;
    }
    bool front = trep > 0.0;
    // No sample ray meets the cut cylinder nearer than its capsule lies (its axis from A to its
    // far end past a bend, less r), so it is ordered no nearer than that: the infinite
    // cylinder's entry can lie far in front of the cut one when the strand points at the
    // camera. The camera beams' keys are the same bound (beams_build.glsl), which lets their
    // walk stop the pixel's list at them.
    trep = max(trep, capsule_near(A, ax, n2, r, o, d));
    // The sample's own |D × ax|² (near the axis's direction it changes across a pixel) is
    // quadratic in its offset; the plane tests are taken times it, so a sample needs no
    // division.
    float su = 2.0 * dot(c, cu), sv = 2.0 * dot(c, cv);
    float suu = dot(cu, cu), svv = dot(cv, cv), suv = 2.0 * dot(cu, cv);
    float sfloor = 1e-30 * L2;
    float rr = r * r;
    hk1 *= s2; hk2 *= s2;
    uint m = 0u;
    for (int i = 0; i < PN; ++i) {
        vec2 q = px_off[i];
        float n = n0 + q.x * nu + q.y * nv;
        float si = max(s2 + q.x * (su + q.x * suu) + q.y * (sv + q.y * svv + q.x * suv), sfloor);
        float gap = rr * si - n * n;          // >= 0: the sample's ray passes within r
        float root = sqrt(max(gap, 0.0));
        bool hit = gap >= 0.0 && (f10 + q.x * f1u + q.y * f1v) * si + hk1 * root >= 0.0
                   && (f20 + q.x * f2u + q.y * f2v) * si - hk2 * root <= 0.0;
#if MESHES
        hit = hit && trep < px_tm[i];       // the sample ended on a nearer mesh
#endif
        m |= hit ? (1u << uint(i)) : 0u;
    }
    return front ? m : 0u;
}

#if LAYERS > 1
// The distinct cylinders hit by any sample that some sample may still see, sorted by
// (distance along the central ray, id); empty slots (BIG, NO_ID, mask 0) at the end.
// Constant indices only (accel.glsl says why).
//
// A cylinder no sample can see (each of its samples has LAYERS entries before it, or an
// opaque one: samples_full) stays unseen however many more come, so the cylinders some
// sample needs are at most LAYERS a sample: PIX_M = PN·LAYERS slots always hold all of them,
// and when a new one finds the list full, one already there is no longer needed and goes.
// The list thus ends as the set of needed cylinders among all offered, whatever order they
// came in (the GPU builds fill lists with atomics), plus perhaps some unneeded ones, which
// weigh nothing in trace_main.glsl. (A list of 24 that kept the nearest, masked by the hits of
// earlier cells or slices only, lost hits once one cell or slice overflowed it.)
const int PIX_M = PN * LAYERS;
float lt[PIX_M]; float la[PIX_M]; int lid[PIX_M]; uint lm[PIX_M];

void list_clear() {
    for (int j = 0; j < PIX_M; ++j) { lt[j] = BIG; la[j] = 0.0; lid[j] = NO_ID; lm[j] = 0u; }
}

// Counts, with one mask per count, the samples of an entry (mask m, alpha a): have[k] holds
// the samples with more than k entries so far, shut those behind one that lets less than
// t_eps through (compositing stops there, as the independent sampler's walk does:
// hits_settled). Opaque hair (alpha 1) thus needs one hit a sample, not LAYERS.
void count_entry(inout uint have[LAYERS], inout uint shut, uint m, float a) {
    for (int k = LAYERS - 1; k > 0; --k) have[k] |= have[k - 1] & m;
    have[0] |= m;
    shut |= 1.0 - a < t_eps ? m : 0u;
}

// The samples that see nothing past (t, id): those with LAYERS entries before it in the
// list's order, or one opaque. A product of translucent layers below t_eps is not looked for
// (that sample only walks on).
uint samples_full(float t, int id) {
    uint have[LAYERS];
    uint shut = 0u;
    for (int k = 0; k < LAYERS; ++k) have[k] = 0u;
    for (int j = 0; j < PIX_M; ++j) {
        bool before = precedes(lt[j], lid[j], t, id);
        count_entry(have, shut, before ? lm[j] : 0u, la[j]);
    }
    return have[LAYERS - 1] | shut;
}

// Cylinder `id` (its TOP and TIP texels A4, B4) as a candidate of the central ray o + t·d:
// into the list when some sample hits it and may see it, once (a cylinder comes from every
// cell or leaf that lists it).
void pixel_offer(int id, vec4 A4, vec4 B4, vec3 o, vec3 d) {
    float t;
    uint m = footprint_mask(A4, B4, cyl(id, CYL_N2).xyz, o, d, t);
    // Most candidates hit no sample: they cost the footprint test only.
    if (m == 0u) return;
    bool dup = false;
    for (int j = 0; j < PIX_M; ++j) dup = dup || lid[j] == id;
    if (dup) return;
    // Samples that already have LAYERS entries before it never see this one: their bits go.
    m &= ~samples_full(t, id);
    if (m == 0u) return;
    float ca = B4.w;
    if (lid[PIX_M - 1] != NO_ID) {
        // Full: the farthest entry, the newcomer counted in its place, that no sample needs
        // any more goes (there is one: at most PIX_M are needed).
        uint have[LAYERS];
        uint shut = 0u;
        for (int k = 0; k < LAYERS; ++k) have[k] = 0u;
        int gone = -1;                  // PIX_M: the newcomer itself
        bool placed = false;
        for (int j = 0; j < PIX_M; ++j) {
            bool here = !placed && precedes(t, id, lt[j], lid[j]);
            uint full = have[LAYERS - 1] | shut;
            gone = here && (m & ~full) == 0u ? PIX_M : gone;
            count_entry(have, shut, here ? m : 0u, ca);
            placed = placed || here;
            full = have[LAYERS - 1] | shut;
            gone = (lm[j] & ~full) == 0u ? j : gone;
            count_entry(have, shut, lm[j], la[j]);
        }
        // (Last in the order: it was needed when checked against the entries before it.)
        if (gone == PIX_M) return;
        // None unneeded cannot happen (see above); were it to, the farthest would go.
        gone = gone < 0 ? PIX_M - 1 : gone;
        for (int j = 0; j < PIX_M - 1; ++j) {
            bool sh = j >= gone;
            lt[j] = sh ? lt[j + 1] : lt[j]; la[j] = sh ? la[j + 1] : la[j];
            lid[j] = sh ? lid[j + 1] : lid[j]; lm[j] = sh ? lm[j + 1] : lm[j];
        }
        lt[PIX_M - 1] = BIG; la[PIX_M - 1] = 0.0; lid[PIX_M - 1] = NO_ID; lm[PIX_M - 1] = 0u;
    }
    float ct = t; int cid = id; uint cm = m;
    for (int j = 0; j < PIX_M; ++j) {
        bool sw = precedes(ct, cid, lt[j], lid[j]);
        float ft = lt[j], fa = la[j]; int fi = lid[j]; uint fm = lm[j];
        lt[j] = sw ? ct : ft; la[j] = sw ? ca : fa; lid[j] = sw ? cid : fi; lm[j] = sw ? cm : fm;
        ct = sw ? ft : ct; ca = sw ? fa : ca; cid = sw ? fi : cid; cm = sw ? fm : cm;
    }
}

// No farther cylinder can change the pixel: every sample has LAYERS hits in the list.
bool pixel_settled() {
    return samples_full(BIG, 0x7fffffff) == FULL;
}

// The farthest distance of a cylinder in the list.
float list_far() {
    float f = 0.0;
    for (int j = 0; j < PIX_M; ++j) f = lt[j] < BIG ? max(f, lt[j]) : f;
    return f;
}
#else
// One layer (every strand opaque: Renderer.effective_layers): a sample sees only its nearest
// hit, so instead of the list each sample keeps its own nearest cylinder (distance, id,
// alpha) and a mask says which samples have one. An offer costs a compare per sample, the
// walk is settled once every sample has a hit, and no slot can run out (a pixel may see as
// many strands as it has samples). trace_main.glsl groups the samples by cylinder.
float st[PN]; int sid[PN]; float sa[PN];
uint have;

void list_clear() {
    for (int i = 0; i < PN; ++i) { st[i] = BIG; sid[i] = NO_ID; sa[i] = 0.0; }
    have = 0u;
}

void pixel_offer(int id, vec4 A4, vec4 B4, vec3 o, vec3 d) {
    float t;
    uint m = footprint_mask(A4, B4, cyl(id, CYL_N2).xyz, o, d, t);
    if (m == 0u) return;
    // Nearer wins, equal distances by id (as the list orders them); a cylinder offered again
    // from another cell changes nothing.
    for (int i = 0; i < PN; ++i) {
        bool on = (m & (1u << uint(i))) != 0u && precedes(t, id, st[i], sid[i]);
        st[i] = on ? t : st[i]; sid[i] = on ? id : sid[i]; sa[i] = on ? B4.w : sa[i];
    }
    have |= m;
}

bool pixel_settled() {
    return have == FULL;
}

float list_far() {
    float f = 0.0;
    for (int i = 0; i < PN; ++i) f = st[i] < BIG ? max(f, st[i]) : f;
    return f;
}
#endif
#endif

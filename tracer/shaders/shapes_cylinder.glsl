// SPDX-License-Identifier: GPL-3.0-or-later
// The shape: continual cylinders (SPEC §6, tracer/cylinders.py), one cut cylinder at a time.
// Reads the cylinder buffer of trace_scene.glsl; knows nothing of accelerators or shading.

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
    // No cheaper pre-test: cells are shorter than the cylinders, so nearly every candidate
    // would pass one, and the quadratic below rejects misses at disc < 0 (docs/DECISIONS.md,
    // "No pre-test before the cylinder intersection").
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
    vec4 N4 = cyl(id, CYL_N2);
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
    bool shared = (surf == 1 && (flags & CAP_PLANE1) == 0) || (surf == 2 && (flags & CAP_PLANE2) == 0);
    int nb = shared ? (surf == 2 ? id + 1 : id - 1) : id;
    vec4 P4 = cyl(nb, CYL_TOP);
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
    return hit_cylinder_ab(id, cyl(id, CYL_TOP), cyl(id, CYL_TIP), o, d, widen_per_t, widen_const, surf, ascale, alpha);
}

// Normal of the surface entered (SPEC §7), facing the ray d: on the side the part of p - tip
// square to the axis (N = ((top - tip) x (p - tip)) x (top - tip)), on plane 1 the reversed
// axis, on plane 2 its normal. `tip` and the unit tangent T are the cylinder's.
vec3 cylinder_normal(int id, int surf, vec3 p, vec3 d, vec3 tip, vec3 T) {
    vec3 N;
    if (surf == 0) {
        vec3 q = p - tip;
        N = q - T * dot(q, T);
    } else if (surf == 1) {
        N = -T;
    } else {
        N = cyl(id, CYL_N2).xyz;
    }
    float nl = length(N);
    N = nl > 0.0 ? N / nl : -d;
    if (dot(N, d) > 0.0) N = -N;
    return N;
}

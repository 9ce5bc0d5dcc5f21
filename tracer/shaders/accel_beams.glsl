// SPDX-License-Identifier: GPL-3.0-or-later
// Beams (tracer/beams.py): for the camera's rays (CAMERA_BEAMS) a bin of whole pixels, and for
// the shadow rays toward up to SUN_BEAMS suns a bin of the plane square to each, list every
// cylinder a ray of the bin can meet, slice by slice in depth. A ray looks its bin up once
// and tests the list in order until no later entry can change what it finds; the rays of
// other lights walk the scene's grid (accel_grid.glsl), as do the camera's when it has no
// beams. An entry is id | fine << (BEAM_ID_BITS - sub), fine one of 2^sub slices a slice
// (tracer/layout.py), and a list is ordered by its entries' fine slices: no entry after one
// has a key below its fine slice's start, key0 + fine·step (camera: the distance from the
// camera, or from its plane when orthographic, at which its rays can meet the cylinder; sun:
// minus the cylinder's greatest height toward the sun). A walk stops at the first entry whose
// fine slice starts past what it has found.

// Where entry e's fine slice starts, for keys key0 + fine·step over fine slices of `sub` bits.
float beam_entry_start(uint e, int sub, float key0, float step) {
    return key0 + float(e >> uint(BEAM_ID_BITS - sub)) * step;
}

int beam_entry_id(uint e, int sub) {
    return int(e & ((1u << uint(BEAM_ID_BITS - sub)) - 1u));
}

// Entries of a beam walk go in runs of BEAM_RUN (the bits of a uint) where they come with
// marks (a sun's, and the camera's with CAMERA_MARKS: a texel (entry, mark), the mark its
// cylinder's capsule axis in its bin, beams_build.glsl's beam_mark): each entry's capsule
// against the ray's point first, a bit each, then the full test of those that pass, in list
// order. Runs of 32 against 8 and 16, interleaved on llvmpipe, shadow rays toward a sun:
// straight.hair's trace 72 ms against 84 and 77, 10,000 wavy strands 36 against 37 and 38;
// without the capsule test 95 and 47 (docs/DECISIONS.md, "Rays of a beam test a cylinder's
// capsule first"; the marks: "A beam's entries carry their marks"). Not the full test behind
// a branch: llvmpipe would run it for every entry (hit_cylinder_ab); the bits make a loop of
// the entries that pass. BEAM_RUN comes from tracer/layout.py (at most 32: a uint's bits).

// Whether point g (bins) lies within `reach` of the capsule axis G.xy..G.zw (bins).
bool beam_capsule_holds(vec2 g, vec4 G, float reach) {
    vec2 ab = G.zw - G.xy, ga = g - G.xy;
    float s = clamp(dot(ga, ab) / max(dot(ab, ab), 1e-30), 0.0, 1.0);
    vec2 q = ga - s * ab;
    return dot(q, q) <= reach * reach;
}

// Whether point l of a bin (bins, from its corner) lies within `reach` of the axis that mark m
// codes (beams_build.glsl, beam_mark: over the bin widened by `reach`, 8 bits a coordinate;
// each end within half a step a coordinate of the clipped axis, so a step more is enough).
bool beam_mark_holds(vec2 l, uint m, float reach) {
    float step = (1.0 + 2.0 * reach) / 255.0;
    vec4 G = vec4(uvec4(m, m >> 8u, m >> 16u, m >> 24u) & 255u) * step - reach;
    return beam_capsule_holds(l, G, reach + step);
}

// The lowest set bit of `bits` (nonzero) as an index (GLSL 3.30 has no findLSB), and `bits`
// without it.
int beam_next_bit(inout uint bits) {
    uint low = bits & (~bits + 1u);
    bits ^= low;
    return int(round(log2(float(low))));
}

#if CAMERA_BEAMS
uniform usamplerBuffer tex_beam;        // the camera's lists
uniform isamplerBuffer tex_beam_cell;   // per bin: first entry, count
uniform ivec4 beam_box;                 // whole-image pixel of bin (0, 0)'s corner, pixels a bin side, bins across
uniform int beam_rows;                  // bins down
uniform vec2 beam_keys;                 // slice 0's start, the fine slices' step (distances)
uniform int beam_sub;                   // the fine slices' bits
uniform vec2 beam_shift;                // the bins' pixel grid less this camera's (a pass moved by a
                                        // fraction of a pixel keeps its first pass's beams)

// The bin of whole-image pixel p of the bins' grid: its first entry and count (none outside
// the bins).
ivec2 bin_at(ivec2 p) {
    ivec2 q = p - beam_box.xy;
    bool inside = all(greaterThanEqual(q, ivec2(0))) && q.x < beam_box.w * beam_box.z && q.y < beam_rows * beam_box.z;
    ivec2 b = q / beam_box.z;
    return inside ? texelFetch(tex_beam_cell, b.x + beam_box.w * b.y).xy : ivec2(0);
}

// How far entries may start and still hold a hit nearer than t along a camera ray (an entry's
// key bounds the distance at which any camera ray meets it): a little more than t, for
// float32's sake.
float beam_reach(float t) {
    return t + abs(t) * 1e-5 + 1e-30;
}

// The full test of cylinder `id` for the camera ray o + t·d, its hit offered to the hit list;
// returns how far later entries may start (`reach`, or nearer after a hit).
float beam_offer(int id, vec3 o, vec3 d, float tmax, float widen_per_t, float widen_const, float reach) {
#if COUNT
    counter.w += 1.0;
#endif
    int surf; float asc, alpha;
    float t = hit_cylinder_ab(id, cyl(id, CYL_TOP), cyl(id, CYL_TIP), o, d, widen_per_t, widen_const,
                              surf, asc, alpha);
    bool ok = t > 0.0 && t < tmax;
    hits_offer(ok ? t : BIG, ok ? id : NO_ID, surf, alpha * asc);
    return ok ? beam_reach(min(tmax, hits_horizon())) : reach;
}

#if CAMERA_MARKS
uniform float beam_axis_reach;          // the widest listing radius in bins (Beams.reach)
#endif

// accel_nearest for the camera ray o + t·d of camera_pixel (accel.glsl's contract): entries in
// key order until the next starts farther than the hit list's horizon (hits_horizon) or the
// nearest mesh.
void beam_nearest(vec3 o, vec3 d, float tmax, float widen_per_t, float widen_const) {
    // The bin the ray crosses: its point of the image in the bins' pixel grid.
    vec2 at = camera_point + beam_shift;
    ivec2 sc = bin_at(ivec2(floor(at)));
    float reach = beam_reach(tmax);
#if CAMERA_MARKS
    // The ray's point in its bin (tracer/beams.py, camera_frame: bin (0, 0) at beam_box.xy).
    vec2 g = (at - vec2(beam_box.xy)) / float(beam_box.z);
    g -= vec2((ivec2(floor(at)) - beam_box.xy) / beam_box.z);
    for (int k0 = 0; k0 < sc.y; k0 += BEAM_RUN) {
        uint pass_ = 0u;
        int k1 = min(sc.y, k0 + BEAM_RUN);
        bool last = false;
        for (int k = k0; k < k1; ++k) {
            uvec2 em = texelFetch(tex_beam, sc.x + k).xy;
#if COUNT
            counter.z += 1.0;
#endif
            if (beam_entry_start(em.x, beam_sub, beam_keys.x, beam_keys.y) > reach) { last = true; break; }
            if (beam_mark_holds(g, em.y, beam_axis_reach))
                pass_ |= 1u << uint(k - k0);
        }
        while (pass_ != 0u) {
            uint e = texelFetch(tex_beam, sc.x + k0 + beam_next_bit(pass_)).x;
            // The horizon may have come nearer since the run's first half.
            if (beam_entry_start(e, beam_sub, beam_keys.x, beam_keys.y) > reach) { last = true; break; }
            reach = beam_offer(beam_entry_id(e, beam_sub), o, d, tmax, widen_per_t, widen_const, reach);
        }
        if (last) break;
    }
#else
    for (int k = 0; k < sc.y; ++k) {
        uint e = texelFetch(tex_beam, sc.x + k).x;
#if COUNT
        counter.z += 1.0;
#endif
        if (beam_entry_start(e, beam_sub, beam_keys.x, beam_keys.y) > reach) break;
        reach = beam_offer(beam_entry_id(e, beam_sub), o, d, tmax, widen_per_t, widen_const, reach);
    }
#endif
#if COUNT
    counter.z += 1.0;
#endif
}

#if PIXEL
// accel_pixel_nearest for the pixel sampler: every sample of camera_pixel lies in its bin, so
// every candidate is the bin's; entries in key order, slice by slice, offered to pixel_offer until
// the pixel is settled and the next starts farther than its list's farthest entry
// (footprint_mask puts an entry no nearer than its key).
void beam_pixel_nearest(vec3 o, vec3 d, float tmax) {
    // The pixel's own bin: with the grids apart by beam_shift its samples lie up to that far
    // outside, which the lists were widened for (tracer/scene_beams.py, camera_beams).
    ivec2 sc = bin_at(camera_pixel);
    float reach = beam_reach(tmax);
    for (int k = 0; k < sc.y; ++k) {
        uint e = texelFetch(tex_beam, sc.x + k).x;
#if COUNT
        counter.z += 1.0;
#endif
        if (beam_entry_start(e, beam_sub, beam_keys.x, beam_keys.y) > reach) break;
        int id = beam_entry_id(e, beam_sub);
#if COUNT
        counter.w += 1.0;
#endif
        pixel_offer(id, cyl(id, CYL_TOP), cyl(id, CYL_TIP), o, d);
        if (pixel_settled()) reach = min(reach, beam_reach(list_far()));
    }
#if COUNT
    counter.z += 1.0;
#endif
}
#endif
#endif

#if SUN_BEAMS > 0
// Per sun set: its lists and bin table, its axes (u and v across the sun scaled to bins, w
// toward it), (offset x, offset y, slice 0's start, fine slices' step), bins across and down,
// fine slices' bits.
uniform usamplerBuffer tex_sun0;
uniform isamplerBuffer tex_sun_cell0;
#if SUN_BEAMS > 1
uniform usamplerBuffer tex_sun1;
uniform isamplerBuffer tex_sun_cell1;
#endif
#if SUN_BEAMS > 2
uniform usamplerBuffer tex_sun2;
uniform isamplerBuffer tex_sun_cell2;
#endif
#if SUN_BEAMS > 3
uniform usamplerBuffer tex_sun3;
uniform isamplerBuffer tex_sun_cell3;
#endif
uniform vec3 sun_u[SUN_BEAMS];
uniform vec3 sun_v[SUN_BEAMS];
uniform vec3 sun_w[SUN_BEAMS];
uniform vec4 sun_frame[SUN_BEAMS];
uniform ivec2 sun_dims[SUN_BEAMS];
uniform int sun_sub[SUN_BEAMS];
uniform float sun_reach[SUN_BEAMS];     // the widest capsule's radius in bins, the drift and the listing's margin
// A point, spot or area light's set (tracer/beams.py, light_frame): its position and how far
// from it its rays may end (w >= 0); its bins are a perspective frame's from there, its keys
// distances from there. A sun's: w < 0.
uniform vec4 sun_origin[SUN_BEAMS];
uniform float sun_far[SUN_BEAMS];       // a light's: the hair's farthest depth from it
uniform vec4 sun_anchor[SUN_BEAMS];     // a point amid the hair (xyz) and its frame coordinates
uniform vec4 sun_anchor_frame[SUN_BEAMS];
// Entry i of sun set `set` and its mark.
uvec2 sun_entry(int set, int i) {
#if SUN_BEAMS > 3
    if (set == 3) return texelFetch(tex_sun3, i).xy;
#endif
#if SUN_BEAMS > 2
    if (set == 2) return texelFetch(tex_sun2, i).xy;
#endif
#if SUN_BEAMS > 1
    if (set == 1) return texelFetch(tex_sun1, i).xy;
#endif
    return texelFetch(tex_sun0, i).xy;
}

// The frame coordinates of the point `from_anchor` away from set `set`'s anchor.
vec3 sun_set_point(int set, vec3 from_anchor) {
    return vec3(dot(from_anchor, sun_u[set]), dot(from_anchor, sun_v[set]), dot(from_anchor, sun_w[set]))
        + sun_anchor_frame[set].xyz;
}

// accel_transmittance for a shadow ray from p toward sun set `set` (its direction, or within
// the spread its lists were padded for; a light's: toward a point within its extent of its
// position): the entries of p's bin nearest the sun (or the light) first, until the rest lie
// wholly below p (farther from the light than p, or than its extent).
float sun_transmittance(int set, vec3 p, vec3 d, float tmax, int own, float tmin, inout int hint) {
    vec4 fr = sun_frame[set];
    ivec2 n = sun_dims[set];
    vec4 org = sun_origin[set];
    // p in the frame, from its offset to the set's anchor amid the hair (tracer/beams.py,
    // anchored), which float32 keeps however far the light (or the world's origin) lies.
    vec3 from_anchor = p - sun_anchor[set].xyz;
    vec3 f = sun_set_point(set, from_anchor);
    // An entry whose fine slice starts past -height(p) lies wholly below p, as do all after it
    // (a light's: past p's distance, or its extent).
    float hp;
    vec2 g;
    if (org.w >= 0.0) {
        // A ray from deeper than the hair meets none until it comes back to the hair's
        // farthest depth, where the lists take it up (tracer/beams.py, light_frame); one from
        // behind the light's plane, or outside its bins, meets none at all: the hair lies
        // beyond the extent, and every capsule's listing reaches as far as the rays drift.
        vec3 q = p - org.xyz;
        float far = sun_far[set];
        if (f.z > far) {
            float dz = -dot(d, sun_w[set]);
            float t = (f.z - far) / max(dz, 1e-30);
            if (dz <= 0.0 || t >= tmax) return 1.0;
            from_anchor += t * d;
            q += t * d;
            f = sun_set_point(set, from_anchor);
        }
        if (f.z <= 0.0) return 1.0;
        hp = max(length(q), org.w);
        g = f.xy / f.z + fr.xy;
    } else {
        hp = -f.z;
        g = f.xy + fr.xy;
    }
    ivec2 b = ivec2(floor(g));
    if (any(lessThan(b, ivec2(0))) || any(greaterThanEqual(b, n))) return 1.0;
    int cell = b.x + n.x * b.y;
    ivec2 sc;
#if SUN_BEAMS > 3
    if (set == 3) sc = texelFetch(tex_sun_cell3, cell).xy; else
#endif
#if SUN_BEAMS > 2
    if (set == 2) sc = texelFetch(tex_sun_cell2, cell).xy; else
#endif
#if SUN_BEAMS > 1
    if (set == 1) sc = texelFetch(tex_sun_cell1, cell).xy; else
#endif
    sc = texelFetch(tex_sun_cell0, cell).xy;
    float below = hp + abs(hp) * 1e-5 + 1e-30;
    float trans = 1.0;
#if COUNT
    counter.z += 1.0;
#endif
    int sub = sun_sub[set];
    float reach = sun_reach[set];
    // In runs of BEAM_RUN entries, the capsule first (above): a ray whose point g lies
    // farther from a cylinder's axis across the sun than its listing radius (the drift
    // included: tracer/beams.py) cannot meet it.
    for (int k0 = 0; k0 < sc.y; k0 += BEAM_RUN) {
        uint pass_ = 0u;
        int k1 = min(sc.y, k0 + BEAM_RUN);
        bool last = false;
        for (int k = k0; k < k1; ++k) {
            uvec2 em = sun_entry(set, sc.x + k);
#if COUNT
            counter.z += 1.0;
#endif
            if (beam_entry_start(em.x, sub, fr.z, fr.w) > below) { last = true; break; }
            int id = beam_entry_id(em.x, sub);
            if (id != own && beam_mark_holds(g - vec2(b), em.y, reach)) pass_ |= 1u << uint(k - k0);
        }
        while (pass_ != 0u) {
            int id = beam_entry_id(sun_entry(set, sc.x + k0 + beam_next_bit(pass_)).x, sub);
#if COUNT
            counter.w += 1.0;
#endif
            int surf; float asc, alpha;
            float t = hit_cylinder_ab(id, cyl(id, CYL_TOP), cyl(id, CYL_TIP), p, d, 0.0, 0.0, surf, asc, alpha);
#if SHADOWS == 1
            if (t > tmin && t < tmax) { hint = id; return 0.0; }
#else
            if (t > tmin && t < tmax) {
                trans *= 1.0 - alpha;
                if (trans < t_eps) return 0.0;
            }
#endif
        }
        if (last) break;
    }
    return trans;
}
#endif

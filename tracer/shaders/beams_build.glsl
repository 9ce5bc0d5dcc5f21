// SPDX-License-Identifier: GPL-3.0-or-later
// Beams built on the GPU (GL 4.3 compute), the same listing as tracer/beams.py's numpy build:
// every cylinder in every bin its projected capsule may reach, each entry its id and the
// depth slice of its key, a bin's entries slice by slice. The host prepends
// "#version 430 core", PASS, CENTRES (1: lists for the rays through the bins' centres alone,
// tracer/beams.py's `centres`) and the generated header of tracer/layout.py, then
// build_cylinders.glsl and capsule.glsl:
//   PASS 0  zero:   counts[i] = 0 for i < n_items (the bins' counters, then the slices')
//   PASS 1  count:  counts[bin] += 1 for every (cylinder, bin), slices[fine slice] += 1 per
//                   cylinder listed somewhere, filed[cylinder] = its fine slice (-1: listed
//                   nowhere), the fine slices of the most bits the ids leave
//   PASS 2  sums:   sums[c] = the counts of bins c·CHUNK .. (c+1)·CHUNK (counts is padded
//                   with zeros to whole chunks), flags[2] the most entries a bin has
//   PASS 3  scan:   one invocation: sums become exclusive prefix sums, sums[n_items] the total
//   PASS 4  starts: per chunk of bins, each bin's first entry into the bin table (start,
//                   count), and into counts, which become the cursors
//   PASS 5  bucket: perm[slices[fine slice]++] = cylinder, by filed (slices hold the fine
//                   slices' first places, written by the host from their counts)
//   PASS 6  fill:   for the cylinders perm[first_item ..] of one fine slice of sub_bits (the
//                   host's choice, tracer/beams.py fill_plan; PASS 1 files them at the most
//                   bits), one dispatch a fine slice in order: slot = cursors[bin]++,
//                   lists[slot] = id | fine slice << (BEAM_ID_BITS - sub_bits); MARKS: the
//                   entry is that and the cylinder's capsule axis in that bin (beam_mark),
//                   which the walks test a ray's point against first (accel_beams.glsl);
//                   SORTED: every cylinder filed somewhere, in id order in one dispatch (no
//                   PASS 5), into `lists` = a scratch buffer of the same layout, for PASS 7
//   PASS 7  sort:   one bin an invocation (SORTED): its entries from the scratch buffer into
//                   the lists by fine slice, a counting sort of SORT_KEYS keys (stable)
// Where the lists outgrow the driver's largest storage block, the host binds them a window
// of bins at a time (PASS 6 and 7: `window`, `band`, `window_base`), the same entries.
// The fine slices are dispatched one after another (or sorted), so a bin's entries come fine
// slice by fine slice; within one their order depends on the atomics, which no walk depends on
// (tracer/beams.py; the pixel sampler's list ends the same whatever the order:
// sampler_pixel.glsl, pixel_offer).
// A cylinder that reaches the camera's plane, or whose listing could take more than
// MAX_BINS_PER_CYLINDER loop steps, is counted in flags[0] and flags[1]: the host then gives
// the family no beams (its rays walk the grid), as the numpy build raises BeamsUnfit.
uniform int n_items;          // cylinders, bins (zero: words) or chunks of this pass
uniform int first_item;       // fill: the fine slice's first place in perm
uniform float pad_factor;     // capsules widened this many times
// The frame (tracer/beams.py, BeamFrame): kind 0 perspective, 1 orthographic, 2 sun.
uniform int frame_kind;
uniform vec3 frame_origin;
// A point amid the hair and its frame coordinates, made on the host (tracer/beams.py, anchored):
// a point's are those plus its offset's, which float32 keeps however far the origin lies.
uniform vec3 frame_anchor;
uniform vec3 anchor_frame;
uniform vec3 axis_x;
uniform vec3 axis_y;
uniform vec3 axis_z;
uniform vec2 frame_offset;
uniform float radius_scale;
uniform float drift;
uniform float key0;
uniform float key_step;
uniform float near_limit;     // perspective: a capsule's key at or below this reaches the camera's plane
uniform float frame_spread;   // perspective: how far a light's rays drift (tracer/beams.py, light_frame; 0: a camera's)
uniform float frame_extent;   // a light's extent and the hair's farthest depth from it (light_frame)
uniform float frame_far;
uniform vec4 frame_cone;      // a spot light's axis and half angle (w < 0: none; tracer/beams.py, outside_cone)
uniform ivec2 dims;
uniform int max_bins;         // MAX_BINS_PER_CYLINDER
uniform int sub_bits;         // fine slices a slice: 2^sub_bits (count: the most, fill: the host's choice)
// The lists as bound by a fill or sort (tracer/gpu_beams.py, _windows): the entries of bins
// window.x .. window.y - 1 alone, from entry window_base on, within the driver's largest
// storage block; `band`, the rows of bins (y) those bins lie in, is all of them for the count.
uniform ivec2 band;
uniform ivec2 window;
uniform int window_base;

layout(std430, binding = 0) buffer Counts { int counts[]; };     // per bin: count, then cursor
layout(std430, binding = 1) buffer Slices { int slices[]; };     // per fine slice: count, then cursor
layout(std430, binding = 2) buffer Perm { int perm[]; };         // cylinders, fine slice by fine slice
layout(std430, binding = 3) buffer Sums { int sums[]; };         // per chunk of bins
layout(std430, binding = 4) buffer Flags { int flags[]; };       // [0] near the camera, [1] too wide, [2] longest list
layout(std430, binding = 5) buffer Filed { int filed[]; };       // per cylinder: its fine slice, -1 listed nowhere
#if PASS == 4
layout(std430, binding = 6) writeonly buffer Table { ivec2 table[]; };
#endif
// MARKS: an entry is (id | fine slice, its mark), else id | fine slice.
#if MARKS
#define ENTRY uvec2
#define ENTRY_CODE(e) (e).x
#else
#define ENTRY uint
#define ENTRY_CODE(e) (e)
#endif
#if PASS == 6
layout(std430, binding = 6) writeonly buffer Lists { ENTRY lists[]; };
#endif
#if PASS == 7
layout(std430, binding = 6) readonly buffer TableIn { ivec2 table_in[]; };
layout(std430, binding = 7) readonly buffer Unsorted { ENTRY unsorted[]; };
layout(std430, binding = 8) writeonly buffer Lists { ENTRY lists[]; };
#endif
const float FAR = 1e30;     // past every bin, every crossing of an axis
// A point in the frame: (X, Y, Z) = axes·(p - origin).
vec3 to_frame(vec3 p) {
    vec3 q = p - frame_anchor;
    return vec3(dot(q, axis_x), dot(q, axis_y), dot(q, axis_z)) + anchor_frame;
}

vec2 to_bins(vec3 f) {
    return (frame_kind == 0 ? f.xy / f.z : f.xy) + frame_offset;
}

// Distance from c to the segment a..b (tracer/beams.py, segment_distance; the pixel sampler
// bounds its cylinders' distances by the same rule: sampler_pixel.glsl, footprint_mask).
float segment_distance(vec3 c, vec3 a, vec3 b) {
    vec3 ab = b - a;
    float s = clamp(dot(c - a, ab) / max(dot(ab, ab), 1e-30), 0.0, 1.0);
    return length(a + s * ab - c);
}

// Whether no shadow ray toward the spot light at frame_origin crosses the capsule a..b of
// radius r (tracer/beams.py, outside_cone, the same test in float64).
bool outside_cone(vec3 a, vec3 b, float r) {
    vec3 m = 0.5 * (a + b) - frame_origin;
    float rho = 0.5 * length(b - a) + r + frame_extent;
    float d = length(m);
    float along = dot(m, frame_cone.xyz);
    float across = sqrt(max(d * d - along * along, 0.0));
    float alpha = atan(across, along);
    float beta = atan(rho, sqrt(max(d * d - rho * rho, 0.0)));
    return d > rho && alpha > frame_cone.w + beta + BEAM_CONE_MARGIN;
}

// Cylinder `id`'s projected axis g0..g1 (bins), how far its capsule reaches past it (rho,
// bins) and its key's fine slice of sub_bits (tracer/beams.py, slice_of). Returns 0: to be
// listed, 1: never seen (wholly behind the camera), 2: it reaches the camera's plane.
int project_cylinder(int id, out vec2 g0, out vec2 g1, out float rho, out int slice) {
    vec4 top = cyl(id, CYL_TOP), tip = cyl(id, CYL_TIP), n2 = cyl(id, CYL_N2);
    vec3 far = capsule_far(top.xyz, tip.xyz, n2.xyz, top.w);
    float r = top.w * pad_factor;
    vec3 f0 = to_frame(top.xyz), f1 = to_frame(far);
    float key;
    rho = r * radius_scale + drift + BEAM_BIN_EPS;
    if (frame_kind == 2) {
        key = -(max(f0.z, f1.z) + r);
    } else {
        float near = min(f0.z, f1.z);
        key = near - r;
        if (frame_kind == 0) {
            if (key <= near_limit) return max(f0.z, f1.z) + r < 0.0 ? 1 : 2;
            if (frame_cone.w >= 0.0 && outside_cone(top.xyz, far, r)) return 1;
            if (frame_spread > 0.0) {
                // A light's rays drift from their origin's direction (tracer/beams.py,
                // light_frame, drift_at).
                float spread = min(frame_extent * max(frame_far - (near - r), 0.0) / (frame_far - frame_extent),
                                   frame_spread);
                rho = (r + spread) * radius_scale / (near - r) + drift + BEAM_BIN_EPS;
            } else {
                rho = r * radius_scale / near + drift + BEAM_BIN_EPS;
            }
            key = segment_distance(frame_origin, top.xyz, far) - r;
        }
    }
    g0 = to_bins(f0);
    g1 = to_bins(f1);
    slice = clamp(int(floor(((key - key0) / key_step - BEAM_SLICE_EPS) * float(1 << sub_bits))), 0,
                  (BEAM_SLICES << sub_bits) - 1);
    return 0;
}

#if PASS == 6 && MARKS
uniform float mark_reach;     // the walks' reach (Beams.reach, bins): the marks' box is the bin widened by it
// The cylinder being filled (fill_begin): its projected axis g0 + s·dg, and where its line
// crosses the lines x, y = -mark_reach and 1 + mark_reach of bin (0, 0), s = cross + corner·per
// for a bin's corner (a direction along which it does not move: never, or always inside).
vec2 fill_g0, fill_dg, fill_lo, fill_hi, fill_per;

void fill_begin(vec2 g0, vec2 g1) {
    fill_g0 = g0;
    fill_dg = g1 - g0;
    bvec2 moves = greaterThanEqual(abs(fill_dg), vec2(1e-30));
    vec2 per = 1.0 / mix(vec2(1.0), fill_dg, moves);
    vec2 outside = vec2(FAR);
    fill_lo = mix(-outside, (-mark_reach - g0) * per, moves);
    fill_hi = mix(outside, (1.0 + mark_reach - g0) * per, moves);
    fill_per = mix(vec2(0.0), per, moves);
}

// The axis as seen from the bin of corner (x, y) (bins): clipped to the bin's square widened
// by mark_reach on every side, its ends relative to that box in 8 bits a coordinate
// (x0 | y0 << 8 | x1 << 16 | y1 << 24; accel_beams.glsl, beam_mark_holds). A point of the bin
// within mark_reach of the axis is within it of the clipped part, whose ends the code moves by
// at most half a step a coordinate; an axis that misses the box (the listing never lists one,
// bar float32's rounding) comes no nearer than mark_reach to the bin, and whatever its code
// says only costs a test. A direction along which the axis does not move clips nothing: its
// coordinate, the same at both ends, is coded clamped to the box.
uint beam_mark(vec2 corner) {
    vec2 u = fill_lo + corner * fill_per, v = fill_hi + corner * fill_per;
    vec2 enter = min(u, v), leave = max(u, v);
    float t0 = clamp(max(enter.x, enter.y), 0.0, 1.0), t1 = clamp(min(leave.x, leave.y), t0, 1.0);
    float scale = 255.0 / (1.0 + 2.0 * mark_reach);
    vec2 base = fill_g0 - corner + mark_reach;
    vec4 ends = (base.xyxy + vec4(t0 * fill_dg, t1 * fill_dg)) * scale;
    uvec4 c = uvec4(clamp(round(ends), 0.0, 255.0));
    return c.x | (c.y << 8u) | (c.z << 16u) | (c.w << 24u);
}
#endif

#if PASS == 1 || PASS == 6
void visit(int bin, vec2 corner, int id, int slice) {
#if PASS == 1
    atomicAdd(counts[bin], 1);
#else
    if (bin < window.x || bin >= window.y) return;
    int slot = atomicAdd(counts[bin], 1) - window_base;
    uint e = uint(id) | (uint(slice) << uint(BEAM_ID_BITS - sub_bits));
#if MARKS
    lists[slot] = uvec2(e, beam_mark(corner));
#else
    lists[slot] = e;
#endif
#endif
}

#if CENTRES
// Where the line A = a crosses the points within P of the segment (A0, B0) + s·(dA, dB):
// (lo, hi), lo > hi where it does not (tracer/beams.py, centre_span, the same steps).

vec2 centre_span(float a, float A0, float dA, float B0, float dB, float P) {
    float lo = FAR, hi = -FAR;
    for (int e = 0; e < 2; ++e) {
        float ea = e == 0 ? A0 : A0 + dA, eb = e == 0 ? B0 : B0 + dB;
        float da = a - ea, h2 = P * P - da * da;
        float h = sqrt(max(h2, 0.0));
        if (h2 >= 0.0) { lo = min(lo, eb - h); hi = max(hi, eb + h); }
    }
    bool point = abs(dA) < 1e-12;
    float da = a - A0, sdA = point ? 1.0 : dA;
    float L2 = dA * dA + dB * dB;
    float mid = B0 + da / sdA * dB, half_ = P * sqrt(L2) / abs(sdA), t0 = da * dA;
    bool level = dB == 0.0, on = t0 >= 0.0 && t0 <= L2;
    float sdB = level ? 1.0 : dB;
    float f0 = B0 - t0 / sdB, f1 = B0 + (L2 - t0) / sdB;
    float foot_lo = level ? (on ? -FAR : FAR) : min(f0, f1), foot_hi = level ? (on ? FAR : -FAR) : max(f0, f1);
    float band_lo = max(mid - half_, foot_lo), band_hi = min(mid + half_, foot_hi);
    if (!point && band_lo <= band_hi) { lo = min(lo, band_lo); hi = max(hi, band_hi); }
    return vec2(lo, hi);
}
#endif

// Every bin the projected capsule may reach (tracer/beams.py, bins_touched): the segment cut
// into the bins' columns along its longer side, each column's rows within rho of its part
// (CENTRES: the columns and rows whose centre lies within rho of the projected axis).
// One loop over (column, row), not nested loops (docs/DECISIONS.md, "One loop over the grid
// build's cells"), over the rows of `band` alone. False when the bound on its steps passes
// max_bins; `listed` counts the bins it was listed in.
bool list_cylinder(int id, vec2 g0, vec2 g1, float rho, int slice, inout int listed) {
    vec2 dg = g1 - g0;
    bool xdom = abs(dg.x) >= abs(dg.y);
    float A0 = xdom ? g0.x : g0.y, dA = xdom ? dg.x : dg.y;
    float B0 = xdom ? g0.y : g0.x, dB = xdom ? dg.y : dg.x;
    int NA = xdom ? dims.x : dims.y, NB = xdom ? dims.y : dims.x;
    int SA = xdom ? 1 : dims.x, SB = xdom ? dims.x : 1;
    ivec2 lim_a = xdom ? ivec2(0, NA - 1) : band, lim_b = xdom ? band : ivec2(0, NB - 1);
#if CENTRES
    float a_lo = ceil(min(A0, A0 + dA) - rho - 0.5), a_hi = floor(max(A0, A0 + dA) + rho - 0.5);
#else
    float a_lo = floor(min(A0, A0 + dA) - rho), a_hi = floor(max(A0, A0 + dA) + rho);
#endif
    if (a_hi < float(lim_a.x) || a_lo > float(lim_a.y) || a_lo > a_hi) return true;
    int i0 = int(clamp(a_lo, float(lim_a.x), float(lim_a.y))), i1 = int(clamp(a_hi, float(lim_a.x), float(lim_a.y)));
    if (float(i1 - i0 + 1) * min(abs(dB) + 2.0 * rho + 2.0, float(NB)) > float(max_bins)) return false;
#if !CENTRES
    bool no_dir = abs(dA) < 1e-12;
    float inv = no_dir ? 1.0 : 1.0 / dA;
#endif
    int col = i0, row = 0, row_end = -1;
    for (;;) {
        if (row > row_end) {
            if (col > i1) break;
#if CENTRES
            vec2 span = centre_span(float(col) + 0.5, A0, dA, B0, dB, rho);
            float b_lo = ceil(span.x - 0.5), b_hi = floor(span.y - 0.5);
#else
            // The part of the segment (s in [0, 1]) within rho of this column, its rows.
            float s0 = 0.0, s1 = 1.0;
            if (!no_dir) {
                float sa = (float(col) - rho - A0) * inv, sb = (float(col + 1) + rho - A0) * inv;
                s0 = clamp(min(sa, sb), 0.0, 1.0);
                s1 = clamp(max(sa, sb), 0.0, 1.0);
            }
            float e0 = B0 + s0 * dB, e1 = B0 + s1 * dB;
            float b_lo = floor(min(e0, e1) - rho), b_hi = floor(max(e0, e1) + rho);
#endif
            bool some = b_hi >= float(lim_b.x) && b_lo <= float(lim_b.y) && b_lo <= b_hi;
            row = int(clamp(b_lo, float(lim_b.x), float(lim_b.y)));
            row_end = some ? int(clamp(b_hi, float(lim_b.x), float(lim_b.y))) : row - 1;
            col++;
            continue;
        }
        visit((col - 1) * SA + row * SB, xdom ? vec2(col - 1, row) : vec2(row, col - 1), id, slice);
        listed++;
        row++;
    }
    return true;
}
#endif

void main() {
    int i = item_index();
#if PASS == 0
    if (i < n_items) counts[i] = 0;
#elif PASS == 1
    if (i >= n_items) return;
    vec2 g0, g1; float rho; int slice;
    int state = project_cylinder(i, g0, g1, rho, slice);
    filed[i] = -1;
    if (state == 2) { atomicAdd(flags[0], 1); return; }
    if (state == 1) return;
    int listed = 0;
    if (!list_cylinder(i, g0, g1, rho, slice, listed)) atomicAdd(flags[1], 1);
    // Only a cylinder listed somewhere is filled: the fill goes over filed's cylinders alone
    // (lists for the pixels' centres hold a few of them).
    if (listed > 0) {
        filed[i] = slice;
        atomicAdd(slices[slice], 1);
    }
#elif PASS == 2
    if (i >= n_items) return;
    int s = 0, most = 0;
    for (int k = 0; k < BEAM_SCAN_CHUNK; ++k) {
        int c = counts[i * BEAM_SCAN_CHUNK + k];
        s += c;
        most = max(most, c);
    }
    sums[i] = s;
    atomicMax(flags[2], most);
#elif PASS == 3
    if (i != 0) return;
    int total = 0;
    for (int c = 0; c < n_items; ++c) { int s = sums[c]; sums[c] = total; total += s; }
    sums[n_items] = total;
#elif PASS == 4
    // One chunk of bins an invocation (n_items: chunks; bins: dims.x·dims.y), in order: each
    // bin's (start, count) into the table, and its start into counts, the cursors of PASS 6.
    if (i >= n_items) return;
    int nb = dims.x * dims.y;
    int start = sums[i];
    for (int k = 0; k < BEAM_SCAN_CHUNK; ++k) {
        int b = i * BEAM_SCAN_CHUNK + k;
        if (b >= nb) break;
        int c = counts[b];
        table[b] = ivec2(start, c);
        counts[b] = start;
        start += c;
    }
#elif PASS == 5
    if (i >= n_items) return;
    int slice = filed[i];
    if (slice < 0) return;
    perm[atomicAdd(slices[slice], 1)] = i;
#elif PASS == 6
    if (i >= n_items) return;
#if SORTED
    int id = i;
    if (filed[id] < 0) return;
#else
    int id = perm[first_item + i];
#endif
    vec2 g0, g1; float rho; int slice;
    project_cylinder(id, g0, g1, rho, slice);
    // Wholly outside the window's rows (every row it lists lies within its projection's
    // extent widened by rho).
    if (max(g0.y, g1.y) + rho < float(band.x) || min(g0.y, g1.y) - rho >= float(band.y + 1)) return;
#if MARKS
    fill_begin(g0, g1);
#endif
    int listed = 0;
    list_cylinder(id, g0, g1, rho, slice, listed);
#elif PASS == 7
    // Bin i's entries (filled in id order) into its run of the lists by fine slice: each
    // fine slice's first place from the counts of those before it, then each entry to its
    // fine slice's next place, in the order filled.
    if (i >= n_items) return;
    i += window.x;
    ivec2 sc = table_in[i];
    sc.x -= window_base;
    if (sc.y < 2) {
        if (sc.y == 1) lists[sc.x] = unsorted[sc.x];
        return;
    }
    uint shift = uint(BEAM_ID_BITS - sub_bits);
    int place[SORT_KEYS];
    for (int k = 0; k < SORT_KEYS; ++k) place[k] = 0;
    for (int k = 0; k < sc.y; ++k) place[int(ENTRY_CODE(unsorted[sc.x + k]) >> shift)]++;
    int at = sc.x;
    for (int k = 0; k < SORT_KEYS; ++k) {
        int c = place[k];
        place[k] = at;
        at += c;
    }
    for (int k = 0; k < sc.y; ++k) {
        ENTRY e = unsorted[sc.x + k];
        int key = int(ENTRY_CODE(e) >> shift);
        lists[place[key]] = e;
        place[key]++;
    }
#endif
}

// SPDX-License-Identifier: GPL-3.0-or-later
// The tracer's own part (SPEC §7): camera rays, one sample per draw, the LAYERS nearest
// hits composited front to back, shadow rays toward every light, shading by the model's
// shade_light. Finds hits only through the accelerator interface (accel.glsl).

uniform vec3 cam_pos;
uniform mat3 cam_rot;
uniform float pixel_size;
uniform vec2 image_size;      // this draw's image (a window of the whole image, or all of it)
uniform ivec2 pixel_origin;   // its pixel (0, 0) in the whole image (tracer/camera.py)
uniform vec2 centre_px;       // the optical axis in the whole image's pixels (Camera.centre_px)

uniform vec4 light_vec[NUM_LIGHTS];   // w = 0: xyz is the direction light travels; w = 1: position;
                                      // w = 2: position, with the inverse-square fall-off; 3: a spot
                                      // light's position, 4: an area light's (both falling off);
                                      // 5: an even environment (xyz unused)
uniform vec3 light_col[NUM_LIGHTS];
uniform vec4 light_axis[NUM_LIGHTS];  // spot and area: the unit axis it shines along; w: a spot's
                                      // cosine of its half angle
uniform float light_blend[NUM_LIGHTS];   // a spot: the cosine range its edge is softened over
uniform float light_shadow[NUM_LIGHTS];  // 1: shadow rays toward it; 0: nothing shadows it
uniform vec4 light_u[NUM_LIGHTS];     // an area light's half width (w = 1: an ellipse)
uniform vec4 light_v[NUM_LIGHTS];     // its half height; w: the sampled disk's radius of a point or
                                      // spot light (its sphere) or a sun (tan of half its angle)
uniform vec4 background;              // premultiplied

layout(location = 0) out vec4 frag_color;
#if COUNT
layout(location = 1) out vec4 frag_count;   // the counters of trace_scene.glsl
#endif

// Fixed per-sample hash (lowbias32); the reference tracer computes the same integers.
uint hash32(uint x) {
    x ^= x >> 16; x *= 0x7feb352du;
    x ^= x >> 15; x *= 0x846ca68bu;
    x ^= x >> 16; return x;
}

// A number in [0, 1) from a hash's top 24 bits.
float unit_of(uint h) {
    return float(h >> 8u) * (1.0 / 16777216.0);
}

// This draw's sample (the independent sampler) or group of samples (the pixel sampler).
uniform int sample_index;

// The pixel's hash of `seed` (this draw's sample or group and the pixel's place in the image):
// each use of random numbers in a pixel starts from a seed of its own.
uint pixel_hash(int px, int py, uint seed) {
    return hash32(hash32(hash32(uint(sample_index) ^ seed) ^ uint(py)) ^ uint(px));
}

// The seed of this sample's (or this pixel sampler walk's) points on lights with an extent,
// set by main; light_sample(k, l): the two numbers for light l at the pixel's k-th shading.
uint light_seed;
vec2 light_sample(int k, int l) {
    uint h = hash32(light_seed ^ uint(k * NUM_LIGHTS + l + 1));
    return vec2(unit_of(h), unit_of(hash32(h ^ 0x68bc21ebu)));
}

#if SHADOWS
#if SUN_BEAMS > 0
uniform int light_sun[NUM_LIGHTS];    // the sun beams (accel_beams.glsl) serving light l; -1: none
#endif

// Transmittance toward light l through the hair alone: its sun beams' when it has them, else
// the accelerator's walk.
float light_transmittance(int l, vec3 p, vec3 d, float tmax, int own, float tmin, inout int hint) {
#if SUN_BEAMS > 0
    int set = light_sun[l];
    if (set >= 0) return sun_transmittance(set, p, d, tmax, own, tmin, hint);
#endif
#if WALK
    return accel_transmittance(p, d, tmax, own, tmin, hint);
#else
    return 1.0;     // not reached: with no walk every shadowed light has sun beams
#endif
}

// Transmittance toward light l from p (1 = lit): 0 behind a mesh, else the hair's, after one
// guess.
float shadow_ray(int l, vec3 p, vec3 d, float tmax, int own, float tmin, inout int hint) {
#if COUNT
    counter.x += 1.0;
#endif
#if MESHES
    if (mesh_blocked(p, d, tmax, -1)) return 0.0;
#endif
#if SHADOWS == 1 && LAYERS > 1
    // The cylinder that shadowed this pixel's previous (nearer) layer often shadows this
    // one too: one test that can end the walk before it starts (docs/DECISIONS.md,
    // "Shadow rays try the last occluder first"). Any hit in (tmin, tmax) darkens, so
    // which one is found first does not change the result.
    {
        int h = max(hint, 0), hsurf; float hasc, halpha;
        float th = hit_cylinder(h, p, d, 0.0, 0.0, hsurf, hasc, halpha);
#if COUNT
        if (hint >= 0) counter.w += 1.0;
#endif
        if (hint >= 0 && h != own && th > tmin && th < tmax) return 0.0;
    }
#endif
    return light_transmittance(l, p, d, tmax, own, tmin, hint);
}

int occluder[NUM_LIGHTS];   // per light, the last cylinder that blocked a shadow ray
#endif

// The surface of cylinder `id` where the ray o + t·d meets it (surf: which face).
Surface surface_at(int id, int surf, vec3 o, vec3 d, float t) {
    vec4 A4 = cyl(id, CYL_TOP);
    vec4 B4 = cyl(id, CYL_TIP);
    Surface s;
    s.color = cyl(id, CYL_COL).rgb;
    s.T = normalize(B4.xyz - A4.xyz);
    s.p = o + t * d;
    s.V = d;
    // A model that reads no normal (Kajiya-Kay) leaves this to the compiler to drop.
    s.N = cylinder_normal(id, surf, s.p, d, B4.xyz, s.T);
    return s;
}

// Two unit vectors across unit n (tracer.settings._basis).
void basis(vec3 n, out vec3 t, out vec3 b) {
    t = normalize(abs(n.z) < 0.999 ? cross(n, vec3(0.0, 0.0, 1.0)) : cross(n, vec3(1.0, 0.0, 0.0)));
    b = cross(n, t);
}

// Shirley's concentric map of u in [0, 1)² onto the unit disk (tracer.settings._concentric).
vec2 concentric(vec2 u) {
    vec2 a = 2.0 * u - 1.0;
    if (a.x == 0.0 && a.y == 0.0) return vec2(0.0);
    bool first = abs(a.x) > abs(a.y);
    float r = first ? a.x : a.y;
    float phi = first ? 0.7853981633974483 * (a.y / a.x) : 1.5707963267948966 - 0.7853981633974483 * (a.x / a.y);
    return r * vec2(cos(phi), sin(phi));
}

// Light l's direction from p toward its point drawn by u (its centre without an extent:
// tracer.settings.Light.towards), and how far it is (BIG: directional).
vec3 light_dir(int l, vec3 p, vec2 u, out float dist) {
    vec4 lv = light_vec[l];
    float disk = light_v[l].w;
    vec3 t, b;
    if (lv.w > 4.5) {                 // an environment: a direction evenly over the sphere
        float z = 1.0 - 2.0 * u.x, r = sqrt(max(1.0 - z * z, 0.0)), phi = 6.283185307179586 * u.y;
        dist = BIG;
        return vec3(r * cos(phi), r * sin(phi), z);
    }
    if (lv.w < 0.5) {
        vec3 L = -lv.xyz;
        dist = BIG;
        if (disk > 0.0) { basis(L, t, b); vec2 c = disk * concentric(u); L = normalize(L + c.x * t + c.y * b); }
        return L;
    }
    vec3 q = lv.xyz;
    if (lv.w > 3.5) {                 // an area light: zero half sides leave its centre
        vec2 c = light_u[l].w > 0.5 ? concentric(u) : 2.0 * u - 1.0;
        q += c.x * light_u[l].xyz + c.y * light_v[l].xyz;
    } else if (disk > 0.0) {
        basis(normalize(q - p), t, b);
        vec2 c = disk * concentric(u);
        q += c.x * t + c.y * b;
    }
    vec3 L = q - p;
    dist = length(L);
    return L / max(dist, 1e-30);
}

// Light l's colour times its intensity toward a point that sees it along L at distance dist:
// the inverse-square fall-off for w >= 2, times a spot's cone (Blender's smoothstep edge) or an
// area light's cosine from its axis (tracer.settings.Light.scale, the references' model).
vec3 light_at(int l, vec3 L, float dist) {
    float w = light_vec[l].w;
    if (w < 1.5 || w > 4.5) return light_col[l];
    float f = 1.0 / max(dist * dist, 1e-30);
    float c = -dot(L, light_axis[l].xyz);
    if (w > 3.5) f *= max(c, 0.0);
    else if (w > 2.5) {
        float t = c - light_axis[l].w, b = light_blend[l];
        f *= t <= 0.0 ? 0.0 : (b > 0.0 ? smoothstep(0.0, 1.0, t / b) : 1.0);
    }
    return light_col[l] * f;
}

// `k`: which shading of the pixel's sample this is (its layer), for the points on lights.
vec3 shade(int id, int surf, vec3 o, vec3 d, float t, int k) {
    Surface s = surface_at(id, surf, o, d, t);
    vec3 result = material.x * s.color;
    for (int l = 0; l < NUM_LIGHTS; ++l) {
        float dist;
        vec3 L = light_dir(l, s.p, light_sample(k, l), dist);
        vec3 E = light_at(l, L, dist);
        // Nothing from this light here (outside a spot's cone, behind an area light): no
        // shadow ray, as the sum would gain 0 whatever it found.
        if (all(equal(E, vec3(0.0)))) continue;
        float lit = 1.0;
#if SHADOWS
        if (light_shadow[l] > 0.5) {
            lit = shadow_ray(l, s.p, L, dist, id, 1e-3 * cyl(id, CYL_TOP).w, occluder[l]);
            if (lit <= 0.0) continue;
        }
#endif
        result += lit * E * shade_light(s, L);
    }
    return result;
}

#if MESHES
// A mesh's point, shaded diffusely with its base colour (tracer/meshes.py): ambient plus
// every light's colour times max(N·L, 0) times mesh_brdf (1/pi where the model's lights
// are irradiance: tracer/shading), in the shadow of hair and meshes. Shadow rays
// leave mesh_offset off the surface, ignoring the triangle they leave.
uniform float mesh_brdf;
const int MESH_SHADING = 255;   // the mesh's shading index for light_sample
vec3 shade_mesh(int tri, vec3 o, vec3 d, float t, vec3 N) {
    vec3 col = triangle_color(tri);
    vec3 q = o + t * d + N * mesh_offset;
    vec3 result = material.x * col;
    for (int l = 0; l < NUM_LIGHTS; ++l) {
        float dist;
        vec3 L = light_dir(l, q, light_sample(MESH_SHADING, l), dist);
        vec3 E = light_at(l, L, dist);
        float ndl = max(dot(N, L), 0.0);
        // A face turned from the light, or a point the light gives nothing, gains 0 from it:
        // no shadow rays.
        if (ndl <= 0.0 || all(equal(E, vec3(0.0)))) continue;
        float lit = 1.0;
#if SHADOWS
        if (light_shadow[l] > 0.5) {
#if COUNT
            counter.x += 1.0;
#endif
            if (mesh_blocked(q, L, dist, tri)) continue;
            int hint = -1;
            lit = light_transmittance(l, q, L, dist, -1, 0.0, hint);
            if (lit <= 0.0) continue;
        }
#endif
        result += lit * E * ndl * (mesh_brdf * col);
    }
    return result;
}
#endif

// One primary ray: first find its LAYERS nearest hits without shading (accel_nearest fills
// the hit list of accel.glsl), then shade them front to back. Keeping the shadow rays out
// of the traversal loop matters on SIMD hardware (llvmpipe included): nested in it, one
// lane's shadow ray stalls all the lanes still traversing. The flat loops tried instead:
// docs/DECISIONS.md, "The trace loop finds the nearest hits first".
vec4 trace(vec3 o, vec3 d, float widen_per_t, float widen_const) {
    float tmesh = BIG;
#if MESHES
    // The nearest mesh hides every hair behind it.
    int mtri; vec3 mn;
    tmesh = mesh_nearest(o, d, BIG, mtri, mn);
#endif
    hits_clear();
#if CAMERA_BEAMS
    beam_nearest(o, d, tmesh, widen_per_t, widen_const);
#elif WALK
    accel_nearest(o, d, tmesh, widen_per_t, widen_const);
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
        // Entry i by constant indices (accel.glsl: a computed index would move the arrays
        // to memory for the whole traversal).
        float et = 0.0, ea = 0.0; int eid = 0, es = 0;
        for (int j = 0; j < LAYERS; ++j) if (j == i) { et = ht[j]; ea = ha[j]; eid = hid[j]; es = hs[j]; }
        C += T * ea * shade(eid, es, o, d, et, i);
        T *= 1.0 - ea;
#if COUNT
        counter.y += 1.0;
#endif
    }
#if MESHES
    if (mtri >= 0) {            // opaque: what is left of the ray ends on the mesh
        C += T * shade_mesh(mtri, o, d, tmesh, mn);
        T = 0.0;
    }
#endif
    return vec4(C + T * background.rgb, 1.0 - T + T * background.a);
}


// The sample positions of both samplers: sample s of pixel (px, py), stratified over an
// SPP_N x SPP_N grid and jittered by a fixed hash, as an offset in pixels from the pixel's
// top-left corner (x right, y down). A pixel's samples depend only on its place in the whole
// image and the sample index, so the tiles of a large render are the image rendered whole.
vec2 sample_jitter(int s, int px, int py) {
    vec2 jit = vec2(0.5);
#if SPP_N > 1
    uint h = hash32(hash32(hash32(uint(s)) ^ uint(py)) ^ uint(px));
    vec2 rnd = vec2(float(h >> 8u), float(hash32(h ^ 0x68bc21ebu) >> 8u)) * (1.0 / 16777216.0);
    jit = (vec2(s % SPP_N, s / SPP_N) + rnd) / float(SPP_N);
#endif
    return jit;
}

// The camera ray through image point (x, y) (pixels, y down), and its `len` (the length of
// the unnormalised direction; 1 for an orthographic camera).
void camera_ray(float x, float y, out vec3 o, out vec3 d, out float len) {
    float u = (x - centre_px.x) * pixel_size;
    float v = (centre_px.y - y) * pixel_size;
#if ORTHO
    o = cam_pos + cam_rot * vec3(u, v, 0.0);
    d = -cam_rot[2];
    len = 1.0;
#else
    o = cam_pos;
    vec3 dc = cam_rot * vec3(u, v, -1.0);
    len = length(dc);
    d = dc / len;
#endif
}

#if PIXEL
// The pixel sampler (sampler_pixel.glsl): one walk for all of a pixel's samples, then each
// sample composites its own hits front to back (at most LAYERS, none after its
// transmittance fell below t_eps past the first, as trace() does per sample), which gives
// every distinct cylinder its weight in the pixel; the PIX_SHADE heaviest that weigh at least
// SHADE_MIN are shaded, once each, on the ray of one of the samples they cover (sample_among),
// with one shadow ray per light (with one layer the PIX_SHADE_ONE heaviest, with one set of
// shadow rays from one of them, drawn by its light), and one more entry, drawn by weight,
// stands for the rest. Loops over the samples and the list have constant trip counts and
// are unrolled, so llvmpipe's cap on loop iterations sees one walk and the shading loop.
const float SHADE_MIN = 1.0 / 512.0;

// The ray of the sample at offset q (pixels, from the pixel's centre) of the central ray
// o + t·d: moved sideways (orthographic) or turned (perspective) by q pixels.
void sample_ray(vec3 o, vec3 d, vec2 q, out vec3 so, out vec3 sd) {
    so = o; sd = d;
#if ORTHO
    so = o + q.x * px_du + q.y * px_dv;
#else
    sd = normalize(d + q.x * px_du + q.y * px_dv);
#endif
}

// The offset of a sample drawn evenly, by u in [0, 1), among those of `mask` (bit s: sample
// s): where a strand is shaded. A sample's ray meets a strand at an offset h across it spread
// evenly over its width, so the drawn sample's is too; the middle of several samples' rays
// met it nearer its axis, and the first sample by index nearer the edge the strata are
// counted from (both darkened Chiang-shaded hair, by 5 % and 9 % at 100 samples).
vec2 sample_among(uint mask, float u) {
    int n = 0;
    for (int s = 0; s < PN; ++s) n += (mask & (1u << uint(s))) != 0u ? 1 : 0;
    int k = min(int(u * float(n)), n - 1);
    vec2 q = vec2(0.0);
    int c = 0;
    for (int s = 0; s < PN; ++s) {
        bool on = (mask & (1u << uint(s))) != 0u;
        q = on && c == k ? px_off[s] : q;
        c += on ? 1 : 0;
    }
    return q;
}

#if LAYERS == 1
// One layer: one set of shadow rays for the pixel's shaded strands (the shadow walks are what
// costs; the shading itself little), from a strand drawn per light in proportion to its
// unshadowed light (a running draw: each strand shaded replaces the one drawn so far with
// probability its share of the sum so far). Its visibility times the sum is an unbiased
// estimate of the sum of each strand's light times its own visibility. (The heaviest strand's
// rays, as before, lit the pixel too much where the strands behind lie in its shadow.) Per
// light: the sum so far, its luminance, and the point and strand drawn.
vec3 lit[NUM_LIGHTS]; float lsum[NUM_LIGHTS]; vec3 lp[NUM_LIGHTS]; int lstrand[NUM_LIGHTS];
vec2 lu[NUM_LIGHTS];          // the drawn strand's point on the light
uint draw;

// Cylinder `eid` (distance `et` along the central ray o + t·d) of weight w, shaded on the ray
// of a sample drawn by u among those whose nearest hit it is (as shade_entry): returns the
// light no shadow touches, adds each light's to `lit` and takes its turn in the draw (`k`:
// which strand of the pixel it is).
vec3 shade_one(int eid, float et, float w, int k, float u, vec3 o, vec3 d) {
    uint mask = 0u;
    for (int s = 0; s < PN; ++s) mask |= sid[s] == eid ? 1u << uint(s) : 0u;
    vec3 so, sd;
    sample_ray(o, d, sample_among(mask, u), so, sd);
    int surf; float asc, alpha;
    float th = hit_cylinder(eid, so, sd, 0.0, 0.0, surf, asc, alpha);
    bool exact = th > 0.0;
    Surface S = surface_at(eid, exact ? surf : 0, so, sd, exact ? th : et);
    for (int l = 0; l < NUM_LIGHTS; ++l) {
        float dist;
        vec2 u2 = light_sample(k, l);
        vec3 L = light_dir(l, S.p, u2, dist);
        vec3 cl = w * light_at(l, L, dist) * shade_light(S, L);
        float y = dot(cl, vec3(0.2126, 0.7152, 0.0722));
        lsum[l] += y;
        draw = hash32(draw ^ uint(NUM_LIGHTS * k + l + 1));
        bool take = y > 0.0 && unit_of(draw) * lsum[l] < y;
        lp[l] = take ? S.p : lp[l];
        lu[l] = take ? u2 : lu[l];
        lstrand[l] = take ? eid : lstrand[l];
        lit[l] += cl;
    }
    return w * material.x * S.color;
}
#else
// List entry `eid` (distance `et` along the central ray o + t·d) shaded on the ray of the
// sample at `mi` (one it covers, sample_among), which meets the strand but for the linear
// test's rounding; where the exact test disagrees, the side at the representative distance.
vec3 shade_entry(int eid, vec2 mi, float et, vec3 o, vec3 d, int k) {
    vec3 so, sd;
    sample_ray(o, d, mi, so, sd);
    int surf; float asc, alpha;
    float th = hit_cylinder(eid, so, sd, 0.0, 0.0, surf, asc, alpha);
    bool exact = th > 0.0;
    return shade(eid, exact ? surf : 0, so, sd, exact ? th : et, k);
}
#endif

void main() {
    int px = int(gl_FragCoord.x) + pixel_origin.x;
    int py = int(image_size.y) - 1 - int(gl_FragCoord.y) + pixel_origin.y;   // row 0 = top
    camera_pixel = ivec2(px, py);
    for (int s = 0; s < PN; ++s) px_off[s] = sample_jitter(sample_index * PN + s, px, py) - 0.5;
    light_seed = pixel_hash(px, py, 0x27d4eb2du);
    vec3 o, d; float len;
    camera_ray(float(px) + 0.5, float(py) + 0.5, o, d, len);
    px_du = cam_rot[0] * (pixel_size / len);
    px_dv = -cam_rot[1] * (pixel_size / len);
#if ORTHO
    px_reach_c = 0.7072 * pixel_size; px_reach_t = 0.0;
#else
    px_reach_c = 0.0; px_reach_t = 0.7072 * pixel_size / len;
#endif
    float tmax = BIG;
#if MESHES
    // Each sample's own mesh hit ends that sample; the walk goes as far as the farthest.
    int mesh_s = -1, mesh_tri = -1; vec3 mesh_n = vec3(0.0); float mesh_t = BIG;
    float tfar = 0.0;
    for (int s = 0; s < PN; ++s) {
        vec3 so, sd;
        sample_ray(o, d, px_off[s], so, sd);
        int tri; vec3 n;
        float tm = mesh_nearest(so, sd, BIG, tri, n);
        px_tm[s] = tri >= 0 ? tm : BIG;
        tfar = max(tfar, px_tm[s]);
        bool first = tri >= 0 && mesh_s < 0;
        mesh_s = first ? s : mesh_s; mesh_tri = first ? tri : mesh_tri;
        mesh_n = first ? n : mesh_n; mesh_t = first ? tm : mesh_t;
    }
    tmax = tfar;
#endif
    list_clear();
#if CAMERA_BEAMS
    beam_pixel_nearest(o, d, tmax);
#elif WALK
    accel_pixel_nearest(o, d, tmax);
#endif

    // Each sample's compositing, entry by entry in depth order: the entry's weight and the
    // samples it counts in (one of them is where it is shaded, below).
    float Ts[PN];
#if LAYERS > 1
    const int NE = PIX_M;
    float wgt[NE]; uint onm[NE]; int eids[NE]; float ets[NE];
    int cnt[PN];
    for (int s = 0; s < PN; ++s) { Ts[s] = 1.0; cnt[s] = 0; }
    for (int j = 0; j < PIX_M; ++j) {
        float a = la[j], wj = 0.0;
        uint mj = 0u;
        for (int s = 0; s < PN; ++s) {
            bool on = (lm[j] & (1u << uint(s))) != 0u && cnt[s] < LAYERS && (cnt[s] == 0 || Ts[s] >= t_eps);
            wj += on ? Ts[s] * a : 0.0;
            mj |= on ? 1u << uint(s) : 0u;
            Ts[s] *= on ? 1.0 - a : 1.0;
            cnt[s] += on ? 1 : 0;
        }
        wgt[j] = wj / float(PN);
        onm[j] = mj;
        eids[j] = lid[j]; ets[j] = lt[j];
    }
#else
    // One layer: each sample's own nearest hit. The entries are the samples that come first
    // among those on their cylinder, each with the weight of all of them (where it is shaded
    // is worked out for the ones shaded). A pixel no sample hits skips the grouping.
    const int NE = PN;
    float wgt[NE]; int eids[NE]; float ets[NE];
    for (int s = 0; s < PN; ++s) { Ts[s] = 1.0 - sa[s]; wgt[s] = 0.0; eids[s] = sid[s]; ets[s] = st[s]; }
    if (have != 0u) {
        for (int s = 0; s < PN; ++s) {
            float wj = 0.0;
            bool first = sid[s] != NO_ID;
            for (int k = 0; k < PN; ++k) {
                bool same = sid[k] == sid[s];
                first = first && !(same && k < s);
                wj += same ? sa[k] : 0.0;
            }
            wgt[s] = first ? wj / float(PN) : 0.0;
        }
    }
#endif
    // The PIX_SHADE (one layer: PIX_SHADE_ONE) heaviest entries are shaded, and one more entry
    // stands for the rest (below).
    float wall = 0.0, wshaded = 0.0;
    int nshade = 0;
    for (int j = 0; j < NE; ++j) {
        wall += wgt[j];
        nshade += wgt[j] >= SHADE_MIN ? 1 : 0;
    }
#if LAYERS == 1
    nshade = min(nshade, PIX_SHADE_ONE);
    for (int l = 0; l < NUM_LIGHTS; ++l) {
        lit[l] = vec3(0.0); lsum[l] = 0.0; lp[l] = vec3(0.0); lstrand[l] = -1; lu[l] = vec2(0.5);
    }
    draw = pixel_hash(px, py, 0x85ebca6bu);
#else
    nshade = min(nshade, PIX_SHADE);
#endif
    vec3 C = vec3(0.0);
#if SHADOWS
    for (int l = 0; l < NUM_LIGHTS; ++l) occluder[l] = -1;
#endif
    // Where each shaded entry is shaded (sample_among) draws from this seed.
    uint where = pixel_hash(px, py, 0xc2b2ae35u);
    for (int i = 0; i < nshade; ++i) {
        // The heaviest entry not shaded yet, by constant indices (accel.glsl says why).
        int eid = 0, pick = -1; float wi = -1.0, et = 0.0; uint mm = 0u;
        for (int j = 0; j < NE; ++j) {
            bool here = wgt[j] > wi;
            pick = here ? j : pick;
            eid = here ? eids[j] : eid; wi = here ? wgt[j] : wi; et = here ? ets[j] : et;
#if LAYERS > 1
            mm = here ? onm[j] : mm;
#endif
        }
        for (int j = 0; j < NE; ++j) wgt[j] = j == pick ? -1.0 : wgt[j];
        wshaded += wi;
        float u = unit_of(hash32(where ^ uint(i)));
#if LAYERS == 1
        C += shade_one(eid, et, wi, i, u, o, d);
#else
        C += wi * shade_entry(eid, sample_among(mm, u), et, o, d, i);
#endif
#if COUNT
        counter.y += 1.0;
#endif
    }
    // The entries left unshaded: one of them, drawn in proportion to its weight, stands for
    // all their weight, an unbiased estimate of their sum. (Their weight given to the shaded
    // ones in proportion brightened the hair, as the strands behind the heaviest lie in their
    // shadow: see-through straight.hair under a sun, 16 samples, 16 %; opaque wavy 1 %.)
    float wrest = wall - wshaded;
    if (wrest > 0.0) {
        float u = unit_of(pixel_hash(px, py, 0x9e3779b9u)) * wrest;
        int eid = -1; float et = 0.0, acc = 0.0; uint mm = 0u;
        for (int j = 0; j < NE; ++j) {
            float wj = max(wgt[j], 0.0);
            // The entry whose stretch of the running sum holds u: the last whose sum before it is <= u.
            bool here = wj > 0.0 && (eid < 0 || acc <= u);
            eid = here ? eids[j] : eid; et = here ? ets[j] : et;
#if LAYERS > 1
            mm = here ? onm[j] : mm;
#endif
            acc += wj;
        }
        if (eid >= 0) {
            float us = unit_of(hash32(where ^ 0x3c6ef372u));
#if LAYERS > 1
            C += wrest * shade_entry(eid, sample_among(mm, us), et, o, d, PIX_SHADE);
#else
            C += shade_one(eid, et, wrest, PIX_SHADE_ONE, us, o, d);
#endif
            wshaded = wall;
#if COUNT
            counter.y += 1.0;
#endif
        }
    }
#if LAYERS == 1
    for (int l = 0; l < NUM_LIGHTS; ++l) {
        float v = 1.0;
#if SHADOWS
        if (lstrand[l] >= 0 && light_shadow[l] > 0.5) {
            float dist;
            vec3 L = light_dir(l, lp[l], lu[l], dist);
            v = shadow_ray(l, lp[l], L, dist, lstrand[l], 1e-3 * cyl(lstrand[l], CYL_TOP).w, occluder[l]);
        }
#endif
        C += v * lit[l];
    }
#endif
    C *= wshaded > 0.0 ? wall / wshaded : 0.0;
    float Tbg = 0.0;
#if MESHES
    float Tmesh = 0.0;
    for (int s = 0; s < PN; ++s) {
        bool m = px_tm[s] < BIG;
        Tmesh += m ? Ts[s] : 0.0;
        Tbg += m ? 0.0 : Ts[s];
    }
    if (mesh_s >= 0) {           // opaque: the samples that end on a mesh take its shade
        vec2 q = vec2(0.0);
        for (int s = 0; s < PN; ++s) q = s == mesh_s ? px_off[s] : q;
        vec3 so, sd;
        sample_ray(o, d, q, so, sd);
        C += (Tmesh / float(PN)) * shade_mesh(mesh_tri, so, sd, mesh_t, mesh_n);
    }
#else
    for (int s = 0; s < PN; ++s) Tbg += Ts[s];
#endif
    Tbg /= float(PN);
    frag_color = vec4(C + Tbg * background.rgb, 1.0 - Tbg + Tbg * background.a) / float(GROUPS);
#if COUNT
    frag_count = counter;
#endif
}

#else
// One sample per draw: the host draws every pixel SPP_N² times, sample_index = 0, 1, ...,
// and adds the passes with blending. Mesa's llvmpipe caps the loop iterations of one
// shader invocation (65535 back-edges over all loops together, then every loop exits
// early, silently); all samples in one invocation with several layers and shadow rays ran
// past it and dropped hits, so the work of one invocation is kept to one sample (the pixel
// sampler above shares one walk between the samples instead).
void main() {
    int px = int(gl_FragCoord.x) + pixel_origin.x;
    int py = int(image_size.y) - 1 - int(gl_FragCoord.y) + pixel_origin.y;   // row 0 = top
    camera_pixel = ivec2(px, py);
    vec2 jit = sample_jitter(sample_index, px, py);
    camera_point = vec2(px, py) + jit;
    light_seed = pixel_hash(px, py, 0x27d4eb2du);
    vec3 o, d; float len;
    camera_ray(float(px) + jit.x, float(py) + jit.y, o, d, len);
    float widen_per_t = 0.0, widen_const = 0.0;
#if ORTHO
    widen_const = 0.5 * pixel_size;
#else
    // At distance t along this ray the depth is t / len and a pixel spans pixel_size times
    // that; the minimum width is half of it.
    widen_per_t = 0.5 * pixel_size / len;
#endif
    frag_color = trace(o, d, widen_per_t, widen_const) / float(SPP_N * SPP_N);
#if COUNT
    frag_count = counter;
#endif
}
#endif

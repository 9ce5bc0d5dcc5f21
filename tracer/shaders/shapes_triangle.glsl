// SPDX-License-Identifier: GPL-3.0-or-later
// The second shape: opaque triangles of meshes (tracer/meshes.py), TEXELS_PER_TRI texels
// each (TRI_V0, TRI_V1, TRI_V2: a corner in xyz, one channel of the base colour in w).
// Part of the trace program only when it has meshes (MESHES 1).

uniform samplerBuffer tex_tri;

vec3 triangle_color(int id) {
    int base = id * TEXELS_PER_TRI;
    return vec3(texelFetch(tex_tri, base + TRI_V0).w, texelFetch(tex_tri, base + TRI_V1).w,
                texelFetch(tex_tri, base + TRI_V2).w);
}

// Möller-Trumbore, two-sided: the distance t along o + t·d where the ray meets triangle
// `id`, or -1. The barycentric tests keep TRI_EDGE_EPS of overlap, so rounding on an edge
// two triangles share cannot let a ray slip between them. `n` gets the unit normal facing
// the ray. A ray in the triangle's plane (det 0) misses: it sees an edge of no width.
float hit_triangle(int id, vec3 o, vec3 d, out vec3 n) {
    int base = id * TEXELS_PER_TRI;
    vec3 v0 = texelFetch(tex_tri, base + TRI_V0).xyz;
    vec3 e1 = texelFetch(tex_tri, base + TRI_V1).xyz - v0;
    vec3 e2 = texelFetch(tex_tri, base + TRI_V2).xyz - v0;
    n = vec3(0.0, 0.0, 1.0);
    vec3 pv = cross(d, e2);
    float det = dot(e1, pv);
    if (det == 0.0) return -1.0;
    float inv = 1.0 / det;
    vec3 tv = o - v0;
    float u = dot(tv, pv) * inv;
    vec3 qv = cross(tv, e1);
    float v = dot(d, qv) * inv;
    if (u < -TRI_EDGE_EPS || v < -TRI_EDGE_EPS || u + v > 1.0 + TRI_EDGE_EPS) return -1.0;
    vec3 g = cross(e1, e2);
    n = normalize(dot(g, d) > 0.0 ? -g : g);
    return dot(e2, qv) * inv;
}

// SPDX-License-Identifier: GPL-3.0-or-later
// The meshes' own acceleration structure (tracer/mesh_grid.py): a uniform grid of cubic
// cells, each with a compact list of the triangles whose boxes touch it, walked by a plain
// 3-D DDA. Part of the trace program only when it has meshes (MESHES 1). Two questions:
//   mesh_nearest(o, d, tmax, tri, n)   the nearest triangle hit in (0, tmax): its t (BIG:
//                                      none), id and normal facing the ray
//   mesh_blocked(o, d, tmax, own)      is any triangle but `own` hit in (0, tmax)?

uniform isamplerBuffer tex_mesh_idx;   // cell lists (CSR), triangle ids
uniform isamplerBuffer tex_mesh_cell;  // per cell (x + nx*(y + ny*z)): first slot, count
uniform vec3 mesh_lo;
uniform vec3 mesh_cell_size;
uniform ivec3 mesh_dims;
uniform float mesh_offset;             // how far shadow rays leave a mesh's surface

// One walk for both questions: `any_hit` stops at the first hit (shadows), otherwise the
// walk ends after the cell that holds the nearest hit so far (cells come in ray order).
float mesh_walk(vec3 o, vec3 d, float tmax, int own, bool any_hit, out int tri, out vec3 n) {
    tri = -1;
    n = vec3(0.0);
    vec3 inv = safe_inverse(d);
    vec3 hi = mesh_lo + mesh_cell_size * vec3(mesh_dims);
    vec3 ta = (mesh_lo - o) * inv, tb = (hi - o) * inv;
    vec3 tn = min(ta, tb), tf = max(ta, tb);
    float t0 = max(0.0, max(tn.x, max(tn.y, tn.z)));
    float t1 = min(tmax, min(tf.x, min(tf.y, tf.z)));
    if (t0 > t1) return BIG;
    ivec3 cell = clamp(ivec3(floor((o + t0 * d - mesh_lo) / mesh_cell_size)), ivec3(0), mesh_dims - 1);
    ivec3 stp = ivec3(sign(d));
    vec3 tdelta = abs(mesh_cell_size * inv);
    vec3 tnext = (mesh_lo + (vec3(cell) + step(0.0, d)) * mesh_cell_size - o) * inv;
    float best = BIG;
    int guard = mesh_dims.x + mesh_dims.y + mesh_dims.z + 3;
    for (int it = 0; it < guard; ++it) {
        ivec2 sc = texelFetch(tex_mesh_cell, cell.x + mesh_dims.x * (cell.y + mesh_dims.y * cell.z)).xy;
        for (int k = 0; k < sc.y; ++k) {
            int id = texelFetch(tex_mesh_idx, sc.x + k).x;
            vec3 hn;
            float t = hit_triangle(id, o, d, hn);
            if (id != own && t > 0.0 && t < tmax && precedes(t, id, best, tri)) {
                best = t; tri = id; n = hn;
            }
        }
        if (any_hit && tri >= 0) break;
        float texit = min(min(tnext.x, tnext.y), tnext.z);
        if (best <= texit || texit >= t1) break;
        if (tnext.x <= tnext.y && tnext.x <= tnext.z) { cell.x += stp.x; tnext.x += tdelta.x; }
        else if (tnext.y <= tnext.z) { cell.y += stp.y; tnext.y += tdelta.y; }
        else { cell.z += stp.z; tnext.z += tdelta.z; }
        if (any(lessThan(cell, ivec3(0))) || any(greaterThanEqual(cell, mesh_dims))) break;
    }
    return best;
}

float mesh_nearest(vec3 o, vec3 d, float tmax, out int tri, out vec3 n) {
    return mesh_walk(o, d, tmax, -1, false, tri, n);
}

bool mesh_blocked(vec3 o, vec3 d, float tmax, int own) {
    int tri; vec3 n;
    mesh_walk(o, d, tmax, own, true, tri, n);
    return tri >= 0;
}

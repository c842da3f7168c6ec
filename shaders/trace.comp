/* One primary ray per pixel of a tile (RAYGEN camera), or one ray of the ray buffer per
 * invocation (RAYGEN buffer, vkrt_trace_rays). The mode, traversal, heat kind, ray source and
 * intersector are specialization constants, so each pipeline keeps only the code it uses.
 * Mirrors trace_pixel(), trace_one_ray() and their callees in src/cpu_trace.c and
 * src/cpu_trace_real.h. */
#version 460
#extension GL_GOOGLE_include_directive : require

#include "vkrt_shared.h"

layout(local_size_x = VKRT_TRACE_GROUP_X, local_size_y = VKRT_TRACE_GROUP_Y, local_size_z = 1) in;

layout(constant_id = VKRT_SPEC_MODE) const uint MODE = VKRT_GPU_MODE_NORMAL;
layout(constant_id = VKRT_SPEC_TRAVERSAL) const uint TRAVERSAL = VKRT_GPU_TRAVERSAL_BVH;
layout(constant_id = VKRT_SPEC_HEAT) const uint HEAT = VKRT_GPU_HEAT_NODES;
layout(constant_id = VKRT_SPEC_RAYGEN) const uint RAYGEN = VKRT_GPU_RAYGEN_CAMERA;
layout(constant_id = VKRT_SPEC_ISECT) const uint ISECT = VKRT_GPU_ISECT_WATERTIGHT;

layout(set = 0, binding = VKRT_BINDING_NODES, std430) readonly buffer Nodes {
    vkrt_gpu_node nodes[];
};
layout(set = 0, binding = VKRT_BINDING_TRIS, std430) readonly buffer Tris {
    vkrt_gpu_tri tris[];
};
/* Tile-sized: pixels are stored at their coordinate within the tile. */
layout(set = 0, binding = VKRT_BINDING_IMAGE, rgba32f) writeonly uniform image2D out_image;
/* Naive traversal: the closest hit so far, carried from one chunk dispatch to the next. Ray
 * mode: also the output, one vkrt_hit per ray. */
layout(set = 0, binding = VKRT_BINDING_HITS, std430) buffer Hits {
    vkrt_gpu_hit hits[];
};
/* Ray mode: the rays of this submission. */
layout(set = 0, binding = VKRT_BINDING_RAYS, std430) readonly buffer Rays {
    vkrt_gpu_ray rays[];
};
layout(push_constant, std430) uniform Push {
    vkrt_gpu_push p;
};

#include "trace_common.glsl"

struct hit {
    float t;
    float u;
    float v;
    uint tri;
    uint prim;
};

struct heat_counts {
    uint nodes;
    uint leaves;
    uint tris;
};

void test_triangle(ray r, uint index, inout hit best)
{
    vkrt_gpu_tri tri = tris[index];
    float t, u, v;
    if (intersect_triangle(r, tri, t, u, v) && hit_closer(t, tri.prim_id, best.t, best.prim)) {
        best.t = t;
        best.u = u;
        best.v = v;
        best.tri = index;
        best.prim = tri.prim_id;
    }
}

void trace_bvh(ray r, inout hit best, inout heat_counts heat)
{
    uint stack_node[VKRT_TRAVERSAL_STACK_SIZE];
    float stack_tnear[VKRT_TRAVERSAL_STACK_SIZE];
    uint sp = 0u;
    float tnear;
    if (!intersect_box(r, nodes[0].bmin, nodes[0].bmax, best.t, tnear)) return;
    heat.nodes++;
    if (nodes[0].tri_count != 0u) heat.leaves++;
    uint node = 0u;
    for (;;) {
        vkrt_gpu_node n = nodes[node];
        bool descend = false;
        if (n.tri_count != 0u) {
            for (uint i = n.left_first; i < n.left_first + n.tri_count; i++) {
                heat.tris++;
                test_triangle(r, i, best);
            }
        } else {
            uint left = n.left_first, right = left + 1u;
            vkrt_gpu_node ln = nodes[left], rn = nodes[right];
            float tl, tr;
            bool hit_l = intersect_box(r, ln.bmin, ln.bmax, best.t, tl);
            bool hit_r = intersect_box(r, rn.bmin, rn.bmax, best.t, tr);
            if (hit_l) {
                heat.nodes++;
                if (ln.tri_count != 0u) heat.leaves++;
            }
            if (hit_r) {
                heat.nodes++;
                if (rn.tri_count != 0u) heat.leaves++;
            }
            if (hit_l && hit_r) {
                uint far_node = tr < tl ? left : right;
                float far_t = tr < tl ? tl : tr;
                node = tr < tl ? right : left;
                /* Never full for a BVH within VKRT_MAX_BVH_DEPTH: one entry per level above. */
                if (sp < VKRT_TRAVERSAL_STACK_SIZE) {
                    stack_node[sp] = far_node;
                    stack_tnear[sp] = far_t;
                    sp++;
                }
                descend = true;
            } else if (hit_l) {
                node = left;
                descend = true;
            } else if (hit_r) {
                node = right;
                descend = true;
            }
        }
        if (descend) continue;
        /* A pushed box that starts beyond the closest hit found since cannot improve it. */
        while (sp > 0u && stack_tnear[sp - 1u] > best.t) sp--;
        if (sp == 0u) break;
        sp--;
        node = stack_node[sp];
    }
}

vec4 shade(hit best, heat_counts heat)
{
    bool is_hit = best.prim != NO_PRIM;
    if (MODE == VKRT_GPU_MODE_HEATMAP) {
        uint count = HEAT == VKRT_GPU_HEAT_LEAVES ? heat.leaves : (HEAT == VKRT_GPU_HEAT_TRIS ? heat.tris : heat.nodes);
        return vec4(float(count), 0.0, 0.0, 1.0);
    }
    if (MODE == VKRT_GPU_MODE_DEPTH)
        return is_hit ? vec4(best.t, 0.0, 0.0, 1.0) : vec4(VKRT_MISS, 0.0, 0.0, 0.0);
    if (MODE == VKRT_GPU_MODE_ID)
        return is_hit ? vec4(float(best.prim), best.u, best.v, 1.0) : vec4(VKRT_MISS, 0.0, 0.0, 0.0);
    if (!is_hit) return vec4(0.0);
    return shade_normal(tris[best.tri], best.u, best.v);
}

/* Naive traversal: the closest hit carried from the previous chunk. The host clears the
 * buffer to t = +inf and may leave tri unset then: only a finite t names a triangle. */
void restore_carried(uint slot, inout hit best)
{
    vkrt_gpu_hit carried = hits[slot];
    if (carried.t < T_INFINITY) {
        best.t = carried.t;
        best.u = carried.u;
        best.v = carried.v;
        best.tri = carried.tri;
        best.prim = tris[carried.tri].prim_id;
    }
}

/* Naive traversal: the closest hit so far, for the next chunk (t = +inf: none yet). */
void store_carried(uint slot, hit best)
{
    hits[slot] = vkrt_gpu_hit(best.prim != NO_PRIM ? best.t : T_INFINITY, best.tri, best.u, best.v);
}

/* vkrt_trace_rays: one ray of the buffer, its closest hit written as a vkrt_hit. */
void trace_buffer_ray()
{
    uint index = gl_WorkGroupID.x * VKRT_TRACE_GROUP_SIZE + gl_LocalInvocationIndex;
    if (index >= p.tile_width) return;
    ray r;
    bool valid = ray_from_buffer(rays[index], r);
    hit best = hit(r.tmax, 0.0, 0.0, NO_PRIM, NO_PRIM);
    heat_counts heat = heat_counts(0u, 0u, 0u);
    if (TRAVERSAL == VKRT_GPU_TRAVERSAL_NAIVE) {
        restore_carried(index, best);
        if (valid)
            for (uint i = p.tri_first; i < p.tri_end; i++) test_triangle(r, i, best);
        if (p.last_chunk == 0u) {
            store_carried(index, best);
            return;
        }
    } else if (valid) {
        trace_bvh(r, best, heat);
    }
    hits[index] = best.prim != NO_PRIM ? vkrt_gpu_hit(best.t, best.prim, best.u, best.v)
                                       : vkrt_gpu_hit(-1.0, NO_PRIM, 0.0, 0.0);
}

void main()
{
    if (RAYGEN == VKRT_GPU_RAYGEN_BUFFER) {
        trace_buffer_ray();
        return;
    }
    uvec2 local = gl_GlobalInvocationID.xy;
    if (local.x >= p.tile_width || local.y >= p.tile_height) return;
    uint x = p.tile_x + local.x, y = p.tile_y + local.y;
    hit best = hit(T_INFINITY, 0.0, 0.0, NO_PRIM, NO_PRIM);
    heat_counts heat = heat_counts(0u, 0u, 0u);

    if (TRAVERSAL == VKRT_GPU_TRAVERSAL_NAIVE) {
        heat.tris = p.tri_total;
        /* Naive heat is tri_total whatever the ray does, so the heatmap skips the tests (and
         * every chunk but the last does nothing). */
        if (MODE == VKRT_GPU_MODE_HEATMAP) {
            if (p.last_chunk != 0u) imageStore(out_image, ivec2(local), shade(best, heat));
            return;
        }
        uint slot = local.y * p.tile_width + local.x;
        restore_carried(slot, best);
        ray r = camera_ray(p, x, y);
        for (uint i = p.tri_first; i < p.tri_end; i++) test_triangle(r, i, best);
        if (p.last_chunk != 0u) {
            imageStore(out_image, ivec2(local), shade(best, heat));
        } else {
            store_carried(slot, best);
        }
        return;
    }

    ray r = camera_ray(p, x, y);
    trace_bvh(r, best, heat);
    imageStore(out_image, ivec2(local), shade(best, heat));
}

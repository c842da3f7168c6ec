/* One primary ray per pixel of a tile (RAYGEN camera), or one ray of the ray buffer per
 * invocation (RAYGEN buffer, vkrt_trace_rays). The mode, traversal, heat kind, ray source,
 * intersector, loop budget, traversal counters, alpha test, any-hit and the scene's split
 * across buffers are specialization constants, so each
 * pipeline keeps only the code it uses.
 * Mirrors trace_pixel(), trace_one_ray() and their callees in src/cpu_trace.c and
 * src/cpu_trace_real.h. */
#version 460
#extension GL_GOOGLE_include_directive : require
#ifdef VKRT_HAS_BUFFER_ADDRESS
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_buffer_reference_uvec2 : require
#endif

#include "vkrt_shared.h"
#if VKRT_NAIVE_SHARE > 1
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_vote : require
#extension GL_KHR_shader_subgroup_ballot : require
#endif

layout(local_size_x = VKRT_TRACE_GROUP_X, local_size_y = VKRT_TRACE_GROUP_Y, local_size_z = 1) in;

layout(constant_id = VKRT_SPEC_MODE) const uint MODE = VKRT_GPU_MODE_NORMAL;
layout(constant_id = VKRT_SPEC_TRAVERSAL) const uint TRAVERSAL = VKRT_GPU_TRAVERSAL_BVH;
layout(constant_id = VKRT_SPEC_HEAT) const uint HEAT = VKRT_GPU_HEAT_NODES;
layout(constant_id = VKRT_SPEC_RAYGEN) const uint RAYGEN = VKRT_GPU_RAYGEN_CAMERA;
layout(constant_id = VKRT_SPEC_ISECT) const uint ISECT = VKRT_GPU_ISECT_WATERTIGHT;
layout(constant_id = VKRT_SPEC_BUDGET) const uint BUDGET = 0u;
layout(constant_id = VKRT_SPEC_COUNTERS) const uint COUNTERS = 0u;
layout(constant_id = VKRT_SPEC_ALPHA) const uint ALPHA = 0u;
layout(constant_id = VKRT_SPEC_ANYHIT) const uint ANYHIT = 0u;
layout(constant_id = VKRT_SPEC_TEXTURES) const uint TEXTURES = 0u;
layout(constant_id = VKRT_SPEC_SPLIT) const uint SPLIT = 0u;
layout(constant_id = VKRT_SPEC_WIDE) const uint WIDE = 0u;
layout(constant_id = VKRT_SPEC_FINISH) const uint FINISH = 0u;

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
/* BVH traversal with a budget: the state of each traversal that stopped at it, and how many
 * stopped in this dispatch (the host repeats resume dispatches until none did). */
layout(set = 0, binding = VKRT_BINDING_RESUME, std430) buffer Resume {
    vkrt_gpu_resume states[];
};
layout(set = 0, binding = VKRT_BINDING_RESUME_STACK, std430) buffer ResumeStack {
    vkrt_gpu_stack_entry saved_stack[];
};
layout(set = 0, binding = VKRT_BINDING_UNFINISHED, std430) buffer Unfinished {
    uint unfinished;
    uint next_slot; /* the wide traversal's next ray slot free (take_ray_slot) */
};
/* With COUNTERS: what each pixel's traversal did, summed by the host (render statistics). */
layout(set = 0, binding = VKRT_BINDING_COUNTERS, std430) writeonly buffer Counters {
    vkrt_gpu_counters counters[];
};
/* Albedo and uv modes: each triangle's texture coordinates and material (by prim_id), and the
 * material table. Other modes never read them (and their buffers are placeholders then). */
layout(set = 0, binding = VKRT_BINDING_SURFACES, std430) readonly buffer Surfaces {
    vkrt_gpu_surface surfaces[];
};
layout(set = 0, binding = VKRT_BINDING_MATERIALS, std430) readonly buffer Materials {
    vkrt_gpu_material materials[];
};
layout(set = 0, binding = VKRT_BINDING_TEXTURES, std430) readonly buffer Textures {
    vkrt_gpu_texture textures[];
};
layout(set = 0, binding = VKRT_BINDING_TEXELS, std430) readonly buffer Texels {
    uvec2 texels[]; /* linear RGBA as halves: (R | G << 16, B | A << 16) */
};
/* With WIDE: the wide BVH and its triangles (placeholders otherwise), and the
 * wide traversal's view of the rays and hits buffers (a ray two texels, a hit one). lavapipe
 * runs a storage-buffer access as a loop over the lanes with a bounds check per word, a texel
 * access as one gather; the ray refill is in every step of the wide traversal's loop, and
 * through texels a trace takes 12% fewer instructions (valgrind's count) and 9-13% less time.
 * Storage texel buffers rather than uniform ones (texelFetch): lavapipe calls a function for
 * each texelFetch, which spills the loop's live vectors around it, and inlines imageLoad;
 * 6.5% fewer instructions. */
layout(set = 0, binding = VKRT_BINDING_WIDE_NODES, rgba32ui) readonly uniform uimageBuffer wide_nodes;
layout(set = 0, binding = VKRT_BINDING_TRACE_TRIS, rgba32ui) readonly uniform uimageBuffer trace_tris;
layout(set = 0, binding = VKRT_BINDING_RAY_TEXELS, rgba32ui) readonly uniform uimageBuffer ray_texels;
/* A word a texel, so that the finish can write a hit's triangle word alone. */
layout(set = 0, binding = VKRT_BINDING_HIT_WORDS, r32ui) uniform uimageBuffer hit_words;
/* The wide ray trace's record of each ray's closest triangle so far, by ray slot (a slot's
 * VKRT_WIDE_RAYS_PER_LANE words together; see store_slot_tri). */
layout(set = 0, binding = VKRT_BINDING_SLOT_TRIS, r32ui) uniform uimageBuffer slot_tris;
/* The binned traversal's lists (TRAVERSAL_BINNED; one-texel placeholders otherwise). */
layout(set = 0, binding = VKRT_BINDING_RAY_LISTS, r32ui) readonly uniform uimageBuffer ray_lists;
layout(set = 0, binding = VKRT_BINDING_LIST_TRIS, r32ui) readonly uniform uimageBuffer list_tris;
/* A split scene's piece addresses (a placeholder otherwise): the nodes, triangles and surfaces
 * bindings then hold only the first piece of each. */
layout(set = 0, binding = VKRT_BINDING_PIECES, std430) readonly buffer Pieces {
    vkrt_gpu_address pieces[];
};
layout(push_constant, std430) uniform Push {
    vkrt_gpu_push p;
};

#define VKRT_SCENE_NODES
#include "scene_arrays.glsl"
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

bool alpha_passes(uint prim, float u, float v);

/* With ALPHA (a scene with alpha-masked materials) a closer hit must also pass its material's
 * alpha test: where the surface is cut away the ray goes on. Mirrors R(test_triangle) in
 * src/cpu_trace_real.h. */
void test_triangle_data(ray r, uint index, vkrt_gpu_tri tri, inout hit best)
{
    float t, u, v;
    if (intersect_triangle(r, tri, t, u, v) && hit_closer(t, tri.prim_id, best.t, best.prim) &&
        (ALPHA == 0u || alpha_passes(tri.prim_id, u, v))) {
        best.t = t;
        best.u = u;
        best.v = v;
        best.tri = index;
        best.prim = tri.prim_id;
    }
}

void test_triangle(ray r, uint index, inout hit best)
{
    test_triangle_data(r, index, load_tri(index), best);
}

/* Marks a BVH traversal complete, so resume dispatches pass it by. */
void mark_finished(uint slot)
{
    if (BUDGET != 0u) states[slot].unfinished = 0u;
}

#define NO_NODE 0xFFFFFFFFu

/* Front-to-back BVH traversal as one flat loop: each iteration pops a stack entry that turns
 * out too far (it can no longer improve the closest hit), visits an interior node, or tests
 * one triangle of the current leaf (its first together with the step that reached the leaf). One loop
 * and no nested one, so a SIMD group iterates as often as its busiest lane and the budget
 * bounds exactly what lavapipe counts. With BUDGET != 0 it stops after BUDGET iterations,
 * saves its state in `slot` and returns false; a resume dispatch (p.resume) reloads the state
 * and goes on. Returns true when done (the slot then says so). Mirrors trace_bvh_f in
 * src/cpu_trace_real.h: same visiting order, pruning, ties and heat counts. */
bool trace_bvh(ray r, uint slot, inout hit best, inout heat_counts heat)
{
    uint stack_node[VKRT_TRAVERSAL_STACK_SIZE];
    float stack_tnear[VKRT_TRAVERSAL_STACK_SIZE];
    uint sp = 0u, node = NO_NODE, tri_next = 0u, tri_end = 0u;
    if (BUDGET != 0u && p.resume != 0u) {
        vkrt_gpu_resume s = states[slot];
        node = s.node;
        tri_next = s.tri_next;
        tri_end = s.tri_end;
        sp = s.sp;
        best = hit(s.t, s.u, s.v, s.tri, s.prim);
        heat = heat_counts(s.heat_nodes, s.heat_leaves, s.heat_tris);
        for (uint i = 0u; i < sp; i++) {
            vkrt_gpu_stack_entry e = saved_stack[slot * VKRT_TRAVERSAL_STACK_SIZE + i];
            stack_node[i] = e.node;
            stack_tnear[i] = uintBitsToFloat(e.word);
        }
    } else {
        float tnear;
        vkrt_gpu_node root = load_node(0u);
        if (!intersect_box(r, root.bmin, root.bmax, best.t, tnear)) {
            mark_finished(slot);
            return true;
        }
        heat.nodes++;
        if (root.tri_count != 0u) heat.leaves++;
        node = 0u;
    }
    uint steps = 0u;
    bool suspended = false;
    for (;;) {
        if (BUDGET != 0u) {
            if (steps == BUDGET) {
                suspended = true;
                break;
            }
            steps++;
        }
        if (node == NO_NODE && tri_next == tri_end) {
            if (sp == 0u) break;
            sp--;
            /* A pushed box that starts beyond the closest hit found since cannot improve it. */
            if (stack_tnear[sp] > prune_bound(best.t)) continue;
            node = stack_node[sp];
        }
        if (node != NO_NODE) {
            vkrt_gpu_node n = load_node(node);
            node = NO_NODE;
            if (n.tri_count != 0u) {
                tri_next = n.left_first;
                tri_end = n.left_first + n.tri_count;
            } else {
                uint left = n.left_first, right = left + 1u;
                vkrt_gpu_node ln = load_node(left), rn = load_node(right);
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
                bool near_r = hit_r && (!hit_l || tr < tl);
                if (hit_l && hit_r) {
                    /* Never full for a BVH within VKRT_MAX_BVH_DEPTH: one entry per level above. */
                    if (sp < VKRT_TRAVERSAL_STACK_SIZE) {
                        stack_node[sp] = near_r ? left : right;
                        stack_tnear[sp] = near_r ? tl : tr;
                        sp++;
                    }
                }
                if (!hit_l && !hit_r) continue;
                /* A leaf child's first triangle is tested in this iteration (its node is
                 * loaded already); an interior child is the next iteration's node step. */
                vkrt_gpu_node child = near_r ? rn : ln;
                if (child.tri_count == 0u) {
                    node = near_r ? right : left;
                    continue;
                }
                tri_next = child.left_first;
                tri_end = child.left_first + child.tri_count;
            }
        }
        heat.tris++;
        test_triangle(r, tri_next, best);
        tri_next++;
        /* An occlusion query is answered by the first hit. */
        if (ANYHIT != 0u && best.prim != NO_PRIM) break;
    }
    /* Saved after the loop, not inside it: lavapipe runs the body of an `if` that no lane
     * takes, and a loop in that body would count against its limit on every iteration. */
    if (BUDGET != 0u && suspended) {
        states[slot] = vkrt_gpu_resume(1u, node, tri_next, tri_end, sp, best.t, best.u, best.v, best.tri, best.prim,
                                       heat.nodes, heat.leaves, heat.tris, 0u, 0u, 0u);
        for (uint i = 0u; i < sp; i++)
            saved_stack[slot * VKRT_TRAVERSAL_STACK_SIZE + i] =
                vkrt_gpu_stack_entry(stack_node[i], floatBitsToUint(stack_tnear[i]));
        atomicAdd(unfinished, 1u);
        return false;
    }
    mark_finished(slot);
    return true;
}

/* The wide traversal's rays come from the ray buffer. Its hits go to the hit buffer in two
 * passes: the traversal records each ray's triangle (store_slot_tri), and once every ray is
 * traced the finish (finish_buffer_rays_wide) writes the whole hit. */
bool load_wide_ray(uint index, out ray r)
{
    vec4 a = uintBitsToFloat(imageLoad(ray_texels, int(2u * index)));
    vec4 b = uintBitsToFloat(imageLoad(ray_texels, int(2u * index + 1u)));
    return ray_from_buffer(vkrt_gpu_ray(a.xyz, a.w, b.xyz, b.w), r);
}

/* Triangle `tri` of the wide arrays as the wide traversal tests it: its corners and prim_id
 * (the shading fields are left zero). */
vkrt_gpu_tri load_wide_tri(uint tri, out bool last)
{
    int first = int(VKRT_WIDE_TRI_FIRST_TEXEL(tri));
    uvec4 a = imageLoad(trace_tris, first), b = imageLoad(trace_tris, first + 1), c = imageLoad(trace_tris, first + 2);
    /* An even triangle starts at a texel, an odd one half-way into one. */
    bool odd = (tri & 1u) != 0u;
    uvec3 v0 = odd ? uvec3(a.zw, b.x) : a.xyz;
    uvec3 v1 = odd ? b.yzw : uvec3(a.w, b.xy);
    uvec3 v2 = odd ? c.xyz : uvec3(b.zw, c.x);
    uint id = odd ? c.w : c.y;
    last = (id & VKRT_TRACE_TRI_LAST) != 0u;
    return vkrt_gpu_tri(uintBitsToFloat(v0), id & ~VKRT_TRACE_TRI_LAST, uintBitsToFloat(v1), 0u, uintBitsToFloat(v2), 0u,
                        vec3(0.0), 0u);
}

/* The closest triangle so far (NO_PRIM: none) of the k-th ray of ray slot `slot`, one word,
 * which the traversal stores every iteration (see trace_wide). A slot's words lie together,
 * two whole cache lines (the buffer starts on one), and one lane traces a slot at a time, so
 * no two lanes store into one line. The words were the hits' triangle words, by ray, when a
 * slot's rays lay 64 apart (wide_ray_index): four slots' rays shared a line there, and a line
 * whose rays lavapipe's two threads were tracing at once went back and forth between their
 * cores at every store; the record by slot traced 0.88-0.94x the time on primary rays and
 * 0.93-0.95x on AO rays (in-process pairs). With a slot's rays together, its hits' words are
 * its own too, but four times as many lines: 1.00-1.03x the time of this record. */
void store_slot_tri(uint slot, uint k, hit best)
{
    imageStore(slot_tris, int(slot * VKRT_WIDE_RAYS_PER_LANE + k), uvec4(best.prim != NO_PRIM ? best.tri : NO_PRIM));
}

uint load_slot_tri(uint slot, uint k)
{
    return imageLoad(slot_tris, int(slot * VKRT_WIDE_RAYS_PER_LANE + k)).x;
}

/* The triangle word of a hit (vkrt_gpu_hit.tri). */
const uint HIT_TRI_WORD = 1u;

void store_wide_hit(uint index, vkrt_gpu_hit h)
{
    int word = int(4u * index);
    imageStore(hit_words, word, uvec4(floatBitsToUint(h.t)));
    imageStore(hit_words, word + 1, uvec4(h.tri));
    imageStore(hit_words, word + 2, uvec4(floatBitsToUint(h.u)));
    imageStore(hit_words, word + 3, uvec4(floatBitsToUint(h.v)));
}

#include "traverse_wide.glsl"

/* The closest (ANYHIT: any) hit of r through the BVH: the wide one where the pipeline has it. */
bool trace_scene(ray r, uint slot, inout hit best, inout heat_counts heat)
{
    if (WIDE != 0u) return trace_wide(r, true, slot, slot, 0u, best);
    return trace_bvh(r, slot, best, heat);
}

/* In a resume dispatch: true for an invocation whose traversal is already complete. */
bool already_finished(uint slot)
{
    return BUDGET != 0u && p.resume != 0u && states[slot].unfinished == 0u;
}

#include "texture.glsl"

/* Whether a hit at barycentrics (u, v) on triangle prim is there: its material is opaque, or
 * its alpha (times the texture's) reaches the cutoff. Mirrors alpha_passes() in
 * src/cpu_trace.c. */
bool alpha_passes(uint prim, float u, float v)
{
    vkrt_gpu_surface f = load_surface(prim);
    vkrt_gpu_material m = materials[f.material];
    if (!(m.alpha_cutoff > 0.0)) return true;
    precise float alpha = m.alpha;
    if (TEXTURES != 0u && m.base_color_texture != VKRT_NO_TEXTURE)
        alpha = alpha * sample_texture(textures[m.base_color_texture], surface_uv(f, u, v)).w;
    return alpha >= m.alpha_cutoff;
}

/* The material's base colour and alpha, times its texture where it has one. Mirrors the
 * VKRT_MODE_ALBEDO case of shade() in src/cpu_trace.c. */
vec4 shade_albedo(vkrt_gpu_surface f, float u, float v)
{
    vkrt_gpu_material m = materials[f.material];
    precise vec4 colour = vec4(m.base_color, m.alpha);
    if (TEXTURES != 0u && m.base_color_texture != VKRT_NO_TEXTURE)
        colour = colour * sample_texture(textures[m.base_color_texture], surface_uv(f, u, v));
    return colour;
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
    if (MODE == VKRT_GPU_MODE_ALBEDO) return is_hit ? shade_albedo(load_surface(best.prim), best.u, best.v) : vec4(0.0);
    if (MODE == VKRT_GPU_MODE_UV) return is_hit ? vec4(surface_uv(load_surface(best.prim), best.u, best.v), 0.0, 1.0) : vec4(0.0);
    if (!is_hit) return vec4(0.0);
    return shade_normal(load_tri(best.tri), best.u, best.v);
}

/* The final closest hit of pixel (x, y): its distance refined (refine_hit_distance) where the
 * mode reports it and the device has doubles. */
void finish_pixel_hit(uint x, uint y, inout hit best)
{
#ifdef VKRT_HAS_FLOAT64
    if (MODE == VKRT_GPU_MODE_DEPTH && best.prim != NO_PRIM) {
        dvec3 origin, dir;
        camera_ray_double(p, x, y, origin, dir);
        best.t = refine_hit_distance(origin, dir, 0.0LF, double(T_INFINITY), load_tri(best.tri), best.t);
    }
#endif
}

/* The final closest hit of a ray of the buffer, its distance refined where the device has
 * doubles. */
void finish_ray_hit(ray r, inout hit best)
{
#ifdef VKRT_HAS_FLOAT64
    if (best.prim != NO_PRIM)
        best.t = refine_hit_distance(dvec3(r.origin), dvec3(r.dir), double(r.tmin), double(r.tmax), load_tri(best.tri), best.t);
#endif
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
        best.prim = load_tri(carried.tri).prim_id;
    }
}

/* Naive traversal: the closest hit so far, for the next chunk (t = +inf: none yet). */
void store_carried(uint slot, hit best)
{
    hits[slot] = vkrt_gpu_hit(best.prim != NO_PRIM ? best.t : T_INFINITY, best.tri, best.u, best.v);
}

#if VKRT_NAIVE_SHARE > 1
/* Lane k's triangle, read by every lane of the subgroup. */
#define BROADCAST_TRI(t, k)                                                                                 \
    vkrt_gpu_tri(subgroupBroadcast(t.v0, k), subgroupBroadcast(t.prim_id, k), subgroupBroadcast(t.v1, k), \
                 subgroupBroadcast(t.n0, k), subgroupBroadcast(t.v2, k), subgroupBroadcast(t.n1, k),       \
                 subgroupBroadcast(t.face_n, k), subgroupBroadcast(t.n2, k))
/* The step's k-th triangle (subgroupBroadcast takes a constant lane), for the lanes still
 * tracing; an occlusion query's lane stops at its first hit. */
#define TEST_SHARED_TRIANGLE(k)                                                          \
    if (k < VKRT_NAIVE_SHARE) {                                                          \
        uint index_k = subgroupBroadcast(mine, k);                                       \
        vkrt_gpu_tri tri_k = BROADCAST_TRI(tri, k);                                      \
        if (tracing) {                                                                   \
            test_triangle_data(r, index_k, tri_k, best);                                 \
            if (ANYHIT != 0u) tracing = best.prim == NO_PRIM;                            \
        }                                                                                \
    }
#endif

/* Naive traversal of one ray over this dispatch's chunk; an occlusion query stops at its first
 * hit (or passes a chunk by when an earlier one found it). Every invocation of the subgroup
 * calls it, `tracing` false where it has no ray (past the tile's edge or the buffer's end, or
 * an invalid ray): with VKRT_NAIVE_SHARE > 1 each step reads VKRT_NAIVE_SHARE triangles, one
 * a lane, and every lane tests all of them through subgroupBroadcast. lavapipe reads memory a
 * lane at a time inside a loop, whatever the address, so a triangle read by every lane cost
 * eight reads: shared, naive images took 0.29-0.31x the time (docs/issue7.md, the thirty-fourth session).
 * The last step's lanes past the chunk's end read its last triangle again; a second test of a
 * triangle never changes the closest hit (hit_closer), so the images stay the BVH's. */
void trace_naive_chunk(ray r, bool tracing, inout hit best)
{
    if (ANYHIT != 0u && best.prim != NO_PRIM) tracing = false;
#if VKRT_NAIVE_SHARE > 1
    for (uint base = p.tri_first; base < p.tri_end; base += VKRT_NAIVE_SHARE) {
        if (ANYHIT != 0u && !subgroupAny(tracing)) break;
        uint mine = min(base + gl_SubgroupInvocationID % VKRT_NAIVE_SHARE, p.tri_end - 1u);
        vkrt_gpu_tri tri = load_tri(mine);
        TEST_SHARED_TRIANGLE(0u) TEST_SHARED_TRIANGLE(1u) TEST_SHARED_TRIANGLE(2u) TEST_SHARED_TRIANGLE(3u)
        TEST_SHARED_TRIANGLE(4u) TEST_SHARED_TRIANGLE(5u) TEST_SHARED_TRIANGLE(6u) TEST_SHARED_TRIANGLE(7u)
    }
#else
    if (!tracing) return;
    for (uint i = p.tri_first; i < p.tri_end; i++) {
        test_triangle(r, i, best);
        if (ANYHIT != 0u && best.prim != NO_PRIM) break;
    }
#endif
}

/* vkrt_trace_rays: one ray of the buffer, its closest hit written as a vkrt_hit. The wavefront
 * variant (the lighting modes) names the triangle array index instead of prim_id, for
 * shade.comp to read, and keeps the float distance, as the CPU's wavefront mirror does. */
void trace_buffer_ray()
{
    uint index = gl_WorkGroupID.x * VKRT_TRACE_GROUP_SIZE + gl_LocalInvocationIndex;
    /* Naive traversal keeps the invocations past the buffer's end to the end of the chunk's
     * loop, which the whole subgroup runs together (trace_naive_chunk). */
    bool inside = index < p.tile_width;
    if (!inside && TRAVERSAL != VKRT_GPU_TRAVERSAL_NAIVE) return;
    ray r;
    bool valid = false;
    if (inside) valid = ray_from_buffer(rays[index], r);
    else r = ray_setup(vec3(0.0), vec3(0.0, 0.0, 1.0), 0.0, 0.0);
    hit best = hit(r.tmax, 0.0, 0.0, NO_PRIM, NO_PRIM);
    heat_counts heat = heat_counts(0u, 0u, 0u);
    if (TRAVERSAL == VKRT_GPU_TRAVERSAL_NAIVE) {
        if (inside) restore_carried(index, best);
        trace_naive_chunk(r, valid, best);
        if (!inside) return;
        if (p.last_chunk == 0u) {
            store_carried(index, best);
            return;
        }
    } else {
        if (already_finished(index)) return;
        if (!valid) {
            mark_finished(index);
        } else if (!trace_scene(r, index, best, heat)) {
            return; /* its hit is written by the dispatch that finishes it */
        }
    }
    if (RAYGEN == VKRT_GPU_RAYGEN_WAVEFRONT) {
        hits[index] = best.prim != NO_PRIM ? vkrt_gpu_hit(best.t, best.tri, best.u, best.v)
                                           : vkrt_gpu_hit(-1.0, NO_PRIM, 0.0, 0.0);
        return;
    }
    if (valid) finish_ray_hit(r, best);
    hits[index] = best.prim != NO_PRIM ? vkrt_gpu_hit(best.t, best.prim, best.u, best.v)
                                       : vkrt_gpu_hit(-1.0, NO_PRIM, 0.0, 0.0);
}

/* vkrt_trace_rays and the wavefront through the wide BVH, in two dispatches. The trace: each
 * lane takes a ray slot (WIDE_RAYS rays) and, as it finishes one, the next slot free
 * (take_ray_slot), recording each ray's closest triangle; a lane the budget stops keeps the
 * slot it was tracing in its continuation slot. */
void trace_buffer_rays_wide()
{
    uint slot = gl_WorkGroupID.x * VKRT_TRACE_GROUP_SIZE + gl_LocalInvocationIndex;
    uint rays = slot;
    if (BUDGET != 0u && p.resume != 0u) {
        if (already_finished(slot)) return;
    } else {
        rays = take_ray_slot(0u);
        if (rays == NO_SLOT || wide_ray_index(rays, 0u) >= p.tile_width) {
            mark_finished(slot);
            return;
        }
    }
    ray r;
    bool valid = load_wide_ray(wide_ray_index(rays, 0u), r);
    hit best = hit(r.tmax, 0.0, 0.0, NO_PRIM, NO_PRIM);
    trace_wide(r, valid, slot, rays, 0u, best);
}

/* The finish (FINISH), once every ray is traced: each recorded triangle tested again for the
 * distance and barycentrics (the same function on the same ray and triangle, so the same
 * bits), an invocation a slot; the buffer variant's hits become vkrt_hit: prim_id instead of
 * the triangle, the distance refined. A dispatch of its own, since a lane no longer knows which
 * slots it traced. */
void finish_buffer_rays_wide()
{
    /* A pass the budget stopped leaves its rays to the next, whose finish turns every ray's
     * triangle into its hit once: a finished hit holds prim_id, not the triangle. */
    if (unfinished != 0u) return;
    uint slot = gl_WorkGroupID.x * VKRT_TRACE_GROUP_SIZE + gl_LocalInvocationIndex;
    /* The rays that hit listed first, then the hits alone: lavapipe runs an `if`'s body for all
     * eight lanes whatever they need, but a loop only as often as its busiest lane, and most rays
     * of a view miss (71% of the primary rays of dragon_200k; 2% fewer instructions a
     * primary-ray trace). Every ray's triangle word of its hit is written here, NO_PRIM for a
     * miss, which the host makes a vkrt_hit miss as it reads the hits back (ray_chunk_collect):
     * writing a miss's four words cost lavapipe four per-lane store loops a ray (0.97-0.98x the
     * time on primary rays with one). Only the wavefront, whose hits shade.comp reads on the
     * device, gets its misses written whole. */
    uint hit_index[WIDE_RAYS], hit_tri[WIDE_RAYS];
    uint hits = 0u;
    for (uint k = 0u; k < WIDE_RAYS; k++) {
        uint index = wide_ray_index(slot, k);
        if (index >= p.tile_width) break;
        uint tri_index = load_slot_tri(slot, k);
        /* Written at the next free entry whether it hits or not, so that the store is the same
         * for every lane; only a hit moves past it. */
        hit_index[hits] = index;
        hit_tri[hits] = tri_index;
        hits += tri_index != NO_PRIM ? 1u : 0u;
        if (RAYGEN == VKRT_GPU_RAYGEN_WAVEFRONT) store_wide_hit(index, vkrt_gpu_hit(-1.0, NO_PRIM, 0.0, 0.0));
        else imageStore(hit_words, int(4u * index + HIT_TRI_WORD), uvec4(tri_index));
    }
    for (uint i = 0u; i < hits; i++) {
        uint index = hit_index[i];
        uint tri_index = hit_tri[i];
        /* From the wide arrays: lavapipe reads the triangle array (a storage buffer) a lane and
         * a word at a time, 8% of a primary-ray trace. */
        bool last;
        vkrt_gpu_tri tri = load_wide_tri(tri_index, last);
        ray r;
        load_wide_ray(index, r);
        hit again = hit(r.tmax, 0.0, 0.0, NO_PRIM, NO_PRIM);
        test_triangle_data(r, tri_index, tri, again);
        vkrt_gpu_hit h =
            vkrt_gpu_hit(again.t, RAYGEN == VKRT_GPU_RAYGEN_BUFFER ? tri.prim_id : tri_index, again.u, again.v);
#ifdef VKRT_HAS_FLOAT64
        /* finish_ray_hit's refinement, from the ray as read (r holds the buffer's origin,
         * direction and bounds as given, tmax 0 as infinity). */
        if (RAYGEN == VKRT_GPU_RAYGEN_BUFFER)
            h.t = refine_hit_distance(dvec3(r.origin), dvec3(r.dir), double(r.tmin), double(r.tmax), tri, h.t);
#endif
        store_wide_hit(index, h);
    }
}

/* The binned traversal (TRAVERSAL_BINNED, a CPU device): the triangles the host listed for ray
 * slot `index` (src/ray_bin.h), each tested with the BVH's test and tie rule, so the closest
 * hit is the wide traversal's. Every list is short (ray_bin_limits), so no loop nears
 * lavapipe's limit. */
uvec2 ray_list(uint index)
{
    return uvec2(imageLoad(ray_lists, int(2u * index)).x, imageLoad(ray_lists, int(2u * index + 1u)).x);
}

/* Tests a ray's list: its first entry and its entry count. */
void test_ray_list(ray r, uvec2 list, inout hit best)
{
    for (uint k = 0u; k < list.y; k++) {
        uint tri_index = imageLoad(list_tris, int(list.x + k)).x;
        bool last;
        test_triangle_data(r, tri_index, load_wide_tri(tri_index, last), best);
    }
}

/* vkrt_trace_rays of rays that share one origin, binned: an invocation a ray, which tests its
 * list and then does the wide finish's work for its hit in place (the refined distance; a miss
 * writes its triangle word alone). */
void trace_buffer_ray_binned()
{
    uint index = gl_WorkGroupID.x * VKRT_TRACE_GROUP_SIZE + gl_LocalInvocationIndex;
    if (index >= p.tile_width) return;
    ray r;
    load_wide_ray(index, r);
    hit best = hit(r.tmax, 0.0, 0.0, NO_PRIM, NO_PRIM);
    test_ray_list(r, ray_list(index), best);
    if (best.prim == NO_PRIM) {
        imageStore(hit_words, int(4u * index + HIT_TRI_WORD), uvec4(NO_PRIM));
        return;
    }
    vkrt_gpu_hit h = vkrt_gpu_hit(best.t, best.prim, best.u, best.v);
#ifdef VKRT_HAS_FLOAT64
    bool last;
    h.t = refine_hit_distance(dvec3(r.origin), dvec3(r.dir), double(r.tmin), double(r.tmax),
                              load_wide_tri(best.tri, last), h.t);
#endif
    store_wide_hit(index, h);
}

void main()
{
    if (TRAVERSAL == VKRT_GPU_TRAVERSAL_BINNED && RAYGEN != VKRT_GPU_RAYGEN_CAMERA) {
        trace_buffer_ray_binned();
        return;
    }
    if (RAYGEN != VKRT_GPU_RAYGEN_CAMERA && WIDE != 0u) {
        if (FINISH != 0u) finish_buffer_rays_wide();
        else trace_buffer_rays_wide();
        return;
    }
    if (RAYGEN != VKRT_GPU_RAYGEN_CAMERA) {
        trace_buffer_ray();
        return;
    }
    uvec2 local = gl_GlobalInvocationID.xy;
    /* Naive traversal keeps the invocations past the tile's edge to the end of the chunk's
     * loop, which the whole subgroup runs together (trace_naive_chunk). */
    bool inside = local.x < p.tile_width && local.y < p.tile_height;
    if (!inside && TRAVERSAL != VKRT_GPU_TRAVERSAL_NAIVE) return;
    uint x = p.tile_x + local.x, y = p.tile_y + local.y;
    hit best = hit(T_INFINITY, 0.0, 0.0, NO_PRIM, NO_PRIM);
    heat_counts heat = heat_counts(0u, 0u, 0u);

    if (TRAVERSAL == VKRT_GPU_TRAVERSAL_NAIVE) {
        heat.tris = p.tri_total;
        /* Naive heat is tri_total whatever the ray does, so the heatmap skips the tests (and
         * every chunk but the last does nothing). */
        if (MODE == VKRT_GPU_MODE_HEATMAP) {
            if (inside && p.last_chunk != 0u) imageStore(out_image, ivec2(local), shade(best, heat));
            return;
        }
        uint slot = local.y * p.tile_width + local.x;
        if (inside) restore_carried(slot, best);
        ray r = camera_ray(p, x, y);
        trace_naive_chunk(r, inside, best);
        if (!inside) return;
        if (p.last_chunk != 0u) {
            finish_pixel_hit(x, y, best);
            imageStore(out_image, ivec2(local), shade(best, heat));
        } else {
            store_carried(slot, best);
        }
        return;
    }

    uint slot = local.y * p.tile_width + local.x;
    if (TRAVERSAL == VKRT_GPU_TRAVERSAL_BINNED) {
        /* A render's camera rays, binned: the host listed each pixel's triangles from the same
         * rays (vkrt_camera_rays), slot by slot of the rectangle. A pixel with none (three in
         * four of the standard view's) is a miss without its ray. */
        uvec2 list = ray_list(slot);
        if (list.y != 0u) {
            test_ray_list(camera_ray(p, x, y), list, best);
            finish_pixel_hit(x, y, best);
        }
        imageStore(out_image, ivec2(local), shade(best, heat));
        return;
    }
    if (already_finished(slot)) return;
    ray r = camera_ray(p, x, y);
    if (trace_scene(r, slot, best, heat)) {
        if (COUNTERS != 0u) counters[slot] = vkrt_gpu_counters(heat.nodes, heat.leaves, heat.tris, 0u);
        finish_pixel_hit(x, y, best);
        imageStore(out_image, ivec2(local), shade(best, heat));
    }
}

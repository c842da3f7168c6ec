/* The float traversal of the 4-wide BVH (bvh_wide.h), a pure speed-up of the binary
 * trace_bvh_f for the CPU backend. Included by src/cpu_trace.c after the float instance of
 * cpu_trace_real.h, whose ray_f, hit_f, intersect_box_f and test_triangle_f it uses.
 *
 * Same answers as trace_bvh_f: each of a node's four child boxes is tested with
 * intersect_box_f's arithmetic and a leaf's triangles with test_triangle_f's (four boxes or
 * four watertight triangle tests at once through float4.h, operation for operation, so the
 * results are the same bits: cpu_trace_simd4.h), and the closest hit is chosen by hit_closer
 * (nearer t, then lower prim_id), which does not depend on the order boxes are visited. An
 * any-hit ray
 * may stop at another triangle than the binary traversal's (the first found differs with the
 * order), never with another hit-or-miss answer. The binary traversal's counters (boxes,
 * leaves, triangles) have no equivalent here: whoever needs them (heat map, render counters)
 * traces the binary tree, which is also what the GPU mirrors.
 *
 * Traversal as in Wald, Benthin, Boulos, "Getting Rid of Packets", RT 2008: the hit children
 * sorted by entry distance, the nearest visited next and the others pushed with their entry
 * distance, so entries beyond the closest hit found since are dropped when popped. */

#include "cpu_trace_simd4.h"

/* Entries pushed per wide node visited are at most BVH4_WIDTH - 1 and all one level below it,
 * so a tree of at most VKRT_MAX_BVH_DEPTH + 1 levels never holds more than this many. */
#define BVH4_STACK_SIZE ((BVH4_WIDTH - 1) * (VKRT_MAX_BVH_DEPTH + 1))

/* A slot to visit: an interior node (count 0, first = the node's index) or a leaf's
 * triangles [first, first + count), with its entry distance. */
typedef struct bvh4_item {
    uint32_t first, count;
    float tnear;
} bvh4_item;


/* test_triangle_f on the count triangles from first, in order; true when any_hit and one hit. */
static inline bool test_leaf_f(vkrt_intersector isect, const ray_f *r, const cpu_trace_scene *s, uint32_t first,
                               uint32_t count, hit_f *best, bool any_hit)
{
    if (isect != VKRT_INTERSECTOR_MOLLER_TRUMBORE && count > 1) {
        for (uint32_t at = first, end = first + count; at < end; at += 4) {
            const uint32_t n = end - at < 4 ? end - at : 4;
            /* Lanes past the leaf repeat its last triangle, and are ignored. */
            const vkrt_gpu_tri *const tris[4] = { &s->tris[at], &s->tris[at + (n > 1)], &s->tris[at + (n > 2 ? 2 : n - 1)],
                                                  &s->tris[at + n - 1] };
            float t[4], u[4], v[4];
            unsigned hits = watertight4(r, tris, t, u, v) & ((1u << n) - 1u);
            for (; hits; hits &= hits - 1) {
                unsigned l = lowest_slot(hits);
                uint32_t prim = tris[l]->prim_id;
                if (hit_closer_f(t[l], prim, best->t, best->prim) && (!s->alpha_tested || alpha_passes(s, prim, u[l], v[l]))) {
                    *best = (hit_f){ .t = t[l], .u = u[l], .v = v[l], .tri = at + l, .prim = prim };
                    if (any_hit) return true;
                }
            }
        }
        return false;
    }
    for (uint32_t i = first; i < first + count; i++) {
        test_triangle_f(isect, r, s, i, best);
        if (any_hit && best->prim != NO_PRIM) return true;
    }
    return false;
}

/* Asks for the first two cache lines of each of node n's children (a node, or a leaf's first
 * triangles) as soon as n is read, before its boxes are tested: the next node a ray visits is
 * one of them, and without this its fetch only starts once the test has chosen it, so every
 * level of the tree would wait for memory in turn. Always inlined: GCC drops the prefetches
 * of a helper it has not inlined (it takes the helper for one without effects). */
BVH4_INLINE void prefetch_children(const cpu_trace_scene *s, const bvh4_node *n)
{
#if defined(__GNUC__)
    for (unsigned k = 0; k < BVH4_WIDTH && n->child[k] != BVH4_EMPTY; k++) {
        const char *p = n->count[k] ? (const char *)&s->tris[n->child[k]] : (const char *)&s->wide->nodes[n->child[k]];
        /* Read, kept in every cache level (PREFETCHT0 on x86). */
        __builtin_prefetch(p, 0, 3);
        __builtin_prefetch(p + 64, 0, 3);
    }
#else
    (void)s, (void)n;
#endif
}

/* Closest (any_hit: the first found) hit of r in s->wide into *best. */
static void trace_bvh4_f(const cpu_trace_scene *s, vkrt_intersector isect, const ray_f *r, hit_f *best, bool any_hit)
{
    const bvh4 *w = s->wide;
    const vkrt_gpu_node root = { { w->root_lo[0], w->root_lo[1], w->root_lo[2] }, 0,
                                 { w->root_hi[0], w->root_hi[1], w->root_hi[2] }, 0 };
    float root_tnear;
    /* The binary traversal's first test, so a ray that misses the scene costs one box. */
    if (!intersect_box_f(r, &root, best->t, &root_tnear)) return;
    const box4_ray b = box4_ray_setup(r);
    bvh4_item stack[BVH4_STACK_SIZE];
    uint32_t sp = 0;
    bvh4_item item = { 0, 0, root_tnear };
    for (;;) {
        if (item.count != 0) {
            if (test_leaf_f(isect, r, s, item.first, item.count, best, any_hit)) return;
        } else {
            const bvh4_node *n = &w->nodes[item.first];
            prefetch_children(s, n);
            float tnear[BVH4_WIDTH];
            unsigned mask = box4_test(&b, n, best->t, tnear);
            if (mask) {
                /* The hit slots in order of entry distance (a stable insertion sort; one and two
                 * hits, the common cases, take the short ways): the nearest is visited next, the
                 * others pushed farthest first so the nearer ones come off the stack first. */
                unsigned i = lowest_slot(mask);
                bvh4_item nearest = { n->child[i], n->count[i], tnear[i] };
                if (!(mask &= mask - 1)) {
                    item = nearest;
                    continue;
                }
                i = lowest_slot(mask);
                bvh4_item second = { n->child[i], n->count[i], tnear[i] };
                if (second.tnear < nearest.tnear) {
                    bvh4_item t = nearest;
                    nearest = second, second = t;
                }
                if (!(mask &= mask - 1)) {
                    if (sp < BVH4_STACK_SIZE) stack[sp++] = second; /* never full: see BVH4_STACK_SIZE */
                    item = nearest;
                    continue;
                }
                bvh4_item hits[BVH4_WIDTH] = { nearest, second };
                uint32_t count = 2;
                for (; mask; mask &= mask - 1) {
                    i = lowest_slot(mask);
                    bvh4_item h = { n->child[i], n->count[i], tnear[i] };
                    uint32_t k = count++;
                    while (k > 0 && h.tnear < hits[k - 1].tnear) {
                        hits[k] = hits[k - 1];
                        k--;
                    }
                    hits[k] = h;
                }
                for (uint32_t k = count - 1; k > 0; k--)
                    if (sp < BVH4_STACK_SIZE) stack[sp++] = hits[k];
                item = hits[0];
                continue;
            }
        }
        /* A pushed box that starts beyond the closest hit found since cannot improve it. */
        while (sp > 0 && stack[sp - 1].tnear > prune_bound_f(best->t)) sp--;
        if (sp == 0) break;
        item = stack[--sp];
    }
}

/* Closest (or with any_hit, the first found) hit of one ray through the 4-wide BVH, as
 * trace_ray_f gives it for the binary one. */
static hit trace_ray_bvh4_f(const cpu_trace_scene *s, vkrt_intersector isect, const ray_f *r, bool any_hit)
{
    hit_f best = { .t = r->tmax, .tri = NO_PRIM, .prim = NO_PRIM };
    trace_bvh4_f(s, isect, r, &best, any_hit);
    return (hit){ .t = best.t, .u = best.u, .v = best.v, .tri = best.tri, .prim = best.prim };
}

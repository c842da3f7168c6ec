/* BVH entry point, statistics and the invariant checker shared by every builder. The builders
 * themselves live one per file (bvh_build_midpoint.c, bvh_build_sah.c, bvh_build_sbvh.c). */
#include "bvh.h"

#include "bvh_build_common.h"

#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

vkrt_result bvh_build(core *c, const mesh *m, const bvh_build_desc *desc, bvh *out)
{
    if (!out) return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "bvh_build: out is NULL");
    memset(out, 0, sizeof *out);
    if (!m) return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "bvh_build: mesh is NULL");
    bvh_build_desc d = desc ? *desc : (bvh_build_desc){ 0 };
    if (m->tri_count == 0) return core_fail(c, VKRT_ERROR_EMPTY_SCENE, "the mesh has no triangles to build a BVH over");
    if (!m->positions) return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "bvh_build: mesh positions are NULL");

    double t0 = core_now_ms();
    vkrt_result r;
    switch (d.builder) {
    case VKRT_BVH_BUILDER_DEFAULT:
    case VKRT_BVH_BUILDER_BINNED_SAH: r = bvh_build_sah(c, m, &d, out); break;
    case VKRT_BVH_BUILDER_MIDPOINT: r = bvh_build_midpoint(c, m, &d, out); break;
    case VKRT_BVH_BUILDER_SPATIAL_SAH: r = bvh_build_sbvh(c, m, &d, out); break;
    default:
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "bvh_build_desc.builder has no valid value (%d)", (int)d.builder);
    }
    if (r != VKRT_OK) return r;
    out->build_ms = core_now_ms() - t0;
    return VKRT_OK;
}

static double node_area(const vkrt_gpu_node *n)
{
    double dx = (double)n->bmax.x - n->bmin.x, dy = (double)n->bmax.y - n->bmin.y,
           dz = (double)n->bmax.z - n->bmin.z;
    return 2.0 * (dx * dy + dy * dz + dz * dx);
}

void bvh_compute_stats(const bvh *b, bvh_stats *out)
{
    memset(out, 0, sizeof *out);
    if (!b || !b->nodes || b->node_count == 0) return;
    double root_area = node_area(&b->nodes[0]);
    double interior = 0.0, leaves = 0.0;
    /* Depth-first from the root with a fixed stack: a valid tree is at most
     * VKRT_MAX_BVH_DEPTH deep, and a broken one is cut off there instead of overrunning. */
    struct { uint32_t node, depth; } stack[2 * (VKRT_MAX_BVH_DEPTH + 2)];
    uint32_t sp = 0;
    stack[sp].node = 0;
    stack[sp++].depth = 0;
    while (sp) {
        sp--;
        uint32_t i = stack[sp].node, depth = stack[sp].depth;
        const vkrt_gpu_node *n = &b->nodes[i];
        out->nodes++;
        if (depth > out->depth) out->depth = depth;
        /* A zero-area root (a single flat triangle, collinear input) would divide by zero;
         * every box inside it is then degenerate too, so each counts with weight 1. */
        double rel = root_area > 0.0 ? node_area(n) / root_area : 1.0;
        if (n->tri_count) {
            out->leaves++;
            if (n->tri_count > out->max_leaf_triangles) out->max_leaf_triangles = n->tri_count;
            uint32_t bin = n->tri_count < VKRT_LEAF_HISTOGRAM_BINS ? n->tri_count - 1 : VKRT_LEAF_HISTOGRAM_BINS - 1;
            out->leaf_histogram[bin]++;
            leaves += rel * n->tri_count;
            continue;
        }
        interior += rel;
        if (n->left_first >= b->node_count - 1 || depth >= VKRT_MAX_BVH_DEPTH + 1) continue;
        stack[sp].node = n->left_first + 1;
        stack[sp++].depth = depth + 1;
        stack[sp].node = n->left_first;
        stack[sp++].depth = depth + 1;
    }
    out->sah_cost = interior + leaves;
}

static bool fail_msg(char *message, size_t size, const char *format, ...) CORE_PRINTF(3, 4);

static bool fail_msg(char *message, size_t size, const char *format, ...)
{
    if (message && size) {
        va_list args;
        va_start(args, format);
        vsnprintf(message, size, format, args);
        va_end(args);
    }
    return false;
}

static bool box_inside(const vkrt_gpu_node *inner, const vkrt_gpu_node *outer)
{
    return inner->bmin.x >= outer->bmin.x && inner->bmin.y >= outer->bmin.y && inner->bmin.z >= outer->bmin.z &&
           inner->bmax.x <= outer->bmax.x && inner->bmax.y <= outer->bmax.y && inner->bmax.z <= outer->bmax.z;
}

static bool point_inside(const float *p, const vkrt_gpu_node *n)
{
    return p[0] >= n->bmin.x && p[1] >= n->bmin.y && p[2] >= n->bmin.z &&
           p[0] <= n->bmax.x && p[1] <= n->bmax.y && p[2] <= n->bmax.z;
}

static bool boxes_overlap(const float *bmin, const float *bmax, const vkrt_gpu_node *n)
{
    return bmin[0] <= n->bmax.x && bmin[1] <= n->bmax.y && bmin[2] <= n->bmax.z && bmax[0] >= n->bmin.x &&
           bmax[1] >= n->bmin.y && bmax[2] >= n->bmin.z;
}

/* Whether the leaf box of n holds corner `v` of the triangle at p (without spatial splits), or
 * (with them) overlaps the triangle's box: a leaf then bounds only its part of the triangle,
 * whose cover validate_parts() checks. */
static bool leaf_bounds_triangle(const bvh *b, const float *p, const vkrt_gpu_node *n, int *v)
{
    if (b->spatial_splits) {
        float bmin[3], bmax[3];
        bvh_build_tri_box(p, bmin, bmax);
        *v = -1;
        return boxes_overlap(bmin, bmax, n);
    }
    for (*v = 0; *v < 3; (*v)++)
        if (!point_inside(p + 3 * *v, n)) return false;
    return true;
}

/* The checks, given scratch flags: reached[node_count], covered[tri_count], seen[m->tri_count]. */
static bool validate_tree(const bvh *b, const mesh *m, uint8_t *reached, uint8_t *covered, uint8_t *seen,
                          char *message, size_t size)
{
    uint32_t nt = b->tri_count, mt = m->tri_count;
    for (uint32_t k = 0; k < nt; k++) {
        uint32_t t = b->tri_order[k];
        if (t >= mt) return fail_msg(message, size, "tri_order[%u] = %u is not a triangle (%u triangles)", k, t, mt);
        if (seen[t] && !b->spatial_splits)
            return fail_msg(message, size, "triangle %u appears twice in tri_order (again at position %u)", t, k);
        seen[t] = 1;
    }
    for (uint32_t t = 0; t < mt; t++)
        if (!seen[t]) return fail_msg(message, size, "triangle %u is in no leaf", t);

    struct { uint32_t node, depth; } stack[2 * (VKRT_MAX_BVH_DEPTH + 2)];
    uint32_t sp = 0, max_depth = 0;
    stack[sp].node = 0;
    stack[sp++].depth = 0;
    reached[0] = 1;
    while (sp) {
        sp--;
        uint32_t i = stack[sp].node, depth = stack[sp].depth;
        const vkrt_gpu_node *n = &b->nodes[i];
        if (depth > max_depth) max_depth = depth;
        if (!(n->bmin.x <= n->bmax.x && n->bmin.y <= n->bmax.y && n->bmin.z <= n->bmax.z))
            return fail_msg(message, size, "node %u has an empty or NaN box (%g %g %g)-(%g %g %g)", i,
                            n->bmin.x, n->bmin.y, n->bmin.z, n->bmax.x, n->bmax.y, n->bmax.z);
        if (n->tri_count) {
            if (n->left_first > nt || n->tri_count > nt - n->left_first)
                return fail_msg(message, size, "leaf %u holds positions [%u, %u + %u), beyond the %u triangles", i,
                                n->left_first, n->left_first, n->tri_count, nt);
            for (uint32_t k = n->left_first; k < n->left_first + n->tri_count; k++) {
                if (covered[k]) return fail_msg(message, size, "position %u of tri_order is in two leaves (again in leaf %u)", k, i);
                covered[k] = 1;
                for (uint32_t j = n->left_first; j < k; j++)
                    if (b->tri_order[j] == b->tri_order[k])
                        return fail_msg(message, size, "leaf %u holds triangle %u twice", i, b->tri_order[k]);
                const float *p = m->positions + (size_t)b->tri_order[k] * 9;
                int v;
                if (!leaf_bounds_triangle(b, p, n, &v)) {
                    if (v < 0)
                        return fail_msg(message, size, "leaf %u box (%g %g %g)-(%g %g %g) does not touch triangle %u", i,
                                        n->bmin.x, n->bmin.y, n->bmin.z, n->bmax.x, n->bmax.y, n->bmax.z,
                                        b->tri_order[k]);
                    return fail_msg(message, size, "leaf %u box (%g %g %g)-(%g %g %g) misses corner %d (%g %g %g) of triangle %u",
                                    i, n->bmin.x, n->bmin.y, n->bmin.z, n->bmax.x, n->bmax.y, n->bmax.z, v,
                                    p[3 * v], p[3 * v + 1], p[3 * v + 2], b->tri_order[k]);
                }
            }
            continue;
        }
        if (n->left_first == 0 || n->left_first >= b->node_count - 1)
            return fail_msg(message, size, "interior node %u has children %u and %u, outside [1, %u)", i, n->left_first,
                            n->left_first + 1, b->node_count);
        if (depth + 1 > VKRT_MAX_BVH_DEPTH)
            return fail_msg(message, size, "node %u at depth %u has children, deeper than VKRT_MAX_BVH_DEPTH (%d)", i,
                            depth, VKRT_MAX_BVH_DEPTH);
        for (uint32_t ch = n->left_first; ch <= n->left_first + 1; ch++) {
            if (reached[ch]) return fail_msg(message, size, "node %u is reached twice (again as a child of node %u)", ch, i);
            reached[ch] = 1;
            const vkrt_gpu_node *cn = &b->nodes[ch];
            if (!box_inside(cn, n))
                return fail_msg(message, size, "child %u box (%g %g %g)-(%g %g %g) is not inside parent %u box (%g %g %g)-(%g %g %g)",
                                ch, cn->bmin.x, cn->bmin.y, cn->bmin.z, cn->bmax.x, cn->bmax.y, cn->bmax.z, i,
                                n->bmin.x, n->bmin.y, n->bmin.z, n->bmax.x, n->bmax.y, n->bmax.z);
            stack[sp].node = ch;
            stack[sp++].depth = depth + 1;
        }
    }
    for (uint32_t i = 0; i < b->node_count; i++)
        if (!reached[i]) return fail_msg(message, size, "node %u is not reachable from the root", i);
    for (uint32_t k = 0; k < nt; k++)
        if (!covered[k]) return fail_msg(message, size, "position %u of tri_order is in no leaf", k);
    if (max_depth != b->depth)
        return fail_msg(message, size, "the tree is %u deep but bvh.depth says %u", max_depth, b->depth);
    return true;
}

/* Points of a triangle checked for cover: a barycentric grid of this many steps a side. */
#define PART_GRID 4

/* With spatial splits, where a leaf bounds only part of a triangle: every point of each
 * triangle lies in the box of some leaf holding it, checked at its corners and a barycentric
 * grid over it (edges and interior), each point allowed 4 ulps of the triangle's coordinates,
 * what computing it in float may be off by. */
static bool validate_parts(core *scratch, const bvh *b, const mesh *m, char *message, size_t size)
{
    uint32_t nt = b->tri_count, mt = m->tri_count;
    uint32_t *leaf_of = core_alloc_array(scratch, nt, sizeof *leaf_of);
    uint32_t *by_tri = core_alloc_array(scratch, nt, sizeof *by_tri);
    uint32_t *start = core_calloc_array(scratch, (size_t)mt + 1, sizeof *start);
    bool ok = leaf_of && by_tri && start;
    if (!ok) fail_msg(message, size, "out of memory validating the BVH");
    for (uint32_t i = 0; ok && i < b->node_count; i++) {
        const vkrt_gpu_node *n = &b->nodes[i];
        for (uint32_t k = n->left_first; n->tri_count && k < n->left_first + n->tri_count; k++) leaf_of[k] = i;
    }
    for (uint32_t k = 0; ok && k < nt; k++) start[b->tri_order[k] + 1]++;
    for (uint32_t t = 0; ok && t < mt; t++) start[t + 1] += start[t];
    for (uint32_t k = 0; ok && k < nt; k++) by_tri[start[b->tri_order[k]]++] = leaf_of[k];
    /* start[t] is now where triangle t + 1's leaves begin. */
    for (uint32_t t = 0; ok && t < mt; t++) {
        const float *p = m->positions + (size_t)t * 9;
        uint32_t first = t ? start[t - 1] : 0, end = start[t];
        double tol[3];
        for (int a = 0; a < 3; a++)
            tol[a] = 4.0 * FLT_EPSILON * fmax(fabs(p[a]), fmax(fabs(p[3 + a]), fabs(p[6 + a])));
        for (int i = 0; ok && i <= PART_GRID; i++) {
            for (int j = 0; ok && i + j <= PART_GRID; j++) {
                double w1 = (double)i / PART_GRID, w2 = (double)j / PART_GRID, q[3];
                for (int a = 0; a < 3; a++) q[a] = p[a] + w1 * ((double)p[3 + a] - p[a]) + w2 * ((double)p[6 + a] - p[a]);
                bool inside = false;
                for (uint32_t k = first; k < end && !inside; k++) {
                    const vkrt_gpu_node *n = &b->nodes[by_tri[k]];
                    const double lo[3] = { n->bmin.x, n->bmin.y, n->bmin.z }, hi[3] = { n->bmax.x, n->bmax.y, n->bmax.z };
                    inside = true;
                    for (int a = 0; a < 3; a++) inside = inside && q[a] >= lo[a] - tol[a] && q[a] <= hi[a] + tol[a];
                }
                if (!inside)
                    ok = fail_msg(message, size, "point (%g %g %g) of triangle %u is in none of the boxes of its %u leaves",
                                  q[0], q[1], q[2], t, end - first);
            }
        }
    }
    core_free(scratch, leaf_of);
    core_free(scratch, by_tri);
    core_free(scratch, start);
    return ok;
}

bool bvh_validate(const bvh *b, const mesh *m, char *message, size_t message_size)
{
    if (message && message_size) message[0] = '\0';
    if (!b || !m) return fail_msg(message, message_size, "bvh or mesh is NULL");
    if (!b->nodes || b->node_count == 0) return fail_msg(message, message_size, "the BVH has no nodes");
    if (!b->tri_order) return fail_msg(message, message_size, "the BVH has no triangle order");
    if (b->spatial_splits ? b->tri_count < m->tri_count : b->tri_count != m->tri_count)
        return fail_msg(message, message_size, "the BVH holds %u triangles, the mesh %u", b->tri_count, m->tri_count);
    if (b->depth > VKRT_MAX_BVH_DEPTH)
        return fail_msg(message, message_size, "depth %u exceeds VKRT_MAX_BVH_DEPTH (%d)", b->depth, VKRT_MAX_BVH_DEPTH);

    /* bvh_validate() takes no allocator (it is a test and debugging aid), so it uses the
     * default one through core like every other allocation of the library. */
    core scratch;
    core_init(&scratch, NULL, NULL, NULL);
    size_t bytes = (size_t)b->node_count + (size_t)b->tri_count + m->tri_count;
    uint8_t *flags = core_calloc_array(&scratch, bytes, 1);
    if (!flags) return fail_msg(message, message_size, "out of memory validating the BVH");
    bool ok = validate_tree(b, m, flags, flags + b->node_count, flags + b->node_count + b->tri_count, message,
                            message_size);
    core_free(&scratch, flags);
    if (ok && b->spatial_splits) ok = validate_parts(&scratch, b, m, message, message_size);
    return ok;
}

void bvh_destroy(core *c, bvh *b)
{
    if (!b) return;
    core_free(c, b->nodes);
    core_free(c, b->tri_order);
    memset(b, 0, sizeof *b);
}

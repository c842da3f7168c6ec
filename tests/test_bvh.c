/* test_bvh: both BVH builders keep the layout invariants the GPU relies on (bvh_validate),
 * boxes are exact, statistics are consistent, degenerate input terminates with a bounded
 * depth, max_leaf_size holds, cancellation and out-of-memory leave nothing behind; the SAH
 * builder's BVH is the same on any number of threads; and the same on every mesh of the shared
 * model set. Every tree built here is also collapsed 4-wide (bvh_wide.h) and checked against
 * itself, and the GPU's quantised wide nodes (wide_pack.h) decode to boxes that hold their
 * children with not a step to spare. */
#include <dirent.h>
#include <float.h>
#include <malloc.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bvh.h"
#include "bvh_build_sah.h"
#include "bvh_wide.h"
#include "check.h"
#include "core.h"
#include "huge_pages.h"
#include "mesh.h"
#include "scene_pack.h"
#include "wide_pack.h"

static const vkrt_bvh_builder builders[] = { VKRT_BVH_BUILDER_MIDPOINT, VKRT_BVH_BUILDER_BINNED_SAH,
                                              VKRT_BVH_BUILDER_SPATIAL_SAH };
static const char *const builder_names[] = { "midpoint", "sah", "sbvh" };
#define BUILDER_COUNT 3

/* ---- synthetic meshes ---------------------------------------------------------------- */

static void test_mesh_free(core *c, mesh *m)
{
    core_free(c, m->positions);
    core_free(c, m->normals);
    memset(m, 0, sizeof *m);
}

static mesh test_mesh_new(core *c, uint32_t tri_count)
{
    mesh m = { 0 };
    m.tri_count = tri_count;
    m.tri_capacity = tri_count;
    m.positions = core_calloc_array(c, (size_t)tri_count * 9, sizeof(float));
    m.normals = core_calloc_array(c, (size_t)tri_count * 9, sizeof(float));
    if (!m.positions || !m.normals) {
        fprintf(stderr, "out of memory making a test mesh of %u triangles\n", tri_count);
        exit(2);
    }
    for (size_t i = 0; i < (size_t)tri_count * 3; i++) m.normals[i * 3 + 2] = 1.0f;
    return m;
}

static void set_tri(mesh *m, uint32_t i, float ax, float ay, float az, float bx, float by, float bz, float cx,
                    float cy, float cz)
{
    float *p = m->positions + (size_t)i * 9;
    p[0] = ax, p[1] = ay, p[2] = az;
    p[3] = bx, p[4] = by, p[5] = bz;
    p[6] = cx, p[7] = cy, p[8] = cz;
}

static void update_bounds(mesh *m)
{
    for (int a = 0; a < 3; a++) {
        m->bounds_min[a] = FLT_MAX;
        m->bounds_max[a] = -FLT_MAX;
    }
    for (size_t i = 0; i < (size_t)m->tri_count * 3; i++)
        for (int a = 0; a < 3; a++) {
            float v = m->positions[i * 3 + a];
            if (v < m->bounds_min[a]) m->bounds_min[a] = v;
            if (v > m->bounds_max[a]) m->bounds_max[a] = v;
        }
}

static uint32_t rng_state = 12345u;
static float frand(void) /* [0, 1), deterministic */
{
    rng_state = rng_state * 1664525u + 1013904223u;
    return (float)(rng_state >> 8) / 16777216.0f;
}

static mesh make_random(core *c, uint32_t n)
{
    mesh m = test_mesh_new(c, n);
    for (uint32_t i = 0; i < n; i++) {
        float x = frand() * 10.0f, y = frand() * 10.0f, z = frand() * 10.0f;
        set_tri(&m, i, x, y, z, x + frand() * 0.5f, y + frand() * 0.5f, z, x, y + frand() * 0.5f, z + frand() * 0.5f);
    }
    update_bounds(&m);
    return m;
}

/* ---- checks shared by the tests ------------------------------------------------------ */

static void box_of_tris(const bvh *b, const mesh *m, uint32_t first, uint32_t count, float *bmin, float *bmax)
{
    for (int a = 0; a < 3; a++) {
        bmin[a] = FLT_MAX;
        bmax[a] = -FLT_MAX;
    }
    for (uint32_t k = first; k < first + count; k++) {
        const float *p = m->positions + (size_t)b->tri_order[k] * 9;
        for (int v = 0; v < 9; v++) {
            if (p[v] < bmin[v % 3]) bmin[v % 3] = p[v];
            if (p[v] > bmax[v % 3]) bmax[v % 3] = p[v];
        }
    }
}

static bool same_box(const vkrt_gpu_node *n, const float *bmin, const float *bmax)
{
    return n->bmin.x == bmin[0] && n->bmin.y == bmin[1] && n->bmin.z == bmin[2] && n->bmax.x == bmax[0] &&
           n->bmax.y == bmax[1] && n->bmax.z == bmax[2];
}

static bool box_within(const vkrt_gpu_node *n, const float *bmin, const float *bmax)
{
    return n->bmin.x >= bmin[0] && n->bmin.y >= bmin[1] && n->bmin.z >= bmin[2] && n->bmax.x <= bmax[0] &&
           n->bmax.y <= bmax[1] && n->bmax.z <= bmax[2];
}

/* Every leaf box is exactly the bounds of its triangles' corners and every interior box
 * exactly the union of its children's, so by induction every box is exact. With spatial
 * splits a leaf bounds its triangles' parts: within their corners' bounds (bvh_validate checks
 * that it covers the parts). */
static void check_exact_boxes(const char *what, const bvh *b, const mesh *m)
{
    int reported = 0;
    for (uint32_t i = 0; i < b->node_count && reported < 3; i++) {
        const vkrt_gpu_node *n = &b->nodes[i];
        float bmin[3], bmax[3];
        if (n->tri_count) {
            box_of_tris(b, m, n->left_first, n->tri_count, bmin, bmax);
            if (b->spatial_splits) {
                bool ok = box_within(n, bmin, bmax);
                CHECK_MSG(ok, "%s: leaf %u box reaches beyond its triangles' corners", what, i);
                if (!ok) reported++;
                continue;
            }
        } else {
            const vkrt_gpu_node *l = &b->nodes[n->left_first], *r = &b->nodes[n->left_first + 1];
            bmin[0] = fminf(l->bmin.x, r->bmin.x), bmin[1] = fminf(l->bmin.y, r->bmin.y), bmin[2] = fminf(l->bmin.z, r->bmin.z);
            bmax[0] = fmaxf(l->bmax.x, r->bmax.x), bmax[1] = fmaxf(l->bmax.y, r->bmax.y), bmax[2] = fmaxf(l->bmax.z, r->bmax.z);
        }
        bool ok = same_box(n, bmin, bmax);
        CHECK_MSG(ok, "%s: node %u box is not the exact bounds of its contents", what, i);
        if (!ok) reported++;
    }
}

/* Statistics agree with a direct count over the node array. */
static void check_stats(const char *what, const bvh *b, const bvh_stats *s)
{
    uint64_t leaves = 0, tris = 0, hist[VKRT_LEAF_HISTOGRAM_BINS] = { 0 };
    uint32_t max_leaf = 0;
    for (uint32_t i = 0; i < b->node_count; i++) {
        uint32_t t = b->nodes[i].tri_count;
        if (!t) continue;
        leaves++;
        tris += t;
        if (t > max_leaf) max_leaf = t;
        hist[t < VKRT_LEAF_HISTOGRAM_BINS ? t - 1 : VKRT_LEAF_HISTOGRAM_BINS - 1]++;
    }
    uint64_t hist_sum = 0;
    for (int i = 0; i < VKRT_LEAF_HISTOGRAM_BINS; i++) {
        hist_sum += s->leaf_histogram[i];
        CHECK_MSG(s->leaf_histogram[i] == hist[i], "%s: histogram bin %d is %llu, counted %llu", what, i,
                  (unsigned long long)s->leaf_histogram[i], (unsigned long long)hist[i]);
    }
    CHECK_MSG(hist_sum == s->leaves, "%s: histogram sums to %llu, leaves %llu", what, (unsigned long long)hist_sum,
              (unsigned long long)s->leaves);
    CHECK_MSG(s->leaves == leaves, "%s: stats leaves %llu, counted %llu", what, (unsigned long long)s->leaves,
              (unsigned long long)leaves);
    CHECK_MSG(tris == b->tri_count, "%s: leaves hold %llu triangles, mesh %u", what, (unsigned long long)tris, b->tri_count);
    CHECK_MSG(s->nodes == 2 * s->leaves - 1, "%s: %llu nodes for %llu leaves", what, (unsigned long long)s->nodes,
              (unsigned long long)s->leaves);
    CHECK_MSG(s->nodes == b->node_count, "%s: stats nodes %llu, node_count %u", what, (unsigned long long)s->nodes,
              b->node_count);
    CHECK_MSG(s->depth == b->depth, "%s: stats depth %u, bvh depth %u", what, s->depth, b->depth);
    CHECK_MSG(s->max_leaf_triangles == max_leaf, "%s: max leaf %u, counted %u", what, s->max_leaf_triangles, max_leaf);
    CHECK_MSG(b->depth <= VKRT_MAX_BVH_DEPTH, "%s: depth %u", what, b->depth);
    CHECK_MSG(isfinite(s->sah_cost) && s->sah_cost >= 1.0 - 1e-9 * (double)s->nodes, "%s: SAH cost %g", what, s->sah_cost);
}

static bool same_bits(float a, float b) { return memcmp(&a, &b, sizeof a) == 0; }

/* The 4-wide collapse of b: every wide node reached once from the root, used slots first,
 * unused ones BVH4_EMPTY with count 0 and the empty box; each leaf slot is one of b's nodes
 * (a leaf, or an interior node over at most BVH4_LEAF_MERGE triangles in one run: same
 * triangles, box copied bit for bit), each binary leaf under exactly one slot, so every
 * triangle is reached exactly once; no interior slot leads to triangles that could have been
 * merged; an interior slot's box is exactly the union of its child's slot boxes (as b's boxes
 * are of their children's), so it is the binary node's box; a node with a free slot has only
 * leaves (the collapse opens interior children while it can); depth counts the levels and
 * never exceeds b's. */
static void check_bvh4(core *c, const char *what, const bvh *b)
{
    bvh4 w;
    vkrt_result r = bvh4_collapse(c, b, &w);
    CHECK_MSG(r == VKRT_OK, "%s: bvh4_collapse: %s (%s)", what, vkrt_result_string(r), c->last_error);
    if (r != VKRT_OK) return;
    CHECK_MSG(((uintptr_t)w.nodes & 63) == 0, "%s: the 4-wide nodes are not 64-byte aligned", what);
    uint32_t interior = 0;
    for (uint32_t i = 0; i < b->node_count; i++) interior += b->nodes[i].tri_count == 0;
    CHECK_MSG(w.node_count >= 1 && w.node_count <= (interior ? interior : 1), "%s: %u wide nodes for %u interior",
              what, w.node_count, interior);
    const vkrt_gpu_node *root = &b->nodes[0];
    CHECK(same_bits(w.root_lo[0], root->bmin.x) && same_bits(w.root_lo[1], root->bmin.y) &&
          same_bits(w.root_lo[2], root->bmin.z) && same_bits(w.root_hi[0], root->bmax.x) &&
          same_bits(w.root_hi[1], root->bmax.y) && same_bits(w.root_hi[2], root->bmax.z));
    /* Each binary node's triangles: lowest position, count, and whether they are one run
     * (children follow their parents in b's array, so one backward pass fills them). */
    uint32_t *sub_first = calloc(b->node_count, sizeof *sub_first), *sub_count = calloc(b->node_count, sizeof *sub_count);
    uint8_t *sub_run = calloc(b->node_count, 1);
    if (!sub_first || !sub_count || !sub_run) abort();
    for (uint32_t i = b->node_count; i-- > 0;) {
        const vkrt_gpu_node *n = &b->nodes[i];
        if (n->tri_count) {
            sub_first[i] = n->left_first, sub_count[i] = n->tri_count, sub_run[i] = 1;
            continue;
        }
        uint32_t l = n->left_first, right = l + 1;
        CHECK_MSG(l > i, "%s: binary node %u's children come before it", what, i);
        /* A spatial-split subtree may hold its right child's triangles first. */
        uint32_t lower = sub_first[l] < sub_first[right] ? l : right, upper = lower == l ? right : l;
        sub_first[i] = sub_first[lower], sub_count[i] = sub_count[l] + sub_count[right];
        sub_run[i] = sub_run[l] && sub_run[right] && sub_first[lower] + sub_count[lower] == sub_first[upper];
    }
    /* node_at[4 k + c - 1]: the binary node whose c <= 4 triangles start at position k in one
     * run (0: none; the root is never a slot, and a root leaf is looked up as node 0 below);
     * leaf_at[k]: the binary leaf whose triangles start at k. */
    uint32_t *node_at = calloc((size_t)b->tri_count * BVH4_LEAF_MERGE, sizeof *node_at);
    uint32_t *leaf_at = calloc(b->tri_count, sizeof *leaf_at);
    uint8_t *leaf_used = calloc(b->node_count, 1), *node_seen = calloc(w.node_count, 1);
    if (!node_at || !leaf_at || !leaf_used || !node_seen) abort();
    for (uint32_t i = 1; i < b->node_count; i++) {
        if (b->nodes[i].tri_count) leaf_at[b->nodes[i].left_first] = i;
        if (sub_run[i] && sub_count[i] <= BVH4_LEAF_MERGE) node_at[sub_first[i] * BVH4_LEAF_MERGE + sub_count[i] - 1] = i;
    }
    struct { uint32_t node, level; float lo[3], hi[3]; } stack[BVH4_WIDTH * (VKRT_MAX_BVH_DEPTH + 2)];
    uint32_t sp = 0, levels = 0, errors = 0;
    stack[sp].node = 0, stack[sp].level = 1;
    memcpy(stack[sp].lo, w.root_lo, sizeof w.root_lo);
    memcpy(stack[sp++].hi, w.root_hi, sizeof w.root_hi);
    while (sp && errors < 3) {
        sp--;
        uint32_t i = stack[sp].node, level = stack[sp].level;
        float plo[3], phi[3];
        memcpy(plo, stack[sp].lo, sizeof plo);
        memcpy(phi, stack[sp].hi, sizeof phi);
        if (i >= w.node_count || node_seen[i]) {
            CHECK_MSG(0, "%s: wide node %u is out of range or reached twice", what, i);
            errors++;
            continue;
        }
        node_seen[i] = 1;
        if (level > levels) levels = level;
        const bvh4_node *n = &w.nodes[i];
        uint32_t used = 0;
        bool has_interior = false;
        float ulo[3] = { INFINITY, INFINITY, INFINITY }, uhi[3] = { -INFINITY, -INFINITY, -INFINITY };
        for (uint32_t k = 0; k < BVH4_WIDTH; k++) {
            if (n->child[k] == BVH4_EMPTY) {
                bool empty_box = true;
                for (int a = 0; a < 3; a++) empty_box &= n->lo[a][k] == INFINITY && n->hi[a][k] == -INFINITY;
                CHECK_MSG(n->count[k] == 0 && empty_box, "%s: unused slot %u of wide node %u has count %u or a box", what,
                          k, i, n->count[k]);
                continue;
            }
            if (used++ != k) {
                CHECK_MSG(0, "%s: wide node %u uses slot %u after an unused one", what, i, k);
                errors++;
            }
            for (int a = 0; a < 3; a++) {
                ulo[a] = fminf(ulo[a], n->lo[a][k]);
                uhi[a] = fmaxf(uhi[a], n->hi[a][k]);
            }
            if (n->count[k] == 0) {
                has_interior = true;
                stack[sp].node = n->child[k], stack[sp].level = level + 1;
                for (int a = 0; a < 3; a++) stack[sp].lo[a] = n->lo[a][k], stack[sp].hi[a] = n->hi[a][k];
                sp++;
                continue;
            }
            uint32_t first = n->child[k], count = n->count[k], from = 0;
            if (first < b->tri_count && count <= BVH4_LEAF_MERGE) from = node_at[first * BVH4_LEAF_MERGE + count - 1];
            else if (first < b->tri_count && b->nodes[leaf_at[first]].tri_count == count) from = leaf_at[first];
            const vkrt_gpu_node *l = &b->nodes[from];
            bool same = sub_first[from] == first && sub_count[from] == count && same_bits(n->lo[0][k], l->bmin.x) &&
                        same_bits(n->lo[1][k], l->bmin.y) && same_bits(n->lo[2][k], l->bmin.z) &&
                        same_bits(n->hi[0][k], l->bmax.x) && same_bits(n->hi[1][k], l->bmax.y) &&
                        same_bits(n->hi[2][k], l->bmax.z);
            /* Every binary leaf under the slot's node, each in this slot alone. */
            uint32_t under[VKRT_MAX_BVH_DEPTH + 2], depth = 0;
            under[depth++] = from;
            while (same && depth) {
                const vkrt_gpu_node *u = &b->nodes[under[--depth]];
                if (u->tri_count == 0) {
                    under[depth++] = u->left_first, under[depth++] = u->left_first + 1;
                    continue;
                }
                uint32_t leaf = (uint32_t)(u - b->nodes);
                same = !leaf_used[leaf];
                leaf_used[leaf] = 1;
            }
            CHECK_MSG(same, "%s: leaf slot %u of wide node %u (triangles %u + %u) is no binary leaf or small subtree, "
                      "or shares a leaf with another slot", what, k, i, first, count);
            errors += !same;
        }
        CHECK_MSG(used >= (i == 0 && root->tri_count ? 1u : 2u), "%s: wide node %u uses %u slots", what, i, used);
        CHECK_MSG(used == BVH4_WIDTH || !has_interior, "%s: wide node %u has a free slot and an interior child", what, i);
        bool encloses = true;
        for (int a = 0; a < 3; a++) encloses &= ulo[a] == plo[a] && uhi[a] == phi[a];
        CHECK_MSG(encloses, "%s: wide node %u's slots do not make up its parent's box", what, i);
        errors += !encloses;
    }
    for (uint32_t i = 0; i < w.node_count; i++) CHECK_MSG(node_seen[i], "%s: wide node %u is unreachable", what, i);
    /* The triangles under each wide node (children follow their parents here too): none that
     * the collapse should have merged into a leaf stands behind an interior slot. */
    uint32_t *wide_first = calloc(w.node_count, sizeof *wide_first), *wide_count = calloc(w.node_count, sizeof *wide_count);
    uint8_t *wide_run = calloc(w.node_count, 1);
    if (!wide_first || !wide_count || !wide_run) abort();
    for (uint32_t i = w.node_count; errors == 0 && i-- > 0;) {
        const bvh4_node *n = &w.nodes[i];
        uint32_t lo = UINT32_MAX, hi = 0, total = 0;
        bool runs = true;
        for (uint32_t k = 0; k < BVH4_WIDTH && n->child[k] != BVH4_EMPTY; k++) {
            uint32_t first = n->child[k], count = n->count[k];
            if (count == 0) {
                CHECK_MSG(n->child[k] > i, "%s: wide node %u's child %u comes before it", what, i, n->child[k]);
                bool mergeable = wide_run[first] && wide_count[first] <= BVH4_LEAF_MERGE;
                CHECK_MSG(!mergeable, "%s: slot %u of wide node %u leads to %u triangles in one run, not merged", what, k,
                          i, wide_count[first]);
                runs &= wide_run[first] != 0;
                count = wide_count[first];
                first = wide_first[first];
            }
            lo = first < lo ? first : lo;
            hi = first + count > hi ? first + count : hi;
            total += count;
        }
        wide_first[i] = lo, wide_count[i] = total, wide_run[i] = runs && hi - lo == total;
    }
    for (uint32_t i = 0; i < b->node_count; i++)
        if (b->nodes[i].tri_count) CHECK_MSG(leaf_used[i], "%s: binary leaf %u is in no wide slot", what, i);
    CHECK_MSG(w.depth == levels && w.depth <= (b->depth ? b->depth : 1), "%s: wide depth %u, %u levels, binary %u",
              what, w.depth, levels, b->depth);
    free(wide_first);
    free(wide_count);
    free(wide_run);
    free(sub_first);
    free(sub_count);
    free(sub_run);
    free(node_at);
    free(leaf_at);
    free(leaf_used);
    free(node_seen);
    bvh4_destroy(c, &w);
    CHECK(w.nodes == NULL && w.node_count == 0);
}

/* Builds, validates, checks boxes and statistics and the 4-wide collapse; the tree is left in
 * *out (destroy it). */
static vkrt_result build_checked(core *c, const char *what, const mesh *m, vkrt_bvh_builder builder,
                                 uint32_t max_leaf, uint32_t threads, bvh *out, bvh_stats *stats)
{
    vkrt_result r = bvh_build(c, m, &(bvh_build_desc){ .builder = builder, .max_leaf_size = max_leaf, .threads = threads }, out);
    CHECK_MSG(r == VKRT_OK, "%s: bvh_build: %s (%s)", what, vkrt_result_string(r), c->last_error);
    if (r != VKRT_OK) return r;
    char message[512];
    bool valid = bvh_validate(out, m, message, sizeof message);
    CHECK_MSG(valid, "%s: %s", what, message);
    CHECK_MSG(out->build_ms >= 0.0, "%s: build_ms %g", what, out->build_ms);
    if (valid) {
        check_exact_boxes(what, out, m);
        bvh_compute_stats(out, stats);
        check_stats(what, out, stats);
        check_bvh4(c, what, out);
    } else {
        memset(stats, 0, sizeof *stats);
    }
    return r;
}

/* The SAH builder leaves more than max_leaf triangles in a leaf only where no split exists
 * (all centroids equal, the centres of the triangles' boxes) or at the depth cap. */
static void check_leaf_limit(const char *what, const bvh *b, const mesh *m, uint32_t max_leaf)
{
    int reported = 0;
    struct { uint32_t node, depth; } stack[2 * (VKRT_MAX_BVH_DEPTH + 2)];
    uint32_t sp = 0;
    stack[sp].node = 0;
    stack[sp++].depth = 0;
    while (sp && reported < 3) {
        sp--;
        uint32_t i = stack[sp].node, depth = stack[sp].depth;
        const vkrt_gpu_node *n = &b->nodes[i];
        if (!n->tri_count) {
            stack[sp].node = n->left_first;
            stack[sp++].depth = depth + 1;
            stack[sp].node = n->left_first + 1;
            stack[sp++].depth = depth + 1;
            continue;
        }
        if (n->tri_count <= max_leaf || depth == VKRT_MAX_BVH_DEPTH) continue;
        float c0[3] = { 0 };
        bool all_equal = true;
        for (uint32_t k = n->left_first; k < n->left_first + n->tri_count; k++) {
            float bmin[3], bmax[3];
            box_of_tris(b, m, k, 1, bmin, bmax);
            for (int a = 0; a < 3; a++) {
                float cen = 0.5f * (bmin[a] + bmax[a]);
                if (k == n->left_first) c0[a] = cen;
                else if (cen != c0[a]) all_equal = false;
            }
        }
        CHECK_MSG(all_equal, "%s: leaf %u holds %u > %u triangles that a split could separate", what, i,
                  n->tri_count, max_leaf);
        if (!all_equal) reported++;
    }
}

/* ---- allocator that counts and fails on request ------------------------------------- */

typedef struct counting {
    uint64_t calls, allocs, frees;
    uint64_t fail_at; /* 0: never; else the call number that returns NULL */
} counting;

static void *counting_alloc(void *user, size_t size)
{
    counting *k = user;
    k->calls++;
    if (k->fail_at && k->calls == k->fail_at) return NULL;
    void *p = malloc(size);
    if (p) k->allocs++;
    return p;
}

static void counting_free(void *user, void *p)
{
    counting *k = user;
    k->frees++;
    free(p);
}

/* ---- tests --------------------------------------------------------------------------- */

static void bvh_empty_mesh_is_empty_scene(void)
{
    core c;
    core_init(&c, NULL, NULL, NULL);
    mesh m = { 0 };
    for (int b = 0; b < BUILDER_COUNT; b++) {
        bvh out;
        memset(&out, 0xab, sizeof out);
        vkrt_result r = bvh_build(&c, &m, &(bvh_build_desc){ .builder = builders[b] }, &out);
        CHECK_MSG(r == VKRT_ERROR_EMPTY_SCENE, "%s: %s", builder_names[b], vkrt_result_string(r));
        CHECK(out.nodes == NULL && out.tri_order == NULL && out.node_count == 0);
        CHECK(c.last_error[0] != '\0');
        bvh_destroy(&c, &out);
    }
}

static void bvh_unknown_builder_is_invalid_argument(void)
{
    core c;
    core_init(&c, NULL, NULL, NULL);
    mesh m = make_random(&c, 10);
    bvh out;
    vkrt_result r = bvh_build(&c, &m, &(bvh_build_desc){ .builder = (vkrt_bvh_builder)77 }, &out);
    CHECK(r == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(out.nodes == NULL);
    CHECK(strstr(c.last_error, "builder") != NULL);
    /* A NULL desc means every default: binned SAH. */
    r = bvh_build(&c, &m, NULL, &out);
    CHECK(r == VKRT_OK);
    bvh_destroy(&c, &out);
    bvh_destroy(&c, NULL);
    test_mesh_free(&c, &m);
}

static void bvh_single_triangle_is_one_leaf_root(void)
{
    core c;
    core_init(&c, NULL, NULL, NULL);
    mesh m = test_mesh_new(&c, 1);
    set_tri(&m, 0, 0, 0, 0, 1, 0, 0, 0, 2, 3);
    for (int b = 0; b < BUILDER_COUNT; b++) {
        bvh out;
        bvh_stats s;
        if (build_checked(&c, builder_names[b], &m, builders[b], 0, 0, &out, &s) != VKRT_OK) continue;
        CHECK_EQ_U64(out.node_count, 1);
        CHECK_EQ_U64(out.nodes[0].tri_count, 1);
        CHECK_EQ_U64(out.nodes[0].left_first, 0);
        CHECK_EQ_U64(out.depth, 0);
        CHECK(out.nodes[0].bmin.x == 0 && out.nodes[0].bmin.y == 0 && out.nodes[0].bmin.z == 0);
        CHECK(out.nodes[0].bmax.x == 1 && out.nodes[0].bmax.y == 2 && out.nodes[0].bmax.z == 3);
        CHECK_NEAR(s.sah_cost, 1.0, 1e-12);
        bvh_destroy(&c, &out);
    }
    test_mesh_free(&c, &m);
}

static void bvh_two_triangles_are_valid(void)
{
    core c;
    core_init(&c, NULL, NULL, NULL);
    mesh m = test_mesh_new(&c, 2);
    set_tri(&m, 0, 0, 0, 0, 1, 0, 0, 0, 1, 0);
    set_tri(&m, 1, 5, 0, 0, 6, 0, 0, 5, 1, 0);
    for (int b = 0; b < BUILDER_COUNT; b++) {
        bvh out;
        bvh_stats s;
        if (build_checked(&c, builder_names[b], &m, builders[b], 0, 0, &out, &s) != VKRT_OK) continue;
        /* Midpoint always splits distinct centroids; SAH keeps a pair of small far-apart
         * triangles together only if that were cheaper, which it is not here. */
        CHECK_EQ_U64(out.node_count, 3);
        CHECK_EQ_U64(s.leaves, 2);
        bvh_destroy(&c, &out);
    }
    test_mesh_free(&c, &m);
}

static void bvh_random_10k_is_valid_for_every_builder(void)
{
    core c;
    core_init(&c, NULL, NULL, NULL);
    mesh m = make_random(&c, 10000);
    double cost[BUILDER_COUNT] = { 0 };
    for (int b = 0; b < BUILDER_COUNT; b++) {
        bvh out;
        bvh_stats s;
        if (build_checked(&c, builder_names[b], &m, builders[b], 0, 0, &out, &s) != VKRT_OK) continue;
        cost[b] = s.sah_cost;
        if (builders[b] == VKRT_BVH_BUILDER_BINNED_SAH) check_leaf_limit("sah random", &out, &m, 4);
        else if (builders[b] == VKRT_BVH_BUILDER_SPATIAL_SAH) CHECK(s.max_leaf_triangles <= 4);
        else CHECK_EQ_U64(s.max_leaf_triangles, 1);
        bvh_destroy(&c, &out);
    }
    CHECK_MSG(cost[1] <= cost[0], "SAH cost of sah %g > midpoint %g", cost[1], cost[0]);
    CHECK_MSG(cost[2] <= cost[1], "SAH cost of sbvh %g > sah %g", cost[2], cost[1]);
    test_mesh_free(&c, &m);
}

/* Small triangles filling a box, and a few large ones across it (a room's walls around its
 * furniture): wherever the large triangles go, their boxes cover the whole scene, so every
 * object split leaves children that overlap, the case spatial splits are for. The SBVH cuts
 * them: a clearly lower SAH cost, triangles in several leaves, within its reference budget, and
 * every part of every triangle inside one of its leaves (bvh_validate). */
static void bvh_sbvh_splits_large_triangles(void)
{
    core c;
    core_init(&c, NULL, NULL, NULL);
    uint32_t n = 4000, large = 40;
    mesh m = test_mesh_new(&c, n);
    for (uint32_t i = 0; i < n; i++) {
        float x = frand() * 10.0f, y = frand() * 10.0f, z = frand() * 10.0f, s = i < large ? 10.0f : 0.1f;
        set_tri(&m, i, x, y, z, x + s * (frand() - 0.5f), y + s * (frand() - 0.5f), z + s * (frand() - 0.5f),
                x + s * (frand() - 0.5f), y + s * (frand() - 0.5f), z + s * (frand() - 0.5f));
    }
    update_bounds(&m);
    bvh sah, sbvh;
    bvh_stats ss, sp;
    if (build_checked(&c, "sah large triangles", &m, VKRT_BVH_BUILDER_BINNED_SAH, 0, 0, &sah, &ss) == VKRT_OK) {
        if (build_checked(&c, "sbvh large triangles", &m, VKRT_BVH_BUILDER_SPATIAL_SAH, 0, 0, &sbvh, &sp) == VKRT_OK) {
            CHECK_MSG(sbvh.spatial_splits && !sah.spatial_splits, "spatial_splits %d and %d", sbvh.spatial_splits,
                      sah.spatial_splits);
            CHECK_MSG(sp.sah_cost < 0.9 * ss.sah_cost, "SAH cost of sbvh %g, of sah %g", sp.sah_cost, ss.sah_cost);
            CHECK_MSG(sbvh.tri_count > n + large && sbvh.tri_count <= n + n / 2, "%u references for %u triangles",
                      sbvh.tri_count, n);
            fprintf(stderr, "  large triangles: sah SAH %.2f, sbvh SAH %.2f with %u references for %u triangles\n",
                    ss.sah_cost, sp.sah_cost, sbvh.tri_count, n);
            bvh_destroy(&c, &sbvh);
        }
        bvh_destroy(&c, &sah);
    }
    test_mesh_free(&c, &m);
}

static void bvh_identical_triangles_terminate_in_one_leaf(void)
{
    core c;
    core_init(&c, NULL, NULL, NULL);
    mesh m = test_mesh_new(&c, 10000);
    for (uint32_t i = 0; i < m.tri_count; i++) set_tri(&m, i, 0, 0, 0, 1, 0, 0, 0, 1, 0);
    for (int b = 0; b < BUILDER_COUNT; b++) {
        bvh out;
        bvh_stats s;
        if (build_checked(&c, builder_names[b], &m, builders[b], 0, 0, &out, &s) != VKRT_OK) continue;
        /* No plane separates equal centroids, so splitting would only add overlapping boxes. */
        CHECK_EQ_U64(out.node_count, 1);
        CHECK_EQ_U64(s.max_leaf_triangles, 10000);
        CHECK(out.depth <= VKRT_MAX_BVH_DEPTH);
        bvh_destroy(&c, &out);
    }
    test_mesh_free(&c, &m);
}

static void bvh_degenerate_triangles_are_valid(void)
{
    core c;
    core_init(&c, NULL, NULL, NULL);
    /* Points (all three corners equal), collinear corners along random directions, and a
     * line of collinear triangles along x whose boxes all have zero area. */
    mesh m = test_mesh_new(&c, 6000);
    for (uint32_t i = 0; i < 2000; i++) {
        float x = frand(), y = frand(), z = frand();
        set_tri(&m, i, x, y, z, x, y, z, x, y, z);
    }
    for (uint32_t i = 2000; i < 4000; i++) {
        float x = frand(), y = frand(), z = frand(), dx = frand(), dy = frand(), dz = frand();
        set_tri(&m, i, x, y, z, x + dx, y + dy, z + dz, x + 2 * dx, y + 2 * dy, z + 2 * dz);
    }
    for (uint32_t i = 4000; i < 6000; i++) {
        float x = (float)i;
        set_tri(&m, i, x, 0, 0, x + 0.5f, 0, 0, x + 2.0f, 0, 0);
    }
    mesh line = test_mesh_new(&c, 2000);
    memcpy(line.positions, m.positions + 4000 * 9, 2000 * 9 * sizeof(float));
    const mesh *meshes[] = { &m, &line };
    for (int k = 0; k < 2; k++) {
        for (int b = 0; b < BUILDER_COUNT; b++) {
            char what[64];
            snprintf(what, sizeof what, "%s %s", builder_names[b], k ? "zero-area line" : "degenerate mix");
            bvh out;
            bvh_stats s;
            if (build_checked(&c, what, meshes[k], builders[b], 0, 0, &out, &s) != VKRT_OK) continue;
            if (builders[b] == VKRT_BVH_BUILDER_BINNED_SAH) check_leaf_limit(what, &out, meshes[k], 4);
            /* Every candidate costs zero on the line; ties go to the balanced split. */
            if (k == 1) CHECK_MSG(out.depth <= 16, "%s: depth %u", what, out.depth);
            bvh_destroy(&c, &out);
        }
    }
    test_mesh_free(&c, &line);
    test_mesh_free(&c, &m);
}

static void bvh_flat_grid_is_valid(void)
{
    core c;
    core_init(&c, NULL, NULL, NULL);
    /* 100 x 100 quads in the plane z = 0: every box has zero thickness. */
    mesh m = test_mesh_new(&c, 2 * 100 * 100);
    uint32_t t = 0;
    for (int y = 0; y < 100; y++)
        for (int x = 0; x < 100; x++) {
            float x0 = (float)x, y0 = (float)y, x1 = x0 + 1, y1 = y0 + 1;
            set_tri(&m, t++, x0, y0, 0, x1, y0, 0, x1, y1, 0);
            set_tri(&m, t++, x0, y0, 0, x1, y1, 0, x0, y1, 0);
        }
    for (int b = 0; b < BUILDER_COUNT; b++) {
        bvh out;
        bvh_stats s;
        if (build_checked(&c, builder_names[b], &m, builders[b], 0, 0, &out, &s) != VKRT_OK) continue;
        CHECK(out.nodes[0].bmin.z == 0 && out.nodes[0].bmax.z == 0);
        if (builders[b] == VKRT_BVH_BUILDER_BINNED_SAH) check_leaf_limit("sah grid", &out, &m, 4);
        bvh_destroy(&c, &out);
    }
    test_mesh_free(&c, &m);
}

static void bvh_fan_of_100k_is_valid(void)
{
    core c;
    core_init(&c, NULL, NULL, NULL);
    /* Every triangle shares the origin, so every box overlaps every other. */
    uint32_t n = 100000;
    mesh m = test_mesh_new(&c, n);
    for (uint32_t i = 0; i < n; i++) {
        double a0 = 6.283185307179586 * i / n, a1 = 6.283185307179586 * (i + 1) / n;
        set_tri(&m, i, 0, 0, 0, (float)cos(a0), (float)sin(a0), 0, (float)cos(a1), (float)sin(a1), 0);
    }
    for (int b = 0; b < BUILDER_COUNT; b++) {
        bvh out;
        bvh_stats s;
        if (build_checked(&c, builder_names[b], &m, builders[b], 0, 0, &out, &s) != VKRT_OK) continue;
        if (builders[b] == VKRT_BVH_BUILDER_BINNED_SAH) check_leaf_limit("sah fan", &out, &m, 4);
        bvh_destroy(&c, &out);
    }
    test_mesh_free(&c, &m);
}

static void bvh_depth_is_capped(void)
{
    core c;
    core_init(&c, NULL, NULL, NULL);
    /* Point triangles at 2^(58 - 5i) along x and, as many, along y: each centroid is 1/32 of
     * the next, so the midpoint split and all 32 SAH bins but the last see only the farthest
     * point apart from the rest. Both builders peel one triangle per level, and an uncapped
     * tree would be 79 deep. */
    uint32_t n = 80;
    mesh m = test_mesh_new(&c, n);
    for (uint32_t i = 0; i < n / 2; i++) {
        float v = ldexpf(1.0f, 58 - 5 * (int)i);
        set_tri(&m, 2 * i, v, 0, 0, v, 0, 0, v, 0, 0);
        set_tri(&m, 2 * i + 1, 0, v, 0, 0, v, 0, 0, v, 0);
    }
    for (int b = 0; b < BUILDER_COUNT; b++) {
        bvh out;
        bvh_stats s;
        if (build_checked(&c, builder_names[b], &m, builders[b], 1, 0, &out, &s) != VKRT_OK) continue;
        CHECK_MSG(out.depth == VKRT_MAX_BVH_DEPTH, "%s: depth %u", builder_names[b], out.depth);
        CHECK(s.max_leaf_triangles > 1);
        bvh_destroy(&c, &out);
    }
    test_mesh_free(&c, &m);
}

static void bvh_sah_splits_centroids_too_close_to_bin(void)
{
    core c;
    core_init(&c, NULL, NULL, NULL);
    /* Centroids one denormal apart: the bin scale 32 / extent overflows to infinity, so
     * binning cannot separate them and the median fallback must. */
    uint32_t n = 100;
    mesh m = test_mesh_new(&c, n);
    for (uint32_t i = 0; i < n; i++) {
        float x = (float)i * FLT_TRUE_MIN;
        set_tri(&m, i, x, 0, 0, x, 1, 0, x, 0, 1);
    }
    for (int b = 0; b < BUILDER_COUNT; b++) {
        bvh out;
        bvh_stats s;
        if (build_checked(&c, builder_names[b], &m, builders[b], 4, 0, &out, &s) != VKRT_OK) continue;
        if (builders[b] == VKRT_BVH_BUILDER_BINNED_SAH) {
            check_leaf_limit("sah denormal", &out, &m, 4);
            CHECK(s.max_leaf_triangles <= 4);
        }
        bvh_destroy(&c, &out);
    }
    test_mesh_free(&c, &m);
}

static void bvh_sah_respects_max_leaf_size(void)
{
    core c;
    core_init(&c, NULL, NULL, NULL);
    mesh m = make_random(&c, 5000);
    /* Mixed in: 50 copies of one triangle, which no split can separate. */
    mesh dup = make_random(&c, 5050);
    for (uint32_t i = 5000; i < 5050; i++) set_tri(&dup, i, 3, 3, 3, 4, 3, 3, 3, 4, 3);
    const uint32_t limits[] = { 1, 2, 3, 4, 8, 16, 100 };
    for (size_t l = 0; l < sizeof limits / sizeof limits[0]; l++) {
        const mesh *meshes[] = { &m, &dup };
        for (int k = 0; k < 2; k++) {
            char what[64];
            snprintf(what, sizeof what, "sah max_leaf %u%s", limits[l], k ? " with duplicates" : "");
            bvh out;
            bvh_stats s;
            if (build_checked(&c, what, meshes[k], VKRT_BVH_BUILDER_BINNED_SAH, limits[l], 0, &out, &s) != VKRT_OK) continue;
            check_leaf_limit(what, &out, meshes[k], limits[l]);
            if (k == 0) CHECK_MSG(s.max_leaf_triangles <= limits[l], "%s: max leaf %u", what, s.max_leaf_triangles);
            else CHECK_MSG(s.max_leaf_triangles >= 50, "%s: max leaf %u", what, s.max_leaf_triangles);
            bvh_destroy(&c, &out);
        }
    }
    test_mesh_free(&c, &dup);
    test_mesh_free(&c, &m);
}

typedef struct progress_log {
    int calls, cancel_at; /* cancel_at: the call (1-based) that returns false; 0 never */
    int zero_calls;       /* zero_calls_cb: calls before the first fraction above 0 */
    float last;
    bool in_order;
} progress_log;

static bool progress_cb(void *user, const char *stage, float fraction)
{
    progress_log *p = user;
    p->calls++;
    if (!(fraction >= p->last && fraction <= 1.0f) || !stage) p->in_order = false;
    p->last = fraction;
    return p->cancel_at == 0 || p->calls < p->cancel_at;
}

static bool zero_calls_cb(void *user, const char *stage, float fraction)
{
    progress_log *p = user;
    if (fraction == 0.0f && p->last == 0.0f) p->zero_calls++;
    return progress_cb(user, stage, fraction);
}

static void bvh_progress_runs_from_zero_to_one(void)
{
    core c;
    core_init(&c, NULL, NULL, NULL);
    mesh m = make_random(&c, 20000);
    for (int b = 0; b < BUILDER_COUNT; b++) {
        progress_log p = { .in_order = true };
        bvh out;
        vkrt_result r = bvh_build(&c, &m, &(bvh_build_desc){ .builder = builders[b], .progress = progress_cb, .progress_user = &p }, &out);
        CHECK(r == VKRT_OK);
        CHECK_MSG(p.calls >= 3 && p.calls <= 200, "%s: %d progress calls", builder_names[b], p.calls);
        CHECK_MSG(p.in_order, "%s: fractions out of order", builder_names[b]);
        CHECK_MSG(p.last == 1.0f, "%s: last fraction %g", builder_names[b], p.last);
        bvh_destroy(&c, &out);
    }
    test_mesh_free(&c, &m);
}

/* Cancels a build at each progress call in turn until the build finishes first: every cancel
 * returns VKRT_ERROR_CANCELLED and leaks nothing. */
static void check_cancel_at_every_call(const char *what, core *c, const counting *k, const mesh *m, bvh_build_desc desc)
{
    for (int at = 1;; at++) {
        uint64_t allocs = k->allocs, frees = k->frees;
        progress_log p = { .cancel_at = at, .in_order = true };
        desc.progress = progress_cb;
        desc.progress_user = &p;
        bvh out;
        vkrt_result r = bvh_build(c, m, &desc, &out);
        if (p.calls < at) {
            CHECK(r == VKRT_OK);
            bvh_destroy(c, &out);
            CHECK_EQ_U64(k->allocs - allocs, k->frees - frees);
            CHECK_MSG(at > 3, "%s: only %d progress calls", what, at - 1);
            break;
        }
        CHECK_MSG(r == VKRT_ERROR_CANCELLED, "%s cancel at %d: %s", what, at, vkrt_result_string(r));
        CHECK(strstr(c->last_error, "cancelled") != NULL);
        CHECK(out.nodes == NULL && out.tri_order == NULL);
        CHECK_EQ_U64(k->allocs - allocs, k->frees - frees);
        CHECK_MSG(p.in_order, "%s cancel at %d: fractions out of order", what, at);
        if (r == VKRT_OK) bvh_destroy(c, &out);
        if (at > 1000) break;
    }
}

static void bvh_progress_false_cancels_without_leak(void)
{
    counting k = { 0 };
    core c;
    core_init(&c, &(vkrt_allocator){ counting_alloc, counting_free, &k }, NULL, NULL);
    mesh m = make_random(&c, 3000);
    for (int b = 0; b < BUILDER_COUNT; b++)
        check_cancel_at_every_call(builder_names[b], &c, &k, &m, (bvh_build_desc){ .builder = builders[b] });
    test_mesh_free(&c, &m);
    CHECK_EQ_U64(k.allocs, k.frees);
}

/* Fails each allocation of a build in turn until the build gets past them all: every failure
 * returns VKRT_ERROR_OUT_OF_MEMORY and leaks nothing. Returns how many allocations failed. */
static int check_out_of_memory_at_every_allocation(const char *what, core *c, counting *k, const mesh *m,
                                                   const bvh_build_desc *desc)
{
    int failures = 0;
    for (uint64_t n = 1;; n++) {
        uint64_t allocs = k->allocs, frees = k->frees;
        k->calls = 0;
        k->fail_at = n;
        bvh out;
        vkrt_result r = bvh_build(c, m, desc, &out);
        k->fail_at = 0;
        if (r == VKRT_OK) {
            char message[256];
            CHECK_MSG(bvh_validate(&out, m, message, sizeof message), "%s after failing allocation %llu: %s", what,
                      (unsigned long long)n, message);
            bvh_destroy(c, &out);
            CHECK_EQ_U64(k->allocs - allocs, k->frees - frees);
            /* Success only once the failing call is past every allocation of the build
             * (the final shrink of the node array may fail harmlessly). */
            if (k->calls < n) break;
            continue;
        }
        failures++;
        CHECK_MSG(r == VKRT_ERROR_OUT_OF_MEMORY, "%s failing allocation %llu: %s", what, (unsigned long long)n,
                  vkrt_result_string(r));
        CHECK(out.nodes == NULL && out.tri_order == NULL);
        CHECK(strstr(c->last_error, "out of memory") != NULL);
        CHECK_EQ_U64(k->allocs - allocs, k->frees - frees);
        if (n > 100) {
            CHECK_MSG(0, "%s: still failing after 100 allocations", what);
            break;
        }
    }
    return failures;
}

static void bvh_out_of_memory_at_every_allocation_without_leak(void)
{
    counting k = { 0 };
    core c;
    core_init(&c, &(vkrt_allocator){ counting_alloc, counting_free, &k }, NULL, NULL);
    mesh m = make_random(&c, 2000);
    for (int b = 0; b < BUILDER_COUNT; b++) {
        int failures = check_out_of_memory_at_every_allocation(builder_names[b], &c, &k, &m,
                                                               &(bvh_build_desc){ .builder = builders[b] });
        CHECK_MSG(failures >= 3, "%s: only %d allocations could fail", builder_names[b], failures);
    }
    test_mesh_free(&c, &m);
    CHECK_EQ_U64(k.allocs, k.frees);
}

/* ---- several threads ----------------------------------------------------------------- */

/* Above SAH_TASK_REFS triangles the SAH builder splits the top levels on all threads and hands
 * subtrees to each; 100000 random triangles make a few levels of both. */
#define PARALLEL_TEST_TRIS 100000

static void check_same_bvh(const char *what, const bvh *a, const bvh *b)
{
    CHECK_MSG(a->node_count == b->node_count && a->tri_count == b->tri_count && a->depth == b->depth,
              "%s: %u nodes, %u triangles, depth %u against %u, %u, %u", what, b->node_count, b->tri_count, b->depth,
              a->node_count, a->tri_count, a->depth);
    if (a->node_count != b->node_count || a->tri_count != b->tri_count) return;
    uint32_t node = 0, tri = 0;
    while (node < a->node_count && !memcmp(&a->nodes[node], &b->nodes[node], sizeof a->nodes[node])) node++;
    while (tri < a->tri_count && a->tri_order[tri] == b->tri_order[tri]) tri++;
    CHECK_MSG(node == a->node_count, "%s: node %u differs", what, node);
    CHECK_MSG(tri == a->tri_count, "%s: tri_order[%u] differs", what, tri);
}

/* Builds m on 1 thread and then on each count of `threads`: the same nodes and triangle order
 * every time (results must not depend on scheduling), valid, exact boxes. Returns the SAH cost
 * (of the one tree). */
static double check_identical_on_thread_counts(const char *name, core *c, const mesh *m, uint32_t max_leaf)
{
    static const uint32_t threads[] = { 2, 3, 8 };
    bvh one;
    bvh_stats s;
    char what[256];
    snprintf(what, sizeof what, "%s max_leaf %u, 1 thread", name, max_leaf);
    if (build_checked(c, what, m, VKRT_BVH_BUILDER_BINNED_SAH, max_leaf, 1, &one, &s) != VKRT_OK) return INFINITY;
    for (size_t t = 0; t < sizeof threads / sizeof threads[0]; t++) {
        snprintf(what, sizeof what, "%s max_leaf %u, %u threads", name, max_leaf, threads[t]);
        bvh many;
        bvh_stats ms;
        if (build_checked(c, what, m, VKRT_BVH_BUILDER_BINNED_SAH, max_leaf, threads[t], &many, &ms) != VKRT_OK) continue;
        check_same_bvh(what, &one, &many);
        bvh_destroy(c, &many);
    }
    bvh_destroy(c, &one);
    return s.sah_cost;
}

static void bvh_sah_is_identical_on_any_thread_count(void)
{
    core c;
    core_init(&c, NULL, NULL, NULL);
    mesh random = make_random(&c, PARALLEL_TEST_TRIS);
    const uint32_t limits[] = { 1, 4, 100000 };
    for (size_t l = 0; l < sizeof limits / sizeof limits[0]; l++) check_identical_on_thread_counts("random", &c, &random, limits[l]);
    test_mesh_free(&c, &random);

    /* Issue 7's mesh and bound: the full dragon at an SAH cost (C_trav = C_isect = 1) of at most
     * 50.07. The single-threaded builder before the parallel one reached 48.77, and 48.89 with
     * fewer bins for small nodes; binning a node in pieces gives the same bins as binning it
     * whole, so every split decision and the cost stay put, and the bound (2.4% over) leaves
     * room for a change of bin count or leaf rule. */
    const char *path = VKRT_MODELS_DIR "/meshes/dragon_871k.glb";
    mesh dragon = { 0 };
    vkrt_result r = mesh_load(&c, path, &dragon);
    CHECK_MSG(r == VKRT_OK, "%s: %s (%s)", path, vkrt_result_string(r), c.last_error);
    if (r != VKRT_OK) return;
    double cost = check_identical_on_thread_counts("dragon_871k", &c, &dragon, 0);
    CHECK_MSG(cost <= 50.07, "dragon_871k: SAH cost %.4f > 50.07", cost);
    fprintf(stderr, "  dragon_871k SAH cost %.4f on 1, 2, 3 and 8 threads\n", cost);
    mesh_destroy(&c, &dragon);
}

/* A subtree of more than SAH_TASK_REFS references: the parallel build hands a node of the top
 * levels to one thread as it is once bins cannot split it. 12,000 triangles whose centroids
 * lie a denormal apart (no bin scale can separate them, so the median fallback splits them,
 * inside that one subtree) beside 20,000 random ones far off: the same nodes and order on any
 * thread count, a valid tree, and leaves of at most 4. */
static void bvh_sah_parallel_builds_oversized_subtrees(void)
{
    core c;
    core_init(&c, NULL, NULL, NULL);
    const uint32_t cluster = 12000, spread = 20000;
    mesh m = test_mesh_new(&c, cluster + spread);
    for (uint32_t i = 0; i < cluster; i++) {
        float x = (float)i * FLT_TRUE_MIN;
        set_tri(&m, i, x, 0, 0, x, 1, 0, x, 0, 1);
    }
    for (uint32_t i = cluster; i < cluster + spread; i++) {
        float x = 10 + frand(), y = 10 + frand(), z = 10 + frand();
        set_tri(&m, i, x, y, z, x + 0.01f * frand(), y + 0.01f, z, x, y + 0.01f * frand(), z + 0.01f);
    }
    CHECK(cluster > SAH_TASK_REFS);
    check_identical_on_thread_counts("oversized subtree", &c, &m, 4);
    bvh out;
    bvh_stats s;
    if (build_checked(&c, "oversized subtree, 2 threads", &m, VKRT_BVH_BUILDER_BINNED_SAH, 4, 2, &out, &s) == VKRT_OK) {
        check_leaf_limit("oversized subtree", &out, &m, 4);
        /* The median splits reach below the cluster's node: it was built, not left a leaf. */
        CHECK_MSG(s.leaves > cluster / 4, "%u leaves", (unsigned)s.leaves);
        bvh_destroy(&c, &out);
    }
    test_mesh_free(&c, &m);
}

typedef struct warn_log {
    int warnings;
    bool named_threads;
} warn_log;

static void on_log(void *user, vkrt_log_level level, const char *message)
{
    warn_log *l = user;
    if (level != VKRT_LOG_WARN) return;
    l->warnings++;
    if (strstr(message, "worker threads")) l->named_threads = true;
}

/* Where worker threads fail to start (the test cap stops them where pthread_create would) the
 * pool runs with those that did, down to the caller alone: the same tree, and a warning. */
static void bvh_sah_builds_the_same_tree_when_threads_fail_to_start(void)
{
    warn_log l = { 0 };
    core c;
    core_init(&c, NULL, on_log, &l);
    mesh m = make_random(&c, PARALLEL_TEST_TRIS);
    bvh one;
    bvh_stats s;
    if (build_checked(&c, "1 thread", &m, VKRT_BVH_BUILDER_BINNED_SAH, 0, 1, &one, &s) == VKRT_OK) {
        CHECK_EQ_U64(l.warnings, 0);
        const uint32_t caps[] = { 1, 2 };
        for (size_t i = 0; i < sizeof caps / sizeof caps[0]; i++) {
            char what[64];
            snprintf(what, sizeof what, "8 threads, %u started", caps[i]);
            c.test_thread_cap = caps[i];
            l = (warn_log){ 0 };
            bvh capped;
            bvh_stats cs;
            if (build_checked(&c, what, &m, VKRT_BVH_BUILDER_BINNED_SAH, 0, 8, &capped, &cs) == VKRT_OK) {
                check_same_bvh(what, &one, &capped);
                bvh_destroy(&c, &capped);
            }
            CHECK_MSG(l.warnings >= 1 && l.named_threads, "%s: no warning about the threads that did not start", what);
        }
        c.test_thread_cap = 0;
        bvh_destroy(&c, &one);
    }
    test_mesh_free(&c, &m);
}

/* A builder's parallel path on 1 and 3 threads over `tris` random triangles: out of memory at
 * every allocation (at least min_failures of them) and a cancel at every progress call, each
 * leaking nothing. */
static void check_parallel_failures(const char *name, vkrt_bvh_builder builder, uint32_t tris, int min_failures)
{
    counting k = { 0 };
    core c;
    core_init(&c, &(vkrt_allocator){ counting_alloc, counting_free, &k }, NULL, NULL);
    mesh m = make_random(&c, tris);
    const uint32_t threads[] = { 1, 3 };
    for (size_t t = 0; t < sizeof threads / sizeof threads[0]; t++) {
        char what[64];
        snprintf(what, sizeof what, "%s parallel on %u threads", name, threads[t]);
        bvh_build_desc desc = { .builder = builder, .threads = threads[t] };
        int failures = check_out_of_memory_at_every_allocation(what, &c, &k, &m, &desc);
        CHECK_MSG(failures >= min_failures, "%s: only %d allocations could fail", what, failures);
        check_cancel_at_every_call(what, &c, &k, &m, desc);
    }
    test_mesh_free(&c, &m);
    CHECK_EQ_U64(k.allocs, k.frees);
}

static void bvh_sah_parallel_out_of_memory_and_cancel_without_leak(void)
{
    check_parallel_failures("sah", VKRT_BVH_BUILDER_BINNED_SAH, PARALLEL_TEST_TRIS, 8);
}

/* The spatial-split builder above 8,192 triangles: the nodes above subtrees of at most that many
 * references serially, the subtrees on the threads. The same nodes and order on 1, 2, 3 and 8
 * threads (dragon_48k); out of memory at every allocation and a cancel at every progress call
 * on 1 and 3 threads leak nothing (20,000 random triangles, three subtrees and more). */
static void bvh_sbvh_parallel_is_identical_and_fails_cleanly(void)
{
    core c;
    core_init(&c, NULL, NULL, NULL);
    const char *path = VKRT_MODELS_DIR "/meshes/dragon_48k.obj";
    mesh dragon = { 0 };
    vkrt_result r = mesh_load(&c, path, &dragon);
    CHECK_MSG(r == VKRT_OK, "%s: %s (%s)", path, vkrt_result_string(r), c.last_error);
    bvh one;
    bvh_stats s;
    if (r == VKRT_OK && build_checked(&c, "sbvh dragon_48k, 1 thread", &dragon, VKRT_BVH_BUILDER_SPATIAL_SAH, 0, 1, &one,
                                      &s) == VKRT_OK) {
        static const uint32_t threads[] = { 2, 3, 8 };
        for (size_t t = 0; t < sizeof threads / sizeof threads[0]; t++) {
            char what[64];
            snprintf(what, sizeof what, "sbvh dragon_48k, %u threads", threads[t]);
            bvh many;
            bvh_stats ms;
            if (build_checked(&c, what, &dragon, VKRT_BVH_BUILDER_SPATIAL_SAH, 0, threads[t], &many, &ms) != VKRT_OK)
                continue;
            check_same_bvh(what, &one, &many);
            bvh_destroy(&c, &many);
        }
        CHECK_MSG(one.tri_count > dragon.tri_count, "%u references for %u triangles", one.tri_count, dragon.tri_count);
        bvh_destroy(&c, &one);
    }
    if (r == VKRT_OK) mesh_destroy(&c, &dragon);
    check_parallel_failures("sbvh", VKRT_BVH_BUILDER_SPATIAL_SAH, 20000, 20);
}

/* The parallel build's top levels place no triangle in a leaf, and used to call the progress
 * callback not once: a cancel waited for the first subtree. They now report the fraction so
 * far (0) after each pass over a level, so a cancel takes effect before any subtree is built. */
static void bvh_sah_parallel_top_levels_report_progress(void)
{
    core c;
    core_init(&c, NULL, NULL, NULL);
    mesh m = make_random(&c, PARALLEL_TEST_TRIS);
    progress_log p = { .in_order = true };
    bvh_build_desc desc = { .builder = VKRT_BVH_BUILDER_BINNED_SAH, .threads = 3, .progress = zero_calls_cb,
                            .progress_user = &p };
    bvh out;
    CHECK(bvh_build(&c, &m, &desc, &out) == VKRT_OK);
    bvh_destroy(&c, &out);
    /* The start's report and at least one level's three passes (100,000 references split down
     * to 8,192 take four levels). */
    CHECK_MSG(p.zero_calls >= 4, "%d progress calls before the first triangle was placed", p.zero_calls);
    CHECK(p.in_order && p.last == 1.0f);
    progress_log q = { .cancel_at = 4, .in_order = true };
    desc.progress = progress_cb;
    desc.progress_user = &q;
    CHECK(bvh_build(&c, &m, &desc, &out) == VKRT_ERROR_CANCELLED);
    CHECK(out.nodes == NULL && q.calls == 4);
    CHECK_MSG(q.last == 0.0f, "cancelled at fraction %g, after the top levels", q.last);
    test_mesh_free(&c, &m);
}

/* Small subtrees become leaves only where their triangles are one run of the array: a
 * hand-made tree whose root's left child holds triangles 0 and 2 (its right child, a leaf,
 * triangle 1) keeps that child a node over two leaves, where the tree with triangles 0 and 1 on
 * the left makes it one leaf of two (and the right child stays a leaf of one). check_bvh4 holds
 * the collapse to its rules on both. */
static void bvh4_collapse_merges_only_subtrees_in_one_run(void)
{
    core c;
    core_init(&c, NULL, NULL, NULL);
    for (int run = 0; run < 2; run++) {
        const uint32_t second = run ? 1u : 2u, other = run ? 2u : 1u;
        vkrt_gpu_node nodes[5] = {
            { { 0, 0, 0 }, 1, { 3, 1, 1 }, 0 },               /* root: children 1, 2 */
            { { 0, 0, 0 }, 3, { 2, 1, 1 }, 0 },               /* left: children 3, 4 */
            { { 2, 0, 0 }, other, { 3, 1, 1 }, 1 },           /* right: a leaf */
            { { 0, 0, 0 }, 0, { 1, 1, 1 }, 1 },               /* triangle 0 */
            { { 1, 0, 0 }, second, { 2, 1, 1 }, 1 },          /* triangle 1 or 2 */
        };
        uint32_t order[3] = { 0, 1, 2 };
        bvh b = { .nodes = nodes, .node_count = 5, .tri_order = order, .tri_count = 3, .depth = 2 };
        const char *what = run ? "left child over triangles 0 and 1" : "left child over triangles 0 and 2";
        check_bvh4(&c, what, &b);
        bvh4 w;
        CHECK(bvh4_collapse(&c, &b, &w) == VKRT_OK);
        if (!w.nodes) continue;
        const bvh4_node *root = &w.nodes[0];
        if (run) {
            CHECK_MSG(w.node_count == 1 && root->child[0] == 0 && root->count[0] == 2 && root->child[1] == 2 &&
                          root->count[1] == 1 && root->child[2] == BVH4_EMPTY,
                      "%s: %u wide nodes, slots %u+%u %u+%u", what, w.node_count, root->child[0], root->count[0],
                      root->child[1], root->count[1]);
        } else {
            /* The left child is opened into the root's slots: triangles 0, 2, then 1. */
            CHECK_MSG(w.node_count == 1 && root->child[0] == 0 && root->count[0] == 1 && root->child[1] == 2 &&
                          root->count[1] == 1 && root->child[2] == 1 && root->count[2] == 1,
                      "%s: %u wide nodes, slots %u+%u %u+%u %u+%u", what, w.node_count, root->child[0], root->count[0],
                      root->child[1], root->count[1], root->child[2], root->count[2]);
        }
        bvh4_destroy(&c, &w);
    }
}

/* The collapse makes one allocation: failing it is VKRT_ERROR_OUT_OF_MEMORY with *out zeroed
 * and nothing leaked; an empty tree is an invalid argument; destroy accepts NULL and zeroes. */
static void bvh4_collapse_fails_cleanly(void)
{
    counting k = { 0 };
    core c;
    core_init(&c, &(vkrt_allocator){ counting_alloc, counting_free, &k }, NULL, NULL);
    mesh m = make_random(&c, 500);
    bvh b;
    CHECK(bvh_build(&c, &m, NULL, &b) == VKRT_OK);
    bvh4 w;
    memset(&w, 0xab, sizeof w);
    k.calls = 0;
    k.fail_at = 1;
    CHECK(bvh4_collapse(&c, &b, &w) == VKRT_ERROR_OUT_OF_MEMORY);
    k.fail_at = 0;
    CHECK(w.nodes == NULL && w.allocation == NULL && w.node_count == 0);
    CHECK(strstr(c.last_error, "out of memory") != NULL);
    bvh empty = { 0 };
    CHECK(bvh4_collapse(&c, &empty, &w) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(bvh4_collapse(&c, NULL, &w) == VKRT_ERROR_INVALID_ARGUMENT && w.nodes == NULL);
    CHECK(bvh4_collapse(&c, &b, &w) == VKRT_OK && w.node_count > 1);
    bvh4_destroy(&c, &w);
    bvh4_destroy(&c, &w);
    bvh4_destroy(&c, NULL);
    bvh_destroy(&c, &b);
    test_mesh_free(&c, &m);
    CHECK_EQ_U64(k.allocs, k.frees);
}

/* Decodes every child box of the packed wide nodes of m's BVH as the shader does (origin +
 * step * 2^(e - 127), float arithmetic) and checks the quantisation promised in wide_pack.c: the
 * origin is the children's lowest bound, the exponent the smallest whose 255 steps reach their
 * highest (0 for a flat axis), and each decoded box holds its child's float box (the wide
 * traversal may cull nothing the binary one enters) with not a step to spare on any side. */
static void check_wide_quantisation(const char *what, core *c, const mesh *m)
{
    bvh b;
    if (bvh_build(c, m, NULL, &b) != VKRT_OK) {
        CHECK_MSG(false, "%s: build failed (%s)", what, c->last_error);
        return;
    }
    vkrt_gpu_tri *tris = core_alloc_array(c, b.tri_count, sizeof *tris);
    bvh4 w = { 0 };
    wide_arrays p = { 0 };
    CHECK(tris != NULL);
    if (tris) scene_pack_triangles(m, &b, tris);
    if (tris && bvh4_collapse(c, &b, &w) == VKRT_OK && wide_pack(c, &b, tris, 2, &p) == VKRT_OK) {
        CHECK_MSG(p.node_count == w.node_count, "%s: %u packed nodes for %u wide ones", what, p.node_count, w.node_count);
        uint64_t outside = 0, spare = 0, frames = 0, slots = 0;
        for (uint32_t i = 0; i < p.node_count && i < w.node_count; i++) {
            const uint32_t *t = p.node_texels + (size_t)i * VKRT_WIDE_NODE_TEXELS * 4;
            const bvh4_node *n = &w.nodes[i];
            for (int a = 0; a < 3; a++) {
                float origin, scale, scale_below;
                memcpy(&origin, &t[a], sizeof origin);
                const uint32_t e = (t[3] >> (8 * a)) & 0xFFu, bits = e << 23, below = (e - 1) << 23;
                memcpy(&scale, &bits, sizeof scale);
                memcpy(&scale_below, &below, sizeof scale_below);
                float lo = INFINITY, hi = -INFINITY;
                for (int s = 0; s < BVH4_WIDTH && n->child[s] != BVH4_EMPTY; s++) {
                    lo = fminf(lo, n->lo[a][s]);
                    hi = fmaxf(hi, n->hi[a][s]);
                }
                frames += origin != lo || (hi > lo ? e == 0 || origin + 255.0f * scale < hi ||
                                                         (e > 1 && origin + 255.0f * scale_below >= hi)
                                                   : e != 0);
                for (int s = 0; s < BVH4_WIDTH && n->child[s] != BVH4_EMPTY; s++) {
                    const uint32_t q_lo = (t[4 + a] >> (8 * s)) & 0xFFu, q_hi = (t[7 + a] >> (8 * s)) & 0xFFu;
                    const float d_lo = origin + (float)q_lo * scale, d_hi = origin + (float)q_hi * scale;
                    outside += !(d_lo <= n->lo[a][s] && d_hi >= n->hi[a][s]);
                    if (e != 0)
                        spare += (q_lo < 255 && origin + (float)(q_lo + 1) * scale <= n->lo[a][s]) ||
                                 (q_hi > 0 && origin + (float)(q_hi - 1) * scale >= n->hi[a][s]);
                    slots++;
                }
            }
        }
        fprintf(stderr, "  %s: %u wide nodes, %llu slot axes decoded\n", what, p.node_count, (unsigned long long)slots);
        CHECK_MSG(slots > 0, "%s: no slots decoded", what);
        CHECK_MSG(frames == 0, "%s: %llu node axes with the wrong origin or exponent", what, (unsigned long long)frames);
        CHECK_MSG(outside == 0, "%s: %llu decoded bounds inside the child's box", what, (unsigned long long)outside);
        CHECK_MSG(spare == 0, "%s: %llu decoded bounds a step or more loose", what, (unsigned long long)spare);
    } else {
        CHECK_MSG(false, "%s: collapse or packing failed (%s)", what, c->last_error);
    }
    wide_arrays_destroy(c, &p);
    bvh4_destroy(c, &w);
    core_free(c, tris);
    bvh_destroy(c, &b);
}

static void wide_pack_quantises_conservatively_and_tightly(void)
{
    core c;
    core_init(&c, NULL, NULL, NULL);
    mesh m = make_random(&c, 3000);
    check_wide_quantisation("random 3000", &c, &m);
    test_mesh_free(&c, &m);
    /* Flat axes (z = 0 throughout) and far-from-zero origins with small steps: x near 3e5,
     * where a float's spacing (2^-5) is within a few steps of the children's extents. */
    m = test_mesh_new(&c, 2 * 40 * 40);
    uint32_t t = 0;
    for (int y = 0; y < 40; y++)
        for (int x = 0; x < 40; x++) {
            float x0 = 300000.0f + 0.25f * (float)x, y0 = 1e-3f * (float)y, x1 = x0 + 0.25f, y1 = y0 + 1e-3f;
            set_tri(&m, t++, x0, y0, 0, x1, y0, 0, x1, y1, 0);
            set_tri(&m, t++, x0, y0, 0, x1, y1, 0, x0, y1, 0);
        }
    update_bounds(&m);
    check_wide_quantisation("flat grid far from 0", &c, &m);
    test_mesh_free(&c, &m);
}

static void bvh_validate_reports_broken_trees(void)
{
    core c;
    core_init(&c, NULL, NULL, NULL);
    mesh m = make_random(&c, 200);
    bvh b;
    CHECK(bvh_build(&c, &m, &(bvh_build_desc){ .builder = VKRT_BVH_BUILDER_MIDPOINT }, &b) == VKRT_OK);
    char msg[512];
    CHECK(bvh_validate(&b, &m, msg, sizeof msg));
    uint32_t leaf = 0, interior = 0;
    for (uint32_t i = b.node_count - 1; i > 0; i--) {
        if (b.nodes[i].tri_count) leaf = i;
        else if (!interior) interior = i;
    }
    CHECK(leaf && interior && b.nodes[0].tri_count == 0);

    uint32_t saved = b.tri_order[0];
    b.tri_order[0] = b.tri_order[1];
    CHECK(!bvh_validate(&b, &m, msg, sizeof msg) && strstr(msg, "appears twice"));
    b.tri_order[0] = saved;

    vkrt_gpu_node node = b.nodes[leaf];
    b.nodes[leaf].bmax.x = b.nodes[0].bmax.x + 1.0f;
    CHECK(!bvh_validate(&b, &m, msg, sizeof msg) && strstr(msg, "not inside parent"));
    b.nodes[leaf] = node;

    b.nodes[leaf].bmax.x = b.nodes[leaf].bmin.x;
    CHECK(!bvh_validate(&b, &m, msg, sizeof msg) && strstr(msg, "misses corner"));
    b.nodes[leaf] = node;

    b.nodes[leaf].tri_count++;
    CHECK(!bvh_validate(&b, &m, msg, sizeof msg) && (strstr(msg, "two leaves") || strstr(msg, "beyond")));
    b.nodes[leaf] = node;

    node = b.nodes[interior];
    b.nodes[interior].left_first = b.node_count - 1;
    CHECK(!bvh_validate(&b, &m, msg, sizeof msg) && strstr(msg, "outside"));
    b.nodes[interior].left_first = b.nodes[0].left_first;
    CHECK(!bvh_validate(&b, &m, msg, sizeof msg) && (strstr(msg, "reached twice") || strstr(msg, "not inside")));
    b.nodes[interior] = node;

    b.depth++;
    CHECK(!bvh_validate(&b, &m, msg, sizeof msg) && strstr(msg, "deep"));
    b.depth--;
    CHECK(bvh_validate(&b, &m, msg, sizeof msg));
    bvh_destroy(&c, &b);
    test_mesh_free(&c, &m);
}

static bool has_suffix(const char *s, const char *suffix)
{
    size_t n = strlen(s), k = strlen(suffix);
    return n >= k && strcmp(s + n - k, suffix) == 0;
}

static void bvh_shared_models_are_valid_and_sah_is_cheaper(void)
{
    const char *dir_path = VKRT_MODELS_DIR "/meshes";
    DIR *dir = opendir(dir_path);
    CHECK_MSG(dir != NULL, "cannot open %s", dir_path);
    if (!dir) return;
    int tested = 0;
    struct dirent *e;
    while ((e = readdir(dir)) != NULL) {
        if (!has_suffix(e->d_name, ".obj") && !has_suffix(e->d_name, ".glb")) continue;
        char path[1024];
        snprintf(path, sizeof path, "%s/%s", dir_path, e->d_name);
        core c;
        core_init(&c, NULL, NULL, NULL);
        mesh m = { 0 };
        vkrt_result r = mesh_load(&c, path, &m);
        CHECK_MSG(r == VKRT_OK, "%s: %s (%s)", path, vkrt_result_string(r), c.last_error);
        if (r != VKRT_OK) continue;
        double cost[BUILDER_COUNT] = { 0 }, ms[BUILDER_COUNT] = { 0 };
        uint32_t depth[BUILDER_COUNT] = { 0 };
        for (int b = 0; b < BUILDER_COUNT; b++) {
            char what[1100];
            snprintf(what, sizeof what, "%s %s", builder_names[b], e->d_name);
            bvh out;
            bvh_stats s;
            if (build_checked(&c, what, &m, builders[b], 0, 0, &out, &s) != VKRT_OK) continue;
            if (builders[b] == VKRT_BVH_BUILDER_BINNED_SAH) check_leaf_limit(what, &out, &m, 4);
            cost[b] = s.sah_cost;
            ms[b] = out.build_ms;
            depth[b] = out.depth;
            bvh_destroy(&c, &out);
        }
        CHECK_MSG(cost[1] <= cost[0], "%s: SAH cost of sah %g > midpoint %g", e->d_name, cost[1], cost[0]);
        CHECK_MSG(cost[2] <= cost[1], "%s: SAH cost of sbvh %g > sah %g", e->d_name, cost[2], cost[1]);
        fprintf(stderr,
                "  %-24s %8u tris  midpoint: SAH %7.2f depth %2u %8.1f ms  sah: SAH %7.2f depth %2u %8.1f ms  "
                "sbvh: SAH %7.2f depth %2u %8.1f ms\n",
                e->d_name, m.tri_count, cost[0], depth[0], ms[0], cost[1], depth[1], ms[1], cost[2], depth[2], ms[2]);
        mesh_destroy(&c, &m);
        tested++;
    }
    closedir(dir);
    CHECK_MSG(tested >= 10, "only %d meshes found in %s", tested, dir_path);
}

/* core_alloc asks for huge pages for every block of CORE_HUGE_PAGE_MIN bytes or more (mesh
 * arrays, BVH nodes, packed triangles: a quarter of the full dragon's load and build went to
 * page faults without them) and leaves smaller blocks alone. */
static void core_alloc_advises_huge_pages_for_large_blocks(void)
{
    core c;
    core_init(&c, NULL, NULL, NULL);
    const size_t large = 4 * CORE_HUGE_PAGE_MIN, small = CORE_HUGE_PAGE_MIN / 4;
    unsigned char *big = core_alloc(&c, large), *little = core_alloc(&c, small);
    CHECK(big && little);
    if (big && little) {
        int advised_big = mapping_advised_huge(big + large / 2);
        int advised_little = mapping_advised_huge(little + small / 2);
        CHECK_MSG(advised_big == 1, "a %zu-byte block: advised %d", large, advised_big);
        CHECK_MSG(advised_little == 0, "a %zu-byte block: advised %d", small, advised_little);
    }
    core_free(&c, big);
    core_free(&c, little);
}

/* core_shrink keeps a block's first bytes and gives back the rest: in place with the default
 * allocator (realloc: no copy, and nothing of the tail touched; the builders shrink their
 * worst-case node arrays with it), by a copy into an exact block with a user's allocator, and
 * where that copy cannot be allocated the block comes back whole. */
static void core_shrink_keeps_the_start_and_gives_back_the_rest(void)
{
    const size_t large = 4 * CORE_HUGE_PAGE_MIN, kept = CORE_HUGE_PAGE_MIN / 4 + 12;
    core c;
    core_init(&c, NULL, NULL, NULL);
    uint32_t *block = core_alloc(&c, large);
    CHECK(block != NULL);
    if (block) {
        for (size_t i = 0; i < large / sizeof *block; i++) block[i] = (uint32_t)(i * 2654435761u);
        uint32_t *shrunk = core_shrink(&c, block, kept);
        CHECK(shrunk != NULL);
        bool same = true;
        for (size_t i = 0; shrunk && i < kept / sizeof *shrunk; i++) same &= shrunk[i] == (uint32_t)(i * 2654435761u);
        CHECK_MSG(same, "the default allocator's shrink changed the kept bytes");
        /* The C library's own measure of the block: what was given back is no longer its. */
        size_t usable = shrunk ? malloc_usable_size(shrunk) : 0;
        CHECK_MSG(usable >= kept && usable <= kept + 4096, "a %zu-byte block shrunk to %zu keeps %zu bytes", large,
                  kept, usable);
        core_free(&c, shrunk);
    }

    counting k = { 0 };
    core_init(&c, &(vkrt_allocator){ counting_alloc, counting_free, &k }, NULL, NULL);
    for (int fail = 0; fail < 2; fail++) {
        uint32_t *b = core_alloc(&c, 4096);
        CHECK(b != NULL);
        if (!b) continue;
        for (uint32_t i = 0; i < 1024; i++) b[i] = i ^ 0x5a5a5a5au;
        k.calls = 0;
        k.fail_at = fail ? 1 : 0;
        uint32_t *s = core_shrink(&c, b, 100 * sizeof *b);
        k.fail_at = 0;
        CHECK_MSG(fail ? s == b : s != b, "user allocator, copy %s: the block %s moved", fail ? "refused" : "made",
                  s == b ? "was not" : "was");
        CHECK_EQ_U64(k.calls, 1);
        bool same = true;
        for (uint32_t i = 0; i < 100; i++) same &= s[i] == (i ^ 0x5a5a5a5au);
        CHECK_MSG(same, "user allocator, copy %s: the kept bytes changed", fail ? "refused" : "made");
        core_free(&c, s);
    }
    CHECK_EQ_U64(k.allocs, k.frees);
}

int main(void)
{
    RUN(bvh_empty_mesh_is_empty_scene);
    RUN(core_alloc_advises_huge_pages_for_large_blocks);
    RUN(core_shrink_keeps_the_start_and_gives_back_the_rest);
    RUN(bvh_unknown_builder_is_invalid_argument);
    RUN(bvh_single_triangle_is_one_leaf_root);
    RUN(bvh_two_triangles_are_valid);
    RUN(bvh_random_10k_is_valid_for_every_builder);
    RUN(bvh_sbvh_splits_large_triangles);
    RUN(bvh_identical_triangles_terminate_in_one_leaf);
    RUN(bvh_degenerate_triangles_are_valid);
    RUN(bvh_flat_grid_is_valid);
    RUN(bvh_fan_of_100k_is_valid);
    RUN(bvh_depth_is_capped);
    RUN(bvh_sah_splits_centroids_too_close_to_bin);
    RUN(bvh_sah_respects_max_leaf_size);
    RUN(bvh_progress_runs_from_zero_to_one);
    RUN(bvh_progress_false_cancels_without_leak);
    RUN(bvh_out_of_memory_at_every_allocation_without_leak);
    RUN(bvh_sah_is_identical_on_any_thread_count);
    RUN(bvh_sah_parallel_builds_oversized_subtrees);
    RUN(bvh_sah_parallel_out_of_memory_and_cancel_without_leak);
    RUN(bvh_sah_parallel_top_levels_report_progress);
    RUN(bvh_sbvh_parallel_is_identical_and_fails_cleanly);
    RUN(bvh_sah_builds_the_same_tree_when_threads_fail_to_start);
    RUN(bvh4_collapse_merges_only_subtrees_in_one_run);
    RUN(bvh4_collapse_fails_cleanly);
    RUN(wide_pack_quantises_conservatively_and_tightly);
    RUN(bvh_validate_reports_broken_trees);
    RUN(bvh_shared_models_are_valid_and_sah_is_cheaper);
    return check_exit();
}

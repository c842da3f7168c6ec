/* Binned SAH builder: the default BVH of vkrt.
 *
 * This implements I. Wald, "On fast Construction of SAH-based Bounding Volume Hierarchies",
 * IEEE Symposium on Interactive Ray Tracing 2007: instead of sorting triangles along each
 * axis, every node bins the centres of its triangles' boxes into equal intervals (SAH_BINS,
 * fewer for small nodes) of the centroid bounds on each of the three axes, accumulating a box
 * and a count per bin; a sweep over the bin boundaries then gives the surface area heuristic
 * (MacDonald and Booth 1990, "Heuristics for ray tracing using space subdivision")
 *
 *     cost(split) = C_trav * A(node) + C_isect * (A(left) N(left) + A(right) N(right))
 *     cost(leaf)  = C_isect * A(node) N(node),        with C_trav = C_isect = 1,
 *
 * and the node is partitioned in place at the cheapest boundary. The costs are compared
 * without dividing by A(node), so zero-area nodes (collinear or point triangles) need no
 * special case.
 *
 * Choices beyond the paper, each for a property the GPU or the tests rely on:
 * - A node holding more than max_leaf_size triangles is split whenever any split exists, even
 *   when SAH prefers a leaf, so leaf sizes stay bounded for the traversal kernel. When binning
 *   cannot separate centroids that do differ (their spread is too small for a finite bin
 *   scale), a median split by count along the widest centroid axis is used instead.
 * - A node whose triangles all share one centroid becomes a leaf whatever its size: no plane
 *   can separate them, and splitting by count would only add boxes that all overlap.
 * - A node at depth VKRT_MAX_BVH_DEPTH becomes a leaf, so the traversal stack of the shader
 *   never overflows and the build loop needs only a fixed stack.
 * - Equal costs are broken toward the more balanced split, so degenerate input where every
 *   candidate costs zero still halves the node instead of peeling one bin at a time.
 *
 * Speed (the build is on the critical path of every scene): one pass over a node's references
 * bins all three axes, with 4-lane box updates (float4.h); sweeps, resets and child boxes
 * visit only the bins that hold references (a bit mask per axis), which matters because most
 * nodes hold a handful, and small nodes have fewer bins to fill; the partition is
 * branch-free; each node's child boxes come from its bins, its children's centroid bounds from
 * one pass after the partition, and no node allocates. Large meshes are built by several
 * threads (bvh_build_sah_parallel.c); this file holds the split rule and the serial subtree
 * loop they share.
 *
 * Memory: one array of triangle references (box + index, 32 bytes each) that is partitioned
 * in place, and the node array at its upper bound of 2N - 1, shrunk to size at the end. The
 * allocation, task stack, leaves and progress are the shared frame of bvh_build_common.h. */
#include "bvh_build_sah.h"

#include <math.h>
#include <string.h>

#include "float4.h"

static float box_area(const float *bmin, const float *bmax)
{
    float dx = bmax[0] - bmin[0], dy = bmax[1] - bmin[1], dz = bmax[2] - bmin[2];
    return 2.0f * (dx * dy + dy * dz + dz * dx);
}

/* box_area() of the box lo-hi, in the same order of operations, so the same bits. Lane 3 is
 * masked off: in bins it holds triangle indices as floats, denormals that some processors
 * multiply a hundred times slower. */
static inline float box_area4(float4 lo, float4 hi)
{
    float4 d = f4_xyz(f4_sub(hi, lo));
    float4 p = f4_mul(d, f4_yzxw(d)); /* dx dy, dy dz, dz dx */
    return 2.0f * ((f4_x(p) + f4_y(p)) + f4_z(p));
}

static inline float4 box_empty_min(void) { return f4_set(FLT_MAX, FLT_MAX, FLT_MAX, FLT_MAX); }
static inline float4 box_empty_max(void) { return f4_set(-FLT_MAX, -FLT_MAX, -FLT_MAX, -FLT_MAX); }

/* The centroid of r in all three lanes (bmin + bmax; lane 3 zero). The index in bmax[3] is
 * masked off first: as a float it may be a denormal, which some processors add slowly. */
static inline float4 ref_centroid(const sah_ref *r) { return f4_add(f4_load(r->bmin), f4_xyz(f4_load(r->bmax))); }

static inline float ref_centroid_on(const sah_ref *r, int axis) { return r->bmin[axis] + r->bmax[axis]; }

static void store_xyz(float *out, float4 v)
{
    float lanes[4];
    f4_store(lanes, v);
    memcpy(out, lanes, 3 * sizeof *out);
}

/* Lowest set bit of x, which must not be 0. */
static inline int lowest_bit(uint32_t x)
{
#if defined(__GNUC__)
    return __builtin_ctz(x);
#else
    int k = 0;
    while (!(x & 1u)) {
        x >>= 1;
        k++;
    }
    return k;
#endif
}

void bvh_build_sah_refs(const mesh *m, sah_ref *refs, uint32_t first, uint32_t count, bvh_build_bounds *bounds)
{
    float4 bmin = box_empty_min(), bmax = box_empty_max(), cmin = bmin, cmax = bmax;
    for (uint32_t i = first; i < first + count; i++) {
        sah_ref *r = &refs[i];
        /* bvh_build_tri_box() on 4 lanes: the same comparisons in the same order. */
        const float *p = m->positions + (size_t)i * 9;
        float4 v0 = f4_set(p[0], p[1], p[2], 0.0f), v1 = f4_set(p[3], p[4], p[5], 0.0f);
        float4 v2 = f4_set(p[6], p[7], p[8], 0.0f);
        float4 lo = f4_min(v2, f4_min(v1, v0)), hi = f4_max(v2, f4_max(v1, v0));
        f4_store(r->bmin, lo);
        f4_store(r->bmax, hi);
        memcpy(&r->bmax[3], &i, sizeof i);
        bmin = f4_min(lo, bmin);
        bmax = f4_max(hi, bmax);
        float4 c = f4_add(lo, hi);
        cmin = f4_min(c, cmin);
        cmax = f4_max(c, cmax);
    }
    store_xyz(bounds->bmin, bmin);
    store_xyz(bounds->bmax, bmax);
    store_xyz(bounds->cmin, cmin);
    store_xyz(bounds->cmax, cmax);
}

/* Bins for a node of `count` references: SAH_BINS from 336 references up, fewer below, down to
 * 4 (Embree's builders take 4 + count / 20). Most nodes are small, and a small node's sweep
 * visits up to three times as many filled bins as it holds references, so the sweep had become
 * 17% of the full dragon's build; few references gain little from a fine grid. Full dragon,
 * two threads, in turn with 32 bins everywhere: 4 + count / 12 took 0.89x the build time at
 * SAH cost 48.89 against 48.77 (dragon_200k 43.53 against 43.38); 4 + count / 20 the same
 * time at 49.03 (43.72), 4 + count / 8 0.92x at 48.83 (43.45). */
static uint32_t sah_bins_for(uint32_t count)
{
    uint32_t bins = 4 + count / 12;
    return bins < SAH_BINS ? bins : SAH_BINS;
}

bool bvh_build_sah_grid(const bvh_build_task *t, sah_grid *g)
{
    bool usable = false;
    const uint32_t bins = sah_bins_for(t->count);
    for (int a = 0; a < 3; a++) {
        float extent = t->cmax[a] - t->cmin[a];
        float scale = extent > 0.0f ? (float)bins * (1.0f - 1e-6f) / extent : 0.0f;
        /* A spread so small that the scale overflows cannot be binned; the caller falls back
         * to a median split if no other axis works. */
        bool use = extent > 0.0f && isfinite(scale);
        g->origin[a] = t->cmin[a];
        g->scale[a] = use ? scale : 0.0f;
        usable |= use;
    }
    g->origin[3] = 0.0f;
    g->scale[3] = 0.0f;
    return usable;
}

static void bin_empty(sah_bin *bin)
{
    f4_store(bin->bmin, box_empty_min());
    f4_store(bin->bmax, box_empty_max());
}

void bvh_build_sah_binning_empty(sah_binning *b)
{
    for (int a = 0; a < 3; a++) {
        for (int k = 0; k < SAH_BINS; k++) {
            bin_empty(&b->bin[a][k]);
            b->count[a][k] = 0;
        }
        b->used[a] = 0;
    }
}

void bvh_build_sah_binning_clear(sah_binning *b)
{
    for (int a = 0; a < 3; a++) {
        for (uint32_t m = b->used[a]; m; m &= m - 1) {
            int k = lowest_bit(m);
            bin_empty(&b->bin[a][k]);
            b->count[a][k] = 0;
        }
        b->used[a] = 0;
    }
}

static inline void bin_grow(sah_binning *b, int axis, int k, float4 lo, float4 hi, uint32_t *used)
{
    sah_bin *bin = &b->bin[axis][k];
    f4_store(bin->bmin, f4_min(lo, f4_load(bin->bmin)));
    f4_store(bin->bmax, f4_max(hi, f4_load(bin->bmax)));
    b->count[axis][k]++;
    *used |= 1u << k;
}

void bvh_build_sah_bin(const sah_ref *r, const sah_ref *end, const sah_grid *g, sah_binning *b)
{
    const float4 origin = f4_load(g->origin), scale = f4_load(g->scale);
    const float4 zero = f4_set(0.0f, 0.0f, 0.0f, 0.0f);
    const float4 last = f4_set(SAH_BINS - 1, SAH_BINS - 1, SAH_BINS - 1, SAH_BINS - 1);
    /* The masks stay in registers (one variable per axis, the axes written out): updated in
     * memory, each would wait for its previous store. */
    uint32_t used0 = b->used[0], used1 = b->used[1], used2 = b->used[2];
    for (; r < end; r++) {
        float4 lo = f4_load(r->bmin), hi = f4_load(r->bmax);
        /* bvh_build_sah_bin_index() on all three axes at once (and 0 in lane 3). */
        float4 f = f4_mul(f4_sub(f4_add(lo, f4_xyz(hi)), origin), scale);
        f = f4_min(f4_max(f, zero), last);
        int32_t k[4];
        f4_truncate(f, k);
        bin_grow(b, 0, k[0], lo, hi, &used0);
        bin_grow(b, 1, k[1], lo, hi, &used1);
        bin_grow(b, 2, k[2], lo, hi, &used2);
    }
    b->used[0] = used0;
    b->used[1] = used1;
    b->used[2] = used2;
}

void bvh_build_sah_binning_merge(sah_binning *into, const sah_binning *from)
{
    for (int a = 0; a < 3; a++) {
        for (uint32_t m = from->used[a]; m; m &= m - 1) {
            int k = lowest_bit(m);
            sah_bin *to = &into->bin[a][k];
            const sah_bin *bin = &from->bin[a][k];
            f4_store(to->bmin, f4_min(f4_load(bin->bmin), f4_load(to->bmin)));
            f4_store(to->bmax, f4_max(f4_load(bin->bmax), f4_load(to->bmax)));
            into->count[a][k] += from->count[a][k];
        }
        into->used[a] |= from->used[a];
    }
}

/* The cheapest boundary between non-empty bins over the binnable axes; axis -1 if none. */
static sah_split sweep(const sah_binning *b, const sah_grid *g)
{
    sah_split best = { .axis = -1, .plane = 0, .cost = INFINITY, .balance = UINT32_MAX };
    for (int a = 0; a < 3; a++) {
        if (g->scale[a] == 0.0f) continue;
        /* Only boundaries between non-empty bins give distinct partitions. */
        int filled[SAH_BINS], k = 0;
        for (uint32_t m = b->used[a]; m; m &= m - 1) filled[k++] = lowest_bit(m);
        if (k < 2) continue;
        float left_cost[SAH_BINS];
        uint32_t left_n[SAH_BINS];
        float4 lo = box_empty_min(), hi = box_empty_max();
        uint32_t n = 0;
        for (int j = 0; j < k - 1; j++) {
            const sah_bin *bin = &b->bin[a][filled[j]];
            lo = f4_min(f4_load(bin->bmin), lo);
            hi = f4_max(f4_load(bin->bmax), hi);
            n += b->count[a][filled[j]];
            left_n[j] = n;
            left_cost[j] = box_area4(lo, hi) * (float)n;
        }
        n = 0;
        lo = box_empty_min();
        hi = box_empty_max();
        for (int j = k - 1; j >= 1; j--) {
            const sah_bin *bin = &b->bin[a][filled[j]];
            lo = f4_min(f4_load(bin->bmin), lo);
            hi = f4_max(f4_load(bin->bmax), hi);
            n += b->count[a][filled[j]];
            uint32_t nl = left_n[j - 1];
            float cost = left_cost[j - 1] + box_area4(lo, hi) * (float)n;
            uint32_t balance = nl > n ? nl : n;
            if (cost < best.cost || (cost == best.cost && balance < best.balance)) {
                best.cost = cost;
                best.axis = a;
                best.plane = filled[j];
                best.balance = balance;
            }
        }
    }
    return best;
}

sah_decision bvh_build_sah_decide(const sah_binning *b, const sah_grid *g, const vkrt_gpu_node *node, uint32_t count,
                                  uint32_t max_leaf, sah_split *s)
{
    *s = sweep(b, g);
    if (s->axis < 0) return count > max_leaf ? SAH_MEDIAN : SAH_LEAF;
    float nmin[3] = { node->bmin.x, node->bmin.y, node->bmin.z };
    float nmax[3] = { node->bmax.x, node->bmax.y, node->bmax.z };
    float area = box_area(nmin, nmax);
    if (count <= max_leaf && area * (float)count <= area + s->cost) return SAH_LEAF;
    return SAH_SPLIT;
}

void bvh_build_sah_split_boxes(const sah_binning *b, const sah_split *s, bvh_build_bounds *left, bvh_build_bounds *right)
{
    float4 llo = box_empty_min(), lhi = box_empty_max(), rlo = llo, rhi = lhi;
    for (uint32_t m = b->used[s->axis]; m; m &= m - 1) {
        int k = lowest_bit(m);
        const sah_bin *bin = &b->bin[s->axis][k];
        if (k < s->plane) {
            llo = f4_min(f4_load(bin->bmin), llo);
            lhi = f4_max(f4_load(bin->bmax), lhi);
        } else {
            rlo = f4_min(f4_load(bin->bmin), rlo);
            rhi = f4_max(f4_load(bin->bmax), rhi);
        }
    }
    store_xyz(left->bmin, llo);
    store_xyz(left->bmax, lhi);
    store_xyz(right->bmin, rlo);
    store_xyz(right->bmax, rhi);
}

void bvh_build_sah_centroid_bounds(const sah_ref *r, const sah_ref *end, bvh_build_bounds *b)
{
    float4 lo = box_empty_min(), hi = box_empty_max();
    for (; r < end; r++) {
        float4 c = ref_centroid(r);
        lo = f4_min(c, lo);
        hi = f4_max(c, hi);
    }
    store_xyz(b->cmin, lo);
    store_xyz(b->cmax, hi);
}

/* References classified at a time before they are moved: see bvh_build_sah_partition(). */
#define SAH_PARTITION_BLOCK 256

uint32_t bvh_build_sah_partition(sah_ref *first, sah_ref *end, const sah_grid *g, const sah_split *s,
                                 bvh_build_bounds *left, bvh_build_bounds *right)
{
    sah_ref *split = first;
    for (sah_ref *block = first; block < end; block += SAH_PARTITION_BLOCK) {
        uint32_t n = end - block < SAH_PARTITION_BLOCK ? (uint32_t)(end - block) : SAH_PARTITION_BLOCK;
        uint8_t goes_left[SAH_PARTITION_BLOCK];
        for (uint32_t k = 0; k < n; k++) goes_left[k] = bvh_build_sah_goes_left(&block[k], g, s);
        for (uint32_t k = 0; k < n; k++) {
            sah_ref r = block[k];
            block[k] = *split;
            *split = r;
            split += goes_left[k];
        }
    }
    bvh_build_sah_centroid_bounds(first, split, left);
    bvh_build_sah_centroid_bounds(split, end, right);
    return (uint32_t)(split - first);
}

/* Iterative quickselect: afterwards refs[k] has the centroid it would have in sorted order,
 * with no larger centroid before it and no smaller one after it. */
static void select_nth(sah_ref *refs, uint32_t lo, uint32_t hi, uint32_t k, int axis)
{
    /* [lo, hi] inclusive */
    while (hi > lo) {
        uint32_t mid = lo + (hi - lo) / 2;
        float a = ref_centroid_on(&refs[lo], axis), b = ref_centroid_on(&refs[mid], axis),
              c = ref_centroid_on(&refs[hi], axis);
        float pivot = a < b ? (b < c ? b : (a < c ? c : a)) : (a < c ? a : (b < c ? c : b));
        uint32_t i = lo, j = hi;
        while (i <= j) {
            while (ref_centroid_on(&refs[i], axis) < pivot) i++;
            while (ref_centroid_on(&refs[j], axis) > pivot) j--;
            if (i <= j) {
                sah_ref tmp = refs[i];
                refs[i] = refs[j];
                refs[j] = tmp;
                i++;
                if (j == 0) break;
                j--;
            }
        }
        /* Now [lo, j] <= pivot <= [i, hi], and anything between equals the pivot. */
        if (k <= j) hi = j;
        else if (k >= i) lo = i;
        else return;
    }
}

void bvh_build_sah_bounds(const sah_ref *refs, uint32_t first, uint32_t count, bvh_build_bounds *b)
{
    float4 lo = box_empty_min(), hi = box_empty_max();
    for (const sah_ref *r = refs + first; r < refs + first + count; r++) {
        lo = f4_min(f4_load(r->bmin), lo);
        hi = f4_max(f4_load(r->bmax), hi);
    }
    store_xyz(b->bmin, lo);
    store_xyz(b->bmax, hi);
    bvh_build_sah_centroid_bounds(refs + first, refs + first + count, b);
}

bool bvh_build_sah_median_split(sah_ref *refs, const bvh_build_task *t, uint32_t *left_count, bvh_build_bounds *left,
                         bvh_build_bounds *right)
{
    int axis = -1;
    float widest = 0.0f;
    for (int a = 0; a < 3; a++) {
        float extent = t->cmax[a] - t->cmin[a];
        if (extent > widest) {
            widest = extent;
            axis = a;
        }
    }
    if (axis < 0) return false;
    *left_count = t->count / 2;
    select_nth(refs, t->first, t->first + t->count - 1, t->first + *left_count, axis);
    bvh_build_sah_bounds(refs, t->first, *left_count, left);
    bvh_build_sah_bounds(refs, t->first + *left_count, t->count - *left_count, right);
    return true;
}

/* A node of two references (a third of all nodes): binning puts them in the first and last
 * bins of every binnable axis, so the sweep finds one boundary per axis, all of cost
 * A(r0) + A(r1) and balance 1, and keeps the first axis. The same decision, and the same
 * partition and child bounds as the general path, without bins. */
static sah_decision decide_pair(sah_ref *refs, const bvh_build_task *t, const sah_grid *g, const vkrt_gpu_node *node,
                                uint32_t max_leaf, bvh_build_bounds *left, bvh_build_bounds *right)
{
    sah_ref *r = refs + t->first;
    float cost = box_area4(f4_load(r[0].bmin), f4_load(r[0].bmax)) + box_area4(f4_load(r[1].bmin), f4_load(r[1].bmax));
    float nmin[3] = { node->bmin.x, node->bmin.y, node->bmin.z };
    float nmax[3] = { node->bmax.x, node->bmax.y, node->bmax.z };
    float area = box_area(nmin, nmax);
    if (2 <= max_leaf && area * 2.0f <= area + cost) return SAH_LEAF;
    int axis = g->scale[0] != 0.0f ? 0 : g->scale[1] != 0.0f ? 1 : 2;
    if (ref_centroid_on(&r[1], axis) < ref_centroid_on(&r[0], axis)) {
        sah_ref tmp = r[0];
        r[0] = r[1];
        r[1] = tmp;
    }
    bvh_build_sah_bounds(r, 0, 1, left);
    bvh_build_sah_bounds(r, 1, 1, right);
    return SAH_SPLIT;
}

/* Workers poll for cancellation this often (in leaves): rarely enough to cost nothing. */
#define SAH_CANCEL_POLL 256

void bvh_build_sah_subtree(bvh_build_state *b, sah_ref *refs, bvh_build_task task, uint32_t max_leaf,
                           sah_binning *bins, const work_pool *pool)
{
    uint32_t leaves = 0;
    for (;;) {
        bool leaf = task.count == 1 || task.depth >= VKRT_MAX_BVH_DEPTH;
        uint32_t left_count = 0;
        bvh_build_bounds left, right;
        if (!leaf) {
            sah_grid g;
            sah_split s;
            sah_decision d = SAH_MEDIAN;
            bool binnable = bvh_build_sah_grid(&task, &g);
            if (binnable && task.count == 2) {
                d = decide_pair(refs, &task, &g, &b->nodes[task.node], max_leaf, &left, &right);
                left_count = 1;
            } else if (binnable) {
                bvh_build_sah_bin(refs + task.first, refs + task.first + task.count, &g, bins);
                d = bvh_build_sah_decide(bins, &g, &b->nodes[task.node], task.count, max_leaf, &s);
                if (d == SAH_SPLIT) {
                    bvh_build_sah_split_boxes(bins, &s, &left, &right);
                    left_count = bvh_build_sah_partition(refs + task.first, refs + task.first + task.count, &g, &s, &left, &right);
                }
                bvh_build_sah_binning_clear(bins);
            } else if (task.count <= max_leaf) {
                d = SAH_LEAF;
            }
            if (d == SAH_MEDIAN && !bvh_build_sah_median_split(refs, &task, &left_count, &left, &right)) d = SAH_LEAF;
            /* Binning and partitioning share bvh_build_sah_bin_index(), so this never fires;
             * it keeps a future change from looping forever on an empty child. */
            leaf = d == SAH_LEAF || left_count == 0 || left_count == task.count;
        }
        if (!leaf) {
            bvh_build_split(b, &task, left_count, &left, &right);
            continue;
        }
        if (!bvh_build_leaf(b, &task)) return;
        if (pool && ++leaves % SAH_CANCEL_POLL == 0 && work_pool_cancelled(pool)) {
            b->cancelled = true;
            return;
        }
    }
}

vkrt_result bvh_build_sah(core *c, const mesh *m, const bvh_build_desc *desc, bvh *out)
{
    bvh_build_state b;
    vkrt_result r = bvh_build_begin(&b, c, m, desc, sizeof(sah_ref), SAH_REF_TRI_OFFSET, out);
    if (r != VKRT_OK) return r;
    uint32_t max_leaf = desc && desc->max_leaf_size ? desc->max_leaf_size : SAH_DEFAULT_MAX_LEAF;
    if (b.tri_count > SAH_TASK_REFS) {
        r = bvh_build_sah_parallel(&b, m, max_leaf, desc && desc->threads ? desc->threads : 1);
        if (r != VKRT_OK) return r;
        return bvh_build_finish(&b, out);
    }
    /* Small meshes: one subtree, the caller's thread, progress from its leaves. */
    bvh_build_bounds root;
    bvh_build_sah_refs(m, b.refs, 0, b.tri_count, &root);
    sah_binning bins;
    bvh_build_sah_binning_empty(&bins);
    bvh_build_task task;
    if (bvh_build_start(&b, &root, &task)) bvh_build_sah_subtree(&b, b.refs, task, max_leaf, &bins, NULL);
    return bvh_build_finish(&b, out);
}

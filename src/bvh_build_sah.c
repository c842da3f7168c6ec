/* Binned SAH builder: the default BVH of vkrt.
 *
 * This implements I. Wald, "On fast Construction of SAH-based Bounding Volume Hierarchies",
 * IEEE Symposium on Interactive Ray Tracing 2007: instead of sorting triangles along each
 * axis, every node bins the centres of its triangles' boxes into SAH_BINS equal intervals of
 * the centroid bounds on each of the three axes, accumulating a box and a count per bin; a
 * sweep over the bin boundaries then gives the surface area heuristic
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
 * Memory: one array of triangle references (box + index, 32 bytes each) that is partitioned
 * in place, and the node array at its upper bound of 2N - 1, shrunk to size at the end. No
 * allocation per node; children are allocated as adjacent pairs. The allocation, task stack,
 * leaves and progress are the shared frame of bvh_build_common.h; this file holds the split
 * rule only. */
#include <math.h>
#include <string.h>

#include "bvh_build_common.h"

/* Wald 2007 measured 16-32 bins within a few percent of a full sweep's tree quality. */
#define SAH_BINS 32
#define SAH_DEFAULT_MAX_LEAF 4

typedef struct sah_ref {
    float bmin[3];
    uint32_t tri;
    float bmax[3];
    float pad; /* 32 bytes, so a reference never straddles two cache lines */
} sah_ref;

typedef struct sah_bin {
    float bmin[3];
    uint32_t count;
    float bmax[3];
    float pad; /* 32 bytes, like sah_ref */
} sah_bin;

static float box_area(const float *bmin, const float *bmax)
{
    float dx = bmax[0] - bmin[0], dy = bmax[1] - bmin[1], dz = bmax[2] - bmin[2];
    return 2.0f * (dx * dy + dy * dz + dz * dx);
}

static inline float ref_centroid(const sah_ref *r, int axis)
{
    return 0.5f * (r->bmin[axis] + r->bmax[axis]);
}

/* The bin of a centroid. Binning and partitioning both call this, so they always agree on
 * which side a reference falls; a NaN lands in bin 0 instead of undefined behaviour. */
static inline int bin_index(float centroid, float cmin, float scale)
{
    float f = (centroid - cmin) * scale;
    /* Conditional expressions, not ifs: the compiler turns them into min/max instructions,
     * and this runs for every reference on three axes at every level. */
    f = f > 0.0f ? f : 0.0f;
    f = f < (float)(SAH_BINS - 1) ? f : (float)(SAH_BINS - 1);
    return (int)f;
}

/* Runs for every reference at every level, like bvh_build_box_grow(). */
static inline void centroid_grow(bvh_build_bounds *b, const sah_ref *r)
{
    const float c[3] = { ref_centroid(r, 0), ref_centroid(r, 1), ref_centroid(r, 2) };
    bvh_build_box_grow(b->cmin, b->cmax, c, c);
}

typedef struct sah_split {
    int axis, plane;          /* left: bins [0, plane) of axis; -1 when none exists */
    float cost;               /* A(left) N(left) + A(right) N(right) */
    uint32_t balance;         /* max(N(left), N(right)), the tie-breaker */
    float scale[3];
} sah_split;

/* bins is scratch; empty holds empty bins, copied over it, which is cheaper than resetting
 * 96 bins field by field at each of the ~N/2 nodes. */
static sah_split find_split(const sah_ref *refs, const bvh_build_task *t, sah_bin bins[3][SAH_BINS],
                            const sah_bin *empty)
{
    sah_split best = { .axis = -1, .cost = INFINITY, .balance = UINT32_MAX };
    bool use[3];
    for (int a = 0; a < 3; a++) {
        float extent = t->cmax[a] - t->cmin[a];
        best.scale[a] = extent > 0.0f ? (float)SAH_BINS * (1.0f - 1e-6f) / extent : 0.0f;
        /* A spread so small that the scale overflows cannot be binned; the caller falls back
         * to a median split if no other axis works. A scale of 0 sends the unused axis to
         * bin 0, which is cheaper than testing for it in the loop below. */
        use[a] = extent > 0.0f && isfinite(best.scale[a]);
        if (!use[a]) best.scale[a] = 0.0f;
    }
    if (!use[0] && !use[1] && !use[2]) return best;
    memcpy(bins, empty, 3 * SAH_BINS * sizeof **bins);

    const sah_ref *end = refs + t->first + t->count;
    float cmin0 = t->cmin[0], cmin1 = t->cmin[1], cmin2 = t->cmin[2];
    float scale0 = best.scale[0], scale1 = best.scale[1], scale2 = best.scale[2];
    for (const sah_ref *r = refs + t->first; r < end; r++) {
        sah_bin *b0 = &bins[0][bin_index(ref_centroid(r, 0), cmin0, scale0)];
        sah_bin *b1 = &bins[1][bin_index(ref_centroid(r, 1), cmin1, scale1)];
        sah_bin *b2 = &bins[2][bin_index(ref_centroid(r, 2), cmin2, scale2)];
        b0->count++;
        bvh_build_box_grow(b0->bmin, b0->bmax, r->bmin, r->bmax);
        b1->count++;
        bvh_build_box_grow(b1->bmin, b1->bmax, r->bmin, r->bmax);
        b2->count++;
        bvh_build_box_grow(b2->bmin, b2->bmax, r->bmin, r->bmax);
    }

    for (int a = 0; a < 3; a++) {
        if (!use[a]) continue;
        /* Only boundaries between non-empty bins give distinct partitions; small nodes fill
         * few of the 32 bins, so sweeping just those keeps the per-node cost low. */
        int filled[SAH_BINS], k = 0;
        for (int b = 0; b < SAH_BINS; b++) {
            filled[k] = b; /* branch-free: whether a bin is empty is a coin toss */
            k += bins[a][b].count != 0;
        }
        if (k < 2) continue;
        float left_cost[SAH_BINS];
        uint32_t left_n[SAH_BINS];
        float bmin[3], bmax[3];
        uint32_t n = 0;
        bvh_build_box_empty(bmin, bmax);
        for (int j = 0; j < k - 1; j++) {
            const sah_bin *bin = &bins[a][filled[j]];
            bvh_build_box_grow(bmin, bmax, bin->bmin, bin->bmax);
            n += bin->count;
            left_n[j] = n;
            left_cost[j] = box_area(bmin, bmax) * (float)n;
        }
        n = 0;
        bvh_build_box_empty(bmin, bmax);
        for (int j = k - 1; j >= 1; j--) {
            const sah_bin *bin = &bins[a][filled[j]];
            bvh_build_box_grow(bmin, bmax, bin->bmin, bin->bmax);
            n += bin->count;
            uint32_t nl = left_n[j - 1];
            float cost = left_cost[j - 1] + box_area(bmin, bmax) * (float)n;
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

/* Partitions [first, first + count) so bins below s->plane come first; returns the left count
 * and sets the centroid bounds (only) of both sides. */
static uint32_t partition_bins(sah_ref *refs, const bvh_build_task *t, const sah_split *s,
                               bvh_build_bounds *left, bvh_build_bounds *right)
{
    int a = s->axis;
    float cmin = t->cmin[a], scale = s->scale[a];
    bvh_build_box_empty(left->cmin, left->cmax);
    bvh_build_box_empty(right->cmin, right->cmax);
    /* Each reference is classified once: the one swapped in from the end is examined next. */
    uint32_t i = t->first, j = t->first + t->count;
    while (i < j) {
        if (bin_index(ref_centroid(&refs[i], a), cmin, scale) < s->plane) {
            centroid_grow(left, &refs[i]);
            i++;
        } else {
            j--;
            sah_ref tmp = refs[i];
            refs[i] = refs[j];
            refs[j] = tmp;
            centroid_grow(right, &refs[j]);
        }
    }
    return i - t->first;
}

/* Iterative quickselect: afterwards refs[k] has the centroid it would have in sorted order,
 * with no larger centroid before it and no smaller one after it. */
static void select_nth(sah_ref *refs, uint32_t lo, uint32_t hi, uint32_t k, int axis)
{
    /* [lo, hi] inclusive */
    while (hi > lo) {
        uint32_t mid = lo + (hi - lo) / 2;
        float a = ref_centroid(&refs[lo], axis), b = ref_centroid(&refs[mid], axis),
              c = ref_centroid(&refs[hi], axis);
        float pivot = a < b ? (b < c ? b : (a < c ? c : a)) : (a < c ? a : (b < c ? c : b));
        uint32_t i = lo, j = hi;
        while (i <= j) {
            while (ref_centroid(&refs[i], axis) < pivot) i++;
            while (ref_centroid(&refs[j], axis) > pivot) j--;
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

static void bounds_grow(bvh_build_bounds *b, const sah_ref *r)
{
    bvh_build_box_grow(b->bmin, b->bmax, r->bmin, r->bmax);
    centroid_grow(b, r);
}

static void bounds_of(const sah_ref *refs, uint32_t first, uint32_t count, bvh_build_bounds *b)
{
    bvh_build_bounds_empty(b);
    for (uint32_t i = first; i < first + count; i++) bounds_grow(b, &refs[i]);
}

vkrt_result bvh_build_sah(core *c, const mesh *m, const bvh_build_desc *desc, bvh *out)
{
    bvh_build_state b;
    vkrt_result r = bvh_build_begin(&b, c, m, desc, sizeof(sah_ref), offsetof(sah_ref, tri), out);
    if (r != VKRT_OK) return r;
    uint32_t max_leaf = desc && desc->max_leaf_size ? desc->max_leaf_size : SAH_DEFAULT_MAX_LEAF;
    sah_ref *refs = b.refs;

    bvh_build_bounds root;
    bvh_build_bounds_empty(&root);
    for (uint32_t i = 0; i < b.tri_count; i++) {
        sah_ref *ref = &refs[i];
        bvh_build_tri_box(m->positions + (size_t)i * 9, ref->bmin, ref->bmax);
        ref->tri = i;
        ref->pad = 0.0f;
        bounds_grow(&root, ref);
    }

    sah_bin bins[3][SAH_BINS], empty[3][SAH_BINS];
    for (int k = 0; k < 3 * SAH_BINS; k++) {
        sah_bin *bin = &empty[k / SAH_BINS][k % SAH_BINS];
        bvh_build_box_empty(bin->bmin, bin->bmax);
        bin->count = 0;
        bin->pad = 0.0f;
    }

    bvh_build_task task;
    bool more = bvh_build_start(&b, &root, &task);
    while (more) {
        const vkrt_gpu_node *node = &b.nodes[task.node];
        bool leaf = task.count == 1 || task.depth >= VKRT_MAX_BVH_DEPTH;
        uint32_t left_count = 0;
        bvh_build_bounds left, right;
        if (!leaf) {
            sah_split s = find_split(refs, &task, bins, &empty[0][0]);
            float nmin[3] = { node->bmin.x, node->bmin.y, node->bmin.z };
            float nmax[3] = { node->bmax.x, node->bmax.y, node->bmax.z };
            float area = box_area(nmin, nmax);
            if (s.axis >= 0) {
                if (task.count <= max_leaf && area * (float)task.count <= area + s.cost) {
                    leaf = true;
                } else {
                    left_count = partition_bins(refs, &task, &s, &left, &right);
                    bvh_build_box_empty(left.bmin, left.bmax);
                    bvh_build_box_empty(right.bmin, right.bmax);
                    for (int k = 0; k < SAH_BINS; k++) {
                        const sah_bin *bin = &bins[s.axis][k];
                        if (bin->count == 0) continue;
                        if (k < s.plane) bvh_build_box_grow(left.bmin, left.bmax, bin->bmin, bin->bmax);
                        else bvh_build_box_grow(right.bmin, right.bmax, bin->bmin, bin->bmax);
                    }
                }
            } else if (task.count > max_leaf) {
                int axis = -1;
                float widest = 0.0f;
                for (int a = 0; a < 3; a++) {
                    float extent = task.cmax[a] - task.cmin[a];
                    if (extent > widest) {
                        widest = extent;
                        axis = a;
                    }
                }
                if (axis < 0) {
                    leaf = true; /* all centroids equal: no split exists */
                } else {
                    left_count = task.count / 2;
                    select_nth(refs, task.first, task.first + task.count - 1, task.first + left_count, axis);
                    bounds_of(refs, task.first, left_count, &left);
                    bounds_of(refs, task.first + left_count, task.count - left_count, &right);
                }
            } else {
                leaf = true;
            }
            /* Binning and partitioning share bin_index(), so this never fires; it keeps a
             * future change from looping forever on an empty child. */
            if (!leaf && (left_count == 0 || left_count == task.count)) leaf = true;
        }
        if (leaf) more = bvh_build_leaf(&b, &task);
        else bvh_build_split(&b, &task, left_count, &left, &right);
    }
    return bvh_build_finish(&b, out);
}

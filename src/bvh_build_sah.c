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
 * allocation per node; children are allocated as adjacent pairs. */
#include <float.h>
#include <math.h>
#include <string.h>

#include "bvh.h"

/* Wald 2007 measured 16-32 bins within a few percent of a full sweep's tree quality. */
#define SAH_BINS 32
/* Progress is reported about this many times per build: often enough for a bar, cheap. */
#define SAH_PROGRESS_STEPS 64
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

typedef struct sah_task {
    uint32_t node, first, count, depth;
    float cmin[3], cmax[3]; /* centroid bounds of the task's references */
} sah_task;

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

static void box_empty(float *bmin, float *bmax)
{
    for (int a = 0; a < 3; a++) {
        bmin[a] = FLT_MAX;
        bmax[a] = -FLT_MAX;
    }
}

/* The grow functions run for every reference at every level: written out per component with
 * conditional expressions so the compiler emits straight-line min/max instructions. */
static inline float min_f(float a, float b) { return a < b ? a : b; }
static inline float max_f(float a, float b) { return a > b ? a : b; }

static inline void box_grow(float *bmin, float *bmax, const float *omin, const float *omax)
{
    bmin[0] = min_f(omin[0], bmin[0]);
    bmin[1] = min_f(omin[1], bmin[1]);
    bmin[2] = min_f(omin[2], bmin[2]);
    bmax[0] = max_f(omax[0], bmax[0]);
    bmax[1] = max_f(omax[1], bmax[1]);
    bmax[2] = max_f(omax[2], bmax[2]);
}

static inline void centroid_grow(float *cmin, float *cmax, const sah_ref *r)
{
    float c0 = ref_centroid(r, 0), c1 = ref_centroid(r, 1), c2 = ref_centroid(r, 2);
    cmin[0] = min_f(c0, cmin[0]);
    cmin[1] = min_f(c1, cmin[1]);
    cmin[2] = min_f(c2, cmin[2]);
    cmax[0] = max_f(c0, cmax[0]);
    cmax[1] = max_f(c1, cmax[1]);
    cmax[2] = max_f(c2, cmax[2]);
}

typedef struct sah_split {
    int axis, plane;          /* left: bins [0, plane) of axis; -1 when none exists */
    float cost;               /* A(left) N(left) + A(right) N(right) */
    uint32_t balance;         /* max(N(left), N(right)), the tie-breaker */
    float scale[3];
} sah_split;

/* bins is scratch; empty holds empty bins, copied over it, which is cheaper than resetting
 * 96 bins field by field at each of the ~N/2 nodes. */
static sah_split find_split(const sah_ref *refs, const sah_task *t, sah_bin bins[3][SAH_BINS],
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
        box_grow(b0->bmin, b0->bmax, r->bmin, r->bmax);
        b1->count++;
        box_grow(b1->bmin, b1->bmax, r->bmin, r->bmax);
        b2->count++;
        box_grow(b2->bmin, b2->bmax, r->bmin, r->bmax);
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
        box_empty(bmin, bmax);
        for (int j = 0; j < k - 1; j++) {
            const sah_bin *bin = &bins[a][filled[j]];
            box_grow(bmin, bmax, bin->bmin, bin->bmax);
            n += bin->count;
            left_n[j] = n;
            left_cost[j] = box_area(bmin, bmax) * (float)n;
        }
        n = 0;
        box_empty(bmin, bmax);
        for (int j = k - 1; j >= 1; j--) {
            const sah_bin *bin = &bins[a][filled[j]];
            box_grow(bmin, bmax, bin->bmin, bin->bmax);
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
 * and the centroid bounds of both sides. */
static uint32_t partition_bins(sah_ref *refs, const sah_task *t, const sah_split *s,
                               float *lcmin, float *lcmax, float *rcmin, float *rcmax)
{
    int a = s->axis;
    float cmin = t->cmin[a], scale = s->scale[a];
    box_empty(lcmin, lcmax);
    box_empty(rcmin, rcmax);
    /* Each reference is classified once: the one swapped in from the end is examined next. */
    uint32_t i = t->first, j = t->first + t->count;
    while (i < j) {
        if (bin_index(ref_centroid(&refs[i], a), cmin, scale) < s->plane) {
            centroid_grow(lcmin, lcmax, &refs[i]);
            i++;
        } else {
            j--;
            sah_ref tmp = refs[i];
            refs[i] = refs[j];
            refs[j] = tmp;
            centroid_grow(rcmin, rcmax, &refs[j]);
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

static void bounds_of(const sah_ref *refs, uint32_t first, uint32_t count, float *bmin, float *bmax,
                      float *cmin, float *cmax)
{
    box_empty(bmin, bmax);
    box_empty(cmin, cmax);
    for (uint32_t i = first; i < first + count; i++) {
        box_grow(bmin, bmax, refs[i].bmin, refs[i].bmax);
        centroid_grow(cmin, cmax, &refs[i]);
    }
}

static void set_box(vkrt_gpu_node *n, const float *bmin, const float *bmax)
{
    n->bmin = (vkrt_float3){ bmin[0], bmin[1], bmin[2] };
    n->bmax = (vkrt_float3){ bmax[0], bmax[1], bmax[2] };
}

vkrt_result bvh_build_sah(core *c, const mesh *m, const bvh_build_desc *desc, bvh *out)
{
    memset(out, 0, sizeof *out);
    uint32_t n = m->tri_count;
    if (n == 0) return core_fail(c, VKRT_ERROR_EMPTY_SCENE, "the mesh has no triangles to build a BVH over");
    if (n > UINT32_MAX / 2)
        return core_fail(c, VKRT_ERROR_LIMIT, "%u triangles: a BVH holds at most %u", n, UINT32_MAX / 2);
    uint32_t max_leaf = desc && desc->max_leaf_size ? desc->max_leaf_size : SAH_DEFAULT_MAX_LEAF;
    vkrt_progress_fn progress = desc ? desc->progress : NULL;
    void *progress_user = desc ? desc->progress_user : NULL;

    vkrt_result r = VKRT_ERROR_OUT_OF_MEMORY;
    uint32_t node_cap = 2 * n - 1;
    sah_ref *refs = core_alloc_array(c, n, sizeof *refs);
    vkrt_gpu_node *nodes = core_alloc_array(c, node_cap, sizeof *nodes);
    uint32_t *order = core_alloc_array(c, n, sizeof *order);
    if (!refs || !nodes || !order) {
        r = core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory building the BVH of %u triangles", n);
        goto fail;
    }

    float root_min[3], root_max[3];
    sah_task task = { .node = 0, .first = 0, .count = n, .depth = 0 };
    box_empty(root_min, root_max);
    box_empty(task.cmin, task.cmax);
    for (uint32_t i = 0; i < n; i++) {
        const float *p = m->positions + (size_t)i * 9;
        sah_ref *ref = &refs[i];
        for (int a = 0; a < 3; a++) {
            float lo = p[a], hi = p[a];
            if (p[3 + a] < lo) lo = p[3 + a];
            if (p[3 + a] > hi) hi = p[3 + a];
            if (p[6 + a] < lo) lo = p[6 + a];
            if (p[6 + a] > hi) hi = p[6 + a];
            ref->bmin[a] = lo;
            ref->bmax[a] = hi;
        }
        ref->tri = i;
        ref->pad = 0.0f;
        box_grow(root_min, root_max, ref->bmin, ref->bmax);
        centroid_grow(task.cmin, task.cmax, ref);
    }
    set_box(&nodes[0], root_min, root_max);
    uint32_t node_count = 1;

    uint64_t placed = 0, report_at = 0, report_step = n / SAH_PROGRESS_STEPS ? n / SAH_PROGRESS_STEPS : 1;
    uint32_t depth = 0;
    /* Each split pushes one child and descends into the other, one level deeper, so the
     * stack never holds more entries than the depth cap. */
    sah_task stack[VKRT_MAX_BVH_DEPTH + 2];
    uint32_t sp = 0;
    sah_bin bins[3][SAH_BINS], empty[3][SAH_BINS];
    for (int b = 0; b < 3 * SAH_BINS; b++) {
        sah_bin *bin = &empty[b / SAH_BINS][b % SAH_BINS];
        box_empty(bin->bmin, bin->bmax);
        bin->count = 0;
        bin->pad = 0.0f;
    }
    if (progress && !progress(progress_user, "bvh", 0.0f)) goto cancelled;

    for (;;) {
        vkrt_gpu_node *node = &nodes[task.node];
        bool leaf = task.count == 1 || task.depth >= VKRT_MAX_BVH_DEPTH;
        uint32_t left_count = 0;
        float lmin[3], lmax[3], rmin[3], rmax[3], lcmin[3], lcmax[3], rcmin[3], rcmax[3];
        if (!leaf) {
            sah_split s = find_split(refs, &task, bins, &empty[0][0]);
            float nmin[3] = { node->bmin.x, node->bmin.y, node->bmin.z };
            float nmax[3] = { node->bmax.x, node->bmax.y, node->bmax.z };
            float area = box_area(nmin, nmax);
            if (s.axis >= 0) {
                if (task.count <= max_leaf && area * (float)task.count <= area + s.cost) {
                    leaf = true;
                } else {
                    left_count = partition_bins(refs, &task, &s, lcmin, lcmax, rcmin, rcmax);
                    box_empty(lmin, lmax);
                    box_empty(rmin, rmax);
                    for (int b = 0; b < SAH_BINS; b++) {
                        const sah_bin *bin = &bins[s.axis][b];
                        if (bin->count == 0) continue;
                        if (b < s.plane) box_grow(lmin, lmax, bin->bmin, bin->bmax);
                        else box_grow(rmin, rmax, bin->bmin, bin->bmax);
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
                    bounds_of(refs, task.first, left_count, lmin, lmax, lcmin, lcmax);
                    bounds_of(refs, task.first + left_count, task.count - left_count, rmin, rmax, rcmin, rcmax);
                }
            } else {
                leaf = true;
            }
            /* Binning and partitioning share bin_index(), so this never fires; it keeps a
             * future change from looping forever on an empty child. */
            if (!leaf && (left_count == 0 || left_count == task.count)) leaf = true;
        }

        if (leaf) {
            node->left_first = task.first;
            node->tri_count = task.count;
            if (task.depth > depth) depth = task.depth;
            placed += task.count;
            if (progress && (placed >= report_at || placed == n)) {
                if (!progress(progress_user, "bvh", (float)((double)placed / (double)n))) goto cancelled;
                report_at = placed + report_step;
            }
            if (sp == 0) break;
            task = stack[--sp];
            continue;
        }

        uint32_t left = node_count;
        node_count += 2;
        node->left_first = left;
        node->tri_count = 0;
        set_box(&nodes[left], lmin, lmax);
        set_box(&nodes[left + 1], rmin, rmax);
        sah_task right = { .node = left + 1, .first = task.first + left_count,
                           .count = task.count - left_count, .depth = task.depth + 1 };
        memcpy(right.cmin, rcmin, sizeof right.cmin);
        memcpy(right.cmax, rcmax, sizeof right.cmax);
        stack[sp++] = right;
        task.node = left;
        task.count = left_count;
        task.depth++;
        memcpy(task.cmin, lcmin, sizeof task.cmin);
        memcpy(task.cmax, lcmax, sizeof task.cmax);
    }

    for (uint32_t i = 0; i < n; i++) order[i] = refs[i].tri;
    core_free(c, refs);
    /* The array was sized for the worst case (one triangle per leaf); give back the rest. A
     * failed shrink only wastes memory, so it is not an error. */
    if (node_count < node_cap) {
        vkrt_gpu_node *exact = core_alloc_array(c, node_count, sizeof *exact);
        if (exact) {
            memcpy(exact, nodes, (size_t)node_count * sizeof *exact);
            core_free(c, nodes);
            nodes = exact;
        }
    }
    out->nodes = nodes;
    out->node_count = node_count;
    out->tri_order = order;
    out->tri_count = n;
    out->depth = depth;
    return VKRT_OK;

cancelled:
    r = core_fail(c, VKRT_ERROR_CANCELLED, "BVH build cancelled by the progress callback");
fail:
    core_free(c, refs);
    core_free(c, nodes);
    core_free(c, order);
    return r;
}

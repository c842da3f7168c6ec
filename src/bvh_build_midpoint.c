/* Midpoint builder: the BVH of the original project report this repository grew from (the
 * "seed"), kept so its figures (leaf-box heatmaps, SAH cost, depth) can be reproduced next
 * to the binned SAH builder.
 *
 * Rule, as the report describes it: a node is split at the midpoint of the bounding box of
 * its triangles' centroids ((v0 + v1 + v2) / 3), along the axis depth % 3; triangles whose
 * centroid lies below the midpoint go left, the rest right, reordered in place so that every
 * leaf is a range of the triangle order. Child boxes are then enlarged to enclose their
 * triangles (the split plane is not a box face). When the chosen axis does not separate the
 * centroids the other two are tried in turn; a node becomes a leaf when it holds one triangle,
 * when no axis separates its centroids (they are all equal), or at depth VKRT_MAX_BVH_DEPTH.
 * The split itself is the "middle" method of Pharr, Jakob and Humphreys, Physically Based
 * Rendering (3rd ed., section 4.3.1, SplitMethod::Middle), except that the axis cycles with
 * depth instead of being the widest one. It ignores the surface area heuristic, so leaves hold
 * one triangle wherever centroids differ and max_leaf_size has no effect.
 *
 * The midpoint is nudged to the larger centroid when rounding would put it on the smaller one
 * (centroids one ulp apart), so "separates" means exactly "the centroids differ on this axis".
 * The build is iterative with a fixed stack (the depth cap bounds it) and allocates the
 * reference array and the node array once. */
#include <float.h>
#include <string.h>

#include "bvh.h"

/* Progress is reported about this many times per build: often enough for a bar, cheap. */
#define MID_PROGRESS_STEPS 64

typedef struct mid_ref {
    float bmin[3], bmax[3], c[3];
    uint32_t tri;
} mid_ref;

typedef struct mid_task {
    uint32_t node, first, count, depth;
    float cmin[3], cmax[3]; /* centroid bounds of the task's references */
} mid_task;

static void box_empty(float *bmin, float *bmax)
{
    for (int a = 0; a < 3; a++) {
        bmin[a] = FLT_MAX;
        bmax[a] = -FLT_MAX;
    }
}

static inline float min_f(float a, float b) { return a < b ? a : b; }
static inline float max_f(float a, float b) { return a > b ? a : b; }

/* Runs for every reference at every level: written out per component with conditional
 * expressions so the compiler emits straight-line min/max instructions. */
static inline void ref_grow(float *bmin, float *bmax, float *cmin, float *cmax, const mid_ref *r)
{
    bmin[0] = min_f(r->bmin[0], bmin[0]);
    bmin[1] = min_f(r->bmin[1], bmin[1]);
    bmin[2] = min_f(r->bmin[2], bmin[2]);
    bmax[0] = max_f(r->bmax[0], bmax[0]);
    bmax[1] = max_f(r->bmax[1], bmax[1]);
    bmax[2] = max_f(r->bmax[2], bmax[2]);
    cmin[0] = min_f(r->c[0], cmin[0]);
    cmin[1] = min_f(r->c[1], cmin[1]);
    cmin[2] = min_f(r->c[2], cmin[2]);
    cmax[0] = max_f(r->c[0], cmax[0]);
    cmax[1] = max_f(r->c[1], cmax[1]);
    cmax[2] = max_f(r->c[2], cmax[2]);
}

static void set_box(vkrt_gpu_node *n, const float *bmin, const float *bmax)
{
    n->bmin = (vkrt_float3){ bmin[0], bmin[1], bmin[2] };
    n->bmax = (vkrt_float3){ bmax[0], bmax[1], bmax[2] };
}

vkrt_result bvh_build_midpoint(core *c, const mesh *m, const bvh_build_desc *desc, bvh *out)
{
    memset(out, 0, sizeof *out);
    uint32_t n = m->tri_count;
    if (n == 0) return core_fail(c, VKRT_ERROR_EMPTY_SCENE, "the mesh has no triangles to build a BVH over");
    if (n > UINT32_MAX / 2)
        return core_fail(c, VKRT_ERROR_LIMIT, "%u triangles: a BVH holds at most %u", n, UINT32_MAX / 2);
    vkrt_progress_fn progress = desc ? desc->progress : NULL;
    void *progress_user = desc ? desc->progress_user : NULL;

    vkrt_result r = VKRT_ERROR_OUT_OF_MEMORY;
    uint32_t node_cap = 2 * n - 1;
    mid_ref *refs = core_alloc_array(c, n, sizeof *refs);
    vkrt_gpu_node *nodes = core_alloc_array(c, node_cap, sizeof *nodes);
    uint32_t *order = core_alloc_array(c, n, sizeof *order);
    if (!refs || !nodes || !order) {
        r = core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory building the BVH of %u triangles", n);
        goto fail;
    }

    float root_min[3], root_max[3];
    mid_task task = { .node = 0, .first = 0, .count = n, .depth = 0 };
    box_empty(root_min, root_max);
    box_empty(task.cmin, task.cmax);
    for (uint32_t i = 0; i < n; i++) {
        const float *p = m->positions + (size_t)i * 9;
        mid_ref *ref = &refs[i];
        for (int a = 0; a < 3; a++) {
            float lo = p[a], hi = p[a];
            if (p[3 + a] < lo) lo = p[3 + a];
            if (p[3 + a] > hi) hi = p[3 + a];
            if (p[6 + a] < lo) lo = p[6 + a];
            if (p[6 + a] > hi) hi = p[6 + a];
            ref->bmin[a] = lo;
            ref->bmax[a] = hi;
            ref->c[a] = (p[a] + p[3 + a] + p[6 + a]) / 3.0f;
        }
        ref->tri = i;
        ref_grow(root_min, root_max, task.cmin, task.cmax, ref);
    }
    set_box(&nodes[0], root_min, root_max);
    uint32_t node_count = 1;

    uint64_t placed = 0, report_at = 0, report_step = n / MID_PROGRESS_STEPS ? n / MID_PROGRESS_STEPS : 1;
    uint32_t depth = 0;
    /* Each split pushes one child and descends into the other, one level deeper, so the
     * stack never holds more entries than the depth cap. */
    mid_task stack[VKRT_MAX_BVH_DEPTH + 2];
    uint32_t sp = 0;
    if (progress && !progress(progress_user, "bvh", 0.0f)) goto cancelled;

    for (;;) {
        vkrt_gpu_node *node = &nodes[task.node];
        int axis = -1;
        float mid = 0.0f;
        if (task.count > 1 && task.depth < VKRT_MAX_BVH_DEPTH) {
            for (int k = 0; k < 3 && axis < 0; k++) {
                int a = (int)((task.depth + (uint32_t)k) % 3);
                float lo = task.cmin[a], hi = task.cmax[a];
                if (!(hi > lo)) continue;
                /* Halves first, so huge coordinates do not overflow the sum. */
                mid = lo * 0.5f + hi * 0.5f;
                if (!(mid > lo) || mid > hi) mid = hi;
                axis = a;
            }
        }

        if (axis < 0) {
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

        float lmin[3], lmax[3], rmin[3], rmax[3], lcmin[3], lcmax[3], rcmin[3], rcmax[3];
        box_empty(lmin, lmax);
        box_empty(rmin, rmax);
        box_empty(lcmin, lcmax);
        box_empty(rcmin, rcmax);
        /* Each reference is classified once: the one swapped in from the end is examined next. */
        uint32_t i = task.first, j = task.first + task.count;
        while (i < j) {
            if (refs[i].c[axis] < mid) {
                ref_grow(lmin, lmax, lcmin, lcmax, &refs[i]);
                i++;
            } else {
                j--;
                mid_ref tmp = refs[i];
                refs[i] = refs[j];
                refs[j] = tmp;
                ref_grow(rmin, rmax, rcmin, rcmax, &refs[j]);
            }
        }
        uint32_t left_count = i - task.first;

        uint32_t left = node_count;
        node_count += 2;
        node->left_first = left;
        node->tri_count = 0;
        set_box(&nodes[left], lmin, lmax);
        set_box(&nodes[left + 1], rmin, rmax);
        mid_task right = { .node = left + 1, .first = task.first + left_count,
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

    for (uint32_t k = 0; k < n; k++) order[k] = refs[k].tri;
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

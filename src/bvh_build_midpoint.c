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
 * The allocation, task stack, leaves and progress are the shared frame of
 * bvh_build_common.h; this file holds the split rule only. */
#include "bvh_build_common.h"

typedef struct mid_ref {
    float bmin[3], bmax[3];
    float c[3]; /* the triangle's centroid, which this rule splits on (not its box centre) */
    uint32_t tri;
} mid_ref;

static inline void ref_grow(bvh_build_bounds *b, const mid_ref *r)
{
    bvh_build_box_grow(b->bmin, b->bmax, r->bmin, r->bmax);
    bvh_build_box_grow(b->cmin, b->cmax, r->c, r->c);
}

vkrt_result bvh_build_midpoint(core *c, const mesh *m, const bvh_build_desc *desc, bvh *out)
{
    bvh_build_state b;
    vkrt_result r = bvh_build_begin(&b, c, m, desc, sizeof(mid_ref), offsetof(mid_ref, tri), out);
    if (r != VKRT_OK) return r;
    mid_ref *refs = b.refs;

    bvh_build_bounds root;
    bvh_build_bounds_empty(&root);
    for (uint32_t i = 0; i < b.tri_count; i++) {
        const float *p = m->positions + (size_t)i * 9;
        mid_ref *ref = &refs[i];
        bvh_build_tri_box(p, ref->bmin, ref->bmax);
        for (int a = 0; a < 3; a++) ref->c[a] = (p[a] + p[3 + a] + p[6 + a]) / 3.0f;
        ref->tri = i;
        ref_grow(&root, ref);
    }

    bvh_build_task task;
    bool more = bvh_build_start(&b, &root, &task);
    while (more) {
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
            more = bvh_build_leaf(&b, &task);
            continue;
        }

        bvh_build_bounds left, right;
        bvh_build_bounds_empty(&left);
        bvh_build_bounds_empty(&right);
        /* Each reference is classified once: the one swapped in from the end is examined next. */
        uint32_t i = task.first, j = task.first + task.count;
        while (i < j) {
            if (refs[i].c[axis] < mid) {
                ref_grow(&left, &refs[i]);
                i++;
            } else {
                j--;
                mid_ref tmp = refs[i];
                refs[i] = refs[j];
                refs[j] = tmp;
                ref_grow(&right, &refs[j]);
            }
        }
        bvh_build_split(&b, &task, i - task.first, &left, &right);
    }
    return bvh_build_finish(&b, out);
}

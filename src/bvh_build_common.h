/* What the BVH builders share, so that each bvh_build_*.c holds only its rule for splitting a
 * node: the triangle reference, box arithmetic, and the frame of a top-down build (checks and
 * allocation, an explicit task stack, leaves with progress reports, child pairs, and the node
 * array shrunk to size at the end). Internal to the builders; bvh.h is the module's interface.
 *
 * A build with this frame reads:
 *
 *     bvh_build_state b;
 *     r = bvh_build_begin(&b, c, m, desc, sizeof(my_ref), offsetof(my_ref, tri), out);
 *     if (r != VKRT_OK) return r;
 *     for each triangle i: fill b.refs[i] (its box from bvh_build_tri_box()), grow the root
 *                          bounds
 *     bool more = bvh_build_start(&b, &root, &task);
 *     while (more) {
 *         the split rule: partition task's references in place and bound both sides, or not
 *         leaf:  more = bvh_build_leaf(&b, &task);   (the next task, if any, is in task)
 *         split: bvh_build_split(&b, &task, left_count, &left, &right);  (task is now left)
 *     }
 *     return bvh_build_finish(&b, out);
 *
 * Children are allocated as adjacent pairs when their parent splits, and the left subtree is
 * built before the right, so the node array is in depth-first split order. */
#ifndef VKRT_BVH_BUILD_COMMON_H
#define VKRT_BVH_BUILD_COMMON_H

#include <float.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "bvh.h"

/* Bounds of a set of references: the union of their boxes and the box of their centroids (the
 * builder decides what a reference's centroid is). */
typedef struct bvh_build_bounds {
    float bmin[3], bmax[3];
    float cmin[3], cmax[3];
} bvh_build_bounds;

/* A node still to be built: references [first, first + count) at the given depth. */
typedef struct bvh_build_task {
    uint32_t node, first, count, depth;
    float cmin[3], cmax[3]; /* centroid bounds of the task's references */
} bvh_build_task;

typedef struct bvh_build_state {
    core *c;
    uint32_t tri_count;         /* the mesh's; at the end, the references in leaves */
    uint32_t ref_cap;           /* references, order entries and half the nodes allocated */
    void *refs;                 /* ref_cap references of the builder's type */
    size_t ref_size;
    size_t tri_offset;          /* where a reference keeps its triangle index (a uint32_t) */
    vkrt_gpu_node *nodes;       /* node_cap entries (one triangle per leaf at worst) */
    uint32_t node_count, node_cap;
    uint32_t *order;
    bool order_filled;          /* the builder filled order itself; else bvh_build_finish() does */
    uint32_t depth;             /* of the deepest leaf so far */
    vkrt_progress_fn progress;  /* may be NULL */
    void *progress_user;
    uint64_t placed;            /* triangles in finished leaves */
    uint64_t report_at, report_step;
    bool cancelled;
    /* Each split pushes one child and descends into the other, one level deeper, so the
     * stack never holds more entries than the depth cap. */
    uint32_t sp;
    bvh_build_task stack[VKRT_MAX_BVH_DEPTH + 2];
} bvh_build_state;

/* The helpers below run for every reference at every level, so they live here as static
 * inline (the builders are separate files and the build has no LTO). They are written out per
 * component with conditional expressions so the compiler emits straight-line min/max
 * instructions; the new value is the first operand, which decides the sign of a zero result. */
static inline float bvh_build_min_f(float a, float b) { return a < b ? a : b; }
static inline float bvh_build_max_f(float a, float b) { return a > b ? a : b; }

static inline void bvh_build_box_empty(float *bmin, float *bmax)
{
    for (int a = 0; a < 3; a++) {
        bmin[a] = FLT_MAX;
        bmax[a] = -FLT_MAX;
    }
}

static inline void bvh_build_box_grow(float *bmin, float *bmax, const float *omin, const float *omax)
{
    bmin[0] = bvh_build_min_f(omin[0], bmin[0]);
    bmin[1] = bvh_build_min_f(omin[1], bmin[1]);
    bmin[2] = bvh_build_min_f(omin[2], bmin[2]);
    bmax[0] = bvh_build_max_f(omax[0], bmax[0]);
    bmax[1] = bvh_build_max_f(omax[1], bmax[1]);
    bmax[2] = bvh_build_max_f(omax[2], bmax[2]);
}

static inline void bvh_build_bounds_empty(bvh_build_bounds *b)
{
    bvh_build_box_empty(b->bmin, b->bmax);
    bvh_build_box_empty(b->cmin, b->cmax);
}

/* The box of the triangle whose 9 corner coordinates start at p. */
static inline void bvh_build_tri_box(const float *p, float *bmin, float *bmax)
{
    for (int a = 0; a < 3; a++) {
        float lo = p[a], hi = p[a];
        if (p[3 + a] < lo) lo = p[3 + a];
        if (p[3 + a] > hi) hi = p[3 + a];
        if (p[6 + a] < lo) lo = p[6 + a];
        if (p[6 + a] > hi) hi = p[6 + a];
        bmin[a] = lo;
        bmax[a] = hi;
    }
}

/* Zeroes *out, checks m has triangles and fits a BVH, and allocates m->tri_count references of
 * ref_size bytes (b->refs, for the builder to fill), the nodes and the triangle order. Each
 * reference holds its triangle index as a uint32_t at byte tri_offset; the layout is otherwise
 * the builder's, sized for its partition loop. On failure nothing stays allocated. */
vkrt_result bvh_build_begin(bvh_build_state *b, core *c, const mesh *m, const bvh_build_desc *desc,
                            size_t ref_size, size_t tri_offset, bvh *out);
/* bvh_build_begin() with room for ref_capacity references (at least m->tri_count), for a
 * builder that may reference a triangle from several leaves; the nodes are sized for one
 * reference a leaf. */
vkrt_result bvh_build_begin_capacity(bvh_build_state *b, core *c, const mesh *m, const bvh_build_desc *desc,
                                     size_t ref_size, size_t tri_offset, uint32_t ref_capacity, bvh *out);
/* Gives the root node the box of root and makes *task the root task, then reports progress 0.
 * Returns false when the progress callback cancels. */
bool bvh_build_start(bvh_build_state *b, const bvh_build_bounds *root, bvh_build_task *task);
/* Makes task's node a leaf, reports progress about every 1/64 of the triangles, and loads the
 * next task into *task. Returns false when no task is left or the callback cancels. */
bool bvh_build_leaf(bvh_build_state *b, bvh_build_task *task);
/* Reports progress for `placed` triangles in finished leaves (about every 1/64 of them, and
 * once all are placed) when the build has a progress callback. Returns false when the callback
 * cancels; the build then ends at bvh_build_finish(). Calling thread only. */
bool bvh_build_progress(bvh_build_state *b, uint64_t placed);
/* Reports the progress so far again (b->placed of the triangles) when the build has a progress
 * callback, for a phase that places none but takes long enough to want cancelling (the
 * parallel SAH build's top levels). Returns false when the callback cancels. Calling thread
 * only. */
bool bvh_build_poll(bvh_build_state *b);
/* Fills *sub for building one subtree of b, possibly on another thread: it shares b's nodes
 * and references, allocates child pairs from node `region` on, starts with an empty stack and
 * no deepest leaf, counts its own placed triangles and reports no progress. */
void bvh_build_subtree_state(const bvh_build_state *b, uint32_t region, bvh_build_state *sub);
/* Makes nodes[node] interior with the children nodes[pair] (box of left) and nodes[pair + 1]
 * (box of right): bvh_build_split() without the task stack, for builders that choose where a
 * pair goes. */
void bvh_build_pair(vkrt_gpu_node *nodes, uint32_t node, uint32_t pair, const bvh_build_bounds *left,
                    const bvh_build_bounds *right);
/* Gives task's node two children: the first left_count references with bounds left, the rest
 * with bounds right. The right child is pushed, and *task becomes the left child. */
void bvh_build_split(bvh_build_state *b, bvh_build_task *task, uint32_t left_count,
                     const bvh_build_bounds *left, const bvh_build_bounds *right);
/* Ends the build: on success fills out (nodes shrunk to size, the triangle order read from
 * the references) and returns VKRT_OK; after a cancel frees everything and returns
 * VKRT_ERROR_CANCELLED. The references are freed either way. */
vkrt_result bvh_build_finish(bvh_build_state *b, bvh *out);
/* Frees what bvh_build_begin() allocated, for a build that fails between begin and finish. */
void bvh_build_abort(bvh_build_state *b);

#endif

/* The binned SAH split rule, shared by the serial subtree builder (bvh_build_sah.c) and the
 * top levels that all threads split together (bvh_build_sah_parallel.c). Internal to the
 * builder; see bvh_build_sah.c for the algorithm. */
#ifndef VKRT_BVH_BUILD_SAH_H
#define VKRT_BVH_BUILD_SAH_H

#include <stdbool.h>
#include <stdint.h>

#include "bvh_build_common.h"
#include "work_pool.h"

/* Wald 2007 measured 16-32 bins within a few percent of a full sweep's tree quality. On the
 * full dragon 16 bins for every node cost 0.7% more SAH (49.10 against 48.77) for 3% less
 * build time, 8 bins 2.3% more for 6%; 32 stay for nodes of 336 references and more, and
 * smaller nodes take fewer (sah_bins_for() in bvh_build_sah.c). */
#define SAH_BINS 32
#define SAH_DEFAULT_MAX_LEAF 4

/* A triangle reference: its box, 32 bytes, so a reference never straddles two cache lines.
 * Loaded as two 4-lane vectors; the fourth lanes carry 0 and the triangle index. */
typedef struct sah_ref {
    float bmin[4]; /* [3] is 0 */
    float bmax[4]; /* [3] holds the bits of the triangle index (SAH_REF_TRI_OFFSET) */
} sah_ref;

#define SAH_REF_TRI_OFFSET (offsetof(sah_ref, bmax) + 3 * sizeof(float))

typedef struct sah_bin {
    float bmin[4], bmax[4]; /* [3] unused */
} sah_bin;

/* Boxes and counts of one node's references per bin on each axis. */
typedef struct sah_binning {
    sah_bin bin[3][SAH_BINS];
    uint32_t count[3][SAH_BINS];
    uint32_t used[3]; /* bit k set: bin k is not empty, so sweeps and resets skip the rest */
} sah_binning;

/* Where a node's centroids fall: bin = (centroid - origin) * scale. Centroids are the sums
 * bmin + bmax (twice the box centre, which orders and bins them the same and saves a
 * multiply). An axis the bins cannot resolve has scale 0, which sends everything to bin 0. */
typedef struct sah_grid {
    float origin[4], scale[4];
} sah_grid;

typedef struct sah_split {
    int axis, plane; /* left: bins [0, plane) of axis; axis -1: no binned split exists */
    float cost;      /* A(left) N(left) + A(right) N(right) */
    uint32_t balance; /* max(N(left), N(right)), the tie-breaker */
} sah_split;

/* The bin of a centroid. Binning and partitioning both use it, so they always agree on which
 * side a reference falls; a NaN lands in bin 0 instead of undefined behaviour. */
static inline int bvh_build_sah_bin_index(float centroid, float origin, float scale)
{
    float f = (centroid - origin) * scale;
    f = f > 0.0f ? f : 0.0f;
    f = f < (float)(SAH_BINS - 1) ? f : (float)(SAH_BINS - 1);
    return (int)f;
}

/* Whether r's bin on the split's axis (bvh_build_sah_bin_index()) is left of the split, without
 * the bin: for a plane p in [1, SAH_BINS - 1], the clamped and truncated f is below p exactly
 * when f < p or f is NaN (whose bin is 0), that is when !(f >= p). The clamp's two branches and
 * the conversion were a fifth of the partition's time. */
static inline bool bvh_build_sah_goes_left(const sah_ref *r, const sah_grid *g, const sah_split *s)
{
    int a = s->axis;
    float f = (r->bmin[a] + r->bmax[a] - g->origin[a]) * g->scale[a];
    return !(f >= (float)s->plane);
}

/* The references of triangles [first, first + count) of m, and their bounds. */
void bvh_build_sah_refs(const mesh *m, sah_ref *refs, uint32_t first, uint32_t count, bvh_build_bounds *bounds);
/* The grid of a node with centroid bounds t->cmin, t->cmax, its bins as many as its count of
 * references calls for (at most SAH_BINS); false when no axis can be binned. */
bool bvh_build_sah_grid(const bvh_build_task *t, sah_grid *g);
void bvh_build_sah_binning_empty(sah_binning *b);
/* Empties the bins in use, cheaper than bvh_build_sah_binning_empty() for small nodes. */
void bvh_build_sah_binning_clear(sah_binning *b);
/* Adds references [r, end) to b. */
void bvh_build_sah_bin(const sah_ref *r, const sah_ref *end, const sah_grid *g, sah_binning *b);
/* Adds the bins of from to into. */
void bvh_build_sah_binning_merge(sah_binning *into, const sah_binning *from);
typedef enum sah_decision { SAH_LEAF, SAH_SPLIT, SAH_MEDIAN } sah_decision;
/* What to do with a binned node (its box in `node`, `count` references): a leaf, the split in
 * *s, or (no binned split exists but the node is too large for a leaf) a median split. */
sah_decision bvh_build_sah_decide(const sah_binning *b, const sah_grid *g, const vkrt_gpu_node *node, uint32_t count,
                                  uint32_t max_leaf, sah_split *s);
/* The boxes of both sides of split s (left/right bmin, bmax; the centroid bounds untouched). */
void bvh_build_sah_split_boxes(const sah_binning *b, const sah_split *s, bvh_build_bounds *left, bvh_build_bounds *right);
/* Partitions references [first, end) in place so that those left of split s come first;
 * returns how many are, and sets the centroid bounds (only) of both sides. Lomuto's scheme
 * with an unconditional swap: the side a reference falls on is a coin toss the branch
 * predictor loses, a swap is cheap. The sides of a block are found first, so that where each
 * swap goes (which depends on every side before it) waits for an addition, not for a
 * classification; a reference is classified before anything moves it, as swaps touch only
 * positions already passed. */
uint32_t bvh_build_sah_partition(sah_ref *first, sah_ref *end, const sah_grid *g, const sah_split *s,
                                 bvh_build_bounds *left, bvh_build_bounds *right);
/* Sets b (boxes and centroid bounds) to the bounds of references [first, first + count). */
void bvh_build_sah_bounds(const sah_ref *refs, uint32_t first, uint32_t count, bvh_build_bounds *b);
/* The fallback where bins cannot split a node that is too large for a leaf: halves task t's
 * references by count along the widest centroid axis. False when all centroids are equal (no
 * split exists). */
bool bvh_build_sah_median_split(sah_ref *refs, const bvh_build_task *t, uint32_t *left_count, bvh_build_bounds *left,
                                bvh_build_bounds *right);
/* Sets b's centroid bounds (cmin, cmax) to those of references [r, end). */
void bvh_build_sah_centroid_bounds(const sah_ref *r, const sah_ref *end, bvh_build_bounds *b);
/* Builds the subtree of task serially with state b (whose nodes and references it shares).
 * bins must be empty and is left empty. Where pool is not NULL, stops early once its job is
 * cancelled (b->cancelled is then set). */
void bvh_build_sah_subtree(bvh_build_state *b, sah_ref *refs, bvh_build_task task, uint32_t max_leaf,
                           sah_binning *bins, const work_pool *pool);

/* Builds with desc->threads threads: the levels above SAH_TASK_REFS references by all threads
 * together, then each subtree below by one; see bvh_build_sah_parallel.c. b is begun; the
 * result is the BVH a serial build of the same decomposition gives, bit for bit, for every
 * thread count. SAH_TASK_REFS: subtrees of a few milliseconds, so even the 11k-triangle dragon
 * splits across two threads (1.5 ms against 2.3), while the full one's top levels stay few;
 * 4096 and 16384 measured the same or slower there. */
#define SAH_TASK_REFS 8192
/* Returns VKRT_OK (b then holds the tree, or b->cancelled is set) or VKRT_ERROR_OUT_OF_MEMORY
 * (b is then freed, as by bvh_build_abort()). */
vkrt_result bvh_build_sah_parallel(bvh_build_state *b, const mesh *m, uint32_t max_leaf, uint32_t threads);

#endif

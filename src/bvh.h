/* Bounding volume hierarchy over a mesh, in the flat layout the GPU reads (vkrt_gpu_node of
 * shaders/vkrt_shared.h): children of an interior node are adjacent, leaves are ranges of a
 * triangle order that the builder chooses. */
#ifndef VKRT_BVH_H
#define VKRT_BVH_H

#include <stdbool.h>
#include <stdint.h>

#include "../shaders/vkrt_shared.h"
#include "core.h"
#include "mesh.h"

typedef struct bvh {
    vkrt_gpu_node *nodes;   /* nodes[0] is the root */
    uint32_t node_count;
    uint32_t *tri_order;    /* tri_order[k]: mesh triangle stored at position k */
    uint32_t tri_count;     /* positions: the mesh's triangles, and with spatial splits their
                               duplicates */
    bool spatial_splits;    /* a triangle may be in several leaves, each box bounding the part
                               of it in the leaf (bvh_build_sbvh) */
    uint32_t depth;         /* edges on the longest root-to-leaf path, <= VKRT_MAX_BVH_DEPTH */
    double build_ms;
} bvh;

typedef struct bvh_build_desc {
    vkrt_bvh_builder builder;  /* VKRT_BVH_BUILDER_DEFAULT means binned SAH */
    uint32_t max_leaf_size;    /* 0: 4. SAH: leaves larger than this are always split when
                                  any split exists */
    uint32_t threads;          /* 0: 1. Binned SAH: the threads that build a mesh of more
                                  than SAH_TASK_REFS (8192) triangles; the BVH is the same,
                                  bit for bit, for any count */
    vkrt_progress_fn progress; /* may be NULL; false cancels; called on the calling thread */
    void *progress_user;
} bvh_build_desc;

/* Builds the chosen BVH. A mesh with no triangles is VKRT_ERROR_EMPTY_SCENE. */
vkrt_result bvh_build(core *c, const mesh *m, const bvh_build_desc *desc, bvh *out);
/* The builders behind bvh_build(); each fills out->nodes, node_count, tri_order, depth. */
vkrt_result bvh_build_midpoint(core *c, const mesh *m, const bvh_build_desc *desc, bvh *out);
vkrt_result bvh_build_sah(core *c, const mesh *m, const bvh_build_desc *desc, bvh *out);
vkrt_result bvh_build_sbvh(core *c, const mesh *m, const bvh_build_desc *desc, bvh *out);

typedef struct bvh_stats {
    uint64_t nodes, leaves;
    uint32_t depth;
    uint32_t max_leaf_triangles;
    uint64_t leaf_histogram[VKRT_LEAF_HISTOGRAM_BINS];
    double sah_cost;        /* sum over interior nodes of area/root_area * 1 (C_trav) plus over
                               leaves area/root_area * count (C_isect = 1) */
} bvh_stats;

void bvh_compute_stats(const bvh *b, bvh_stats *out);

/* Checks the invariants every builder must keep: each triangle in exactly one leaf, each
 * child box inside its parent, each leaf box enclosing its triangles' corners, children
 * in range, depth within VKRT_MAX_BVH_DEPTH. With spatial splits: each triangle in at least
 * one leaf and at most once in each, every point of it inside the box of one of its leaves
 * (sampled on a barycentric grid). Returns true when all hold; otherwise writes
 * what failed into message (of message_size bytes). */
bool bvh_validate(const bvh *b, const mesh *m, char *message, size_t message_size);

void bvh_destroy(core *c, bvh *b);

#endif

/* A 4-wide BVH collapsed from the binary one (bvh.h): each node holds up to four child boxes
 * in structure-of-arrays form, so a traversal tests them together (SIMD on the CPU). Leaves
 * name ranges of the same triangle array (BVH order): the binary tree's leaves, and its
 * subtrees of at most BVH4_LEAF_MERGE triangles, each merged into one leaf. */
#ifndef VKRT_BVH_WIDE_H
#define VKRT_BVH_WIDE_H

#include <stdint.h>

#include "bvh.h"
#include "core.h"

#define BVH4_WIDTH 4
#define BVH4_EMPTY 0xFFFFFFFFu            /* child[i] of an unused slot; its count is 0 */
/* A binary subtree of at most this many triangles (in one run of the triangle array) becomes
 * one leaf slot: the CPU tests four triangles together (cpu_trace_simd4.h), so such a leaf
 * costs it one test where the subtree cost a node visit and a test per binary leaf entered. */
#define BVH4_LEAF_MERGE 4u

/* 128 bytes, two 64-byte cache lines; the array is 64-byte aligned. Slots 0..k-1 are used,
 * the rest BVH4_EMPTY with the empty box lo = +inf, hi = -inf (traversals skip them by their
 * child, not by their box). */
typedef struct bvh4_node {
    float lo[3][BVH4_WIDTH];             /* lo[axis][slot]: child boxes, structure of arrays */
    float hi[3][BVH4_WIDTH];
    uint32_t child[BVH4_WIDTH];          /* interior slot: index of the child bvh4_node; leaf slot:
                                            first triangle (BVH order, the same triangle array as
                                            the binary BVH's); unused: BVH4_EMPTY */
    uint32_t count[BVH4_WIDTH];          /* 0: interior (or unused); else triangles in the leaf */
} bvh4_node;

_Static_assert(sizeof(bvh4_node) == 128, "bvh4_node is two cache lines");

typedef struct bvh4 {
    bvh4_node *nodes;                    /* nodes[0] the root; its slots hold the root's children
                                            (a root that is a leaf becomes one leaf slot) */
    uint32_t node_count;
    float root_lo[3], root_hi[3];        /* the root's box */
    uint32_t depth;                      /* levels: 1 for a root alone */
    void *allocation;                    /* what core_alloc returned; nodes is aligned within it */
} bvh4;

/* Collapses the binary BVH b into *out: starting from a node's two children, the child with
 * the largest surface area is replaced by its two children until there are four or only
 * leaves are left (the usual SAH-style collapse: the big boxes are the ones rays enter most
 * often); a subtree of at most BVH4_LEAF_MERGE triangles counts as a leaf and becomes one
 * slot. Boxes are copied bit for bit from the binary nodes, so a box test gives the binary
 * traversal's answer for the same box. b must be valid (bvh_validate); it is borrowed until
 * the call returns. Returns VKRT_OK, VKRT_ERROR_INVALID_ARGUMENT for an empty b, or
 * VKRT_ERROR_OUT_OF_MEMORY; on failure *out is zeroed. */
vkrt_result bvh4_collapse(core *c, const bvh *b, bvh4 *out);

/* Frees w's nodes and zeroes it; NULL and a zeroed bvh4 are no-ops. */
void bvh4_destroy(core *c, bvh4 *w);

#endif

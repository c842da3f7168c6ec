/* A 4-wide BVH collapsed from the binary one (bvh.h): every node holds the boxes of up to four
 * children side by side, so a traversal step tests them from one fetch. Leaves are the binary
 * BVH's leaves, ranges of the same triangle order. */
#ifndef VKRT_BVH_WIDE_H
#define VKRT_BVH_WIDE_H

#include <stdint.h>

#include "bvh.h"
#include "core.h"

#define BVH4_WIDTH 4
#define BVH4_EMPTY 0xFFFFFFFFu /* child[i] of an unused slot; its count is 0 */

typedef struct bvh4_node {
    float lo[3][BVH4_WIDTH];      /* lo[axis][slot]: the child boxes, structure of arrays */
    float hi[3][BVH4_WIDTH];
    uint32_t child[BVH4_WIDTH];   /* interior slot: the child node; leaf slot: its first triangle
                                     (BVH order); unused: BVH4_EMPTY */
    uint32_t count[BVH4_WIDTH];   /* 0: interior (or unused); else the leaf's triangles */
} bvh4_node;

typedef struct bvh4 {
    bvh4_node *nodes;             /* nodes[0] is the root; its slots hold the root's children (a
                                     binary root that is a leaf becomes one leaf slot) */
    uint32_t node_count;
    float root_lo[3], root_hi[3]; /* the root's box */
    uint32_t depth;               /* levels of wide nodes */
} bvh4;

/* Used slots come first. Boxes are the binary nodes' bits. */
vkrt_result bvh4_collapse(core *c, const bvh *b, bvh4 *out);
void bvh4_destroy(core *c, bvh4 *w);

#endif

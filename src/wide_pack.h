/* The wide traversal's device arrays (VKRT_SPEC_WIDE; the layout is in shaders/vkrt_shared.h):
 * the 4-wide BVH collapsed from the scene's binary one and its triangles, whole, both as RGBA32UI
 * texels. Built on the host just before the upload and freed after it. */
#ifndef VKRT_WIDE_PACK_H
#define VKRT_WIDE_PACK_H

#include <stdbool.h>
#include <stdint.h>

#include "../shaders/vkrt_shared.h"
#include "bvh.h"
#include "core.h"

typedef struct wide_arrays {
    uint32_t *node_texels;  /* 4 words a texel, VKRT_WIDE_NODE_TEXELS texels a node */
    uint32_t node_count;
    uint32_t *tri_texels;   /* VKRT_WIDE_TRI_WORDS words a triangle: corners and prim_id */
    uint32_t tri_count;
    uint64_t tri_texel_count; /* through the last triangle's last texel */
    uint32_t depth;         /* levels of wide nodes */
} wide_arrays;

/* Whether the wide traversal can trace this BVH: its stack must hold every entry a descent
 * pushes and prim_id must leave the VKRT_TRACE_TRI_LAST bit free. The stack holds groups (one
 * entry each, shaders/traverse_wide.glsl), each of a proper ancestor of the lane's own group's
 * node and no two of one level: fewer entries than there are levels, plus the group a
 * suspension pushes, so `wide_depth` levels need `wide_depth` entries. Every BVH within
 * VKRT_MAX_BVH_DEPTH fits (a wide level spans at least one binary level); the single entries
 * pushed before groups needed three a level, which sent wide depths above 21 to the binary
 * traversal. */
bool wide_traversal_fits(uint32_t wide_depth, uint32_t tri_count);

/* Fills *out from the binary BVH and its packed triangles (in BVH order), the packing on
 * `threads` threads (0 counts as 1). */
vkrt_result wide_pack(core *c, const bvh *b, const vkrt_gpu_tri *tris, uint32_t threads, wide_arrays *out);
void wide_arrays_destroy(core *c, wide_arrays *w);

#endif

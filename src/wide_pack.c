#include "wide_pack.h"

#include <string.h>

#include "bvh_wide.h"

static uint32_t float_bits(float f)
{
    uint32_t u;
    memcpy(&u, &f, sizeof u);
    return u;
}

bool wide_traversal_fits(uint32_t wide_depth, uint32_t tri_count)
{
    return (uint64_t)3 * wide_depth <= VKRT_TRAVERSAL_STACK_SIZE && tri_count < VKRT_TRACE_TRI_LAST;
}

static void pack_node(const bvh4_node *n, uint32_t *texels)
{
    for (int a = 0; a < 3; a++)
        for (int s = 0; s < BVH4_WIDTH; s++) {
            texels[4 * a + s] = float_bits(n->lo[a][s]);
            texels[4 * (3 + a) + s] = float_bits(n->hi[a][s]);
        }
    for (int s = 0; s < BVH4_WIDTH; s++)
        texels[24 + s] = n->child[s] == BVH4_EMPTY ? VKRT_WIDE_NO_CHILD
                         : n->count[s]             ? VKRT_WIDE_LEAF | n->child[s]
                                                   : n->child[s];
}

static void pack_corner(vkrt_float3 v, uint32_t w, uint32_t *texel)
{
    texel[0] = float_bits(v.x);
    texel[1] = float_bits(v.y);
    texel[2] = float_bits(v.z);
    texel[3] = w;
}

vkrt_result wide_pack(core *c, const bvh *b, const vkrt_gpu_tri *tris, wide_arrays *out)
{
    memset(out, 0, sizeof *out);
    bvh4 w;
    vkrt_result r = bvh4_collapse(c, b, &w);
    if (r != VKRT_OK) return r;
    out->node_texels = core_alloc_array(c, (size_t)w.node_count * VKRT_WIDE_NODE_TEXELS, 4 * sizeof(uint32_t));
    out->tri_texels = core_alloc_array(c, (size_t)b->tri_count * VKRT_TRACE_TRI_TEXELS, 4 * sizeof(uint32_t));
    if (!out->node_texels || !out->tri_texels) {
        bvh4_destroy(c, &w);
        wide_arrays_destroy(c, out);
        return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory packing the wide BVH of %u triangles",
                         b->tri_count);
    }
    for (uint32_t i = 0; i < w.node_count; i++)
        pack_node(&w.nodes[i], out->node_texels + (size_t)i * VKRT_WIDE_NODE_TEXELS * 4);
    for (uint32_t i = 0; i < b->tri_count; i++) {
        uint32_t *t = out->tri_texels + (size_t)i * VKRT_TRACE_TRI_TEXELS * 4;
        pack_corner(tris[i].v0, tris[i].prim_id, t);
        pack_corner(tris[i].v1, 0, t + 4);
        pack_corner(tris[i].v2, 0, t + 8);
    }
    /* Leaves partition the triangle array: mark where each ends. */
    for (uint32_t i = 0; i < b->node_count; i++) {
        const vkrt_gpu_node *n = &b->nodes[i];
        if (n->tri_count) out->tri_texels[(size_t)(n->left_first + n->tri_count - 1) * VKRT_TRACE_TRI_TEXELS * 4 + 3] |=
            VKRT_TRACE_TRI_LAST;
    }
    out->node_count = w.node_count;
    out->tri_count = b->tri_count;
    out->depth = w.depth;
    bvh4_destroy(c, &w);
    return VKRT_OK;
}

void wide_arrays_destroy(core *c, wide_arrays *w)
{
    core_free(c, w->node_texels);
    core_free(c, w->tri_texels);
    memset(w, 0, sizeof *w);
}

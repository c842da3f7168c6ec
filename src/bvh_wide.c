/* Collapse of the binary BVH into a 4-wide one: a wide node starts from a binary interior
 * node's two children and opens the largest-area interior child until it has four (the
 * surface-area order keeps the boxes a ray is likeliest to enter in the upper levels). */
#include "bvh_wide.h"

#include <string.h>

static float node_area(const vkrt_gpu_node *n)
{
    float dx = n->bmax.x - n->bmin.x, dy = n->bmax.y - n->bmin.y, dz = n->bmax.z - n->bmin.z;
    return dx * dy + dy * dz + dz * dx;
}

static void set_slot(bvh4_node *w, uint32_t slot, const vkrt_gpu_node *n)
{
    const float lo[3] = { n->bmin.x, n->bmin.y, n->bmin.z }, hi[3] = { n->bmax.x, n->bmax.y, n->bmax.z };
    for (int a = 0; a < 3; a++) {
        w->lo[a][slot] = lo[a];
        w->hi[a][slot] = hi[a];
    }
    w->child[slot] = n->tri_count ? n->left_first : BVH4_EMPTY; /* interior: patched by the caller */
    w->count[slot] = n->tri_count;
}

/* A binary interior node still to become wide node `wide`, `depth` levels down. */
typedef struct collapse_task {
    uint32_t binary, wide, depth;
} collapse_task;

vkrt_result bvh4_collapse(core *c, const bvh *b, bvh4 *out)
{
    memset(out, 0, sizeof *out);
    /* At most one wide node per binary interior node (each wide node consumes one or more). */
    const uint32_t cap = b->node_count;
    out->nodes = core_alloc_array(c, cap, sizeof *out->nodes);
    collapse_task *todo = core_alloc_array(c, cap, sizeof *todo);
    if (!out->nodes || !todo) {
        core_free(c, todo);
        bvh4_destroy(c, out);
        return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory collapsing a BVH of %u nodes", b->node_count);
    }
    const vkrt_gpu_node *root = &b->nodes[0];
    out->root_lo[0] = root->bmin.x, out->root_lo[1] = root->bmin.y, out->root_lo[2] = root->bmin.z;
    out->root_hi[0] = root->bmax.x, out->root_hi[1] = root->bmax.y, out->root_hi[2] = root->bmax.z;
    uint32_t count = 1, pending = 0;
    todo[pending++] = (collapse_task){ 0, 0, 1 };
    while (pending) {
        const uint32_t binary = todo[--pending].binary, wide = todo[pending].wide, depth = todo[pending].depth;
        if (depth > out->depth) out->depth = depth;
        uint32_t slots[BVH4_WIDTH], used = 0;
        const vkrt_gpu_node *n = &b->nodes[binary];
        if (n->tri_count) {
            slots[used++] = binary;
        } else {
            slots[used++] = n->left_first;
            slots[used++] = n->left_first + 1;
        }
        while (used < BVH4_WIDTH) {
            int open = -1;
            float best = -1.0f;
            for (uint32_t s = 0; s < used; s++) {
                const vkrt_gpu_node *k = &b->nodes[slots[s]];
                if (!k->tri_count && node_area(k) > best) best = node_area(k), open = (int)s;
            }
            if (open < 0) break;
            const uint32_t first = b->nodes[slots[open]].left_first;
            slots[open] = first;
            slots[used++] = first + 1;
        }
        bvh4_node *w = &out->nodes[wide];
        memset(w, 0, sizeof *w);
        for (uint32_t s = 0; s < BVH4_WIDTH; s++) w->child[s] = BVH4_EMPTY;
        for (uint32_t s = 0; s < used; s++) {
            const vkrt_gpu_node *k = &b->nodes[slots[s]];
            set_slot(w, s, k);
            if (!k->tri_count) {
                w->child[s] = count;
                todo[pending++] = (collapse_task){ slots[s], count++, depth + 1 };
            }
        }
    }
    core_free(c, todo);
    out->node_count = count;
    return VKRT_OK;
}

void bvh4_destroy(core *c, bvh4 *w)
{
    core_free(c, w->nodes);
    memset(w, 0, sizeof *w);
}

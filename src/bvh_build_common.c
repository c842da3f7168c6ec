/* The frame of a top-down BVH build that every builder shares; see bvh_build_common.h. */
#include "bvh_build_common.h"

#include <string.h>

/* Progress is reported about this many times per build: often enough for a bar, cheap. */
#define BVH_BUILD_PROGRESS_STEPS 64

static void set_box(vkrt_gpu_node *n, const float *bmin, const float *bmax)
{
    n->bmin = (vkrt_float3){ bmin[0], bmin[1], bmin[2] };
    n->bmax = (vkrt_float3){ bmax[0], bmax[1], bmax[2] };
}

static void free_all(bvh_build_state *b)
{
    core_free(b->c, b->refs);
    core_free(b->c, b->nodes);
    core_free(b->c, b->order);
}

vkrt_result bvh_build_begin(bvh_build_state *b, core *c, const mesh *m, const bvh_build_desc *desc,
                            size_t ref_size, size_t tri_offset, bvh *out)
{
    return bvh_build_begin_capacity(b, c, m, desc, ref_size, tri_offset, m->tri_count, out);
}

vkrt_result bvh_build_begin_capacity(bvh_build_state *b, core *c, const mesh *m, const bvh_build_desc *desc,
                                     size_t ref_size, size_t tri_offset, uint32_t ref_capacity, bvh *out)
{
    memset(out, 0, sizeof *out);
    memset(b, 0, offsetof(bvh_build_state, stack)); /* the stack is written before it is read */
    uint32_t n = m->tri_count;
    if (n == 0) return core_fail(c, VKRT_ERROR_EMPTY_SCENE, "the mesh has no triangles to build a BVH over");
    if (ref_capacity < n) ref_capacity = n;
    if (ref_capacity > UINT32_MAX / 2)
        return core_fail(c, VKRT_ERROR_LIMIT, "%u triangle references: a BVH holds at most %u", ref_capacity,
                         UINT32_MAX / 2);
    b->c = c;
    b->tri_count = n;
    b->ref_cap = ref_capacity;
    b->ref_size = ref_size;
    b->tri_offset = tri_offset;
    b->node_cap = 2 * ref_capacity - 1;
    b->progress = desc ? desc->progress : NULL;
    b->progress_user = desc ? desc->progress_user : NULL;
    b->report_step = n / BVH_BUILD_PROGRESS_STEPS ? n / BVH_BUILD_PROGRESS_STEPS : 1;

    b->refs = core_alloc_array(c, ref_capacity, ref_size);
    b->nodes = core_alloc_array(c, b->node_cap, sizeof *b->nodes);
    b->order = core_alloc_array(c, ref_capacity, sizeof *b->order);
    if (!b->refs || !b->nodes || !b->order) {
        vkrt_result r = core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory building the BVH of %u triangles", n);
        free_all(b);
        return r;
    }
    return VKRT_OK;
}

/* A failed progress callback ends the build at the next bvh_build_finish(). */
static bool report(bvh_build_state *b, float fraction)
{
    if (b->progress(b->progress_user, "bvh", fraction)) return true;
    b->cancelled = true;
    return false;
}

bool bvh_build_start(bvh_build_state *b, const bvh_build_bounds *root, bvh_build_task *task)
{
    set_box(&b->nodes[0], root->bmin, root->bmax);
    b->node_count = 1;
    *task = (bvh_build_task){ .node = 0, .first = 0, .count = b->tri_count, .depth = 0 };
    memcpy(task->cmin, root->cmin, sizeof task->cmin);
    memcpy(task->cmax, root->cmax, sizeof task->cmax);
    return !b->progress || report(b, 0.0f);
}

bool bvh_build_progress(bvh_build_state *b, uint64_t placed)
{
    if (!b->progress || placed < b->report_at) return true;
    /* The next report a step later, or at the end, which is reported once. */
    if (placed >= b->tri_count) b->report_at = UINT64_MAX;
    else b->report_at = b->tri_count - placed > b->report_step ? placed + b->report_step : b->tri_count;
    return report(b, (float)((double)placed / (double)b->tri_count));
}

bool bvh_build_poll(bvh_build_state *b)
{
    return !b->progress || report(b, (float)((double)b->placed / (double)b->tri_count));
}

void bvh_build_subtree_state(const bvh_build_state *b, uint32_t region, bvh_build_state *sub)
{
    memset(sub, 0, offsetof(bvh_build_state, stack));
    sub->c = b->c;
    sub->tri_count = b->tri_count;
    sub->ref_cap = b->ref_cap;
    sub->refs = b->refs;
    sub->ref_size = b->ref_size;
    sub->tri_offset = b->tri_offset;
    sub->nodes = b->nodes;
    sub->node_count = region;
    sub->node_cap = b->node_cap;
    sub->order = b->order;
}

bool bvh_build_leaf(bvh_build_state *b, bvh_build_task *task)
{
    vkrt_gpu_node *node = &b->nodes[task->node];
    node->left_first = task->first;
    node->tri_count = task->count;
    if (task->depth > b->depth) b->depth = task->depth;
    b->placed += task->count;
    if (b->progress && !bvh_build_progress(b, b->placed)) return false;
    if (b->sp == 0) return false;
    *task = b->stack[--b->sp];
    return true;
}

void bvh_build_pair(vkrt_gpu_node *nodes, uint32_t node, uint32_t pair, const bvh_build_bounds *left,
                    const bvh_build_bounds *right)
{
    nodes[node].left_first = pair;
    nodes[node].tri_count = 0;
    set_box(&nodes[pair], left->bmin, left->bmax);
    set_box(&nodes[pair + 1], right->bmin, right->bmax);
}

void bvh_build_split(bvh_build_state *b, bvh_build_task *task, uint32_t left_count,
                     const bvh_build_bounds *left, const bvh_build_bounds *right)
{
    uint32_t first_child = b->node_count;
    b->node_count += 2;
    bvh_build_pair(b->nodes, task->node, first_child, left, right);
    bvh_build_task r = { .node = first_child + 1, .first = task->first + left_count,
                         .count = task->count - left_count, .depth = task->depth + 1 };
    memcpy(r.cmin, right->cmin, sizeof r.cmin);
    memcpy(r.cmax, right->cmax, sizeof r.cmax);
    b->stack[b->sp++] = r;
    task->node = first_child;
    task->count = left_count;
    task->depth++;
    memcpy(task->cmin, left->cmin, sizeof task->cmin);
    memcpy(task->cmax, left->cmax, sizeof task->cmax);
}

void bvh_build_abort(bvh_build_state *b) { free_all(b); }

vkrt_result bvh_build_finish(bvh_build_state *b, bvh *out)
{
    core *c = b->c;
    if (b->cancelled) {
        vkrt_result r = core_fail(c, VKRT_ERROR_CANCELLED, "BVH build cancelled by the progress callback");
        free_all(b);
        return r;
    }
    const unsigned char *tri = (const unsigned char *)b->refs + b->tri_offset;
    for (uint32_t k = 0; k < b->tri_count && !b->order_filled; k++)
        memcpy(&b->order[k], tri + k * b->ref_size, sizeof b->order[k]);
    core_free(c, b->refs);
    /* The arrays were sized for the worst case (one triangle per leaf; a spatial-split build's
     * order for its reference budget): give back the rest. */
    vkrt_gpu_node *nodes = b->nodes;
    if (b->node_count < b->node_cap) nodes = core_shrink(c, nodes, (size_t)b->node_count * sizeof *nodes);
    uint32_t *order = b->order;
    if (b->tri_count < b->ref_cap) order = core_shrink(c, order, (size_t)b->tri_count * sizeof *order);
    out->nodes = nodes;
    out->node_count = b->node_count;
    out->tri_order = order;
    out->tri_count = b->tri_count;
    out->depth = b->depth;
    return VKRT_OK;
}

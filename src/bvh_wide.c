/* The binary BVH collapsed to four children per node: Wald, Benthin, Boulos, "Getting Rid of
 * Packets: Efficient SIMD Single-Ray Traversal using Multi-branching BVHs", RT 2008, and
 * Dammertz, Hanika, Keller, "Shallow Bounding Volume Hierarchies for Fast SIMD Ray Tracing of
 * Incoherent Rays", EGSR 2008. Each wide node takes a binary node's two children and keeps
 * opening the one of largest surface area (as Embree's wide builders choose the child to
 * split), which removes the interior nodes rays are most likely to enter. Small subtrees become
 * leaves of up to four triangles, as Embree's wide BVHs hold them, where the binary SAH build
 * (which prices a triangle test as a node visit) left them as a node over leaves of one or two. */
#include "bvh_wide.h"

#include <assert.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#define NODE_ALIGN 64

static double node_area(const vkrt_gpu_node *n)
{
    double dx = (double)n->bmax.x - n->bmin.x, dy = (double)n->bmax.y - n->bmin.y,
           dz = (double)n->bmax.z - n->bmin.z;
    return 2.0 * (dx * dy + dy * dz + dz * dx);
}

/* The triangles under binary node `node` as one leaf, where they are few enough
 * (BVH4_LEAF_MERGE) and one contiguous run of the triangle array (the builders partition
 * triangles in place, so a subtree's leaves lie side by side, though a spatial-split subtree's
 * need not): returns their count and sets *first; 0 where the subtree stays a subtree. A binary
 * leaf is returned as it is, whatever its size. The walk gives up at the first leaf past the
 * limit, so it reads a handful of nodes. */
static uint32_t subtree_leaf(const bvh *b, uint32_t node, uint32_t *first)
{
    const vkrt_gpu_node *top = &b->nodes[node];
    if (top->tri_count != 0) {
        *first = top->left_first;
        return top->tri_count;
    }
    /* At most BVH4_LEAF_MERGE leaves are read, so at most that many right children wait at
     * once on the way; a deeper subtree holds more triangles and is not merged. */
    uint32_t stack[BVH4_LEAF_MERGE], sp = 0, count = 0, lo = UINT32_MAX, hi = 0, at = node;
    for (;;) {
        const vkrt_gpu_node *n = &b->nodes[at];
        if (n->tri_count == 0) {
            if (sp == BVH4_LEAF_MERGE) return 0;
            stack[sp++] = n->left_first + 1;
            at = n->left_first;
            continue;
        }
        if ((count += n->tri_count) > BVH4_LEAF_MERGE) return 0;
        if (n->left_first < lo) lo = n->left_first;
        if (n->left_first + n->tri_count > hi) hi = n->left_first + n->tri_count;
        if (sp == 0) break;
        at = stack[--sp];
    }
    /* The leaves hold disjoint ranges, so they make one run exactly when its span is their sum. */
    if (hi - lo != count) return 0;
    *first = lo;
    return count;
}

/* What a slot may be opened for: its area, or -1 for a leaf (never opened): a binary leaf or a
 * subtree merged into one (subtree_leaf). An interior slot's children are fetched ahead, as
 * they are read next if it is opened or pushed. */
static double opening_area(const bvh *b, const vkrt_gpu_node *n)
{
    uint32_t first;
    if (n->tri_count != 0 || subtree_leaf(b, (uint32_t)(n - b->nodes), &first) != 0) return -1.0;
    __builtin_prefetch(&b->nodes[n->left_first]);
    return node_area(n);
}

/* The binary nodes that become the slots of one wide node: start with `node`'s children and
 * open the interior one of largest area (the first such in slot order on a tie, so the
 * result is deterministic) while a slot is free. Returns the slot count, 2 to 4. Each slot's
 * area is computed once, when its node is read. */
static uint32_t gather_slots(const bvh *b, uint32_t node, uint32_t slots[BVH4_WIDTH])
{
    uint32_t n = 2;
    double area[BVH4_WIDTH];
    slots[0] = b->nodes[node].left_first;
    slots[1] = slots[0] + 1;
    area[0] = opening_area(b, &b->nodes[slots[0]]);
    area[1] = opening_area(b, &b->nodes[slots[1]]);
    while (n < BVH4_WIDTH) {
        uint32_t open = BVH4_EMPTY;
        double largest = -1.0;
        for (uint32_t i = 0; i < n; i++) {
            if (area[i] > largest) {
                largest = area[i];
                open = i;
            }
        }
        if (open == BVH4_EMPTY) break;
        /* Its children take its slot and the next one, so siblings stay side by side. */
        uint32_t left = b->nodes[slots[open]].left_first;
        memmove(&slots[open + 2], &slots[open + 1], (n - open - 1) * sizeof *slots);
        memmove(&area[open + 2], &area[open + 1], (n - open - 1) * sizeof *area);
        slots[open] = left;
        slots[open + 1] = left + 1;
        area[open] = opening_area(b, &b->nodes[left]);
        area[open + 1] = opening_area(b, &b->nodes[left + 1]);
        n++;
    }
    return n;
}

static void set_slot_box(bvh4_node *w, uint32_t i, const vkrt_gpu_node *n)
{
    w->lo[0][i] = n->bmin.x, w->lo[1][i] = n->bmin.y, w->lo[2][i] = n->bmin.z;
    w->hi[0][i] = n->bmax.x, w->hi[1][i] = n->bmax.y, w->hi[2][i] = n->bmax.z;
}

static void clear_node(bvh4_node *w)
{
    for (uint32_t i = 0; i < BVH4_WIDTH; i++) {
        for (int a = 0; a < 3; a++) w->lo[a][i] = INFINITY, w->hi[a][i] = -INFINITY;
        w->child[i] = BVH4_EMPTY;
        w->count[i] = 0;
    }
}

vkrt_result bvh4_collapse(core *c, const bvh *b, bvh4 *out)
{
    if (!out) return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "bvh4_collapse: out is NULL");
    memset(out, 0, sizeof *out);
    if (!b || !b->nodes || b->node_count == 0)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "bvh4_collapse: the binary BVH has no nodes");
    /* Every wide node stands for one binary interior node, so the interior count bounds them
     * (a root leaf still needs its one node). Every interior node has two children, so a tree
     * of N nodes has (N - 1) / 2 of them: no pass over the whole array to count. */
    uint32_t capacity = 1 + (b->node_count - 1) / 2;
    uint64_t bytes = (uint64_t)capacity * sizeof(bvh4_node) + NODE_ALIGN;
    if (bytes <= SIZE_MAX) out->allocation = core_alloc(c, (size_t)bytes);
    if (!out->allocation)
        return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory for %u 4-wide BVH nodes", capacity);
    uintptr_t base = ((uintptr_t)out->allocation + NODE_ALIGN - 1) & ~(uintptr_t)(NODE_ALIGN - 1);
    out->nodes = (bvh4_node *)base;
    const vkrt_gpu_node *root = &b->nodes[0];
    out->root_lo[0] = root->bmin.x, out->root_lo[1] = root->bmin.y, out->root_lo[2] = root->bmin.z;
    out->root_hi[0] = root->bmax.x, out->root_hi[1] = root->bmax.y, out->root_hi[2] = root->bmax.z;
    out->node_count = 1;
    out->depth = 1;
    clear_node(&out->nodes[0]);
    if (root->tri_count != 0) {
        set_slot_box(&out->nodes[0], 0, root);
        out->nodes[0].child[0] = root->left_first;
        out->nodes[0].count[0] = root->tri_count;
        return VKRT_OK;
    }
    /* Depth first with an explicit stack: each wide node spans at least one binary level, so
     * a valid tree (at most VKRT_MAX_BVH_DEPTH deep) holds at most BVH4_WIDTH - 1 waiting
     * siblings per level. */
    struct { uint32_t binary, wide, level; } stack[BVH4_WIDTH * (VKRT_MAX_BVH_DEPTH + 2)];
    uint32_t sp = 0;
    stack[sp].binary = 0, stack[sp].wide = 0, stack[sp++].level = 1;
    while (sp) {
        sp--;
        uint32_t binary = stack[sp].binary, level = stack[sp].level;
        bvh4_node *w = &out->nodes[stack[sp].wide];
        if (level > out->depth) out->depth = level;
        uint32_t slots[BVH4_WIDTH];
        uint32_t n = gather_slots(b, binary, slots);
        for (uint32_t i = 0; i < n; i++) {
            const vkrt_gpu_node *s = &b->nodes[slots[i]];
            set_slot_box(w, i, s);
            uint32_t first = 0, count = subtree_leaf(b, slots[i], &first);
            if (count != 0) {
                w->child[i] = first;
                w->count[i] = count;
                continue;
            }
            assert(out->node_count < capacity);
            uint32_t k = out->node_count++;
            clear_node(&out->nodes[k]);
            w->child[i] = k;
        }
        /* The interior slots pushed last to first, so that the first is collapsed first: the
         * binary nodes are then read in the order they are stored (depth first, left before
         * right), which the hardware prefetcher follows. Popping the last slot first took 1.4x
         * the time on the full dragon. The children are fetched ahead as each is pushed. */
        for (uint32_t i = n; i-- > 0;) {
            if (w->count[i] != 0) continue;
            assert(sp < sizeof stack / sizeof stack[0]);
            const vkrt_gpu_node *s = &b->nodes[slots[i]];
            stack[sp].binary = slots[i], stack[sp].wide = w->child[i], stack[sp++].level = level + 1;
            __builtin_prefetch(&b->nodes[s->left_first]);
            __builtin_prefetch(&b->nodes[s->left_first + 1]);
        }
    }
    return VKRT_OK;
}

void bvh4_destroy(core *c, bvh4 *w)
{
    if (!w) return;
    core_free(c, w->allocation);
    memset(w, 0, sizeof *w);
}

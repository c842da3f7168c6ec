#include "wide_pack.h"

#include <math.h>
#include <string.h>

#include "bvh_wide.h"

#define NO_VERTEX 0xFFFFFFFFu

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

/* The decoded value of quantised coordinate q, as visit_wide_node computes it: float
 * arithmetic, no fused multiply-add (ISO C mode, -ffp-contract=off; `precise` in the shader). */
static float dequantise(float origin, float scale, uint32_t q)
{
    return origin + (float)q * scale;
}

static float scale_of(uint32_t biased_exponent)
{
    uint32_t bits = biased_exponent << 23;
    float f;
    memcpy(&f, &bits, sizeof f);
    return f;
}

/* One axis of a node: the origin (the children's lowest bound) and a power-of-two scale
 * whose 255 steps reach the highest, then each child's bounds rounded outwards to steps, each
 * checked by decoding it as the shader will: a decoded box never lies inside the true one, so
 * the wide traversal culls nothing the binary one enters. */
static void quantise_axis(const bvh4_node *n, int axis, uint32_t used, float *out_origin, uint32_t *out_exponent,
                          uint32_t q_lo[BVH4_WIDTH], uint32_t q_hi[BVH4_WIDTH])
{
    float lo = n->lo[axis][0], hi = n->hi[axis][0];
    for (uint32_t s = 1; s < used; s++) {
        lo = n->lo[axis][s] < lo ? n->lo[axis][s] : lo;
        hi = n->hi[axis][s] > hi ? n->hi[axis][s] : hi;
    }
    /* The smallest exponent whose 255 steps from lo reach hi (0: a flat axis, scale 0). */
    uint32_t e = 0;
    if (hi > lo) {
        /* From the exponent of (hi - lo) / 255 (frexp), up while 255 steps fall short. */
        int exponent;
        frexp(((double)hi - lo) / 255.0, &exponent);
        e = exponent + 126 < 1 ? 1 : exponent + 126 > 254 ? 254 : (uint32_t)(exponent + 126);
        while (e > 1 && dequantise(lo, scale_of(e - 1), 255) >= hi) e--;
        while (e < 254 && dequantise(lo, scale_of(e), 255) < hi) e++;
    }
    const float scale = scale_of(e);
    for (uint32_t s = 0; s < BVH4_WIDTH; s++) {
        q_lo[s] = q_hi[s] = 0;
        if (s >= used || e == 0) continue;
        /* The step the division points to, then moved until its decoding is at or below the
         * child's lower bound (at or above its upper one): the division's rounding and the
         * decoding's are each a fraction of a step, so this takes a move or two. */
        const double lo_steps = floor(((double)n->lo[axis][s] - lo) / scale);
        const double hi_steps = ceil(((double)n->hi[axis][s] - lo) / scale);
        uint32_t a = lo_steps <= 0.0 ? 0 : lo_steps >= 255.0 ? 255 : (uint32_t)lo_steps;
        uint32_t b = hi_steps <= 0.0 ? 0 : hi_steps >= 255.0 ? 255 : (uint32_t)hi_steps;
        while (a > 0 && dequantise(lo, scale, a) > n->lo[axis][s]) a--;
        while (a < 255 && dequantise(lo, scale, a + 1) <= n->lo[axis][s]) a++;
        while (b < 255 && dequantise(lo, scale, b) < n->hi[axis][s]) b++;
        while (b > 0 && dequantise(lo, scale, b - 1) >= n->hi[axis][s]) b--;
        q_lo[s] = a;
        q_hi[s] = b;
    }
    *out_origin = lo;
    *out_exponent = e;
}

static void pack_node(const bvh4_node *n, uint32_t *texels)
{
    uint32_t used = 0;
    while (used < BVH4_WIDTH && n->child[used] != BVH4_EMPTY) used++;
    uint32_t q[2][3][BVH4_WIDTH], exponents = 0;
    for (int a = 0; a < 3; a++) {
        float origin;
        uint32_t e;
        quantise_axis(n, a, used, &origin, &e, q[0][a], q[1][a]);
        texels[a] = float_bits(origin);
        exponents |= e << (8 * a);
    }
    texels[3] = exponents;
    /* Texels 1 and 2: lo.x, lo.y, lo.z, hi.x, hi.y, hi.z, a byte per slot. */
    for (int k = 0; k < 6; k++) {
        const uint32_t *bytes = q[k / 3][k % 3];
        texels[4 + k] = bytes[0] | bytes[1] << 8 | bytes[2] << 16 | bytes[3] << 24;
    }
    texels[10] = texels[11] = 0;
    for (int s = 0; s < BVH4_WIDTH; s++)
        texels[12 + s] = n->child[s] == BVH4_EMPTY ? VKRT_WIDE_NO_CHILD
                         : n->count[s]             ? VKRT_WIDE_LEAF | n->child[s]
                                                   : n->child[s];
}

/* Distinct corner positions, by their bits (so -0 and +0 stay apart and every corner reads
 * back exactly as the triangle array holds it): an open-addressing table of vertex indices,
 * at most half full. Both it and the vertices grow as corners come: a closed mesh has about
 * half a distinct corner per triangle, a triangle soup three, and sizing for the soup would
 * hold some 75 bytes a triangle (750 MB for ten million) through the packing of any mesh. */
typedef struct vertex_table {
    core *c;
    uint32_t *slots;
    uint64_t slot_count;   /* a power of two */
    uint32_t *texels;      /* 4 words a vertex */
    size_t capacity;       /* vertices texels has room for */
    uint32_t count;
} vertex_table;

static uint32_t position_hash(const uint32_t p[3])
{
    uint32_t h = p[0] * 0x9E3779B1u ^ p[1] * 0x85EBCA77u ^ p[2] * 0xC2B2AE3Du;
    return h ^ (h >> 15);
}

/* The free slot where vertex p belongs, or the slot that holds it. */
static uint32_t *find_slot(const vertex_table *t, const uint32_t p[3])
{
    const uint64_t mask = t->slot_count - 1;
    for (uint64_t i = position_hash(p) & mask;; i = (i + 1) & mask) {
        uint32_t *slot = &t->slots[i];
        if (*slot == NO_VERTEX || memcmp(t->texels + (size_t)*slot * 4, p, 3 * sizeof *p) == 0) return slot;
    }
}

/* A table of `slot_count` slots (a power of two) with every vertex so far in it. */
static bool rehash(vertex_table *t, uint64_t slot_count)
{
    if (slot_count > (uint64_t)UINT32_MAX + 1 || slot_count > SIZE_MAX / sizeof *t->slots) return false;
    uint32_t *slots = core_alloc_array(t->c, (size_t)slot_count, sizeof *slots);
    if (!slots) return false;
    memset(slots, 0xFF, (size_t)slot_count * sizeof *slots);
    core_free(t->c, t->slots);
    t->slots = slots;
    t->slot_count = slot_count;
    for (uint32_t k = 0; k < t->count; k++) *find_slot(t, t->texels + (size_t)k * 4) = k;
    return true;
}

/* The index of corner v, a new vertex if no earlier corner had its bits; false when out of
 * memory. */
static bool vertex_index(vertex_table *t, vkrt_float3 v, uint32_t *out)
{
    const uint32_t p[3] = { float_bits(v.x), float_bits(v.y), float_bits(v.z) };
    uint32_t *slot = find_slot(t, p);
    if (*slot != NO_VERTEX) {
        *out = *slot;
        return true;
    }
    if ((uint64_t)t->count + 1 > t->slot_count / 2) {
        if (!rehash(t, t->slot_count * 2)) return false;
        slot = find_slot(t, p);
    }
    if (core_grow(t->c, (void **)&t->texels, &t->capacity, (size_t)t->count + 1, 4 * sizeof(uint32_t)) != 0) return false;
    uint32_t *texel = t->texels + (size_t)t->count * 4;
    memcpy(texel, p, sizeof p);
    texel[3] = 0;
    *out = *slot = t->count++;
    return true;
}

vkrt_result wide_pack(core *c, const bvh *b, const vkrt_gpu_tri *tris, wide_arrays *out)
{
    memset(out, 0, sizeof *out);
    bvh4 w;
    vkrt_result r = bvh4_collapse(c, b, &w);
    if (r != VKRT_OK) return r;
    /* Room to start with for a closed mesh's vertices; triangle counts up to
     * VKRT_TRACE_TRI_LAST (wide_traversal_fits) keep the indices in range. */
    vertex_table t = { .c = c };
    bool ok = core_grow(c, (void **)&t.texels, &t.capacity, (size_t)b->tri_count / 2 + 16, 4 * sizeof(uint32_t)) == 0;
    uint64_t slots = 64;
    while (slots < 2 * (uint64_t)t.capacity) slots *= 2;
    ok = ok && rehash(&t, slots);
    out->node_texels = core_alloc_array(c, (size_t)w.node_count * VKRT_WIDE_NODE_TEXELS, 4 * sizeof(uint32_t));
    out->tri_texels = core_alloc_array(c, b->tri_count, 4 * sizeof(uint32_t));
    ok = ok && out->node_texels && out->tri_texels;
    if (ok)
        for (uint32_t i = 0; i < w.node_count; i++)
            pack_node(&w.nodes[i], out->node_texels + (size_t)i * VKRT_WIDE_NODE_TEXELS * 4);
    for (uint32_t i = 0; ok && i < b->tri_count; i++) {
        uint32_t *texel = out->tri_texels + (size_t)i * 4;
        ok = vertex_index(&t, tris[i].v0, &texel[0]) && vertex_index(&t, tris[i].v1, &texel[1]) &&
             vertex_index(&t, tris[i].v2, &texel[2]);
        texel[3] = tris[i].prim_id;
    }
    const uint32_t node_count = w.node_count, depth = w.depth;
    bvh4_destroy(c, &w);
    core_free(c, t.slots);
    if (!ok) {
        core_free(c, t.texels);
        wide_arrays_destroy(c, out);
        return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory packing the wide BVH of %u triangles",
                         b->tri_count);
    }
    /* Leaves partition the triangle array: mark where each ends. */
    for (uint32_t i = 0; i < b->node_count; i++) {
        const vkrt_gpu_node *n = &b->nodes[i];
        if (n->tri_count) out->tri_texels[(size_t)(n->left_first + n->tri_count - 1) * 4 + 3] |= VKRT_TRACE_TRI_LAST;
    }
    out->vertex_texels = t.texels;
    out->vertex_count = t.count;
    out->node_count = node_count;
    out->tri_count = b->tri_count;
    out->depth = depth;
    return VKRT_OK;
}

void wide_arrays_destroy(core *c, wide_arrays *w)
{
    core_free(c, w->node_texels);
    core_free(c, w->tri_texels);
    core_free(c, w->vertex_texels);
    memset(w, 0, sizeof *w);
}

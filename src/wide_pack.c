#include "wide_pack.h"

#include <string.h>

#include "bvh_wide.h"
#include "work_pool.h"

static uint32_t float_bits(float f)
{
    uint32_t u;
    memcpy(&u, &f, sizeof u);
    return u;
}

bool wide_traversal_fits(uint32_t wide_depth, uint32_t tri_count)
{
    return wide_depth <= VKRT_TRAVERSAL_STACK_SIZE && tri_count < VKRT_TRACE_TRI_LAST;
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
        /* From the exponent of (hi - lo) / 255, as frexp() gives it (a positive double of at
         * least 2^-149 / 255 is normal, so it is its biased exponent less 1022), up while 255
         * steps fall short. */
        const double d = ((double)hi - lo) / 255.0;
        uint64_t bits;
        memcpy(&bits, &d, sizeof bits);
        const int exponent = (int)((bits >> 52) & 0x7FF) - 1022;
        e = exponent + 126 < 1 ? 1 : exponent + 126 > 254 ? 254 : (uint32_t)(exponent + 126);
        while (e > 1 && dequantise(lo, scale_of(e - 1), 255) >= hi) e--;
        while (e < 254 && dequantise(lo, scale_of(e), 255) < hi) e++;
    }
    const float scale = scale_of(e);
    /* 1 / scale, a power of two too, so multiplying by it is dividing by scale, bit for bit. */
    const double inverse = e ? 1.0 / (double)scale : 0.0;
    for (uint32_t s = 0; s < BVH4_WIDTH; s++) {
        q_lo[s] = q_hi[s] = 0;
        if (s >= used || e == 0) continue;
        /* The step the division points to (floor and ceil clamped to [0, 255], by conversion:
         * the calls to libm's floor, ceil and frexp were a fifth of the nodes' packing), then
         * moved until its decoding is at or below the child's lower bound (at or above its
         * upper one): the division's rounding and the decoding's are each a fraction of a
         * step, so this takes a move or two. */
        const double lo_steps = ((double)n->lo[axis][s] - lo) * inverse;
        const double hi_steps = ((double)n->hi[axis][s] - lo) * inverse;
        uint32_t a = lo_steps >= 255.0 ? 255 : lo_steps > 0.0 ? (uint32_t)lo_steps : 0;
        uint32_t b = 0;
        if (hi_steps > 254.0) {
            b = 255;
        } else if (hi_steps > 0.0) {
            b = (uint32_t)hi_steps;
            b += (double)b < hi_steps;
        }
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

/* Triangle i's VKRT_WIDE_TRI_WORDS words from word VKRT_WIDE_TRI_WORDS * i: its corners' x, y,
 * z float bits (so -0 and +0 stay apart and every corner reads back exactly as the triangle
 * array holds it) and its prim_id, the last word. */
#define PRIM_WORD (VKRT_WIDE_TRI_WORDS - 1)

static void pack_triangle(const vkrt_gpu_tri *t, uint32_t *words)
{
    const vkrt_float3 corners[3] = { t->v0, t->v1, t->v2 };
    for (int k = 0; k < 3; k++) {
        words[3 * k] = float_bits(corners[k].x);
        words[3 * k + 1] = float_bits(corners[k].y);
        words[3 * k + 2] = float_bits(corners[k].z);
    }
    words[PRIM_WORD] = t->prim_id;
}

/* Nodes or triangles a work item packs: small enough to share among threads evenly, large
 * enough that taking an item costs nothing beside it. */
#define PACK_ITEM 4096

typedef struct pack_job {
    const bvh4 *w;
    const vkrt_gpu_tri *tris;
    uint32_t tri_count;
    uint8_t *ends_leaf;            /* per triangle: 1 where a leaf ends */
    wide_arrays *out;
} pack_job;

/* One past the last of the `count` elements that item `item` packs, from item * PACK_ITEM. */
static uint32_t item_end(uint32_t item, uint32_t count)
{
    const uint32_t first = item * PACK_ITEM;
    return count - first < PACK_ITEM ? count : first + PACK_ITEM;
}

/* Packs nodes and notes where each of their leaves ends: every binary leaf is one slot of one
 * wide node, so no two items write the same byte. A byte a triangle (under a megabyte for the
 * full dragon) stays in cache, where marking the packed triangles themselves missed it for
 * every leaf, a third of the nodes' time. */
static void pack_nodes_item(void *job, uint32_t item)
{
    const pack_job *j = job;
    for (uint32_t i = item * PACK_ITEM, end = item_end(item, j->w->node_count); i < end; i++) {
        const bvh4_node *n = &j->w->nodes[i];
        pack_node(n, j->out->node_texels + (size_t)i * VKRT_WIDE_NODE_TEXELS * 4);
        for (int s = 0; s < BVH4_WIDTH; s++)
            if (n->child[s] != BVH4_EMPTY && n->count[s]) j->ends_leaf[n->child[s] + n->count[s] - 1] = 1;
    }
}

static void pack_triangles_item(void *job, uint32_t item)
{
    const pack_job *j = job;
    for (uint32_t i = item * PACK_ITEM, end = item_end(item, j->tri_count); i < end; i++) {
        uint32_t *words = j->out->tri_texels + (size_t)i * VKRT_WIDE_TRI_WORDS;
        pack_triangle(&j->tris[i], words);
        if (j->ends_leaf[i]) words[PRIM_WORD] |= VKRT_TRACE_TRI_LAST;
    }
}

vkrt_result wide_pack(core *c, const bvh *b, const vkrt_gpu_tri *tris, uint32_t threads, wide_arrays *out)
{
    memset(out, 0, sizeof *out);
    bvh4 w;
    vkrt_result r = bvh4_collapse(c, b, &w);
    if (r != VKRT_OK) return r;
    /* Through the last triangle's third texel; upload_wide keeps the array within the
     * device's texel-buffer limit. */
    const uint64_t tri_texels = b->tri_count ? VKRT_WIDE_TRI_FIRST_TEXEL((uint64_t)b->tri_count - 1) + 3 : 0;
    out->node_texels = core_alloc_array(c, (size_t)w.node_count * VKRT_WIDE_NODE_TEXELS, 4 * sizeof(uint32_t));
    out->tri_texels = core_alloc_array(c, (size_t)tri_texels, 4 * sizeof(uint32_t));
    uint8_t *ends_leaf = core_calloc_array(c, b->tri_count ? b->tri_count : 1, 1);
    work_pool *pool = NULL;
    bool ok = out->node_texels && (out->tri_texels || !tri_texels) && ends_leaf;
    if (ok) ok = work_pool_create(c, threads, &pool) == VKRT_OK;
    if (ok) {
        /* The triangles write every word up to the last one's; the rest of its last texel is
         * zero. They carry the leaves' ends, so the nodes come first. */
        const size_t words = (size_t)tri_texels * 4, written = (size_t)b->tri_count * VKRT_WIDE_TRI_WORDS;
        if (words > written) memset(out->tri_texels + written, 0, (words - written) * sizeof(uint32_t));
        pack_job j = { .w = &w, .tris = tris, .tri_count = b->tri_count, .ends_leaf = ends_leaf, .out = out };
        work_pool_run(pool, core_div_up(w.node_count, PACK_ITEM), pack_nodes_item, NULL, &j);
        work_pool_run(pool, core_div_up(b->tri_count, PACK_ITEM), pack_triangles_item, NULL, &j);
    }
    work_pool_destroy(pool);
    core_free(c, ends_leaf);
    const uint32_t node_count = w.node_count, depth = w.depth;
    bvh4_destroy(c, &w);
    if (!ok) {
        wide_arrays_destroy(c, out);
        return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory packing the wide BVH of %u triangles",
                         b->tri_count);
    }
    out->node_count = node_count;
    out->tri_count = b->tri_count;
    out->tri_texel_count = tri_texels;
    out->depth = depth;
    return VKRT_OK;
}

void wide_arrays_destroy(core *c, wide_arrays *w)
{
    core_free(c, w->node_texels);
    core_free(c, w->tri_texels);
    memset(w, 0, sizeof *w);
}

/* The float traversal of the 4-wide BVH (bvh_wide.h), a pure speed-up of the binary
 * trace_bvh_f for the CPU backend. Included by src/cpu_trace.c after the float instance of
 * cpu_trace_real.h, whose ray_f, hit_f, intersect_box_f and test_triangle_f it uses.
 *
 * Same answers as trace_bvh_f: each of a node's four child boxes is tested with
 * intersect_box_f's arithmetic (SSE2 does the four at once, operation for operation, so the
 * results are the same bits; without SSE2 the slots go through intersect_box_f itself), the
 * triangles with the same test_triangle_f, and the closest hit is chosen by hit_closer (nearer
 * t, then lower prim_id), which does not depend on the order boxes are visited. An any-hit ray
 * may stop at another triangle than the binary traversal's (the first found differs with the
 * order), never with another hit-or-miss answer. The binary traversal's counters (boxes,
 * leaves, triangles) have no equivalent here: whoever needs them (heat map, render counters)
 * traces the binary tree, which is also what the GPU mirrors.
 *
 * Traversal as in Wald, Benthin, Boulos, "Getting Rid of Packets", RT 2008: the hit children
 * sorted by entry distance, the nearest visited next and the others pushed with their entry
 * distance, so entries beyond the closest hit found since are dropped when popped. */

#if defined(__SSE2__)
#include <emmintrin.h>
#include <xmmintrin.h>
#endif

/* The box test runs once per node visited: a call there costs as much as the test. */
#if defined(__GNUC__)
#define BVH4_INLINE static inline __attribute__((always_inline))
#else
#define BVH4_INLINE static inline
#endif

/* The lowest set bit's index of a nonzero slot mask. */
static inline unsigned lowest_slot(unsigned mask)
{
#if defined(__GNUC__)
    return (unsigned)__builtin_ctz(mask);
#else
    unsigned i = 0;
    while (!(mask & 1u)) mask >>= 1, i++;
    return i;
#endif
}

/* Entries pushed per wide node visited are at most BVH4_WIDTH - 1 and all one level below it,
 * so a tree of at most VKRT_MAX_BVH_DEPTH + 1 levels never holds more than this many. */
#define BVH4_STACK_SIZE ((BVH4_WIDTH - 1) * (VKRT_MAX_BVH_DEPTH + 1))

/* A slot to visit: an interior node (count 0, first = the node's index) or a leaf's
 * triangles [first, first + count), with its entry distance. */
typedef struct bvh4_item {
    uint32_t first, count;
    float tnear;
} bvh4_item;

#if defined(__SSE2__)
/* The ray's constants of the four-box test, each broadcast to the four slots. */
typedef struct box4_ray {
    __m128 origin[3], inv_dir[3], tmin;
    bool parallel[3];    /* inv_dir infinite (a +-0 direction): slab() takes its other branch */
} box4_ray;

static box4_ray box4_ray_setup(const ray_f *r)
{
    const float o[3] = { r->origin.x, r->origin.y, r->origin.z }, inv[3] = { r->inv_dir.x, r->inv_dir.y, r->inv_dir.z };
    box4_ray b;
    for (int a = 0; a < 3; a++) {
        b.origin[a] = _mm_set1_ps(o[a]);
        b.inv_dir[a] = _mm_set1_ps(inv[a]);
        b.parallel[a] = f_abs_f(inv[a]) == INFINITY;
    }
    b.tmin = _mm_set1_ps(r->tmin);
    return b;
}

/* slab_f on four boxes. f_min_f(x, y) is y < x ? y : x, which _mm_min_ps(y, x) computes
 * (NaN and +-0 included); f_max_f(x, y) is x < y ? y : x, which is _mm_max_ps(y, x). */
BVH4_INLINE void slab4(__m128 o, __m128 inv, bool parallel, __m128 lo, __m128 hi, __m128 *out_lo, __m128 *out_hi)
{
    if (parallel) {
        const __m128 inf = _mm_set1_ps(INFINITY), minus_inf = _mm_set1_ps(-INFINITY);
        __m128 inside = _mm_and_ps(_mm_cmpge_ps(o, lo), _mm_cmple_ps(o, hi));
        *out_lo = _mm_or_ps(_mm_and_ps(inside, minus_inf), _mm_andnot_ps(inside, inf));
        *out_hi = _mm_or_ps(_mm_and_ps(inside, inf), _mm_andnot_ps(inside, minus_inf));
        return;
    }
    __m128 t0 = _mm_mul_ps(_mm_sub_ps(lo, o), inv);
    __m128 t1 = _mm_mul_ps(_mm_sub_ps(hi, o), inv);
    *out_lo = _mm_min_ps(t1, t0);
    *out_hi = _mm_max_ps(t1, t0);
}

/* intersect_box_f on node n's four slots: bit i set when slot i is used and hit, tnear[i] its
 * entry distance (for every slot). */
BVH4_INLINE unsigned box4_test_sse2(const box4_ray *b, const bvh4_node *n, float best_t, float tnear[BVH4_WIDTH])
{
    __m128 lx, hx, ly, hy, lz, hz;
    slab4(b->origin[0], b->inv_dir[0], b->parallel[0], _mm_load_ps(n->lo[0]), _mm_load_ps(n->hi[0]), &lx, &hx);
    slab4(b->origin[1], b->inv_dir[1], b->parallel[1], _mm_load_ps(n->lo[1]), _mm_load_ps(n->hi[1]), &ly, &hy);
    slab4(b->origin[2], b->inv_dir[2], b->parallel[2], _mm_load_ps(n->lo[2]), _mm_load_ps(n->hi[2]), &lz, &hz);
    /* tnear = f_max(f_max(lx, ly), f_max(lz, tmin)); tfar = f_min(f_min(f_min(hx, hy), hz) * widen, best_t) */
    __m128 near = _mm_max_ps(_mm_max_ps(b->tmin, lz), _mm_max_ps(ly, lx));
    __m128 far = _mm_mul_ps(_mm_min_ps(hz, _mm_min_ps(hy, hx)), _mm_set1_ps((float)VKRT_TFAR_WIDEN_FLOAT));
    far = _mm_min_ps(_mm_set1_ps(best_t), far);
    _mm_storeu_ps(tnear, near);
    __m128i unused = _mm_cmpeq_epi32(_mm_load_si128((const __m128i *)n->child), _mm_set1_epi32(-1));
    return (unsigned)_mm_movemask_ps(_mm_cmple_ps(near, far)) & ~(unsigned)_mm_movemask_ps(_mm_castsi128_ps(unused));
}
#endif

/* The portable four-box test: each used slot through intersect_box_f itself. */
static unsigned box4_test_scalar(const ray_f *r, const bvh4_node *n, float best_t, float tnear[BVH4_WIDTH])
{
    unsigned mask = 0;
    for (unsigned i = 0; i < BVH4_WIDTH; i++) {
        tnear[i] = INFINITY;
        if (n->child[i] == BVH4_EMPTY) continue;
        const vkrt_gpu_node box = { { n->lo[0][i], n->lo[1][i], n->lo[2][i] }, 0, { n->hi[0][i], n->hi[1][i], n->hi[2][i] }, 0 };
        if (intersect_box_f(r, &box, best_t, &tnear[i])) mask |= 1u << i;
    }
    return mask;
}

#if defined(__SSE2__)
/* intersect_triangle_watertight_f on four triangles at once, lane l the triangle tris[l]:
 * the same operations in the same order on each lane (the per-ray permutation picks whole
 * vectors, the double re-evaluation of zero edge values runs per lane), so each lane's t, u, v
 * and answer are the scalar test's bits. Bit l of the result: lane l hit. */
static unsigned watertight4_sse2(const ray_f *r, const vkrt_gpu_tri *const tris[4], float t_out[4], float u_out[4],
                                 float v_out[4])
{
    __m128 v0[4], v1[4], v2[4];
    for (int l = 0; l < 4; l++) {
        v0[l] = _mm_loadu_ps(&tris[l]->v0.x);
        v1[l] = _mm_loadu_ps(&tris[l]->v1.x);
        v2[l] = _mm_loadu_ps(&tris[l]->v2.x);
    }
    _MM_TRANSPOSE4_PS(v0[0], v0[1], v0[2], v0[3]);
    _MM_TRANSPOSE4_PS(v1[0], v1[1], v1[2], v1[3]);
    _MM_TRANSPOSE4_PS(v2[0], v2[1], v2[2], v2[3]);
    const __m128 o[3] = { _mm_set1_ps(r->origin.x), _mm_set1_ps(r->origin.y), _mm_set1_ps(r->origin.z) };
    __m128 a[3], b[3], c[3];
    for (int k = 0; k < 3; k++) {
        a[k] = _mm_sub_ps(v0[k], o[k]);
        b[k] = _mm_sub_ps(v1[k], o[k]);
        c[k] = _mm_sub_ps(v2[k], o[k]);
    }
    const __m128 sx = _mm_set1_ps(r->sx), sy = _mm_set1_ps(r->sy), sz = _mm_set1_ps(r->sz);
    const __m128 a_z = a[r->kz], b_z = b[r->kz], c_z = c[r->kz];
    const __m128 ax = _mm_sub_ps(a[r->kx], _mm_mul_ps(sx, a_z)), ay = _mm_sub_ps(a[r->ky], _mm_mul_ps(sy, a_z));
    const __m128 bx = _mm_sub_ps(b[r->kx], _mm_mul_ps(sx, b_z)), by = _mm_sub_ps(b[r->ky], _mm_mul_ps(sy, b_z));
    const __m128 cx = _mm_sub_ps(c[r->kx], _mm_mul_ps(sx, c_z)), cy = _mm_sub_ps(c[r->ky], _mm_mul_ps(sy, c_z));
    __m128 eu = _mm_sub_ps(_mm_mul_ps(cx, by), _mm_mul_ps(cy, bx));
    __m128 ev = _mm_sub_ps(_mm_mul_ps(ax, cy), _mm_mul_ps(ay, cx));
    __m128 ew = _mm_sub_ps(_mm_mul_ps(bx, ay), _mm_mul_ps(by, ax));
    const __m128 zero = _mm_setzero_ps();
    unsigned zeros = (unsigned)_mm_movemask_ps(
        _mm_or_ps(_mm_or_ps(_mm_cmpeq_ps(eu, zero), _mm_cmpeq_ps(ev, zero)), _mm_cmpeq_ps(ew, zero)));
    if (zeros) {
        float e[3][4], p[6][4];
        _mm_storeu_ps(e[0], eu), _mm_storeu_ps(e[1], ev), _mm_storeu_ps(e[2], ew);
        _mm_storeu_ps(p[0], ax), _mm_storeu_ps(p[1], ay), _mm_storeu_ps(p[2], bx);
        _mm_storeu_ps(p[3], by), _mm_storeu_ps(p[4], cx), _mm_storeu_ps(p[5], cy);
        for (; zeros; zeros &= zeros - 1) {
            unsigned l = lowest_slot(zeros);
            double dax = p[0][l], day = p[1][l], dbx = p[2][l], dby = p[3][l], dcx = p[4][l], dcy = p[5][l];
            e[0][l] = (float)(dcx * dby - dcy * dbx);
            e[1][l] = (float)(dax * dcy - day * dcx);
            e[2][l] = (float)(dbx * day - dby * dax);
        }
        eu = _mm_loadu_ps(e[0]), ev = _mm_loadu_ps(e[1]), ew = _mm_loadu_ps(e[2]);
    }
    __m128 negative = _mm_or_ps(_mm_or_ps(_mm_cmplt_ps(eu, zero), _mm_cmplt_ps(ev, zero)), _mm_cmplt_ps(ew, zero));
    __m128 positive = _mm_or_ps(_mm_or_ps(_mm_cmpgt_ps(eu, zero), _mm_cmpgt_ps(ev, zero)), _mm_cmpgt_ps(ew, zero));
    __m128 det = _mm_add_ps(_mm_add_ps(eu, ev), ew);
    __m128 reject = _mm_or_ps(_mm_and_ps(negative, positive), _mm_cmpeq_ps(det, zero));
    __m128 t_scaled = _mm_add_ps(_mm_add_ps(_mm_mul_ps(eu, _mm_mul_ps(sz, a_z)), _mm_mul_ps(ev, _mm_mul_ps(sz, b_z))),
                                 _mm_mul_ps(ew, _mm_mul_ps(sz, c_z)));
    __m128 inv_det = _mm_div_ps(_mm_set1_ps(1.0f), det);
    __m128 t = _mm_mul_ps(t_scaled, inv_det);
    __m128 inside = _mm_and_ps(_mm_cmpgt_ps(t, _mm_set1_ps(r->tmin)), _mm_cmplt_ps(t, _mm_set1_ps(r->tmax)));
    _mm_storeu_ps(t_out, t);
    _mm_storeu_ps(u_out, _mm_mul_ps(ev, inv_det));
    _mm_storeu_ps(v_out, _mm_mul_ps(ew, inv_det));
    return (unsigned)_mm_movemask_ps(_mm_andnot_ps(reject, inside));
}
#endif

/* test_triangle_f on the count triangles from first, in order; true when any_hit and one hit. */
static inline bool test_leaf_f(vkrt_intersector isect, const ray_f *r, const cpu_trace_scene *s, uint32_t first,
                               uint32_t count, hit_f *best, bool any_hit)
{
#if defined(__SSE2__)
    if (isect != VKRT_INTERSECTOR_MOLLER_TRUMBORE && count > 1) {
        for (uint32_t at = first, end = first + count; at < end; at += 4) {
            const uint32_t n = end - at < 4 ? end - at : 4;
            /* Lanes past the leaf repeat its last triangle, and are ignored. */
            const vkrt_gpu_tri *const tris[4] = { &s->tris[at], &s->tris[at + (n > 1)], &s->tris[at + (n > 2 ? 2 : n - 1)],
                                                  &s->tris[at + n - 1] };
            float t[4], u[4], v[4];
            unsigned hits = watertight4_sse2(r, tris, t, u, v) & ((1u << n) - 1u);
            for (; hits; hits &= hits - 1) {
                unsigned l = lowest_slot(hits);
                uint32_t prim = tris[l]->prim_id;
                if (hit_closer_f(t[l], prim, best->t, best->prim) && (!s->alpha_tested || alpha_passes(s, prim, u[l], v[l]))) {
                    *best = (hit_f){ .t = t[l], .u = u[l], .v = v[l], .tri = at + l, .prim = prim };
                    if (any_hit) return true;
                }
            }
        }
        return false;
    }
#endif
    for (uint32_t i = first; i < first + count; i++) {
        test_triangle_f(isect, r, s, i, best);
        if (any_hit && best->prim != NO_PRIM) return true;
    }
    return false;
}

/* Asks for the first two cache lines of each of node n's children (a node, or a leaf's first
 * triangles) as soon as n is read, before its boxes are tested: the next node a ray visits is
 * one of them, and without this its fetch only starts once the test has chosen it, so every
 * level of the tree would wait for memory in turn. Always inlined: GCC drops the prefetches
 * of a helper it has not inlined (it takes the helper for one without effects). */
BVH4_INLINE void prefetch_children(const cpu_trace_scene *s, const bvh4_node *n)
{
#if defined(__SSE2__)
    for (unsigned k = 0; k < BVH4_WIDTH && n->child[k] != BVH4_EMPTY; k++) {
        const char *p = n->count[k] ? (const char *)&s->tris[n->child[k]] : (const char *)&s->wide->nodes[n->child[k]];
        _mm_prefetch(p, _MM_HINT_T0);
        _mm_prefetch(p + 64, _MM_HINT_T0);
    }
#else
    (void)s, (void)n;
#endif
}

/* Closest (any_hit: the first found) hit of r in s->wide into *best. */
static void trace_bvh4_f(const cpu_trace_scene *s, vkrt_intersector isect, const ray_f *r, hit_f *best, bool any_hit)
{
    const bvh4 *w = s->wide;
    const vkrt_gpu_node root = { { w->root_lo[0], w->root_lo[1], w->root_lo[2] }, 0,
                                 { w->root_hi[0], w->root_hi[1], w->root_hi[2] }, 0 };
    float root_tnear;
    /* The binary traversal's first test, so a ray that misses the scene costs one box. */
    if (!intersect_box_f(r, &root, best->t, &root_tnear)) return;
#if defined(__SSE2__)
    const box4_ray b = box4_ray_setup(r);
#endif
    bvh4_item stack[BVH4_STACK_SIZE];
    uint32_t sp = 0;
    bvh4_item item = { 0, 0, root_tnear };
    for (;;) {
        if (item.count != 0) {
            if (test_leaf_f(isect, r, s, item.first, item.count, best, any_hit)) return;
        } else {
            const bvh4_node *n = &w->nodes[item.first];
            prefetch_children(s, n);
            float tnear[BVH4_WIDTH];
#if defined(__SSE2__)
            unsigned mask = box4_test_sse2(&b, n, best->t, tnear);
#else
            unsigned mask = box4_test_scalar(r, n, best->t, tnear);
#endif
            if (mask) {
                /* The hit slots in order of entry distance (a stable insertion sort; one and two
                 * hits, the common cases, take the short ways): the nearest is visited next, the
                 * others pushed farthest first so the nearer ones come off the stack first. */
                unsigned i = lowest_slot(mask);
                bvh4_item nearest = { n->child[i], n->count[i], tnear[i] };
                if (!(mask &= mask - 1)) {
                    item = nearest;
                    continue;
                }
                i = lowest_slot(mask);
                bvh4_item second = { n->child[i], n->count[i], tnear[i] };
                if (second.tnear < nearest.tnear) {
                    bvh4_item t = nearest;
                    nearest = second, second = t;
                }
                if (!(mask &= mask - 1)) {
                    if (sp < BVH4_STACK_SIZE) stack[sp++] = second; /* never full: see BVH4_STACK_SIZE */
                    item = nearest;
                    continue;
                }
                bvh4_item hits[BVH4_WIDTH] = { nearest, second };
                uint32_t count = 2;
                for (; mask; mask &= mask - 1) {
                    i = lowest_slot(mask);
                    bvh4_item h = { n->child[i], n->count[i], tnear[i] };
                    uint32_t k = count++;
                    while (k > 0 && h.tnear < hits[k - 1].tnear) {
                        hits[k] = hits[k - 1];
                        k--;
                    }
                    hits[k] = h;
                }
                for (uint32_t k = count - 1; k > 0; k--)
                    if (sp < BVH4_STACK_SIZE) stack[sp++] = hits[k];
                item = hits[0];
                continue;
            }
        }
        /* A pushed box that starts beyond the closest hit found since cannot improve it. */
        while (sp > 0 && stack[sp - 1].tnear > best->t) sp--;
        if (sp == 0) break;
        item = stack[--sp];
    }
}

/* Closest (or with any_hit, the first found) hit of one ray through the 4-wide BVH, as
 * trace_ray_f gives it for the binary one. */
static hit trace_ray_bvh4_f(const cpu_trace_scene *s, vkrt_intersector isect, const ray_f *r, bool any_hit)
{
    hit_f best = { .t = r->tmax, .tri = NO_PRIM, .prim = NO_PRIM };
    trace_bvh4_f(s, isect, r, &best, any_hit);
    return (hit){ .t = best.t, .u = best.u, .v = best.v, .tri = best.tri, .prim = best.prim };
}

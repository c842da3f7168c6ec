/* Four float tests at once with SSE2, each lane the scalar test of cpu_trace_real.h
 * operation for operation, so every lane's answer is the scalar test's bits: the four child
 * boxes of a bvh4_node against one ray (intersect_box_f), and four triangles against one ray
 * (intersect_triangle_watertight_f). Included by cpu_trace_bvh4.h after the float instance of
 * cpu_trace_real.h; without SSE2 only the portable four-box test is defined. Held to the
 * scalar tests on hostile inputs by test_cpu_trace (cpu_trace_box4_test,
 * cpu_trace_watertight4_test). */

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
    /* tnear = f_max(f_max(lx, ly), f_max(lz, tmin));
     * tfar = f_min(f_min(f_min(hx, hy), hz) * widen, prune_bound(best_t)) */
    __m128 near = _mm_max_ps(_mm_max_ps(b->tmin, lz), _mm_max_ps(ly, lx));
    __m128 far = _mm_mul_ps(_mm_min_ps(hz, _mm_min_ps(hy, hx)), _mm_set1_ps((float)VKRT_TFAR_WIDEN_FLOAT));
    far = _mm_min_ps(_mm_set1_ps(prune_bound_f(best_t)), far);
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

/* Four float tests at once through float4.h (SSE2, or its plain-C twin), each lane the
 * scalar test of cpu_trace_real.h operation for operation, so every lane's answer is the
 * scalar test's bits: the four child boxes of a bvh4_node against one ray (intersect_box_f),
 * and four triangles against one ray (intersect_triangle_watertight_f). Included by
 * cpu_trace_bvh4.h after the float instance of cpu_trace_real.h. Held to the scalar tests on
 * hostile inputs by test_cpu_trace (cpu_trace_box4_test, cpu_trace_watertight4_test). */

#include "float4.h"

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

/* The ray's constants of the four-box test, each broadcast to the four slots. */
typedef struct box4_ray {
    float4 origin[3], inv_dir[3], tmin;
    bool parallel[3];    /* inv_dir infinite (a +-0 direction): slab() takes its other branch */
} box4_ray;

static box4_ray box4_ray_setup(const ray_f *r)
{
    const float o[3] = { r->origin.x, r->origin.y, r->origin.z }, inv[3] = { r->inv_dir.x, r->inv_dir.y, r->inv_dir.z };
    box4_ray b;
    for (int a = 0; a < 3; a++) {
        b.origin[a] = f4_set1(o[a]);
        b.inv_dir[a] = f4_set1(inv[a]);
        b.parallel[a] = f_abs_f(inv[a]) == INFINITY;
    }
    b.tmin = f4_set1(r->tmin);
    return b;
}

/* slab_f on four boxes. f_min_f(x, y) is y < x ? y : x, which f4_min(y, x) computes (NaN
 * and +-0 included); f_max_f(x, y) is x < y ? y : x, which is f4_max(y, x). */
BVH4_INLINE void slab4(float4 o, float4 inv, bool parallel, float4 lo, float4 hi, float4 *out_lo, float4 *out_hi)
{
    if (parallel) {
        const float4 inf = f4_set1(INFINITY), minus_inf = f4_set1(-INFINITY);
        float4 inside = f4_and(f4_ge(o, lo), f4_le(o, hi));
        *out_lo = f4_select(inside, minus_inf, inf);
        *out_hi = f4_select(inside, inf, minus_inf);
        return;
    }
    float4 t0 = f4_mul(f4_sub(lo, o), inv);
    float4 t1 = f4_mul(f4_sub(hi, o), inv);
    *out_lo = f4_min(t1, t0);
    *out_hi = f4_max(t1, t0);
}

/* intersect_box_f on node n's four slots: bit i set when slot i is used and hit, tnear[i] its
 * entry distance (for every slot). */
BVH4_INLINE unsigned box4_test(const box4_ray *b, const bvh4_node *n, float best_t, float tnear[BVH4_WIDTH])
{
    float4 lx, hx, ly, hy, lz, hz;
    slab4(b->origin[0], b->inv_dir[0], b->parallel[0], f4_load(n->lo[0]), f4_load(n->hi[0]), &lx, &hx);
    slab4(b->origin[1], b->inv_dir[1], b->parallel[1], f4_load(n->lo[1]), f4_load(n->hi[1]), &ly, &hy);
    slab4(b->origin[2], b->inv_dir[2], b->parallel[2], f4_load(n->lo[2]), f4_load(n->hi[2]), &lz, &hz);
    /* tnear = f_max(f_max(lx, ly), f_max(lz, tmin));
     * tfar = f_min(f_min(f_min(hx, hy), hz) * widen, prune_bound(best_t)) */
    float4 near = f4_max(f4_max(b->tmin, lz), f4_max(ly, lx));
    float4 far = f4_mul(f4_min(hz, f4_min(hy, hx)), f4_set1((float)VKRT_TFAR_WIDEN_FLOAT));
    far = f4_min(f4_set1(prune_bound_f(best_t)), far);
    f4_store(tnear, near);
    return f4_bits(f4_le(near, far)) & ~f4_equal_u32(n->child, BVH4_EMPTY);
}

/* box4_test's reference for the tests (cpu_trace_box4_test): each used slot through
 * intersect_box_f itself. Not in cpu_trace.c's x86-64-v3 build, which has no test entry points. */
#ifndef VKRT_CPU_TRACE_X86_64_V3
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
#endif

/* intersect_triangle_watertight_f on four triangles at once, lane l the triangle tris[l]:
 * the same operations in the same order on each lane (the per-ray permutation picks whole
 * vectors, the double re-evaluation of zero edge values runs per lane), so each lane's t, u, v
 * and answer are the scalar test's bits. Bit l of the result: lane l hit. */
static unsigned watertight4(const ray_f *r, const vkrt_gpu_tri *const tris[4], float t_out[4], float u_out[4],
                            float v_out[4])
{
    float4 v0[4], v1[4], v2[4];
    for (int l = 0; l < 4; l++) {
        v0[l] = f4_load(&tris[l]->v0.x);
        v1[l] = f4_load(&tris[l]->v1.x);
        v2[l] = f4_load(&tris[l]->v2.x);
    }
    f4_transpose(v0);
    f4_transpose(v1);
    f4_transpose(v2);
    const float4 o[3] = { f4_set1(r->origin.x), f4_set1(r->origin.y), f4_set1(r->origin.z) };
    float4 a[3], b[3], c[3];
    for (int k = 0; k < 3; k++) {
        a[k] = f4_sub(v0[k], o[k]);
        b[k] = f4_sub(v1[k], o[k]);
        c[k] = f4_sub(v2[k], o[k]);
    }
    const float4 sx = f4_set1(r->sx), sy = f4_set1(r->sy), sz = f4_set1(r->sz);
    const float4 a_z = a[r->kz], b_z = b[r->kz], c_z = c[r->kz];
    const float4 ax = f4_sub(a[r->kx], f4_mul(sx, a_z)), ay = f4_sub(a[r->ky], f4_mul(sy, a_z));
    const float4 bx = f4_sub(b[r->kx], f4_mul(sx, b_z)), by = f4_sub(b[r->ky], f4_mul(sy, b_z));
    const float4 cx = f4_sub(c[r->kx], f4_mul(sx, c_z)), cy = f4_sub(c[r->ky], f4_mul(sy, c_z));
    float4 eu = f4_sub(f4_mul(cx, by), f4_mul(cy, bx));
    float4 ev = f4_sub(f4_mul(ax, cy), f4_mul(ay, cx));
    float4 ew = f4_sub(f4_mul(bx, ay), f4_mul(by, ax));
    const float4 zero = f4_set1(0.0f);
    unsigned zeros = f4_bits(f4_or(f4_or(f4_eq(eu, zero), f4_eq(ev, zero)), f4_eq(ew, zero)));
    if (zeros) {
        float e[3][4], p[6][4];
        f4_store(e[0], eu), f4_store(e[1], ev), f4_store(e[2], ew);
        f4_store(p[0], ax), f4_store(p[1], ay), f4_store(p[2], bx);
        f4_store(p[3], by), f4_store(p[4], cx), f4_store(p[5], cy);
        for (; zeros; zeros &= zeros - 1) {
            unsigned l = lowest_slot(zeros);
            double dax = p[0][l], day = p[1][l], dbx = p[2][l], dby = p[3][l], dcx = p[4][l], dcy = p[5][l];
            e[0][l] = (float)(dcx * dby - dcy * dbx);
            e[1][l] = (float)(dax * dcy - day * dcx);
            e[2][l] = (float)(dbx * day - dby * dax);
        }
        eu = f4_load(e[0]), ev = f4_load(e[1]), ew = f4_load(e[2]);
    }
    float4 negative = f4_or(f4_or(f4_lt(eu, zero), f4_lt(ev, zero)), f4_lt(ew, zero));
    float4 positive = f4_or(f4_or(f4_gt(eu, zero), f4_gt(ev, zero)), f4_gt(ew, zero));
    float4 det = f4_add(f4_add(eu, ev), ew);
    float4 reject = f4_or(f4_and(negative, positive), f4_eq(det, zero));
    float4 t_scaled = f4_add(f4_add(f4_mul(eu, f4_mul(sz, a_z)), f4_mul(ev, f4_mul(sz, b_z))), f4_mul(ew, f4_mul(sz, c_z)));
    float4 inv_det = f4_div(f4_set1(1.0f), det);
    float4 t = f4_mul(t_scaled, inv_det);
    float4 inside = f4_and(f4_gt(t, f4_set1(r->tmin)), f4_lt(t, f4_set1(r->tmax)));
    f4_store(t_out, t);
    f4_store(u_out, f4_mul(ev, inv_det));
    f4_store(v_out, f4_mul(ew, inv_det));
    return f4_bits(f4_andnot(reject, inside));
}

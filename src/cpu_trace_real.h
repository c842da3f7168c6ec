/* The traversal and intersection code of the C reference tracer, written once for both
 * precisions: src/cpu_trace.c includes this file twice, with
 *
 *     REAL        float or double
 *     R(name)     name##_f or name##_d (every type and function below gets the suffix)
 *     REAL_IS_FLOAT  1 for float: the watertight test's double fallback for zero edge values
 *     REAL_SQRT, REAL_INF, REAL_TFAR_WIDEN
 *
 * The float instance is the reference for the GPU: every function mirrors the GLSL function of
 * the same name (without the suffix) in shaders/trace_common.glsl or shaders/trace.comp, with
 * the arithmetic in the same order, so the float path and the shader round identically. The
 * double instance reads the same float scene (vertices and boxes widened exactly) and traces
 * double rays: the reference every error figure is measured against.
 *
 * Triangle tests: Woop, Benthin, Wald, "Watertight Ray/Triangle Intersection", JCGT 2(1),
 * 2013 (the default); Möller, Trumbore, "Fast, Minimum Storage Ray/Triangle Intersection",
 * JGT 2(1), 1997. Box test: the slab method (Kay, Kajiya 1986) with a reciprocal direction
 * (Williams et al., JGT 10(1), 2005), made conservative as in Ize, "Robust BVH Ray
 * Traversal", JCGT 2(2), 2013. No include guard: included once per precision; the parameters are
 * undefined at the end. */

typedef struct R(vec3) {
    REAL x, y, z;
} R(vec3);

static inline R(vec3) R(v_load)(vkrt_float3 a) { return (R(vec3)){ (REAL)a.x, (REAL)a.y, (REAL)a.z }; }
static inline R(vec3) R(v_sub)(R(vec3) a, R(vec3) b) { return (R(vec3)){ a.x - b.x, a.y - b.y, a.z - b.z }; }
static inline R(vec3) R(v_add)(R(vec3) a, R(vec3) b) { return (R(vec3)){ a.x + b.x, a.y + b.y, a.z + b.z }; }
static inline R(vec3) R(v_scale)(R(vec3) a, REAL s) { return (R(vec3)){ a.x * s, a.y * s, a.z * s }; }
static inline REAL R(v_dot)(R(vec3) a, R(vec3) b) { return (a.x * b.x + a.y * b.y) + a.z * b.z; }
static inline R(vec3) R(v_cross)(R(vec3) a, R(vec3) b)
{
    return (R(vec3)){ a.y * b.z - b.y * a.z, a.z * b.x - b.z * a.x, a.x * b.y - b.x * a.y };
}
static inline REAL R(v_get)(R(vec3) a, uint32_t k) { return k == 0 ? a.x : k == 1 ? a.y : a.z; }
/* GLSL's definitions, including which operand wins for NaN. */
static inline REAL R(f_min)(REAL x, REAL y) { return y < x ? y : x; }
static inline REAL R(f_max)(REAL x, REAL y) { return x < y ? y : x; }
static inline REAL R(f_abs)(REAL x) { return x < 0 ? -x : x; }
static inline bool R(finite3)(R(vec3) a)
{
    return R(f_abs)(a.x) < REAL_INF && R(f_abs)(a.y) < REAL_INF && R(f_abs)(a.z) < REAL_INF;
}

typedef struct R(ray) {
    R(vec3) origin, dir, inv_dir;
    REAL tmin, tmax;      /* hits accepted for tmin < t < tmax */
    uint32_t kx, ky, kz;  /* watertight: kz the axis of the largest |dir|, kx, ky the others */
    REAL sx, sy, sz;      /* watertight: the shear taking dir to (0, 0, 1) */
} R(ray);

/* Closest hit so far; prim = NO_PRIM means none (t then holds the ray's tmax). */
typedef struct R(hit) {
    REAL t, u, v;
    uint32_t tri;  /* index into the triangle array (BVH order) */
    uint32_t prim; /* its prim_id, the tie-breaker */
} R(hit);

/* Per-ray constants of both tests (Woop et al., section 3: the permutation keeps the
 * winding, so the sign of the edge values is the same for every ray direction). */
static R(ray) R(ray_setup)(R(vec3) origin, R(vec3) dir, REAL tmin, REAL tmax)
{
    R(ray) r;
    r.origin = origin;
    r.dir = dir;
    r.inv_dir = (R(vec3)){ (REAL)1 / dir.x, (REAL)1 / dir.y, (REAL)1 / dir.z };
    r.tmin = tmin;
    r.tmax = tmax;
    REAL ax = R(f_abs)(dir.x), ay = R(f_abs)(dir.y), az = R(f_abs)(dir.z);
    r.kz = ax >= ay && ax >= az ? 0u : (ay >= az ? 1u : 2u);
    watertight_axes(r.kz, R(v_get)(dir, r.kz) < 0, &r.kx, &r.ky);
    REAL dz = R(v_get)(dir, r.kz);
    r.sx = R(v_get)(dir, r.kx) / dz;
    r.sy = R(v_get)(dir, r.ky) / dz;
    r.sz = (REAL)1 / dz;
    return r;
}

typedef struct R(camera) {
    R(vec3) eye, right, up, forward;
    uint32_t width, height;
} R(camera);

/* The unit direction of pixel (x, y)'s primary ray through its centre. */
static R(vec3) R(camera_dir)(const R(camera) *p, uint32_t x, uint32_t y)
{
    REAL sx = (REAL)2 * ((REAL)x + (REAL)0.5) / (REAL)p->width - (REAL)1;
    REAL sy = (REAL)1 - (REAL)2 * ((REAL)y + (REAL)0.5) / (REAL)p->height;
    R(vec3) d = R(v_add)(R(v_add)(p->forward, R(v_scale)(p->right, sx)), R(v_scale)(p->up, sy));
    return R(v_scale)(d, (REAL)1 / REAL_SQRT(R(v_dot)(d, d)));
}

static R(ray) R(camera_ray)(const R(camera) *p, uint32_t x, uint32_t y)
{
    return R(ray_setup)(p->eye, R(camera_dir)(p, x, y), (REAL)0, REAL_INF);
}

/* An arbitrary ray (vkrt_trace_rays); false for one that must miss: a non-finite origin or
 * direction, or a zero direction. tmax = 0 means +infinity. */
static bool R(ray_from_buffer)(const vkrt_ray *g, R(ray) *out)
{
    R(vec3) o = { (REAL)g->origin[0], (REAL)g->origin[1], (REAL)g->origin[2] };
    R(vec3) d = { (REAL)g->dir[0], (REAL)g->dir[1], (REAL)g->dir[2] };
    if (!R(finite3)(o) || !R(finite3)(d) || (d.x == 0 && d.y == 0 && d.z == 0)) return false;
    *out = R(ray_setup)(o, d, (REAL)g->tmin, g->tmax == 0.0f ? REAL_INF : (REAL)g->tmax);
    return true;
}

static bool R(intersect_triangle_moller_trumbore)(const R(ray) *r, const vkrt_gpu_tri *tri, REAL *out_t, REAL *out_u,
                                                  REAL *out_v)
{
    R(vec3) v0 = R(v_load)(tri->v0);
    R(vec3) e1 = R(v_sub)(R(v_load)(tri->v1), v0);
    R(vec3) e2 = R(v_sub)(R(v_load)(tri->v2), v0);
    R(vec3) pvec = R(v_cross)(r->dir, e2);
    REAL det = R(v_dot)(e1, pvec);
    if (det == 0) return false;
    REAL inv_det = (REAL)1 / det;
    R(vec3) tvec = R(v_sub)(r->origin, v0);
    REAL u = R(v_dot)(tvec, pvec) * inv_det;
    R(vec3) qvec = R(v_cross)(tvec, e1);
    REAL v = R(v_dot)(r->dir, qvec) * inv_det;
    REAL t = R(v_dot)(e2, qvec) * inv_det;
    /* Written as acceptance so a NaN from a nearly parallel ray is rejected too. */
    if (!(u >= 0 && v >= 0 && u + v <= 1 && t > r->tmin && t < r->tmax)) return false;
    *out_t = t;
    *out_u = u;
    *out_v = v;
    return true;
}

/* Woop, Benthin, Wald 2013: the corners relative to the origin, permuted and sheared so the
 * ray runs along +z from (0, 0); the 2D edge values U, V, W are then exactly negated for the
 * same edge seen from its two triangles (each a difference of two products of the same
 * per-vertex values), and rounding is monotonic, so a nonzero value has the sign of the exact
 * one and two triangles never both reject a ray through their shared edge.
 * Zero rule: a zero edge value rejects nothing (a ray through a shared edge or vertex hits
 * every triangle there, the closest-hit rule picking the lowest prim_id). The float path first
 * re-evaluates all three values in double when one is exactly 0 (the products of floats are
 * exact in double, so the result has the exact sign), as the paper does; the GPU keeps the
 * float zeros, which the zero rule makes watertight too. */
static bool R(intersect_triangle_watertight)(const R(ray) *r, const vkrt_gpu_tri *tri, REAL *out_t, REAL *out_u,
                                             REAL *out_v)
{
    R(vec3) a = R(v_sub)(R(v_load)(tri->v0), r->origin);
    R(vec3) b = R(v_sub)(R(v_load)(tri->v1), r->origin);
    R(vec3) c = R(v_sub)(R(v_load)(tri->v2), r->origin);
    REAL a_z = R(v_get)(a, r->kz), b_z = R(v_get)(b, r->kz), c_z = R(v_get)(c, r->kz);
    REAL ax = R(v_get)(a, r->kx) - r->sx * a_z;
    REAL ay = R(v_get)(a, r->ky) - r->sy * a_z;
    REAL bx = R(v_get)(b, r->kx) - r->sx * b_z;
    REAL by = R(v_get)(b, r->ky) - r->sy * b_z;
    REAL cx = R(v_get)(c, r->kx) - r->sx * c_z;
    REAL cy = R(v_get)(c, r->ky) - r->sy * c_z;
    REAL eu = cx * by - cy * bx;
    REAL ev = ax * cy - ay * cx;
    REAL ew = bx * ay - by * ax;
#if REAL_IS_FLOAT
    if (eu == 0.0f || ev == 0.0f || ew == 0.0f) {
        eu = (float)((double)cx * (double)by - (double)cy * (double)bx);
        ev = (float)((double)ax * (double)cy - (double)ay * (double)cx);
        ew = (float)((double)bx * (double)ay - (double)by * (double)ax);
    }
#endif
    if ((eu < 0 || ev < 0 || ew < 0) && (eu > 0 || ev > 0 || ew > 0)) return false;
    REAL det = (eu + ev) + ew;
    if (det == 0) return false;
    REAL t_scaled = (eu * (r->sz * a_z) + ev * (r->sz * b_z)) + ew * (r->sz * c_z);
    REAL inv_det = (REAL)1 / det;
    REAL t = t_scaled * inv_det;
    if (!(t > r->tmin && t < r->tmax)) return false;
    *out_t = t;
    *out_u = ev * inv_det;
    *out_v = ew * inv_det;
    return true;
}

static bool R(intersect_triangle)(vkrt_intersector isect, const R(ray) *r, const vkrt_gpu_tri *tri, REAL *out_t,
                                  REAL *out_u, REAL *out_v)
{
    return isect == VKRT_INTERSECTOR_MOLLER_TRUMBORE ? R(intersect_triangle_moller_trumbore)(r, tri, out_t, out_u, out_v)
                                                     : R(intersect_triangle_watertight)(r, tri, out_t, out_u, out_v);
}

/* The shared closest-hit rule: nearer wins, and at equal distance the lower prim_id, so the
 * answer does not depend on the order triangles are visited (BVH vs naive, any builder). */
static inline bool R(hit_closer)(REAL t, uint32_t prim, REAL best_t, uint32_t best_prim)
{
    return t < best_t || (t == best_t && prim < best_prim);
}

/* A closer hit of an alpha-tested scene must also pass its material's alpha test (see
 * alpha_passes in cpu_trace.c; the double reference tests its barycentrics rounded to float). */
static inline void R(test_triangle)(vkrt_intersector isect, const R(ray) *r, const cpu_trace_scene *s, uint32_t index,
                                    R(hit) *best)
{
    const vkrt_gpu_tri *tris = s->tris;
    REAL t, u, v;
    if (R(intersect_triangle)(isect, r, &tris[index], &t, &u, &v) &&
        R(hit_closer)(t, tris[index].prim_id, best->t, best->prim) &&
        (!s->alpha_tested || alpha_passes(s, tris[index].prim_id, (float)u, (float)v))) {
        best->t = t;
        best->u = u;
        best->v = v;
        best->tri = index;
        best->prim = tris[index].prim_id;
    }
}

/* One slab: the t interval in which the ray lies between the planes lo and hi of one axis.
 * A direction component of +0 or -0 (an infinite reciprocal) would give 0 * inf = NaN for an
 * origin on a plane: the ray runs parallel to the planes, so the slab is every t when the
 * origin lies between them (bounds included) and empty otherwise. */
static inline void R(slab)(REAL o, REAL inv, REAL lo, REAL hi, REAL *out_lo, REAL *out_hi)
{
    REAL t0 = (lo - o) * inv;
    REAL t1 = (hi - o) * inv;
    bool parallel = R(f_abs)(inv) == REAL_INF;
    bool inside = o >= lo && o <= hi;
    *out_lo = parallel ? (inside ? -REAL_INF : REAL_INF) : R(f_min)(t0, t1);
    *out_hi = parallel ? (inside ? REAL_INF : -REAL_INF) : R(f_max)(t0, t1);
}

/* The farthest entry distance a box or stack entry may have and still be visited: best t plus
 * VKRT_PRUNE_SLACK of it, so that both triangles of a tie get tested whatever the order (see
 * vkrt_shared.h). Mirrors prune_bound() in shaders/trace_common.glsl. */
static inline REAL R(prune_bound)(REAL best_t)
{
    return best_t + R(f_abs)(best_t) * (REAL)VKRT_PRUNE_SLACK;
}

/* Ize 2013: the far end widened by 1 + 2 gamma(3) (REAL_TFAR_WIDEN) before it meets
 * best_t (as prune_bound), so a box the exact ray enters is never culled by rounding. */
static bool R(intersect_box)(const R(ray) *r, const vkrt_gpu_node *n, REAL best_t, REAL *out_tnear)
{
    REAL lx, hx, ly, hy, lz, hz;
    R(slab)(r->origin.x, r->inv_dir.x, (REAL)n->bmin.x, (REAL)n->bmax.x, &lx, &hx);
    R(slab)(r->origin.y, r->inv_dir.y, (REAL)n->bmin.y, (REAL)n->bmax.y, &ly, &hy);
    R(slab)(r->origin.z, r->inv_dir.z, (REAL)n->bmin.z, (REAL)n->bmax.z, &lz, &hz);
    REAL tnear = R(f_max)(R(f_max)(lx, ly), R(f_max)(lz, r->tmin));
    REAL tfar = R(f_min)(R(f_min)(hx, hy), hz) * (REAL)REAL_TFAR_WIDEN;
    tfar = R(f_min)(tfar, R(prune_bound)(best_t));
    *out_tnear = tnear;
    return tnear <= tfar;
}

/* any_hit: stop at the first hit (shadow and AO rays), as trace_bvh in shaders/trace.comp does
 * with ANYHIT. */
static void R(trace_bvh)(const cpu_trace_scene *s, vkrt_intersector isect, const R(ray) *r, R(hit) *best,
                         heat_counts *heat, bool any_hit)
{
    if (s->node_count == 0) return;
    uint32_t stack_node[VKRT_TRAVERSAL_STACK_SIZE];
    REAL stack_tnear[VKRT_TRAVERSAL_STACK_SIZE];
    uint32_t sp = 0;
    REAL tnear;
    if (!R(intersect_box)(r, &s->nodes[0], best->t, &tnear)) return;
    heat->nodes++;
    if (s->nodes[0].tri_count != 0) heat->leaves++;
    uint32_t node = 0;
    for (;;) {
        const vkrt_gpu_node *n = &s->nodes[node];
        bool descend = false;
        if (n->tri_count != 0) {
            for (uint32_t i = n->left_first; i < n->left_first + n->tri_count; i++) {
                heat->tris++;
                R(test_triangle)(isect, r, s, i, best);
                if (any_hit && best->prim != NO_PRIM) return;
            }
        } else {
            uint32_t left = n->left_first, right = left + 1;
            REAL tl, tr;
            bool hit_l = R(intersect_box)(r, &s->nodes[left], best->t, &tl);
            bool hit_r = R(intersect_box)(r, &s->nodes[right], best->t, &tr);
            if (hit_l) {
                heat->nodes++;
                if (s->nodes[left].tri_count != 0) heat->leaves++;
            }
            if (hit_r) {
                heat->nodes++;
                if (s->nodes[right].tri_count != 0) heat->leaves++;
            }
            if (hit_l && hit_r) {
                uint32_t far_node = tr < tl ? left : right;
                REAL far_t = tr < tl ? tl : tr;
                node = tr < tl ? right : left;
                /* Never full for a BVH within VKRT_MAX_BVH_DEPTH: one entry per level above. */
                if (sp < VKRT_TRAVERSAL_STACK_SIZE) {
                    stack_node[sp] = far_node;
                    stack_tnear[sp] = far_t;
                    sp++;
                }
                descend = true;
            } else if (hit_l) {
                node = left;
                descend = true;
            } else if (hit_r) {
                node = right;
                descend = true;
            }
        }
        if (descend) continue;
        /* A pushed box that starts beyond the closest hit found since cannot improve it. */
        while (sp > 0 && stack_tnear[sp - 1] > R(prune_bound)(best->t)) sp--;
        if (sp == 0) break;
        sp--;
        node = stack_node[sp];
    }
}

static void R(trace_naive)(const cpu_trace_scene *s, vkrt_intersector isect, const R(ray) *r, R(hit) *best,
                           bool any_hit)
{
    for (uint32_t i = 0; i < s->tri_count; i++) {
        R(test_triangle)(isect, r, s, i, best);
        if (any_hit && best->prim != NO_PRIM) return;
    }
}

/* Closest (or with any_hit, the first found) hit of one ray with the chosen traversal, as the
 * float hit the shading reads. */
static hit R(trace_ray)(const cpu_trace_scene *s, vkrt_traversal traversal, vkrt_intersector isect, const R(ray) *r,
                        heat_counts *heat, bool any_hit)
{
    R(hit) best = { .t = r->tmax, .tri = NO_PRIM, .prim = NO_PRIM };
    if (traversal == VKRT_TRAVERSAL_NAIVE) R(trace_naive)(s, isect, r, &best, any_hit);
    else R(trace_bvh)(s, isect, r, &best, heat, any_hit);
    return (hit){ .t = (float)best.t, .u = (float)best.u, .v = (float)best.v, .tri = best.tri, .prim = best.prim };
}

#undef REAL
#undef R
#undef REAL_IS_FLOAT
#undef REAL_SQRT
#undef REAL_INF
#undef REAL_TFAR_WIDEN

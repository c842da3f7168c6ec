/* The C reference tracer. Every function below mirrors the GLSL function of the same name in
 * shaders/trace_common.glsl or shaders/trace.comp, with the arithmetic written in the same
 * order, so the two backends differ only by the rounding freedom GLSL grants the device.
 *
 * Triangle test: Möller, Trumbore, "Fast, Minimum Storage Ray/Triangle Intersection",
 * Journal of Graphics Tools 2(1), 1997. Box test: the slab method of Kay, Kajiya, "Ray
 * Tracing Complex Scenes", SIGGRAPH 1986, with the reciprocal direction of Williams et al.,
 * "An Efficient and Robust Ray-Box Intersection Algorithm", JGT 10(1), 2005. */
#include "cpu_trace.h"

#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>

#include "scene_pack.h"

/* Square tiles of this side are the unit of work a thread claims: small enough that threads
 * finish together and that a cancel is seen soon, large enough that the shared counter is
 * touched once per 256 rays. */
#define TILE 16
#define NO_PRIM 0xFFFFFFFFu

typedef vkrt_float3 vec3;

static vec3 v_sub(vec3 a, vec3 b) { return (vec3){ a.x - b.x, a.y - b.y, a.z - b.z }; }
static vec3 v_add(vec3 a, vec3 b) { return (vec3){ a.x + b.x, a.y + b.y, a.z + b.z }; }
static vec3 v_mul(vec3 a, vec3 b) { return (vec3){ a.x * b.x, a.y * b.y, a.z * b.z }; }
static vec3 v_scale(vec3 a, float s) { return (vec3){ a.x * s, a.y * s, a.z * s }; }
static float v_dot(vec3 a, vec3 b) { return (a.x * b.x + a.y * b.y) + a.z * b.z; }
static vec3 v_cross(vec3 a, vec3 b)
{
    return (vec3){ a.y * b.z - b.y * a.z, a.z * b.x - b.z * a.x, a.x * b.y - b.x * a.y };
}
static vec3 v_normalize(vec3 a) { return v_scale(a, 1.0f / sqrtf(v_dot(a, a))); }
/* GLSL's definitions, including which operand wins for NaN. */
static float f_min(float x, float y) { return y < x ? y : x; }
static float f_max(float x, float y) { return x < y ? y : x; }
static vec3 v_min(vec3 a, vec3 b) { return (vec3){ f_min(a.x, b.x), f_min(a.y, b.y), f_min(a.z, b.z) }; }
static vec3 v_max(vec3 a, vec3 b) { return (vec3){ f_max(a.x, b.x), f_max(a.y, b.y), f_max(a.z, b.z) }; }

typedef struct ray {
    vec3 origin, dir, inv_dir;
} ray;

/* Closest hit so far; t = +inf with prim = NO_PRIM means none. */
typedef struct hit {
    float t, u, v;
    uint32_t tri;  /* index into the triangle array (BVH order) */
    uint32_t prim; /* its prim_id, the tie-breaker */
} hit;

typedef struct heat_counts {
    uint32_t nodes, leaves, tris;
} heat_counts;

static ray camera_ray(const vkrt_gpu_push *p, uint32_t x, uint32_t y)
{
    float sx = 2.0f * ((float)x + 0.5f) / (float)p->width - 1.0f;
    float sy = 1.0f - 2.0f * ((float)y + 0.5f) / (float)p->height;
    ray r;
    r.origin = p->eye;
    r.dir = v_normalize(v_add(v_add(p->forward, v_scale(p->right, sx)), v_scale(p->up, sy)));
    r.inv_dir = (vec3){ 1.0f / r.dir.x, 1.0f / r.dir.y, 1.0f / r.dir.z };
    return r;
}

static bool intersect_triangle(const ray *r, const vkrt_gpu_tri *tri, float *out_t, float *out_u, float *out_v)
{
    vec3 e1 = v_sub(tri->v1, tri->v0);
    vec3 e2 = v_sub(tri->v2, tri->v0);
    vec3 pvec = v_cross(r->dir, e2);
    float det = v_dot(e1, pvec);
    if (det == 0.0f) return false;
    float inv_det = 1.0f / det;
    vec3 tvec = v_sub(r->origin, tri->v0);
    float u = v_dot(tvec, pvec) * inv_det;
    vec3 qvec = v_cross(tvec, e1);
    float v = v_dot(r->dir, qvec) * inv_det;
    float t = v_dot(e2, qvec) * inv_det;
    /* Written as acceptance so a NaN from a nearly parallel ray is rejected too. */
    if (!(u >= 0.0f && v >= 0.0f && u + v <= 1.0f && t > 0.0f)) return false;
    *out_t = t;
    *out_u = u;
    *out_v = v;
    return true;
}

/* The shared closest-hit rule: nearer wins, and at equal distance the lower prim_id, so the
 * answer does not depend on the order triangles are visited (BVH vs naive, any builder). */
static bool hit_closer(float t, uint32_t prim, float best_t, uint32_t best_prim)
{
    return t > 0.0f && (t < best_t || (t == best_t && prim < best_prim));
}

static void test_triangle(const ray *r, const vkrt_gpu_tri *tris, uint32_t index, hit *best)
{
    float t, u, v;
    if (intersect_triangle(r, &tris[index], &t, &u, &v) && hit_closer(t, tris[index].prim_id, best->t, best->prim)) {
        best->t = t;
        best->u = u;
        best->v = v;
        best->tri = index;
        best->prim = tris[index].prim_id;
    }
}

static bool intersect_box(const ray *r, const vkrt_gpu_node *n, float best_t, float *out_tnear)
{
    vec3 t0 = v_mul(v_sub(n->bmin, r->origin), r->inv_dir);
    vec3 t1 = v_mul(v_sub(n->bmax, r->origin), r->inv_dir);
    vec3 tmin = v_min(t0, t1);
    vec3 tmax = v_max(t0, t1);
    float tnear = f_max(f_max(tmin.x, tmin.y), f_max(tmin.z, 0.0f));
    float tfar = f_min(f_min(tmax.x, tmax.y), f_min(tmax.z, best_t));
    *out_tnear = tnear;
    return tnear <= tfar;
}

static void trace_bvh(const cpu_trace_scene *s, const ray *r, hit *best, heat_counts *heat)
{
    if (s->node_count == 0) return;
    uint32_t stack_node[VKRT_TRAVERSAL_STACK_SIZE];
    float stack_tnear[VKRT_TRAVERSAL_STACK_SIZE];
    uint32_t sp = 0;
    float tnear;
    if (!intersect_box(r, &s->nodes[0], best->t, &tnear)) return;
    heat->nodes++;
    if (s->nodes[0].tri_count != 0) heat->leaves++;
    uint32_t node = 0;
    for (;;) {
        const vkrt_gpu_node *n = &s->nodes[node];
        bool descend = false;
        if (n->tri_count != 0) {
            for (uint32_t i = n->left_first; i < n->left_first + n->tri_count; i++) {
                heat->tris++;
                test_triangle(r, s->tris, i, best);
            }
        } else {
            uint32_t left = n->left_first, right = left + 1;
            float tl, tr;
            bool hit_l = intersect_box(r, &s->nodes[left], best->t, &tl);
            bool hit_r = intersect_box(r, &s->nodes[right], best->t, &tr);
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
                float far_t = tr < tl ? tl : tr;
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
        while (sp > 0 && stack_tnear[sp - 1] > best->t) sp--;
        if (sp == 0) break;
        sp--;
        node = stack_node[sp];
    }
}

static void trace_naive(const cpu_trace_scene *s, const ray *r, hit *best)
{
    for (uint32_t i = 0; i < s->tri_count; i++) test_triangle(r, s->tris, i, best);
}

static void shade(const cpu_trace_scene *s, const cpu_trace_params *p, const hit *best, const heat_counts *heat,
                  float out[4])
{
    bool is_hit = best->t < INFINITY;
    switch (p->mode) {
    case VKRT_MODE_HEATMAP: {
        uint32_t count = p->heat == VKRT_HEAT_LEAVES ? heat->leaves : p->heat == VKRT_HEAT_TRIS ? heat->tris : heat->nodes;
        out[0] = (float)count, out[1] = 0.0f, out[2] = 0.0f, out[3] = 1.0f;
        return;
    }
    case VKRT_MODE_DEPTH:
        if (is_hit) out[0] = best->t, out[1] = 0.0f, out[2] = 0.0f, out[3] = 1.0f;
        else out[0] = (float)VKRT_MISS, out[1] = 0.0f, out[2] = 0.0f, out[3] = 0.0f;
        return;
    case VKRT_MODE_ID:
        if (is_hit) out[0] = (float)best->prim, out[1] = best->u, out[2] = best->v, out[3] = 1.0f;
        else out[0] = (float)VKRT_MISS, out[1] = 0.0f, out[2] = 0.0f, out[3] = 0.0f;
        return;
    default: {
        if (!is_hit) {
            out[0] = out[1] = out[2] = out[3] = 0.0f;
            return;
        }
        const vkrt_gpu_tri *tri = &s->tris[best->tri];
        float a[3], b[3], c[3];
        normal_decode_oct(tri->n0, a);
        normal_decode_oct(tri->n1, b);
        normal_decode_oct(tri->n2, c);
        float w = 1.0f - best->u - best->v;
        vec3 n = v_add(v_add(v_scale((vec3){ a[0], a[1], a[2] }, w), v_scale((vec3){ b[0], b[1], b[2] }, best->u)),
                       v_scale((vec3){ c[0], c[1], c[2] }, best->v));
        float len2 = v_dot(n, n);
        /* Opposed vertex normals can cancel; the face normal is the only direction left. */
        n = len2 > 0.0f ? v_scale(n, 1.0f / sqrtf(len2)) : tri->face_n;
        out[0] = n.x * 0.5f + 0.5f, out[1] = n.y * 0.5f + 0.5f, out[2] = n.z * 0.5f + 0.5f, out[3] = 1.0f;
        return;
    }
    }
}

static void trace_pixel(const cpu_trace_scene *s, const cpu_trace_params *p, uint32_t x, uint32_t y, float out[4])
{
    hit best = { .t = INFINITY, .tri = NO_PRIM, .prim = NO_PRIM };
    heat_counts heat = { 0 };
    if (p->traversal == VKRT_TRAVERSAL_NAIVE) {
        heat.tris = s->tri_count;
        /* Naive heat is tri_count whatever the ray does, so the heatmap skips the tests. */
        if (p->mode != VKRT_MODE_HEATMAP) {
            ray r = camera_ray(&p->camera, x, y);
            trace_naive(s, &r, &best);
        }
    } else {
        ray r = camera_ray(&p->camera, x, y);
        trace_bvh(s, &r, &best, &heat);
    }
    shade(s, p, &best, &heat, out);
}

/* ---- threads ---- */

typedef struct job {
    const cpu_trace_scene *scene;
    const cpu_trace_params *params;
    float *out;
    uint32_t tiles_x, tiles;
    atomic_uint next_tile;
    atomic_uint done_tiles;
    atomic_bool cancel;
} job;

/* Claims and traces one tile; false when none is left or the render was cancelled. */
static bool run_one_tile(job *j)
{
    if (atomic_load_explicit(&j->cancel, memory_order_relaxed)) return false;
    uint32_t t = atomic_fetch_add_explicit(&j->next_tile, 1, memory_order_relaxed);
    if (t >= j->tiles) return false;
    const uint32_t width = j->params->camera.width, height = j->params->camera.height;
    uint32_t x0 = (t % j->tiles_x) * TILE, y0 = (t / j->tiles_x) * TILE;
    uint32_t x1 = x0 + TILE < width ? x0 + TILE : width, y1 = y0 + TILE < height ? y0 + TILE : height;
    for (uint32_t y = y0; y < y1; y++) {
        /* Checked per row so a cancel stops a slow (naive, large) tile early. */
        if (atomic_load_explicit(&j->cancel, memory_order_relaxed)) return false;
        for (uint32_t x = x0; x < x1; x++)
            trace_pixel(j->scene, j->params, x, y, j->out + ((size_t)y * width + x) * 4);
    }
    atomic_fetch_add_explicit(&j->done_tiles, 1, memory_order_relaxed);
    return true;
}

static void *worker_main(void *arg)
{
    job *j = arg;
    while (run_one_tile(j)) {
    }
    return NULL;
}

vkrt_result cpu_trace_render(core *c, const cpu_trace_scene *scene, const cpu_trace_params *params, float *out_rgba)
{
    const uint32_t width = params->camera.width, height = params->camera.height;
    job j = { .scene = scene, .params = params, .out = out_rgba };
    j.tiles_x = (width + TILE - 1) / TILE;
    j.tiles = j.tiles_x * ((height + TILE - 1) / TILE);
    atomic_init(&j.next_tile, 0);
    atomic_init(&j.done_tiles, 0);
    atomic_init(&j.cancel, false);

    uint32_t helpers = params->threads > 1 ? params->threads - 1 : 0;
    if (helpers > j.tiles) helpers = j.tiles;
    pthread_t *threads = NULL;
    if (helpers) {
        threads = core_alloc_array(c, helpers, sizeof *threads);
        if (!threads) return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory for %u trace threads", helpers);
    }
    uint32_t started = 0;
    vkrt_result r = VKRT_OK;
    for (; started < helpers; started++) {
        if (pthread_create(&threads[started], NULL, worker_main, &j) != 0) {
            atomic_store(&j.cancel, true);
            r = core_fail(c, VKRT_ERROR_LIMIT, "could not start trace thread %u of %u", started + 1, helpers);
            break;
        }
    }
    /* The calling thread traces too, and between its tiles it alone reports progress, so the
     * callback never runs on a worker. */
    while (r == VKRT_OK && run_one_tile(&j)) {
        if (params->progress) {
            float fraction = (float)atomic_load_explicit(&j.done_tiles, memory_order_relaxed) / (float)j.tiles;
            if (!params->progress(params->progress_user, "trace", fraction)) {
                atomic_store(&j.cancel, true);
                r = core_fail(c, VKRT_ERROR_CANCELLED, "render cancelled by the progress callback");
            }
        }
    }
    for (uint32_t i = 0; i < started; i++) pthread_join(threads[i], NULL);
    core_free(c, threads);
    if (r == VKRT_OK && params->progress) params->progress(params->progress_user, "trace", 1.0f);
    return r;
}

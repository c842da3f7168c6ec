/* The C reference tracer: cpu_trace_real.h holds the traversal and the triangle and box tests,
 * instantiated here for float (the mirror of shaders/trace_common.glsl and trace.comp, with
 * the arithmetic in the same order, so the two backends differ only by the rounding freedom
 * GLSL grants the device) and for double (the reference). This file adds the per-mode
 * outputs and the threads. Papers: see cpu_trace_real.h. */
#include "cpu_trace.h"

#include <math.h>
#include <stdatomic.h>
#include <stdbool.h>

#include "cpu_integrate.h"
#include "float8.h"
#include "ray4.h"
#include "scene_pack.h"
#include "texture.h"
#include "work_pool.h"

/* Square tiles of this side are the unit of work a thread claims: small enough that threads
 * finish together and that a cancel is seen soon, large enough that the shared counter is
 * touched once per 256 rays. */
#define TILE 16
/* vkrt_trace_rays: rays per claimed block, for the same reasons. */
#define RAY_BLOCK 1024
#define NO_PRIM 0xFFFFFFFFu

typedef vkrt_float3 vec3;

static vec3 v_add(vec3 a, vec3 b) { return (vec3){ a.x + b.x, a.y + b.y, a.z + b.z }; }
static vec3 v_scale(vec3 a, float s) { return (vec3){ a.x * s, a.y * s, a.z * s }; }
static float v_dot(vec3 a, vec3 b) { return (a.x * b.x + a.y * b.y) + a.z * b.z; }

/* A closest hit as shading reads it (a double hit rounded); prim = NO_PRIM means none. */
typedef struct hit {
    float t, u, v;
    uint32_t tri;  /* index into the triangle array (BVH order) */
    uint32_t prim; /* its prim_id */
} hit;

typedef struct heat_counts {
    uint32_t nodes, leaves, tris;
} heat_counts;

/* Texture coordinates interpolated with the hit's barycentrics (u: corner 1, v: corner 2).
 * Mirrors surface_uv() in shaders/trace.comp. */
static void surface_uv(const vkrt_gpu_surface *f, float u, float v, float out[2])
{
    float w = 1.0f - u - v;
    out[0] = (f->u0 * w + f->u1 * u) + f->u2 * v;
    out[1] = (f->v0 * w + f->v1 * u) + f->v2 * v;
}

/* Whether a hit at barycentrics (u, v) on triangle prim is there: its material is opaque, or
 * its alpha (times the texture's) reaches the cutoff. Mirrors alpha_passes() in
 * shaders/trace.comp. */
static bool alpha_passes(const cpu_trace_scene *s, uint32_t prim, float u, float v)
{
    const vkrt_gpu_surface *f = &s->surfaces[prim];
    const vkrt_gpu_material *m = &s->materials[f->material];
    if (!(m->alpha_cutoff > 0.0f)) return true;
    float alpha = m->alpha;
    if (m->base_color_texture != VKRT_NO_TEXTURE) {
        float uv[2], texel[4];
        surface_uv(f, u, v, uv);
        texture_sample(&s->textures[m->base_color_texture], s->texels, uv[0], uv[1], texel);
        alpha = alpha * texel[3];
    }
    return alpha >= m->alpha_cutoff;
}

/* The watertight test's other two axes for kz, the axis of the largest |dir| (Woop et al.,
 * section 3): the next two in turn, swapped where dir[kz] < 0 so that the permutation keeps the
 * winding. One definition for ray_setup_f/_d and the packets' eight-lane setup. */
static inline void watertight_axes(uint32_t kz, bool dir_kz_negative, uint32_t *out_kx, uint32_t *out_ky)
{
    uint32_t kx = kz == 2u ? 0u : kz + 1u, ky = kx == 2u ? 0u : kx + 1u;
    *out_kx = dir_kz_negative ? ky : kx;
    *out_ky = dir_kz_negative ? kx : ky;
}

#define REAL float
#define R(name) name##_f
#define REAL_IS_FLOAT 1
#define REAL_SQRT sqrtf
#define REAL_INF INFINITY
#define REAL_TFAR_WIDEN VKRT_TFAR_WIDEN_FLOAT
#include "cpu_trace_real.h"

#include "cpu_trace_bvh4.h"
#include "cpu_trace_packet8.h"

#define REAL double
#define R(name) name##_d
#define REAL_IS_FLOAT 0
#define REAL_SQRT sqrt
#define REAL_INF ((double)INFINITY)
#define REAL_TFAR_WIDEN VKRT_TFAR_WIDEN_DOUBLE
#include "cpu_trace_real.h"

/* The distance of a hit the float path found, recomputed in double as the intersection of an
 * exact ray with the triangle's plane: the pixel's ray generated in double from the camera
 * basis (whose values the float ray was rounded from), or a vkrt_trace_rays ray as given.
 * Float edge functions lose digits to cancellation where a ray grazes a triangle (1.8e-5
 * relative at 1e-4 radians), and a float ray's direction is a few ulps off the pixel's, which
 * moves a grazing hit by that angle times tan(incidence): the plane distance of the exact ray
 * in double has neither error. Which triangle wins is still decided in float; this runs once
 * per ray. A ray in the plane, or a distance outside the ray's interval, keeps the float t.
 * Mirrors refine_hit_distance() in shaders/trace_common.glsl (the GPU does this where the
 * device has doubles). */
static float refine_hit_distance(vec3_d origin, vec3_d dir, double tmin, double tmax, const vkrt_gpu_tri *tri,
                                 float t)
{
    vec3_d v0 = v_load_d(tri->v0), v1 = v_load_d(tri->v1), v2 = v_load_d(tri->v2);
    vec3_d n = v_cross_d(v_sub_d(v1, v0), v_sub_d(v2, v0));
    double denom = v_dot_d(n, dir);
    if (denom == 0.0) return t;
    double refined = v_dot_d(n, v_sub_d(v0, origin)) / denom;
    return refined > tmin && refined < tmax ? (float)refined : t;
}

/* A float ray through the binary traversal, or through the 4-wide one where the scene has it
 * and no one reads the binary traversal's counts (`counted`): the same hit either way. */
static hit trace_float(const cpu_trace_scene *s, vkrt_traversal traversal, vkrt_intersector isect, const ray_f *r,
                       heat_counts *heat, bool any_hit, bool counted)
{
    if (s->wide && traversal == VKRT_TRAVERSAL_BVH && !counted) return trace_ray_bvh4_f(s, isect, r, any_hit);
    return trace_ray_f(s, traversal, isect, r, heat, any_hit);
}

/* This file is compiled twice where the compiler can target x86-64-v3 (meson.build): once for
 * the baseline (SSE2, every x86-64), and once with VKRT_CPU_TRACE_X86_64_V3 and
 * -march=x86-64-v3, which makes only the two entry points below with that suffix. AVX2's
 * three-operand encodings, BMI's bit scans and the wider registers cut moves and spills from
 * the traversal; floating-point contraction stays off (ISO C mode and -ffp-contract=off), so
 * both builds round every operation alike and give the same bits. cpu_trace_render and
 * cpu_trace_rays run the v3 code where the host has it (cpu_trace_isa). The other entry points
 * (tests, the GPU wavefront's one-ray trace) exist in the baseline build only. */
#ifndef VKRT_CPU_TRACE_X86_64_V3
unsigned cpu_trace_box4_test(const vkrt_gpu_ray *ray, const bvh4_node *n, float best_t, bool simd,
                             float out_tnear[BVH4_WIDTH])
{
    ray_f r = ray_setup_f(v_load_f(ray->origin), v_load_f(ray->dir), ray->tmin, INFINITY);
    if (simd) {
        box4_ray b = box4_ray_setup(&r);
        return box4_test(&b, n, best_t, out_tnear);
    }
    return box4_test_scalar(&r, n, best_t, out_tnear);
}

unsigned cpu_trace_watertight4_test(const vkrt_gpu_ray *ray, const vkrt_gpu_tri *const tris[4], bool simd,
                                    float out_t[4], float out_u[4], float out_v[4])
{
    ray_f r = ray_setup_f(v_load_f(ray->origin), v_load_f(ray->dir), ray->tmin, ray->tmax);
    if (simd) return watertight4(&r, tris, out_t, out_u, out_v);
    unsigned mask = 0;
    for (unsigned l = 0; l < 4; l++)
        if (intersect_triangle_watertight_f(&r, tris[l], &out_t[l], &out_u[l], &out_v[l])) mask |= 1u << l;
    return mask;
}

bool cpu_trace_ray_enters_box(const vkrt_ray *ray, const vkrt_gpu_node *box)
{
    ray_f r;
    float tnear;
    return ray_from_buffer_f(ray, &r) && intersect_box_f(&r, box, r.tmax, &tnear);
}

vkrt_gpu_ray cpu_trace_camera_ray(const vkrt_gpu_push *camera, uint32_t x, uint32_t y)
{
    camera_f cam = { v_load_f(camera->eye), v_load_f(camera->right), v_load_f(camera->up), v_load_f(camera->forward),
                     camera->width, camera->height };
    /* The direction alone: the traversal's set-up (six divisions) is not the ray's. */
    const vec3_f dir = camera_dir_f(&cam, x, y);
    return (vkrt_gpu_ray){ { cam.eye.x, cam.eye.y, cam.eye.z }, 0.0f, { dir.x, dir.y, dir.z }, 0.0f };
}

bool cpu_trace_one(const cpu_trace_scene *s, vkrt_traversal traversal, vkrt_intersector isect, const vkrt_gpu_ray *ray,
                   bool any_hit, vkrt_gpu_hit *out_hit, trace_counts *counts)
{
    ray_f r;
    heat_counts heat = { 0 };
    hit best = { .prim = NO_PRIM };
    /* vkrt_gpu_ray and vkrt_ray share one layout (asserted in api.c). */
    if (ray_from_buffer_f((const vkrt_ray *)ray, &r)) best = trace_float(s, traversal, isect, &r, &heat, any_hit, false);
    counts->nodes += heat.nodes;
    counts->leaves += heat.leaves;
    counts->tris += heat.tris;
    *out_hit = best.prim != NO_PRIM ? (vkrt_gpu_hit){ best.t, best.tri, best.u, best.v }
                                    : (vkrt_gpu_hit){ -1.0f, NO_PRIM, 0.0f, 0.0f };
    return best.prim != NO_PRIM;
}

#endif /* !VKRT_CPU_TRACE_X86_64_V3 */

static void shade(const cpu_trace_scene *s, const cpu_trace_params *p, const hit *best, const heat_counts *heat,
                  float out[4])
{
    bool is_hit = best->prim != NO_PRIM;
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
    case VKRT_MODE_ALBEDO: {
        out[0] = out[1] = out[2] = out[3] = 0.0f;
        if (!is_hit) return;
        const vkrt_gpu_surface *f = &s->surfaces[best->prim];
        const vkrt_gpu_material *m = &s->materials[f->material];
        out[0] = m->base_color.x, out[1] = m->base_color.y, out[2] = m->base_color.z, out[3] = m->alpha;
        if (m->base_color_texture != VKRT_NO_TEXTURE) {
            /* Mirrors shade_albedo() in shaders/trace.comp. */
            float uv[2], texel[4];
            surface_uv(f, best->u, best->v, uv);
            texture_sample(&s->textures[m->base_color_texture], s->texels, uv[0], uv[1], texel);
            for (int k = 0; k < 4; k++) out[k] = out[k] * texel[k];
        }
        return;
    }
    case VKRT_MODE_UV: {
        out[0] = out[1] = out[2] = out[3] = 0.0f;
        if (!is_hit) return;
        surface_uv(&s->surfaces[best->prim], best->u, best->v, out);
        out[3] = 1.0f;
        return;
    }
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

/* ---- threads ---- */

typedef struct job job;
/* Traces work item `item` (a tile or a block of rays); false when cancelled midway. */
typedef bool (*job_item_fn)(job *j, size_t item);

struct job {
    job_item_fn run_item;
    uint32_t items;
    atomic_uint done_items;
    work_pool *pool;
    vkrt_progress_fn progress;
    void *progress_user;
    const cpu_trace_scene *scene;
    /* render */
    const cpu_trace_params *params;
    camera_f cam_f;
    camera_d cam_d;
    float *out;
    uint32_t tiles_x;
    atomic_uint_fast64_t count_nodes, count_leaves, count_tris; /* params->counters */
    atomic_uint_fast64_t count_samples, count_shadow, count_bounce; /* lighting modes */
    /* rays */
    const cpu_trace_rays_params *rays_params;
    const vkrt_ray *rays;
    size_t ray_count;
    vkrt_hit *hits;
};

/* A float hit of pixel (x, y) with its distance refined along the pixel's exact ray. */
static hit refine_pixel_hit(const job *j, uint32_t x, uint32_t y, hit best)
{
    if (best.prim == NO_PRIM) return best;
    ray_d exact = camera_ray_d(&j->cam_d, x, y);
    best.t = refine_hit_distance(exact.origin, exact.dir, 0.0, INFINITY, &j->scene->tris[best.tri], best.t);
    return best;
}

/* Traces pixel (x, y) into out and adds its traversal counts to *counts. */
static void trace_pixel(const job *j, uint32_t x, uint32_t y, float out[4], trace_counts *counts)
{
    const cpu_trace_scene *s = j->scene;
    const cpu_trace_params *p = j->params;
    if (p->lighting) {
        cpu_integrate_pixel(s, p, x, y, out, counts);
        return;
    }
    hit best = { .t = INFINITY, .tri = NO_PRIM, .prim = NO_PRIM };
    heat_counts heat = { 0 };
    if (p->traversal == VKRT_TRAVERSAL_NAIVE) heat.tris = s->tri_count;
    /* Naive heat is tri_count whatever the ray does, so the heatmap skips the tests. */
    if (p->traversal != VKRT_TRAVERSAL_NAIVE || p->mode != VKRT_MODE_HEATMAP) {
        if (p->precision == VKRT_PRECISION_DOUBLE) {
            ray_d r = camera_ray_d(&j->cam_d, x, y);
            best = trace_ray_d(s, p->traversal, p->intersector, &r, &heat, false);
        } else {
            ray_f r = camera_ray_f(&j->cam_f, x, y);
            /* The heat map and the render counters show the binary traversal (as the GPU's). */
            best = trace_float(s, p->traversal, p->intersector, &r, &heat, false, p->counters || p->mode == VKRT_MODE_HEATMAP);
            best = refine_pixel_hit(j, x, y, best);
        }
    }
    shade(s, p, &best, &heat, out);
    counts->nodes += heat.nodes;
    counts->leaves += heat.leaves;
    counts->tris += heat.tris;
}

/* Whether a tile's rows go eight pixels to a packet: float rays through the 4-wide BVH, which
 * no counter watches (a camera's neighbouring pixels are always coherent). */
static bool pixel_packets(const job *j)
{
    const cpu_trace_params *p = j->params;
    return j->scene->wide && !p->lighting && p->precision != VKRT_PRECISION_DOUBLE && p->traversal == VKRT_TRAVERSAL_BVH &&
           !p->counters && p->mode != VKRT_MODE_HEATMAP;
}

/* Pixels (x, y) to (x + 7, y) as one packet into out (32 floats), each as trace_pixel gives it. */
static void trace_pixels8(const job *j, uint32_t x, uint32_t y, float *out)
{
    packet8 packet;
    for (uint32_t l = 0; l < PACKET8_LANES; l++) packet.ray[l] = camera_ray_f(&j->cam_f, x + l, y);
    packet8_setup(&packet);
    trace_packet8_f(j->scene, j->params->intersector, false, &packet);
    for (uint32_t l = 0; l < PACKET8_LANES; l++) {
        const hit_f *b = &packet.best[l];
        hit best = refine_pixel_hit(j, x + l, y, (hit){ b->t, b->u, b->v, b->tri, b->prim });
        shade(j->scene, j->params, &best, &(heat_counts){ 0 }, out + 4 * l);
    }
}

static bool run_tile(job *j, size_t t)
{
    const uint32_t width = j->params->camera.width, height = j->params->camera.height;
    uint32_t x0 = (uint32_t)(t % j->tiles_x) * TILE, y0 = (uint32_t)(t / j->tiles_x) * TILE;
    uint32_t x1 = x0 + TILE < width ? x0 + TILE : width, y1 = y0 + TILE < height ? y0 + TILE : height;
    trace_counts counts = { 0 };
    const bool packets = pixel_packets(j);
    for (uint32_t y = y0; y < y1; y++) {
        /* Checked per row so a cancel stops a slow (naive, large) tile early. */
        if (work_pool_cancelled(j->pool)) return false;
        uint32_t x = x0;
        for (; packets && x + PACKET8_LANES <= x1; x += PACKET8_LANES)
            trace_pixels8(j, x, y, j->out + ((size_t)y * width + x) * 4);
        for (; x < x1; x++) trace_pixel(j, x, y, j->out + ((size_t)y * width + x) * 4, &counts);
    }
    if (j->params->counters) {
        atomic_fetch_add_explicit(&j->count_nodes, counts.nodes, memory_order_relaxed);
        atomic_fetch_add_explicit(&j->count_leaves, counts.leaves, memory_order_relaxed);
        atomic_fetch_add_explicit(&j->count_tris, counts.tris, memory_order_relaxed);
    }
    if (j->params->lighting) {
        atomic_fetch_add_explicit(&j->count_samples, counts.samples, memory_order_relaxed);
        atomic_fetch_add_explicit(&j->count_shadow, counts.shadow_rays, memory_order_relaxed);
        atomic_fetch_add_explicit(&j->count_bounce, counts.bounce_rays, memory_order_relaxed);
    }
    return true;
}

/* A float hit as vkrt_trace_rays returns it: the distance refined in double along r. Takes
 * the hit by pointer: a packet's hits, copied into a by-value struct for the call, were read
 * back from the stack before their stores had retired (half of trace_packet's samples). */
static vkrt_hit public_hit_f(const cpu_trace_scene *s, const ray_f *r, const hit_f *best)
{
    if (best->prim == NO_PRIM) return cpu_trace_miss();
    float t = refine_hit_distance((vec3_d){ r->origin.x, r->origin.y, r->origin.z }, (vec3_d){ r->dir.x, r->dir.y, r->dir.z },
                                  r->tmin, r->tmax, &s->tris[best->tri], best->t);
    return (vkrt_hit){ .t = t, .prim_id = best->prim, .u = best->u, .v = best->v };
}

static vkrt_hit trace_one_ray(const job *j, const vkrt_ray *in)
{
    const cpu_trace_rays_params *p = j->rays_params;
    heat_counts heat = { 0 };
    hit best = { .prim = NO_PRIM };
    if (p->precision == VKRT_PRECISION_DOUBLE) {
        ray_d r;
        if (ray_from_buffer_d(in, &r)) best = trace_ray_d(j->scene, p->traversal, p->intersector, &r, &heat, p->any_hit);
        if (best.prim == NO_PRIM) return cpu_trace_miss();
        return (vkrt_hit){ .t = best.t, .prim_id = best.prim, .u = best.u, .v = best.v };
    }
    ray_f r;
    if (!ray_from_buffer_f(in, &r)) return cpu_trace_miss();
    best = trace_float(j->scene, p->traversal, p->intersector, &r, &heat, p->any_hit, false);
    return public_hit_f(j->scene, &r, &(hit_f){ best.t, best.u, best.v, best.tri, best.prim });
}

/* Rays [i, i + 8) as one packet where they are valid and coherent (cpu_trace_packet8.h);
 * false, with nothing written, where they are not. */
static bool trace_packet(const job *j, size_t i)
{
    const cpu_trace_rays_params *p = j->rays_params;
    if (!packet8_coherent(&j->rays[i])) return false;
    packet8 packet;
    if (!packet8_load(&j->rays[i], &packet)) return false;
    trace_packet8_f(j->scene, p->intersector, p->any_hit, &packet);
    for (int l = 0; l < PACKET8_LANES; l++) j->hits[i + l] = public_hit_f(j->scene, &packet.ray[l], &packet.best[l]);
    return true;
}

static bool run_ray_block(job *j, size_t block)
{
    size_t first = block * RAY_BLOCK, end = first + RAY_BLOCK < j->ray_count ? first + RAY_BLOCK : j->ray_count;
    const cpu_trace_rays_params *p = j->rays_params;
    const bool packets = j->scene->wide && p->traversal == VKRT_TRAVERSAL_BVH && p->precision != VKRT_PRECISION_DOUBLE;
    for (size_t i = first, check = first; i < end;) {
        /* Checked every 64 rays so a cancel stops a slow (naive) block early. */
        if (i >= check) {
            if (work_pool_cancelled(j->pool)) return false;
            check = i + 64;
        }
        if (packets && i + PACKET8_LANES <= end && trace_packet(j, i)) {
            i += PACKET8_LANES;
            continue;
        }
        j->hits[i] = trace_one_ray(j, &j->rays[i]);
        i++;
    }
    return true;
}

/* Traces item `item` of the job (work_pool's item function). */
static void run_pool_item(void *arg, uint32_t item)
{
    job *j = arg;
    if (j->run_item(j, item)) atomic_fetch_add_explicit(&j->done_items, 1, memory_order_relaxed);
}

/* Between items, on the calling thread alone (work_pool's between hook), so the progress
 * callback never runs on a worker: reports the fraction done; false cancels. */
static bool report_progress(void *arg)
{
    job *j = arg;
    float fraction = (float)atomic_load_explicit(&j->done_items, memory_order_relaxed) / (float)j->items;
    return j->progress(j->progress_user, "trace", fraction);
}

/* Runs j->items items on `threads` threads (the builder's work pool), the caller one of them. */
static vkrt_result run_job(core *c, job *j, uint32_t threads, vkrt_progress_fn progress, void *progress_user)
{
    atomic_init(&j->done_items, 0);
    j->progress = progress;
    j->progress_user = progress_user;
    /* No more threads than items: the others would start only to find nothing left. */
    vkrt_result r = work_pool_create(c, threads < j->items ? threads : j->items, &j->pool);
    if (r != VKRT_OK) return r;
    const bool finished = work_pool_run(j->pool, j->items, run_pool_item, progress ? report_progress : NULL, j);
    work_pool_destroy(j->pool);
    j->pool = NULL;
    if (!finished) return core_fail(c, VKRT_ERROR_CANCELLED, "trace cancelled by the progress callback");
    if (progress) progress(progress_user, "trace", 1.0f);
    return VKRT_OK;
}

#ifdef VKRT_CPU_TRACE_X86_64_V3
#define CPU_TRACE_ENTRY(name) name##_x86_64_v3
#else
#define CPU_TRACE_ENTRY(name) name##_baseline
#endif

vkrt_result CPU_TRACE_ENTRY(cpu_trace_render)(core *c, const cpu_trace_scene *scene, const cpu_trace_params *params,
                                              float *out_rgba, trace_counts *out_counts);
vkrt_result CPU_TRACE_ENTRY(cpu_trace_rays)(core *c, const cpu_trace_scene *scene, const cpu_trace_rays_params *params,
                                            const vkrt_ray *rays, size_t count, vkrt_hit *out_hits);

vkrt_result CPU_TRACE_ENTRY(cpu_trace_render)(core *c, const cpu_trace_scene *scene, const cpu_trace_params *params,
                                              float *out_rgba, trace_counts *out_counts)
{
    const uint32_t width = params->camera.width, height = params->camera.height;
    const vkrt_gpu_push *p = &params->camera;
    const camera_basis *b = &params->camera_d;
    job j = {
        .run_item = run_tile,
        .scene = scene,
        .params = params,
        .cam_f = { v_load_f(p->eye), v_load_f(p->right), v_load_f(p->up), v_load_f(p->forward), width, height },
        .cam_d = { { b->eye[0], b->eye[1], b->eye[2] }, { b->right[0], b->right[1], b->right[2] },
                   { b->up[0], b->up[1], b->up[2] }, { b->forward[0], b->forward[1], b->forward[2] }, width, height },
        .out = out_rgba,
    };
    j.tiles_x = (width + TILE - 1) / TILE;
    /* The API keeps width and height within 65,536 (MAX_IMAGE_SIZE), so the tiles fit 32 bits. */
    j.items = j.tiles_x * ((height + TILE - 1) / TILE);
    atomic_init(&j.count_nodes, 0);
    atomic_init(&j.count_leaves, 0);
    atomic_init(&j.count_tris, 0);
    atomic_init(&j.count_samples, 0);
    atomic_init(&j.count_shadow, 0);
    atomic_init(&j.count_bounce, 0);
    vkrt_result r = run_job(c, &j, params->threads, params->progress, params->progress_user);
    *out_counts = (trace_counts){ atomic_load(&j.count_nodes), atomic_load(&j.count_leaves), atomic_load(&j.count_tris),
                                  atomic_load(&j.count_samples), atomic_load(&j.count_shadow),
                                  atomic_load(&j.count_bounce) };
    return r;
}

vkrt_result CPU_TRACE_ENTRY(cpu_trace_rays)(core *c, const cpu_trace_scene *scene, const cpu_trace_rays_params *params,
                                            const vkrt_ray *rays, size_t count, vkrt_hit *out_hits)
{
    const size_t blocks = (count + RAY_BLOCK - 1) / RAY_BLOCK;
    if (blocks > UINT32_MAX)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "%zu rays exceed the %llu one call can trace", count,
                         (unsigned long long)UINT32_MAX * RAY_BLOCK);
    job j = {
        .run_item = run_ray_block,
        .items = (uint32_t)blocks,
        .scene = scene,
        .rays_params = params,
        .rays = rays,
        .ray_count = count,
        .hits = out_hits,
    };
    if (j.items == 0) return VKRT_OK;
    return run_job(c, &j, params->threads, params->progress, params->progress_user);
}

#ifndef VKRT_CPU_TRACE_X86_64_V3
#ifdef VKRT_HAVE_CPU_TRACE_X86_64_V3
vkrt_result cpu_trace_render_x86_64_v3(core *c, const cpu_trace_scene *scene, const cpu_trace_params *params,
                                       float *out_rgba, trace_counts *out_counts);
vkrt_result cpu_trace_rays_x86_64_v3(core *c, const cpu_trace_scene *scene, const cpu_trace_rays_params *params,
                                     const vkrt_ray *rays, size_t count, vkrt_hit *out_hits);
#endif

#ifdef VKRT_HAVE_CPU_TRACE_X86_64_V3
static bool host_runs_x86_64_v3(void)
{
#if defined(__clang__)
    /* clang 14 cannot ask for the ISA level: the level's features it can ask for (every CPU with
     * them has the others the level adds: LZCNT, MOVBE, F16C, XSAVE). */
    return __builtin_cpu_supports("avx") && __builtin_cpu_supports("avx2") && __builtin_cpu_supports("bmi") &&
           __builtin_cpu_supports("bmi2") && __builtin_cpu_supports("fma") && __builtin_cpu_supports("popcnt");
#else
    return __builtin_cpu_supports("x86-64-v3");
#endif
}
#endif

cpu_trace_code cpu_trace_isa(const core *c)
{
#ifdef VKRT_HAVE_CPU_TRACE_X86_64_V3
    if (!c->test_cpu_baseline && host_runs_x86_64_v3()) return CPU_TRACE_X86_64_V3;
#else
    (void)c;
#endif
    return CPU_TRACE_BASELINE;
}

const char *cpu_trace_isa_name(cpu_trace_code code)
{
    return code == CPU_TRACE_X86_64_V3 ? "x86-64-v3" : "baseline";
}

vkrt_result cpu_trace_render(core *c, const cpu_trace_scene *scene, const cpu_trace_params *params, float *out_rgba,
                             trace_counts *out_counts)
{
#ifdef VKRT_HAVE_CPU_TRACE_X86_64_V3
    if (cpu_trace_isa(c) == CPU_TRACE_X86_64_V3)
        return cpu_trace_render_x86_64_v3(c, scene, params, out_rgba, out_counts);
#endif
    return cpu_trace_render_baseline(c, scene, params, out_rgba, out_counts);
}

vkrt_result cpu_trace_rays(core *c, const cpu_trace_scene *scene, const cpu_trace_rays_params *params,
                           const vkrt_ray *rays, size_t count, vkrt_hit *out_hits)
{
#ifdef VKRT_HAVE_CPU_TRACE_X86_64_V3
    if (cpu_trace_isa(c) == CPU_TRACE_X86_64_V3) return cpu_trace_rays_x86_64_v3(c, scene, params, rays, count, out_hits);
#endif
    return cpu_trace_rays_baseline(c, scene, params, rays, count, out_hits);
}
#endif /* !VKRT_CPU_TRACE_X86_64_V3 */

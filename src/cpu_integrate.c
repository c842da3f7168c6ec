/* See cpu_integrate.h. The stages of one sample are the functions of shaders/shade.comp with
 * the same names, run in the order gpu_integrate.c dispatches them; the CPU traces each shadow
 * ray as soon as the stage made it, which is why a pending contribution is resolved at once. */
#include "cpu_integrate.h"

#include <math.h>
#include <string.h>

#include "sampler.h"
#include "shading.h"

typedef vkrt_float3 vec3;

static vec3 v3(float x, float y, float z) { return (vec3){ x, y, z }; }
static vec3 add(vec3 a, vec3 b) { return v3(a.x + b.x, a.y + b.y, a.z + b.z); }
static vec3 mul(vec3 a, vec3 b) { return v3(a.x * b.x, a.y * b.y, a.z * b.z); }
static vec3 scale(vec3 a, float s) { return v3(a.x * s, a.y * s, a.z * s); }
static float dot(vec3 a, vec3 b) { return (a.x * b.x + a.y * b.y) + a.z * b.z; }
static float max3(vec3 a) { return a.x > a.y ? (a.x > a.z ? a.x : a.z) : (a.y > a.z ? a.y : a.z); }

/* Everything one sample of one pixel carries from stage to stage (vkrt_gpu_path). */
typedef struct sample_ctx {
    const cpu_trace_scene *scene;
    const cpu_trace_params *params;
    const cpu_lighting *lit;
    sh_scene sh;
    uint32_t pixel_seed, index;
    trace_counts *counts;
    vkrt_gpu_path path;
    vkrt_gpu_ray ray;       /* the extension ray (rays buffer) */
    vkrt_gpu_ray shadow;    /* the shadow ray (shadow rays buffer) */
} sample_ctx;

static void next4(sample_ctx *c, float u[4])
{
    sampler_get4(c->pixel_seed, c->index, c->path.rng_dim++, u);
}

/* The shadow ray of a pending contribution, traced any-hit; unoccluded, it adds. */
static void resolve_pending(sample_ctx *c)
{
    if (!(c->path.flags & VKRT_PATH_PENDING)) return;
    c->path.flags &= ~VKRT_PATH_PENDING;
    vkrt_gpu_hit h;
    trace_counts ignored = { 0 };
    if (!cpu_trace_one(c->scene, c->params->traversal, c->params->intersector, &c->shadow, true, &h, &ignored))
        c->path.radiance = add(c->path.radiance, c->path.pending);
}

static void set_pending(sample_ctx *c, vec3 contribution, const vkrt_gpu_ray *ray)
{
    if (!(max3(contribution) > 0.0f)) return;
    c->path.pending = contribution;
    c->path.flags |= VKRT_PATH_PENDING;
    c->shadow = *ray;
    c->counts->shadow_rays++;
}

static sh_material vertex_material(const sample_ctx *c)
{
    return (sh_material){ c->path.albedo, c->path.metallic, c->path.roughness, { 0.0f, 0.0f, 0.0f } };
}

/* VKRT_STAGE_HIT: the extension ray's closest hit. */
static void stage_hit(sample_ctx *c, const vkrt_gpu_hit *h)
{
    vkrt_gpu_path *q = &c->path;
    resolve_pending(c);
    if (!(q->flags & VKRT_PATH_ACTIVE)) return;
    const uint32_t mode = (uint32_t)c->params->mode;
    vec3 dir = c->ray.dir;
    if (h->tri == 0xFFFFFFFFu) {
        q->flags &= ~(VKRT_PATH_ACTIVE | VKRT_PATH_VERTEX);
        if (mode == VKRT_GPU_MODE_AO) {
            if (q->depth == 0) q->radiance = v3(1.0f, 1.0f, 1.0f);
        } else if ((c->lit->features & VKRT_GPU_FEATURE_SKY) && (mode == VKRT_GPU_MODE_PATH || q->depth == 0)) {
            q->radiance = add(q->radiance, mul(q->throughput, sh_sky(&c->lit->lighting, dir)));
        }
        return;
    }
    const vkrt_gpu_tri *tri = &c->scene->tris[h->tri];
    vec3 p, ng, ns;
    sh_hit_geometry(tri, h->u, h->v, dir, &p, &ng, &ns);
    sh_material m = sh_material_at(&c->sh, tri->prim_id, h->u, h->v);
    if (q->depth == 0) q->flags |= VKRT_PATH_PRIMARY_HIT;
    if ((c->lit->features & VKRT_GPU_FEATURE_EMITTERS) && mode != VKRT_GPU_MODE_AO &&
        (mode == VKRT_GPU_MODE_PATH || q->depth == 0) && max3(m.emission) > 0.0f) {
        float w = 1.0f;
        if (q->depth > 0 && q->bsdf_pdf > 0.0f) w = sh_mis_weight(q->bsdf_pdf, sh_emitter_pdf(&c->sh, tri, dir, h->t));
        q->radiance = add(q->radiance, scale(mul(q->throughput, m.emission), w));
    }
    q->position = p;
    q->geo_normal = ng;
    q->normal = ns;
    q->tri = h->tri;
    q->albedo = m.albedo;
    q->metallic = m.metallic;
    q->roughness = m.roughness;
    q->wo = scale(dir, -1.0f);
    q->depth++;
    q->flags |= VKRT_PATH_VERTEX;
    if (mode == VKRT_GPU_MODE_SHADED && (c->lit->features & VKRT_GPU_FEATURE_SKY))
        q->radiance = add(q->radiance, mul(q->throughput, scale(mul(m.albedo, sh_sky(&c->lit->lighting, ns)),
                                                                 1.0f - m.metallic)));
}

/* Direct light from light `index` (probability `pick` of having chosen it): its contribution
 * waits for the shadow ray. `mis`: weigh area lights against BSDF sampling (path mode). */
static void light_contribution(sample_ctx *c, uint32_t index, float pick, float u0, float u1, bool mis)
{
    const vkrt_gpu_path *q = &c->path;
    const vkrt_gpu_light *light = &c->lit->lights[index];
    sh_light_sample ls = sh_sample_light(&c->sh, light, q->position, q->geo_normal, u0, u1);
    if (!ls.valid || !(pick > 0.0f)) return;
    sh_material m = vertex_material(c);
    float bsdf_pdf;
    vec3 f = sh_bsdf_eval(&m, q->normal, q->geo_normal, q->wo, ls.wi, &bsdf_pdf);
    float w = mis && ls.pdf > 0.0f ? sh_mis_weight(pick * ls.pdf, bsdf_pdf) : 1.0f;
    vec3 contribution = scale(mul(mul(q->throughput, f), ls.radiance), dot(q->normal, ls.wi) * w / pick);
    set_pending(c, contribution, &ls.ray);
}

/* VKRT_STAGE_SHADOW `k`: the k-th shadow or AO ray from the stored vertex. */
static void stage_shadow(sample_ctx *c, uint32_t k)
{
    vkrt_gpu_path *q = &c->path;
    resolve_pending(c);
    if (!(q->flags & VKRT_PATH_VERTEX)) return;
    const vkrt_gpu_lighting *l = &c->lit->lighting;
    const uint32_t mode = (uint32_t)c->params->mode;
    if (mode == VKRT_GPU_MODE_AO) {
        float u[4];
        next4(c, u);
        vec3 dir = sh_cosine_dir(q->normal, u[0], u[1]);
        /* A direction into the surface itself is occluded by it. */
        if (dot(dir, q->geo_normal) <= 0.0f) return;
        vkrt_gpu_ray ray = { sh_offset(q->position, q->geo_normal), 0.0f, dir, l->ao_distance };
        set_pending(c, v3(1.0f / (float)l->ao_samples, 1.0f / (float)l->ao_samples, 1.0f / (float)l->ao_samples), &ray);
    } else if (mode == VKRT_GPU_MODE_SHADED) {
        if (k < l->punctual_count) {
            light_contribution(c, k, 1.0f, 0.0f, 0.0f, false);
        } else if (l->emitter_pick > 0.0f) {
            /* One emissive triangle, picked by power among the emitters. */
            float u[4];
            next4(c, u);
            float start = 1.0f - l->emitter_pick;
            uint32_t j = sh_pick_light(c->lit->lights, l->punctual_count, l->light_count - l->punctual_count,
                                       start + u[0] * l->emitter_pick);
            light_contribution(c, j, c->lit->lights[j].pick / l->emitter_pick, u[1], u[2], false);
        }
    } else if (l->light_count > 0) {
        float u[4];
        next4(c, u);
        uint32_t j = sh_pick_light(c->lit->lights, 0, l->light_count, u[0]);
        light_contribution(c, j, c->lit->lights[j].pick, u[1], u[2], true);
    }
}

/* VKRT_STAGE_BOUNCE: the next direction from the BSDF, then Russian roulette. */
static void stage_bounce(sample_ctx *c)
{
    vkrt_gpu_path *q = &c->path;
    if (!(q->flags & VKRT_PATH_ACTIVE)) return;
    q->flags &= ~VKRT_PATH_VERTEX;
    if (q->depth > c->lit->lighting.max_bounces) {
        q->flags &= ~VKRT_PATH_ACTIVE;
        return;
    }
    float u[4];
    next4(c, u);
    sh_material m = vertex_material(c);
    sh_bsdf_sample b = sh_bsdf_sample_dir(&m, q->normal, q->geo_normal, q->wo, u);
    if (!b.valid) {
        q->flags &= ~VKRT_PATH_ACTIVE;
        return;
    }
    q->throughput = mul(q->throughput, b.weight);
    q->bsdf_pdf = b.pdf;
    /* Russian roulette from the third vertex on: a path that carries little goes on with a
     * probability of its throughput, and is weighed up by the inverse when it does. */
    if (q->depth >= 3) {
        float keep = max3(q->throughput);
        keep = keep < 0.95f ? keep : 0.95f;
        if (!(u[3] < keep)) {
            q->flags &= ~VKRT_PATH_ACTIVE;
            return;
        }
        q->throughput = scale(q->throughput, 1.0f / keep);
    }
    c->ray = (vkrt_gpu_ray){ sh_offset(q->position, q->geo_normal), 0.0f, b.dir, 0.0f };
    c->counts->bounce_rays++;
}

/* One sample's radiance; *out_primary_hit: whether the primary ray hit a surface. */
static vec3 run_sample(sample_ctx *c, uint32_t x, uint32_t y, bool *out_primary_hit)
{
    const uint32_t mode = (uint32_t)c->params->mode;
    const vkrt_gpu_lighting *l = &c->lit->lighting;
    memset(&c->path, 0, sizeof c->path);
    c->path.throughput = v3(1.0f, 1.0f, 1.0f);
    c->path.flags = VKRT_PATH_ACTIVE;
    c->ray = cpu_trace_camera_ray(&c->params->camera, x, y);
    for (;;) {
        vkrt_gpu_hit h;
        trace_counts ignored = { 0 };
        cpu_trace_one(c->scene, c->params->traversal, c->params->intersector, &c->ray, false, &h, &ignored);
        stage_hit(c, &h);
        if (mode == VKRT_GPU_MODE_PATH) {
            if (!(c->path.flags & VKRT_PATH_ACTIVE)) break;
            stage_shadow(c, 0);
            stage_bounce(c);
            if (!(c->path.flags & VKRT_PATH_ACTIVE)) break;
            continue;
        }
        uint32_t shadows = mode == VKRT_GPU_MODE_AO ? l->ao_samples
                                                    : l->punctual_count + (l->emitter_pick > 0.0f ? 1u : 0u);
        for (uint32_t k = 0; k < shadows; k++) stage_shadow(c, k);
        break;
    }
    resolve_pending(c);
    *out_primary_hit = (c->path.flags & VKRT_PATH_PRIMARY_HIT) != 0;
    vec3 L = c->path.radiance;
    /* A NaN or infinity from a degenerate sample would poison the pixel for good. */
    if (!isfinite(L.x) || !isfinite(L.y) || !isfinite(L.z)) L = v3(0.0f, 0.0f, 0.0f);
    return L;
}

void cpu_integrate_pixel(const cpu_trace_scene *s, const cpu_trace_params *p, uint32_t x, uint32_t y, float out[4],
                         trace_counts *counts)
{
    const cpu_lighting *lit = p->lighting;
    sample_ctx c = {
        .scene = s, .params = p, .lit = lit,
        .sh = { s->tris, s->surfaces, s->materials, s->textures, s->texels, lit->lights, &lit->lighting, lit->features },
        .pixel_seed = sampler_pixel_seed(x, y, lit->lighting.seed),
        .counts = counts,
    };
    const uint32_t spp = (lit->features & VKRT_GPU_FEATURE_RANDOM) ? lit->lighting.spp : 1u;
    vkrt_gpu_accum acc = { 0 };
    for (uint32_t i = 0; i < spp && !acc.done; i++) {
        c.index = i;
        bool primary_hit;
        vec3 L = run_sample(&c, x, y, &primary_hit);
        float lum = sh_luminance(L);
        acc.sum = add(acc.sum, L);
        acc.samples++;
        acc.lum_sum += lum;
        acc.lum_sq_sum += lum * lum;
        acc.alpha = primary_hit ? 1.0f : 0.0f;
        /* What a pixel that sees the sky shows is the same in every sample. */
        if (!primary_hit) acc.done = 1;
        /* A target of 0 is no target, even where all_features compiles the test in. */
        if ((lit->features & VKRT_GPU_FEATURE_ADAPTIVE) && lit->lighting.target_error > 0.0f && acc.samples >= 8) {
            float n = (float)acc.samples, mean = acc.lum_sum / n;
            float var = (acc.lum_sq_sum - n * mean * mean) / (n - 1.0f);
            float err = sqrtf((var > 0.0f ? var : 0.0f) / n);
            if (err <= lit->lighting.target_error * mean || !(mean > 0.0f)) acc.done = 1;
        }
    }
    counts->samples += acc.samples;
    float inv = 1.0f / (float)acc.samples;
    out[0] = acc.sum.x * inv, out[1] = acc.sum.y * inv, out[2] = acc.sum.z * inv, out[3] = acc.alpha;
    if (lit->out_error) {
        float n = (float)acc.samples, mean = acc.lum_sum / n;
        float var = n > 1.0f ? (acc.lum_sq_sum - n * mean * mean) / (n - 1.0f) : 0.0f;
        lit->out_error[(size_t)y * p->camera.width + x] = sqrtf((var > 0.0f ? var : 0.0f) / n);
    }
}

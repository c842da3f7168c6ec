/* The stages of the lighting modes (shaded, ao, path) over the pixels of a tile, between the
 * wavefront traversals of trace.comp: one invocation per pixel, no loop without a small fixed
 * bound. The stage, the mode and the features are specialization constants, so a pipeline
 * holds only the code its scene uses. Mirrors the functions of the same names in
 * src/cpu_integrate.c, which run the same stages in the same order on the CPU. */
#version 460
#extension GL_GOOGLE_include_directive : require
#ifdef VKRT_HAS_BUFFER_ADDRESS
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_buffer_reference_uvec2 : require
#endif

#include "vkrt_shared.h"

layout(local_size_x = VKRT_TRACE_GROUP_X, local_size_y = VKRT_TRACE_GROUP_Y, local_size_z = 1) in;

layout(constant_id = VKRT_SPEC_SHADE_STAGE) const uint STAGE = VKRT_STAGE_CAMERA;
layout(constant_id = VKRT_SPEC_SHADE_MODE) const uint MODE = VKRT_GPU_MODE_PATH;
layout(constant_id = VKRT_SPEC_SHADE_FEATURES) const uint FEATURES = VKRT_GPU_FEATURE_ALL;
layout(constant_id = VKRT_SPEC_SHADE_SPLIT) const uint SPLIT = 0u;

layout(set = 0, binding = VKRT_SHADE_BINDING_TRIS, std430) readonly buffer Tris { vkrt_gpu_tri tris[]; };
layout(set = 0, binding = VKRT_SHADE_BINDING_SURFACES, std430) readonly buffer Surfaces { vkrt_gpu_surface surfaces[]; };
layout(set = 0, binding = VKRT_SHADE_BINDING_MATERIALS, std430) readonly buffer Materials { vkrt_gpu_material materials[]; };
layout(set = 0, binding = VKRT_SHADE_BINDING_TEXTURES, std430) readonly buffer Textures { vkrt_gpu_texture textures[]; };
layout(set = 0, binding = VKRT_SHADE_BINDING_TEXELS, std430) readonly buffer Texels { uvec2 texels[]; };
layout(set = 0, binding = VKRT_SHADE_BINDING_LIGHTS, std430) readonly buffer Lights { vkrt_gpu_light lights[]; };
layout(set = 0, binding = VKRT_SHADE_BINDING_PATHS, std430) buffer Paths { vkrt_gpu_path paths[]; };
layout(set = 0, binding = VKRT_SHADE_BINDING_ACCUM, std430) buffer Accum { vkrt_gpu_accum accum[]; };
layout(set = 0, binding = VKRT_SHADE_BINDING_RAYS, std430) buffer Rays { vkrt_gpu_ray rays[]; };
layout(set = 0, binding = VKRT_SHADE_BINDING_HITS, std430) readonly buffer Hits { vkrt_gpu_hit hits[]; };
layout(set = 0, binding = VKRT_SHADE_BINDING_SHADOW_RAYS, std430) buffer ShadowRays { vkrt_gpu_ray shadow_rays[]; };
layout(set = 0, binding = VKRT_SHADE_BINDING_SHADOW_HITS, std430) readonly buffer ShadowHits { vkrt_gpu_hit shadow_hits[]; };
/* active_count and queue_count: reset by the host before a stage that counts (the paths that go
 * on, and the entries of the output queue); the ray counts run over the render. */
layout(set = 0, binding = VKRT_SHADE_BINDING_ACTIVE, std430) buffer Active {
    uint active_count;
    uint queue_count;
    uint shadow_count;
    uint bounce_count;
};
layout(set = 0, binding = VKRT_SHADE_BINDING_QUEUE, std430) buffer Queue { uint queue[]; };
layout(set = 0, binding = VKRT_SHADE_BINDING_LIGHTING, std430) readonly buffer Lighting { vkrt_gpu_lighting lighting; };
/* A split scene's piece addresses (see trace.comp). */
layout(set = 0, binding = VKRT_SHADE_BINDING_PIECES, std430) readonly buffer Pieces { vkrt_gpu_address pieces[]; };
layout(push_constant, std430) uniform Push {
    vkrt_gpu_push p;
};

/* trace_common.glsl's intersectors are unused here; ISECT only lets it compile. */
const uint ISECT = VKRT_GPU_ISECT_WATERTIGHT;
#include "scene_arrays.glsl"
#include "trace_common.glsl"
#include "texture.glsl"
#include "sampler.glsl"
#include "shading.glsl"

/* A ray the trace passes skip (a zero direction misses at once). */
const vkrt_gpu_ray NO_RAY = vkrt_gpu_ray(vec3(0.0), 0.0, vec3(0.0), 0.0);

uint slot;   /* the pixel within the tile: its path and accumulation */
uint lane;   /* its place in this stage's queue: its rays and hits */
uint pixel_seed;
vkrt_gpu_path q;

vec4 next4()
{
    vec4 u = sampler_get4(pixel_seed, accum[slot].samples, q.rng_dim);
    q.rng_dim++;
    return u;
}

float max3(vec3 a)
{
    return a.x > a.y ? (a.x > a.z ? a.x : a.z) : (a.y > a.z ? a.y : a.z);
}

/* The shadow ray traced since the last stage: unoccluded, its contribution adds. */
void resolve_pending()
{
    if ((q.flags & VKRT_PATH_PENDING) == 0u) return;
    q.flags &= ~VKRT_PATH_PENDING;
    if (shadow_hits[q.shadow_lane].tri == NO_PRIM) q.radiance = q.radiance + q.pending;
}

/* Every invocation writes its shadow ray slot: a stale ray from an earlier stage must not be
 * traced again. */
void set_pending(vec3 contribution, vkrt_gpu_ray ray)
{
    if (!(max3(contribution) > 0.0)) return;
    q.pending = contribution;
    q.flags |= VKRT_PATH_PENDING;
    q.shadow_lane = lane;
    shadow_rays[lane] = ray;
    atomicAdd(shadow_count, 1u);
}

material_sample vertex_material()
{
    return material_sample(q.albedo, q.metallic, q.roughness, vec3(0.0));
}

/* Appends this path to the output queue, its next ray at its new lane. */
void enqueue(vkrt_gpu_ray next)
{
    uint k = atomicAdd(queue_count, 1u);
    queue[p.tri_end + k] = slot;
    rays[k] = next;
}

void stage_camera()
{
    q.throughput = vec3(1.0);
    q.flags = VKRT_PATH_ACTIVE;
    q.radiance = vec3(0.0);
    q.bsdf_pdf = 0.0;
    q.depth = 0u;
    q.rng_dim = 0u;
    ray r = camera_ray(p, p.tile_x + slot % p.tile_width, p.tile_y + slot / p.tile_width);
    q.wo = -r.dir;
    enqueue(vkrt_gpu_ray(r.origin, 0.0, r.dir, 0.0));
}

void stage_hit()
{
    resolve_pending();
    if ((q.flags & VKRT_PATH_ACTIVE) == 0u) return;
    vkrt_gpu_hit h = hits[lane];
    vec3 dir = -q.wo;
    if (h.tri == NO_PRIM) {
        q.flags &= ~(VKRT_PATH_ACTIVE | VKRT_PATH_VERTEX);
        if (MODE == VKRT_GPU_MODE_AO) {
            if (q.depth == 0u) q.radiance = vec3(1.0);
        } else if ((FEATURES & VKRT_GPU_FEATURE_SKY) != 0u && (MODE == VKRT_GPU_MODE_PATH || q.depth == 0u)) {
            q.radiance = q.radiance + q.throughput * sky(dir);
        }
        return;
    }
    vkrt_gpu_tri tri = load_tri(h.tri);
    vec3 pos, ng, ns;
    hit_geometry(tri, h.u, h.v, dir, pos, ng, ns);
    material_sample m = material_at(tri.prim_id, h.u, h.v);
    if (q.depth == 0u) q.flags |= VKRT_PATH_PRIMARY_HIT;
    if ((FEATURES & VKRT_GPU_FEATURE_EMITTERS) != 0u && MODE != VKRT_GPU_MODE_AO &&
        (MODE == VKRT_GPU_MODE_PATH || q.depth == 0u) && max3(m.emission) > 0.0) {
        float w = 1.0;
        if (q.depth > 0u && q.bsdf_pdf > 0.0) w = mis_weight(q.bsdf_pdf, emitter_pdf(tri, dir, h.t));
        q.radiance = q.radiance + (q.throughput * m.emission) * w;
    }
    q.position = pos;
    q.geo_normal = ng;
    q.normal = ns;
    q.tri = h.tri;
    q.albedo = m.albedo;
    q.metallic = m.metallic;
    q.roughness = m.roughness;
    q.wo = -dir;
    q.depth++;
    q.flags |= VKRT_PATH_VERTEX;
    if (MODE == VKRT_GPU_MODE_SHADED && (FEATURES & VKRT_GPU_FEATURE_SKY) != 0u)
        q.radiance = q.radiance + q.throughput * ((m.albedo * sky(ns)) * (1.0 - m.metallic));
}

void light_contribution(uint index, float pick, float u0, float u1, bool mis)
{
    vkrt_gpu_light light = lights[index];
    light_sample ls = sample_light(light, q.position, q.geo_normal, u0, u1);
    if (!ls.valid || !(pick > 0.0)) return;
    material_sample m = vertex_material();
    float bsdf_pdf;
    vec3 f = bsdf_eval(m, q.normal, q.geo_normal, q.wo, ls.wi, bsdf_pdf);
    float w = mis && ls.pdf > 0.0 ? mis_weight(pick * ls.pdf, bsdf_pdf) : 1.0;
    vec3 contribution = ((q.throughput * f) * ls.radiance) * (dot3(q.normal, ls.wi) * w / pick);
    set_pending(contribution, ls.ray);
}

void stage_shadow(uint k)
{
    resolve_pending();
    shadow_rays[lane] = NO_RAY;
    if ((q.flags & VKRT_PATH_VERTEX) == 0u) return;
    if (MODE == VKRT_GPU_MODE_AO) {
        vec4 u = next4();
        vec3 dir = cosine_dir(q.normal, u.x, u.y);
        if (dot3(dir, q.geo_normal) <= 0.0) return;
        float share = 1.0 / float(lighting.ao_samples);
        set_pending(vec3(share), vkrt_gpu_ray(ray_offset(q.position, q.geo_normal), 0.0, dir, lighting.ao_distance));
    } else if (MODE == VKRT_GPU_MODE_SHADED) {
        if (k < lighting.punctual_count) {
            if ((FEATURES & VKRT_GPU_FEATURE_PUNCTUAL) != 0u) light_contribution(k, 1.0, 0.0, 0.0, false);
        } else if ((FEATURES & VKRT_GPU_FEATURE_EMITTERS) != 0u && lighting.emitter_pick > 0.0) {
            vec4 u = next4();
            float start = 1.0 - lighting.emitter_pick;
            uint j = pick_light(lighting.punctual_count, lighting.light_count - lighting.punctual_count,
                                start + u.x * lighting.emitter_pick);
            light_contribution(j, lights[j].pick / lighting.emitter_pick, u.y, u.z, false);
        }
    } else if ((FEATURES & (VKRT_GPU_FEATURE_PUNCTUAL | VKRT_GPU_FEATURE_EMITTERS)) != 0u && lighting.light_count > 0u) {
        /* Next-event estimation: compiled out of a render lit only by the sky. */
        vec4 u = next4();
        uint j = pick_light(0u, lighting.light_count, u.x);
        light_contribution(j, lights[j].pick, u.y, u.z, true);
    }
}

void bounce_direction()
{
    q.flags &= ~VKRT_PATH_VERTEX;
    if (q.depth > lighting.max_bounces) {
        q.flags &= ~VKRT_PATH_ACTIVE;
        return;
    }
    vec4 u = next4();
    material_sample m = vertex_material();
    bsdf_sample b = bsdf_sample_dir(m, q.normal, q.geo_normal, q.wo, u.xyz);
    if (!b.valid) {
        q.flags &= ~VKRT_PATH_ACTIVE;
        return;
    }
    q.throughput = q.throughput * b.weight;
    q.bsdf_pdf = b.pdf;
    q.wo = -b.dir;
    if (q.depth >= 3u) {
        float keep = max3(q.throughput);
        keep = keep < 0.95 ? keep : 0.95;
        if (!(u.w < keep)) {
            q.flags &= ~VKRT_PATH_ACTIVE;
            return;
        }
        q.throughput = q.throughput * (1.0 / keep);
    }
}

/* The next direction from the BSDF, then Russian roulette. A path that goes on is queued with
 * its ray; one that ends with a shadow ray pending is queued without one, so the next stage
 * resolves it before the shadow lanes are reused. */
void stage_bounce()
{
    if ((q.flags & VKRT_PATH_ACTIVE) != 0u) bounce_direction();
    if ((q.flags & VKRT_PATH_ACTIVE) != 0u) {
        enqueue(vkrt_gpu_ray(ray_offset(q.position, q.geo_normal), 0.0, -q.wo, 0.0));
        atomicAdd(active_count, 1u);
        atomicAdd(bounce_count, 1u);
    } else if ((q.flags & VKRT_PATH_PENDING) != 0u) {
        enqueue(NO_RAY);
    }
}

void stage_finish()
{
    resolve_pending();
    vkrt_gpu_accum a = accum[slot];
    if (a.done != 0u) return;
    vec3 radiance = q.radiance;
    if (!finite3(radiance)) radiance = vec3(0.0);
    bool primary_hit = (q.flags & VKRT_PATH_PRIMARY_HIT) != 0u;
    float lum = luminance(radiance);
    a.sum = a.sum + radiance;
    a.samples++;
    a.lum_sum += lum;
    a.lum_sq_sum += lum * lum;
    a.alpha = primary_hit ? 1.0 : 0.0;
    if (!primary_hit) a.done = 1u;
    /* A target of 0 is no target, even where all_features compiles the test in. */
    if ((FEATURES & VKRT_GPU_FEATURE_ADAPTIVE) != 0u && lighting.target_error > 0.0 && a.samples >= 8u) {
        float n = float(a.samples), mean = a.lum_sum / n;
        precise float var = (a.lum_sq_sum - n * mean * mean) / (n - 1.0);
        float err = sqrt((var > 0.0 ? var : 0.0) / n);
        if (err <= lighting.target_error * mean || !(mean > 0.0)) a.done = 1u;
    }
    accum[slot] = a;
}

void main()
{
    if (STAGE == VKRT_STAGE_CAMERA || STAGE == VKRT_STAGE_FINISH) {
        /* Every pixel of the tile; one done sampling has nothing to do. */
        uvec2 local = gl_GlobalInvocationID.xy;
        if (local.x >= p.tile_width || local.y >= p.tile_height) return;
        slot = local.y * p.tile_width + local.x;
        if (accum[slot].done != 0u) return;
        lane = 0u;
    } else {
        /* The queued paths: a 1D dispatch over the input queue's lanes. */
        lane = gl_WorkGroupID.x * (VKRT_TRACE_GROUP_X * VKRT_TRACE_GROUP_Y) + gl_LocalInvocationIndex;
        if (lane >= p.tri_total) return;
        slot = queue[p.tri_first + lane];
    }
    pixel_seed = sampler_pixel_seed(p.tile_x + slot % p.tile_width, p.tile_y + slot / p.tile_width, lighting.seed);
    q = paths[slot];
    if (STAGE == VKRT_STAGE_CAMERA) {
        stage_camera();
    } else if (STAGE == VKRT_STAGE_HIT) {
        stage_hit();
    } else if (STAGE == VKRT_STAGE_SHADOW) {
        stage_shadow(p.stage_arg);
    } else if (STAGE == VKRT_STAGE_BOUNCE) {
        stage_bounce();
    } else if (STAGE == VKRT_STAGE_VERTEX) {
        stage_hit();
        stage_shadow(0u);
        stage_bounce();
    } else if (STAGE == VKRT_STAGE_HIT_SHADOW) {
        stage_hit();
        stage_shadow(0u);
    } else {
        stage_finish();
    }
    paths[slot] = q;
}

/* Public entry points: validate the caller's input, fill defaults, call the modules. */
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

#include "camera.h"
#include "context.h"
#include "cpu_integrate.h"
#include "cpu_trace.h"
#include "gpu_integrate.h"
#include "lights.h"
#include "mesh.h"
#include "ray_offset.h"
#include "scene_pack.h"

#define DEFAULT_IMAGE_SIZE 1024u
/* Rows or columns beyond this are surely a mistake (and keep width * height * 4 in range). */
#define MAX_IMAGE_SIZE 65536u

_Static_assert(VKRT_GPU_MODE_NORMAL == VKRT_MODE_NORMAL && VKRT_GPU_MODE_DEPTH == VKRT_MODE_DEPTH &&
                   VKRT_GPU_MODE_HEATMAP == VKRT_MODE_HEATMAP && VKRT_GPU_MODE_ID == VKRT_MODE_ID &&
                   VKRT_GPU_MODE_ALBEDO == VKRT_MODE_ALBEDO && VKRT_GPU_MODE_UV == VKRT_MODE_UV &&
                   VKRT_GPU_MODE_SHADED == VKRT_MODE_SHADED && VKRT_GPU_MODE_AO == VKRT_MODE_AO &&
                   VKRT_GPU_MODE_PATH == VKRT_MODE_PATH,
               "shader mode values must equal vkrt_mode");
_Static_assert(VKRT_GPU_FEATURE_TEXTURES == VKRT_FEATURE_TEXTURES && VKRT_GPU_FEATURE_PUNCTUAL == VKRT_FEATURE_PUNCTUAL &&
                   VKRT_GPU_FEATURE_EMITTERS == VKRT_FEATURE_EMITTERS && VKRT_GPU_FEATURE_SKY == VKRT_FEATURE_SKY &&
                   VKRT_GPU_FEATURE_SPECULAR == VKRT_FEATURE_SPECULAR && VKRT_GPU_FEATURE_RANDOM == VKRT_FEATURE_RANDOM &&
                   VKRT_GPU_FEATURE_ADAPTIVE == VKRT_FEATURE_ADAPTIVE && VKRT_GPU_FEATURE_ALL == VKRT_FEATURE_ALL,
               "shader feature bits must equal VKRT_FEATURE_*");
_Static_assert(VKRT_GPU_TRAVERSAL_BVH == VKRT_TRAVERSAL_BVH && VKRT_GPU_TRAVERSAL_NAIVE == VKRT_TRAVERSAL_NAIVE,
               "shader traversal values must equal vkrt_traversal");
_Static_assert(VKRT_GPU_HEAT_NODES == VKRT_HEAT_NODES && VKRT_GPU_HEAT_LEAVES == VKRT_HEAT_LEAVES &&
                   VKRT_GPU_HEAT_TRIS == VKRT_HEAT_TRIS,
               "shader heat values must equal vkrt_heat");
_Static_assert(VKRT_GPU_ISECT_WATERTIGHT == VKRT_INTERSECTOR_WATERTIGHT &&
                   VKRT_GPU_ISECT_MOLLER_TRUMBORE == VKRT_INTERSECTOR_MOLLER_TRUMBORE,
               "shader intersector values must equal vkrt_intersector");
/* vkrt_trace_rays hands the caller's arrays to the device as they are. */
_Static_assert(sizeof(vkrt_ray) == sizeof(vkrt_gpu_ray) && offsetof(vkrt_ray, tmin) == offsetof(vkrt_gpu_ray, tmin) &&
                   offsetof(vkrt_ray, dir) == offsetof(vkrt_gpu_ray, dir) &&
                   offsetof(vkrt_ray, tmax) == offsetof(vkrt_gpu_ray, tmax),
               "vkrt_ray must have the layout of vkrt_gpu_ray");
_Static_assert(sizeof(vkrt_hit) == sizeof(vkrt_gpu_hit) && offsetof(vkrt_hit, prim_id) == offsetof(vkrt_gpu_hit, tri) &&
                   offsetof(vkrt_hit, u) == offsetof(vkrt_gpu_hit, u) && offsetof(vkrt_hit, v) == offsetof(vkrt_gpu_hit, v),
               "vkrt_hit must have the layout of vkrt_gpu_hit");

static uint32_t online_cores(void)
{
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    return n > 0 ? (uint32_t)n : 1u;
}

vkrt_result vkrt_context_create(const vkrt_context_desc *desc, vkrt_context **out_ctx)
{
    if (!out_ctx) return VKRT_ERROR_INVALID_ARGUMENT;
    *out_ctx = NULL;
    vkrt_context_desc d = desc ? *desc : (vkrt_context_desc){ 0 };
    core boot;
    core_init(&boot, &d.allocator, d.log, d.log_user);
    if (d.backend > VKRT_BACKEND_CPU)
        return core_fail(&boot, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_context_desc.backend has no valid value (%d)", (int)d.backend);
    if ((d.allocator.alloc == NULL) != (d.allocator.free == NULL))
        return core_fail(&boot, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_context_desc.allocator needs both alloc and free, or neither");
    vkrt_context *ctx = core_alloc(&boot, sizeof *ctx);
    if (!ctx) return core_fail(&boot, VKRT_ERROR_OUT_OF_MEMORY, "out of memory creating the context");
    memset(ctx, 0, sizeof *ctx);
    ctx->core = boot;
    ctx->backend = d.backend == VKRT_BACKEND_CPU ? VKRT_BACKEND_CPU : VKRT_BACKEND_GPU;
    ctx->cpu_threads = d.cpu_threads ? d.cpu_threads : online_cores();
    if (ctx->backend == VKRT_BACKEND_GPU) {
        vkrt_result r = vk_context_create(&ctx->core, &d, &ctx->vk);
        if (r != VKRT_OK) {
            vkrt_context_destroy(ctx);
            return r;
        }
    }
    *out_ctx = ctx;
    return VKRT_OK;
}

void vkrt_context_destroy(vkrt_context *ctx)
{
    if (!ctx) return;
    vk_context_destroy(ctx->vk);
    core c = ctx->core;
    core_free(&c, ctx);
}

const char *vkrt_context_last_error(const vkrt_context *ctx)
{
    return ctx ? ctx->core.last_error : "vkrt_context is NULL";
}

uint32_t vkrt_context_validation_messages(const vkrt_context *ctx)
{
    return ctx && ctx->vk ? ctx->vk->validation_messages : 0;
}

const char *vkrt_context_device_name(const vkrt_context *ctx)
{
    if (!ctx) return "";
    return ctx->vk ? ctx->vk->properties.deviceName : "CPU reference";
}

const char *vkrt_cpu_code(void)
{
    core c;
    core_init(&c, NULL, NULL, NULL);
    return cpu_trace_isa_name(cpu_trace_isa(&c));
}

vkrt_result vkrt_devices_list(const vkrt_context_desc *desc, vkrt_device_info *out, uint32_t *inout_count)
{
    if (!inout_count) return VKRT_ERROR_INVALID_ARGUMENT;
    core c;
    core_init(&c, desc ? &desc->allocator : NULL, desc ? desc->log : NULL, desc ? desc->log_user : NULL);
    return vk_devices_list(&c, out, inout_count);
}

/* ---- scenes ---- */

vkrt_material vkrt_material_default(void)
{
    return (vkrt_material){ .base_color = { 0.8f, 0.8f, 0.8f, 1.0f }, .metallic = 0.0f, .roughness = 1.0f };
}

void vkrt_scene_destroy(vkrt_scene *scene)
{
    if (!scene) return;
    core *c = &scene->ctx->core;
    if (scene->ctx->vk) gpu_scene_destroy(scene->ctx->vk, &scene->gpu);
    bvh_destroy(c, &scene->bvh);
    bvh4_destroy(c, &scene->wide);
    core_free(c, scene->tris);
    core_free(c, scene->surfaces);
    core_free(c, scene->materials);
    core_free(c, scene->textures);
    core_free(c, scene->texels);
    core_free(c, scene->lights);
    core_free(c, scene);
}

static void fill_stats(vkrt_scene *s, const mesh *m, double load_ms)
{
    bvh_stats bs;
    bvh_compute_stats(&s->bvh, &bs);
    vkrt_scene_stats *st = &s->stats;
    st->triangles = m->tri_count;
    st->bvh_references = s->bvh.tri_count;
    st->nodes = bs.nodes;
    st->leaves = bs.leaves;
    st->depth = bs.depth;
    st->max_leaf_triangles = bs.max_leaf_triangles;
    memcpy(st->leaf_histogram, bs.leaf_histogram, sizeof st->leaf_histogram);
    st->sah_cost = bs.sah_cost;
    st->load_ms = load_ms;
    st->build_ms = s->bvh.build_ms;
    st->node_bytes = (uint64_t)s->bvh.node_count * sizeof(vkrt_gpu_node) +
                     (uint64_t)s->wide.node_count * sizeof(bvh4_node);
    st->triangle_bytes = (uint64_t)s->bvh.tri_count * sizeof(vkrt_gpu_tri);
    memcpy(st->bounds_min, m->bounds_min, sizeof st->bounds_min);
    memcpy(st->bounds_max, m->bounds_max, sizeof st->bounds_max);
    st->materials = m->material_count;
    st->has_texcoords = m->has_texcoords;
    st->textures = m->texture_count;
    st->alpha_tested = s->alpha_tested;
    st->surface_bytes = (uint64_t)m->tri_count * sizeof(vkrt_gpu_surface) +
                        (uint64_t)m->material_count * sizeof(vkrt_gpu_material) +
                        (uint64_t)m->texture_count * sizeof(vkrt_gpu_texture) + (uint64_t)scene_texel_count(m) * 8u;
    st->host_bytes = st->node_bytes + st->triangle_bytes + (uint64_t)s->bvh.tri_count * sizeof(uint32_t) +
                     st->surface_bytes;
}

/* The caller's arrays go through the same validation, normal generation and transform as a
 * file's primitives. */
static vkrt_result meshes_from_memory(core *c, const vkrt_scene_desc *d, mesh *m)
{
    if (!d->meshes) return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_scene_desc.meshes is NULL but mesh_count is %u", d->mesh_count);
    for (uint32_t i = 0; i < d->mesh_count; i++) {
        const vkrt_mesh_desc *md = &d->meshes[i];
        char what[48];
        snprintf(what, sizeof what, "vkrt_scene_desc.meshes[%u]", i);
        if (!md->positions && md->vertex_count) return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "%s.positions is NULL", what);
        mesh_primitive p = {
            .positions = md->positions,
            .vertex_count = md->vertex_count,
            .indices = md->indices,
            .index_count = md->index_count,
            .normals = md->normals,
            .transform = md->transform,
            .texcoords = md->texcoords,
        };
        vkrt_result r = VKRT_OK;
        if (md->material) {
            const vkrt_material *mat = md->material;
            mesh_material_textures textures = MESH_NO_TEXTURES;
            const struct {
                const vkrt_texture_desc *desc;
                texture_encoding encoding;
                uint32_t *index;
                const char *field;
            } maps[] = {
                { mat->base_color_texture, TEXTURE_SRGB, &textures.base_color, "base_color_texture" },
                { mat->metallic_roughness_texture, TEXTURE_LINEAR, &textures.metallic_roughness,
                  "metallic_roughness_texture" },
                { mat->emissive_texture, TEXTURE_SRGB, &textures.emissive, "emissive_texture" },
            };
            for (size_t k = 0; k < sizeof maps / sizeof maps[0] && r == VKRT_OK; k++) {
                if (!maps[k].desc) continue;
                char field[96];
                snprintf(field, sizeof field, "%s.material->%s", what, maps[k].field);
                r = mesh_add_texture(c, m, maps[k].desc, maps[k].encoding, VKRT_ERROR_INVALID_ARGUMENT,
                                     "in-memory scene", field, maps[k].index);
            }
            uint32_t index = 0;
            if (r == VKRT_OK)
                r = mesh_add_material(c, m, mat, &textures, VKRT_ERROR_INVALID_ARGUMENT, "in-memory scene", what,
                                      &index);
            p.material = MESH_MATERIAL(index);
        }
        if (r == VKRT_OK) r = mesh_append_indexed(c, m, &p, "in-memory scene", what);
        if (r != VKRT_OK) {
            mesh_destroy(c, m);
            return r;
        }
    }
    if (m->tri_count == 0) return core_fail(c, VKRT_ERROR_EMPTY_SCENE, "in-memory scene: the meshes hold no triangles");
    return VKRT_OK;
}

vkrt_result vkrt_scene_create(vkrt_context *ctx, const vkrt_scene_desc *desc, vkrt_scene **out_scene)
{
    if (!ctx) return VKRT_ERROR_INVALID_ARGUMENT;
    core *c = &ctx->core;
    core_clear_error(c);
    if (!out_scene) return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "out_scene is NULL");
    *out_scene = NULL;
    vkrt_scene_desc d = desc ? *desc : (vkrt_scene_desc){ 0 };
    if (d.builder > VKRT_BVH_BUILDER_SPATIAL_SAH)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_scene_desc.builder has no valid value (%d)", (int)d.builder);
    /* A lost device refuses at once, before any loading. */
    if (ctx->vk && vk_check_lost(ctx->vk) != VKRT_OK) return VKRT_ERROR_DEVICE_LOST;

    mesh m = { 0 };
    vkrt_result r = VKRT_ERROR_OUT_OF_MEMORY;
    vkrt_scene *s = core_calloc_array(c, 1, sizeof *s);
    if (!s) {
        r = core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory creating the scene");
        goto fail;
    }
    s->ctx = ctx;
    double t0 = core_now_ms();
    if (d.path) r = mesh_load(c, d.path, &m);
    else if (d.mesh_count) r = meshes_from_memory(c, &d, &m);
    else r = mesh_make_builtin(c, &m);
    if (r != VKRT_OK) goto fail;
    if (!d.keep_world_coordinates) {
        const char *source = d.path ? d.path : d.mesh_count ? "in-memory scene" : "built-in scene";
        if ((r = mesh_normalize(c, &m, source)) != VKRT_OK) goto fail;
    } else {
        mesh_update_bounds(&m);
    }
    double load_ms = core_now_ms() - t0;

    bvh_build_desc bd = {
        .builder = d.builder,
        .max_leaf_size = d.max_leaf_size,
        .threads = ctx->cpu_threads,
        .progress = d.progress,
        .progress_user = d.progress_user,
    };
    if ((r = bvh_build(c, &m, &bd, &s->bvh)) != VKRT_OK) goto fail;
    if (!ctx->vk) {
        /* The CPU backend's fast path; its time is part of the build's. */
        double collapse_t0 = core_now_ms();
        if ((r = bvh4_collapse(c, &s->bvh, &s->wide)) != VKRT_OK) goto fail;
        s->bvh.build_ms += core_now_ms() - collapse_t0;
    }
    s->tris = core_alloc_array(c, s->bvh.tri_count, sizeof *s->tris);
    if (!s->tris) {
        r = core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory packing %u triangles", s->bvh.tri_count);
        goto fail;
    }
    scene_pack_triangles(&m, &s->bvh, s->tris);
    s->texel_count = scene_texel_count(&m);
    s->surfaces = core_alloc_array(c, m.tri_count, sizeof *s->surfaces);
    s->materials = core_alloc_array(c, m.material_count, sizeof *s->materials);
    /* At least one entry each: the device buffers always hold something. */
    s->textures = core_alloc_array(c, m.texture_count ? m.texture_count : 1, sizeof *s->textures);
    s->texels = core_alloc_array(c, s->texel_count ? s->texel_count : 1, 2 * sizeof *s->texels);
    if (!s->surfaces || !s->materials || !s->textures || !s->texels) {
        r = core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory packing the surfaces of %u triangles", m.tri_count);
        goto fail;
    }
    s->material_count = m.material_count;
    s->texture_count = m.texture_count;
    for (uint32_t i = 0; i < m.material_count; i++) {
        s->alpha_tested |= m.materials[i].alpha_cutoff > 0.0f;
        s->has_metals |= m.materials[i].metallic > 0.0f;
    }
    if (m.light_count) {
        s->lights = core_alloc_array(c, m.light_count, sizeof *s->lights);
        if (!s->lights) {
            r = core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory for %u lights", m.light_count);
            goto fail;
        }
        memcpy(s->lights, m.lights, m.light_count * sizeof *s->lights);
        s->light_count = m.light_count;
    }
    {
        double r2 = 0.0;
        for (int k = 0; k < 3; k++) {
            double e = 0.5 * ((double)m.bounds_max[k] - m.bounds_min[k]);
            r2 += e * e;
        }
        s->radius = (float)sqrt(r2);
    }
    if (!m.texture_count) memset(s->textures, 0, sizeof *s->textures);
    if (!s->texel_count) memset(s->texels, 0, 2 * sizeof *s->texels);
    scene_pack_surfaces(&m, s->surfaces, s->materials, s->textures, s->texels);
    fill_stats(s, &m, load_ms);
    s->stats.lights = s->light_count;
    s->stats.has_metals = s->has_metals;
    for (uint32_t t = 0; t < m.tri_count; t++) {
        const vkrt_gpu_material *mat = &s->materials[s->surfaces[t].material];
        s->stats.emissive_triangles += mat->emissive.x > 0.0f || mat->emissive.y > 0.0f || mat->emissive.z > 0.0f;
    }
    mesh_destroy(c, &m);
    if (ctx->vk) {
        r = gpu_scene_upload(ctx->vk, &s->bvh, s->tris, ctx->cpu_threads, &s->gpu);
        if (r != VKRT_OK) goto fail;
        /* The wide BVH is part of the GPU's acceleration structure, as the CPU backend's
         * collapse is of its own (both in build_ms). */
        s->stats.build_ms += s->gpu.wide_pack_ms;
    }
    *out_scene = s;
    return VKRT_OK;
fail:
    mesh_destroy(c, &m);
    vkrt_scene_destroy(s);
    return r;
}

vkrt_result vkrt_scene_stats_get(const vkrt_scene *scene, vkrt_scene_stats *out_stats)
{
    if (!scene || !out_stats) return VKRT_ERROR_INVALID_ARGUMENT;
    *out_stats = scene->stats;
    /* Read now: the surfaces may have reached the device since the scene was made. */
    if (scene->ctx->vk) gpu_scene_usage(&scene->gpu, &out_stats->device_bytes, &out_stats->device_buffers);
    out_stats->traversal_bytes = scene->ctx->vk ? gpu_scene_traversal_bytes(&scene->gpu)
                                                : out_stats->node_bytes + out_stats->triangle_bytes;
    return VKRT_OK;
}

vkrt_result vkrt_scene_triangles_get(const vkrt_scene *scene, float *out_positions, size_t out_floats)
{
    if (!scene) return VKRT_ERROR_INVALID_ARGUMENT;
    core *c = &scene->ctx->core;
    core_clear_error(c);
    if (!out_positions) return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "out_positions is NULL");
    size_t tris = scene->stats.triangles;
    if (out_floats / 9 < tris)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "out_positions holds %zu floats; %zu triangles need %zu",
                         out_floats, tris, tris * 9);
    /* The packed array is in BVH order; prim_id is each triangle's place in the loaded file.
     * With spatial splits a triangle is there more than once, each copy the same. */
    for (size_t k = 0; k < scene->bvh.tri_count; k++) {
        const vkrt_gpu_tri *t = &scene->tris[k];
        float *o = out_positions + (size_t)t->prim_id * 9;
        const vkrt_float3 corners[3] = { t->v0, t->v1, t->v2 };
        for (int i = 0; i < 3; i++) o[3 * i] = corners[i].x, o[3 * i + 1] = corners[i].y, o[3 * i + 2] = corners[i].z;
    }
    return VKRT_OK;
}

/* ---- rendering ---- */

/* The scene as the CPU tracer reads it. */
static cpu_trace_scene cpu_scene_of(const vkrt_scene *scene)
{
    return (cpu_trace_scene){
        .nodes = scene->bvh.nodes, .node_count = scene->bvh.node_count, .tris = scene->tris,
        .tri_count = scene->bvh.tri_count, .surfaces = scene->surfaces, .materials = scene->materials,
        .textures = scene->textures, .texels = scene->texels, .alpha_tested = scene->alpha_tested,
        .wide = scene->wide.nodes ? &scene->wide : NULL,
    };
}

/* On the GPU, the surfaces go to the device the first time a render reads them: a mode that
 * shows them (`needed`), or any trace of an alpha-tested scene. */
static vkrt_result ensure_surfaces(vkrt_scene *scene, bool needed)
{
    if (!scene->ctx->vk || !(needed || scene->alpha_tested)) return VKRT_OK;
    const gpu_surface_data data = {
        scene->surfaces,
        (uint32_t)scene->stats.triangles,
        scene->materials,
        scene->material_count,
        scene->textures,
        scene->texture_count ? scene->texture_count : 1,
        scene->texels,
        scene->texel_count ? scene->texel_count : 1,
    };
    return gpu_scene_upload_surfaces(scene->ctx->vk, &scene->gpu, &data);
}

/* On the GPU, the binary BVH's nodes and the shading triangles go to the device the first time
 * a call reads them (GPU_ARRAY_*): a scene traced through the wide BVH alone never holds them. */
static vkrt_result ensure_arrays(vkrt_scene *scene, uint32_t arrays)
{
    if (!scene->ctx->vk || !arrays) return VKRT_OK;
    return gpu_scene_upload_arrays(scene->ctx->vk, &scene->gpu, &scene->bvh, scene->tris, arrays);
}

/* The intersector and precision fields shared by vkrt_render_desc and vkrt_trace_desc. */
static vkrt_result check_tracing(vkrt_context *ctx, vkrt_intersector intersector, vkrt_precision precision,
                                 const char *desc_name)
{
    core *c = &ctx->core;
    if (intersector > VKRT_INTERSECTOR_MOLLER_TRUMBORE)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "%s.intersector has no valid value (%d)", desc_name, (int)intersector);
    if (precision > VKRT_PRECISION_DOUBLE)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "%s.precision has no valid value (%d)", desc_name, (int)precision);
    if (precision == VKRT_PRECISION_DOUBLE && ctx->vk)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT,
                         "%s.precision: double precision needs the CPU backend (VKRT_BACKEND_CPU); the GPU traces in float",
                         desc_name);
    return VKRT_OK;
}

size_t vkrt_render_floats(uint32_t width, uint32_t height)
{
    size_t pixels = (size_t)width * height;
    if (width && pixels / width != height) return 0;
    if (pixels > SIZE_MAX / 4) return 0;
    return pixels * 4;
}

const char *vkrt_feature_name(uint32_t feature)
{
    switch (feature) {
    case VKRT_FEATURE_TEXTURES: return "textures";
    case VKRT_FEATURE_PUNCTUAL: return "point and directional lights";
    case VKRT_FEATURE_EMITTERS: return "emissive triangles";
    case VKRT_FEATURE_SKY: return "sky";
    case VKRT_FEATURE_SPECULAR: return "metals (GGX and mirrors)";
    case VKRT_FEATURE_RANDOM: return "random numbers";
    case VKRT_FEATURE_ADAPTIVE: return "adaptive sampling";
    default: return "";
    }
}

static bool sky_is_black(const vkrt_gpu_lighting *l)
{
    return l->sky_zenith.x == 0.0f && l->sky_zenith.y == 0.0f && l->sky_zenith.z == 0.0f && l->sky_horizon.x == 0.0f &&
           l->sky_horizon.y == 0.0f && l->sky_horizon.z == 0.0f;
}

/* The features a lighting render needs: what the scene has and the render asks for. */
static uint32_t lighting_features(const vkrt_scene *scene, const light_table *t, vkrt_mode mode, float target_error)
{
    uint32_t f = 0;
    if (scene->texture_count > 0) f |= VKRT_GPU_FEATURE_TEXTURES;
    if (t->lighting.punctual_count > 0) f |= VKRT_GPU_FEATURE_PUNCTUAL;
    if (t->count > t->lighting.punctual_count) f |= VKRT_GPU_FEATURE_EMITTERS;
    if (!sky_is_black(&t->lighting)) f |= VKRT_GPU_FEATURE_SKY;
    if (scene->has_metals) f |= VKRT_GPU_FEATURE_SPECULAR;
    /* Shaded with only point and directional lights is deterministic: one sample is exact. */
    if (mode != VKRT_MODE_SHADED || (f & VKRT_GPU_FEATURE_EMITTERS)) f |= VKRT_GPU_FEATURE_RANDOM;
    if (target_error > 0.0f && (f & VKRT_GPU_FEATURE_RANDOM)) f |= VKRT_GPU_FEATURE_ADAPTIVE;
    /* AO reads only geometry. */
    if (mode == VKRT_MODE_AO) f &= VKRT_GPU_FEATURE_RANDOM | VKRT_GPU_FEATURE_ADAPTIVE;
    return f;
}

#define MAX_SPP 65536u
#define MAX_AO_SAMPLES 256u
#define MAX_BOUNCES 64u

/* shaded, ao and path: the light table, the features, then either backend. */
static vkrt_result render_lighting(vkrt_context *ctx, vkrt_scene *scene, const vkrt_render_desc *d, vkrt_mode mode,
                                   vkrt_traversal traversal, const vkrt_gpu_push *camera, camera_basis camera_d,
                                   float *out_rgba, vkrt_render_stats *out_stats)
{
    core *c = &ctx->core;
    if (d->precision == VKRT_PRECISION_DOUBLE)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT,
                         "vkrt_render_desc.precision: the lighting modes trace in float (double is for the primary modes' reference)");
    if (d->light_count && !d->lights)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_render_desc.lights is NULL but light_count is %u", d->light_count);
    if (d->spp > MAX_SPP) return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_render_desc.spp %u exceeds %u", d->spp, MAX_SPP);
    if (d->ao_samples > MAX_AO_SAMPLES)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_render_desc.ao_samples %u exceeds %u", d->ao_samples, MAX_AO_SAMPLES);
    if (d->max_bounces > MAX_BOUNCES)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_render_desc.max_bounces %u exceeds %u", d->max_bounces, MAX_BOUNCES);
    if (!(d->ao_distance >= 0.0f) || !isfinite(d->ao_distance))
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_render_desc.ao_distance must be finite and >= 0 (%g)", d->ao_distance);
    if (d->extra_features & ~VKRT_FEATURE_ALL)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_render_desc.extra_features has bits beyond VKRT_FEATURE_ALL (0x%x)",
                         d->extra_features);
    if (!(d->target_error >= 0.0f) || !isfinite(d->target_error))
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_render_desc.target_error must be finite and >= 0 (%g)", d->target_error);
    vkrt_result r = ensure_surfaces(scene, true);
    if (r == VKRT_OK && ctx->vk)
        r = ensure_arrays(scene, GPU_ARRAY_TRIS | gpu_trace_rays_arrays(&scene->gpu, traversal));
    if (r != VKRT_OK) return r;
    light_table table;
    const light_table_desc ld = {
        .render_lights = d->lights, .render_light_count = d->light_count, .scene_lights = scene->lights,
        .scene_light_count = scene->light_count, .sky = d->sky, .tris = scene->tris, .tri_count = scene->bvh.tri_count,
        .prim_count = (uint32_t)scene->stats.triangles, .surfaces = scene->surfaces, .materials = scene->materials,
        .scene_radius = scene->radius,
    };
    if ((r = light_table_build(c, &ld, &table)) != VKRT_OK) return r;
    uint32_t features = lighting_features(scene, &table, mode, d->target_error) | d->extra_features;
    if (d->all_features) features = VKRT_GPU_FEATURE_ALL;
    vkrt_gpu_lighting lighting = table.lighting;
    lighting.ao_distance = d->ao_distance > 0.0f ? d->ao_distance : 0.5f;
    lighting.ao_samples = d->ao_samples ? d->ao_samples : 4u;
    lighting.max_bounces = d->max_bounces ? d->max_bounces : 8u;
    lighting.target_error = d->target_error;
    lighting.seed = d->seed;
    lighting.spp = d->spp ? d->spp : (mode == VKRT_MODE_PATH ? 16u : 1u);

    double t0 = core_now_ms();
    double trace_ms = 0.0;
    trace_counts counts = { 0 };
    if (ctx->vk) {
        gpu_integrate_params p = {
            .camera = *camera, .mode = mode, .traversal = traversal, .intersector = d->intersector,
            .alpha_tested = scene->alpha_tested, .textured = scene->texture_count > 0, .lights = &table, .lighting = lighting, .features = features,
            .out_error = d->out_error, .progress = d->progress, .progress_user = d->progress_user,
        };
        r = gpu_integrate_render(ctx->vk, &scene->gpu, &p, out_rgba, &trace_ms, &counts);
    } else {
        cpu_lighting lit = { table.lights, lighting, features, d->out_error };
        cpu_trace_scene s = cpu_scene_of(scene);
        cpu_trace_params p = {
            .camera = *camera, .mode = mode, .traversal = traversal, .heat = VKRT_HEAT_NODES,
            .intersector = d->intersector, .camera_d = camera_d, .lighting = &lit, .threads = ctx->cpu_threads,
            .progress = d->progress, .progress_user = d->progress_user,
        };
        r = cpu_trace_render(c, &s, &p, out_rgba, &counts);
        trace_ms = core_now_ms() - t0;
    }
    if (r == VKRT_OK && out_stats) {
        out_stats->trace_ms = trace_ms;
        out_stats->total_ms = core_now_ms() - t0;
        out_stats->rays = (uint64_t)d->width * d->height;
        out_stats->features = features;
        out_stats->lights = table.count;
        out_stats->samples = counts.samples;
        out_stats->shadow_rays = counts.shadow_rays;
        out_stats->bounce_rays = counts.bounce_rays;
        out_stats->submissions = counts.submissions;
        out_stats->longest_submission_ms = counts.longest_submission_ms;
    }
    light_table_destroy(c, &table);
    return r;
}

vkrt_result vkrt_render(vkrt_context *ctx, vkrt_scene *scene, const vkrt_render_desc *desc, float *out_rgba,
                        size_t out_floats, vkrt_render_stats *out_stats)
{
    if (!ctx) return VKRT_ERROR_INVALID_ARGUMENT;
    core *c = &ctx->core;
    core_clear_error(c);
    if (out_stats) memset(out_stats, 0, sizeof *out_stats);
    if (!scene) return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "scene is NULL");
    if (scene->ctx != ctx) return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "the scene belongs to another context");
    if (!out_rgba) return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "out_rgba is NULL");
    if (ctx->vk && vk_check_lost(ctx->vk) != VKRT_OK) return VKRT_ERROR_DEVICE_LOST;
    vkrt_render_desc d = desc ? *desc : (vkrt_render_desc){ 0 };
    if (!d.width) d.width = DEFAULT_IMAGE_SIZE;
    if (!d.height) d.height = DEFAULT_IMAGE_SIZE;
    if (d.width > MAX_IMAGE_SIZE || d.height > MAX_IMAGE_SIZE)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "image size %ux%u exceeds %u on a side", d.width, d.height,
                         MAX_IMAGE_SIZE);
    if (d.mode > VKRT_MODE_PATH) return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_render_desc.mode has no valid value (%d)", (int)d.mode);
    if (d.traversal > VKRT_TRAVERSAL_NAIVE)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_render_desc.traversal has no valid value (%d)", (int)d.traversal);
    if (d.heat > VKRT_HEAT_TRIS) return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_render_desc.heat has no valid value (%d)", (int)d.heat);
    vkrt_result r = check_tracing(ctx, d.intersector, d.precision, "vkrt_render_desc");
    if (r != VKRT_OK) return r;
    size_t needed = vkrt_render_floats(d.width, d.height);
    if (out_floats < needed)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "out_rgba holds %zu floats; a %ux%u image needs %zu", out_floats,
                         d.width, d.height, needed);
    vkrt_gpu_push camera = { 0 };
    camera_basis camera_d = { 0 };
    r = camera_setup(c, &d.camera, d.width, d.height, &camera);
    /* Both CPU precisions read it: double traces from it, float refines hit distances with it. */
    if (r == VKRT_OK) r = camera_setup_double(c, &d.camera, d.width, d.height, &camera_d);
    if (r != VKRT_OK) return r;
    vkrt_mode mode = d.mode ? d.mode : VKRT_MODE_NORMAL;
    vkrt_traversal traversal = d.traversal ? d.traversal : VKRT_TRAVERSAL_BVH;
    vkrt_heat heat = d.heat ? d.heat : VKRT_HEAT_NODES;
    /* The cost model: with C_trav = C_isect = 1 a ray through the BVH is expected to cost the
     * scene's SAH cost, and a naive one a test per triangle; where the BVH saves nothing the
     * default traversal is naive. The heat map shows the BVH, so it keeps it. */
    bool naive_by_cost = d.traversal == VKRT_TRAVERSAL_DEFAULT && mode != VKRT_MODE_HEATMAP &&
                         scene->stats.sah_cost >= (double)scene->stats.triangles;
    if (naive_by_cost) traversal = VKRT_TRAVERSAL_NAIVE;
    if (mode >= VKRT_MODE_SHADED) {
        r = render_lighting(ctx, scene, &d, mode, traversal, &camera, camera_d, out_rgba, out_stats);
        if (r == VKRT_OK && out_stats) out_stats->naive_by_cost = naive_by_cost;
        return r;
    }

    double t0 = core_now_ms();
    double trace_ms = 0.0;
    trace_counts counts = { 0 };
    if ((r = ensure_surfaces(scene, mode == VKRT_MODE_ALBEDO || mode == VKRT_MODE_UV)) != VKRT_OK) return r;
    if (ctx->vk) {
        gpu_trace_params p = {
            .camera = camera, .mode = mode, .traversal = traversal, .heat = heat, .intersector = d.intersector,
            .counters = d.traversal_counters, .alpha_tested = scene->alpha_tested,
            .textured = scene->texture_count > 0, .progress = d.progress,
            .progress_user = d.progress_user, .tris = scene->tris, .threads = ctx->cpu_threads,
        };
        r = ensure_arrays(scene, gpu_trace_render_arrays(&scene->gpu, &p));
        if (r == VKRT_OK) r = gpu_trace_render(ctx->vk, &scene->gpu, &p, out_rgba, &trace_ms, &counts);
    } else {
        cpu_trace_scene s = cpu_scene_of(scene);
        cpu_trace_params p = {
            .camera = camera, .mode = mode, .traversal = traversal, .heat = heat, .intersector = d.intersector,
            .precision = d.precision, .camera_d = camera_d, .counters = d.traversal_counters,
            .threads = ctx->cpu_threads, .progress = d.progress, .progress_user = d.progress_user,
        };
        r = cpu_trace_render(c, &s, &p, out_rgba, &counts);
        trace_ms = core_now_ms() - t0;
    }
    if (r == VKRT_OK && out_stats) {
        out_stats->trace_ms = trace_ms;
        out_stats->total_ms = core_now_ms() - t0;
        out_stats->rays = (uint64_t)d.width * d.height;
        out_stats->nodes_visited = counts.nodes;
        out_stats->leaves_visited = counts.leaves;
        out_stats->tris_tested = counts.tris;
        out_stats->naive_by_cost = naive_by_cost;
        out_stats->submissions = counts.submissions;
        out_stats->longest_submission_ms = counts.longest_submission_ms;
        out_stats->rays_binned = counts.rays_binned;
        out_stats->binned_tests = counts.binned_tests;
    }
    return r;
}

/* ---- arbitrary rays ---- */

vkrt_result vkrt_camera_rays(vkrt_context *ctx, const vkrt_camera *camera, uint32_t width, uint32_t height,
                             vkrt_ray *out_rays, size_t out_count)
{
    if (!ctx) return VKRT_ERROR_INVALID_ARGUMENT;
    core *c = &ctx->core;
    core_clear_error(c);
    if (!out_rays) return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "out_rays is NULL");
    if (!width || !height || width > MAX_IMAGE_SIZE || height > MAX_IMAGE_SIZE)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "image size %ux%u is not 1 to %u on a side", width, height,
                         MAX_IMAGE_SIZE);
    size_t pixels = (size_t)width * height;
    if (out_count < pixels)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "out_rays holds %zu rays; a %ux%u image needs %zu", out_count,
                         width, height, pixels);
    vkrt_gpu_push push = { 0 };
    vkrt_result r = camera_setup(c, camera ? camera : &(vkrt_camera){ 0 }, width, height, &push);
    if (r != VKRT_OK) return r;
    for (uint32_t y = 0; y < height; y++) {
        for (uint32_t x = 0; x < width; x++) {
            vkrt_gpu_ray g = cpu_trace_camera_ray(&push, x, y);
            memcpy(&out_rays[(size_t)y * width + x], &g, sizeof g); /* one layout (asserted above) */
        }
    }
    return VKRT_OK;
}

void vkrt_ray_offset(const float p[3], const float n[3], float out_origin[3])
{
    vkrt_float3 o = ray_offset((vkrt_float3){ p[0], p[1], p[2] }, (vkrt_float3){ n[0], n[1], n[2] });
    out_origin[0] = o.x, out_origin[1] = o.y, out_origin[2] = o.z;
}

vkrt_result vkrt_trace_rays(vkrt_context *ctx, vkrt_scene *scene, const vkrt_trace_desc *desc, const vkrt_ray *rays,
                            size_t count, vkrt_hit *out_hits)
{
    if (!ctx) return VKRT_ERROR_INVALID_ARGUMENT;
    core *c = &ctx->core;
    core_clear_error(c);
    if (!scene) return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "scene is NULL");
    if (scene->ctx != ctx) return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "the scene belongs to another context");
    if (count && !rays) return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "rays is NULL");
    if (count && !out_hits) return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "out_hits is NULL");
    if (ctx->vk && vk_check_lost(ctx->vk) != VKRT_OK) return VKRT_ERROR_DEVICE_LOST;
    vkrt_trace_desc d = desc ? *desc : (vkrt_trace_desc){ 0 };
    if (d.traversal > VKRT_TRAVERSAL_NAIVE)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_trace_desc.traversal has no valid value (%d)", (int)d.traversal);
    vkrt_result r = check_tracing(ctx, d.intersector, d.precision, "vkrt_trace_desc");
    if (r != VKRT_OK) return r;
    const double t0 = core_now_ms();
    vkrt_trace_stats stats = { .rays = count };
    if (count == 0) {
        if (d.out_stats) *d.out_stats = stats;
        return VKRT_OK;
    }
    vkrt_traversal traversal = d.traversal ? d.traversal : VKRT_TRAVERSAL_BVH;
    if (ctx->vk) {
        gpu_trace_rays_params p = {
            .traversal = traversal, .intersector = d.intersector, .alpha_tested = scene->alpha_tested,
            .textured = scene->texture_count > 0, .any_hit = d.any_hit,
            .progress = d.progress, .progress_user = d.progress_user,
            .tris = scene->tris, .threads = ctx->cpu_threads,
        };
        if ((r = ensure_surfaces(scene, false)) == VKRT_OK)
            r = ensure_arrays(scene, gpu_trace_rays_arrays(&scene->gpu, traversal));
        trace_counts counts = { 0 };
        if (r == VKRT_OK) r = gpu_trace_rays(ctx->vk, &scene->gpu, &p, rays, count, out_hits, &stats.trace_ms, &counts);
        stats.rays_culled = counts.rays_culled;
        stats.rays_binned = counts.rays_binned;
        stats.binned_tests = counts.binned_tests;
        stats.submissions = counts.submissions;
    } else {
        cpu_trace_scene s = cpu_scene_of(scene);
        cpu_trace_rays_params p = {
            .traversal = traversal, .any_hit = d.any_hit, .intersector = d.intersector, .precision = d.precision,
            .threads = ctx->cpu_threads, .progress = d.progress, .progress_user = d.progress_user,
        };
        r = cpu_trace_rays(c, &s, &p, rays, count, out_hits);
        stats.trace_ms = core_now_ms() - t0;
    }
    stats.total_ms = core_now_ms() - t0;
    if (r == VKRT_OK && d.out_stats) *d.out_stats = stats;
    return r;
}

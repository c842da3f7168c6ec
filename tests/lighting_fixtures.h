/* Scenes of known radiance for the lighting modes, built in memory and rendered through vkrt.h
 * on either backend: shared by test_lighting.c (CPU) and test_lighting_gpu.c (GPU, against the
 * CPU). Include after check.h. */
#ifndef VKRT_LIGHTING_FIXTURES_H
#define VKRT_LIGHTING_FIXTURES_H

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "vkrt.h"

/* A UV sphere of radius r at the origin, outward-facing, `rings` x `segments` quads. */
typedef struct test_mesh {
    float *positions;
    uint32_t *indices;
    uint32_t vertex_count, index_count;
} test_mesh;

static inline test_mesh test_sphere(float r, uint32_t rings, uint32_t segments)
{
    test_mesh m = { 0 };
    m.vertex_count = (rings + 1) * (segments + 1);
    m.index_count = rings * segments * 6;
    m.positions = malloc((size_t)m.vertex_count * 3 * sizeof(float));
    m.indices = malloc((size_t)m.index_count * sizeof(uint32_t));
    if (!m.positions || !m.indices) return m;
    for (uint32_t i = 0; i <= rings; i++) {
        double theta = 3.14159265358979323846 * i / rings;
        for (uint32_t j = 0; j <= segments; j++) {
            double phi = 2.0 * 3.14159265358979323846 * j / segments;
            float *p = m.positions + (size_t)(i * (segments + 1) + j) * 3;
            p[0] = (float)(r * sin(theta) * cos(phi));
            p[1] = (float)(r * cos(theta));
            p[2] = (float)(r * sin(theta) * sin(phi));
        }
    }
    uint32_t k = 0;
    for (uint32_t i = 0; i < rings; i++)
        for (uint32_t j = 0; j < segments; j++) {
            uint32_t a = i * (segments + 1) + j, b = a + segments + 1;
            uint32_t quad[6] = { a, a + 1, b, a + 1, b + 1, b };
            memcpy(m.indices + k, quad, sizeof quad);
            k += 6;
        }
    return m;
}

/* The rectangle of corners c0, c1, c2, c0 + (c2 - c1) + (c1 - c0)... given as four corners in
 * order around it. */
static inline test_mesh test_quad(const float corners[12])
{
    test_mesh m = { 0 };
    m.vertex_count = 4;
    m.index_count = 6;
    m.positions = malloc(12 * sizeof(float));
    m.indices = malloc(6 * sizeof(uint32_t));
    if (!m.positions || !m.indices) return m;
    memcpy(m.positions, corners, 12 * sizeof(float));
    const uint32_t idx[6] = { 0, 1, 2, 0, 2, 3 };
    memcpy(m.indices, idx, sizeof idx);
    return m;
}

/* The same triangles unshared (three vertices each) with their face normals as vertex
 * normals: flat shading, so the shading normal is the geometric one and no BSDF sample is lost
 * below the surface, which keeps the analytic answers exact. */
typedef struct flat_mesh {
    float *positions;
    float *normals;
    uint32_t vertex_count;
} flat_mesh;

static inline flat_mesh test_flatten(const test_mesh *m)
{
    flat_mesh f = { 0 };
    f.vertex_count = m->index_count;
    f.positions = malloc((size_t)f.vertex_count * 3 * sizeof(float));
    f.normals = malloc((size_t)f.vertex_count * 3 * sizeof(float));
    if (!f.positions || !f.normals) return f;
    for (uint32_t t = 0; t < m->index_count / 3; t++) {
        const float *a = m->positions + m->indices[t * 3] * 3, *b = m->positions + m->indices[t * 3 + 1] * 3,
                    *c = m->positions + m->indices[t * 3 + 2] * 3;
        double e1[3] = { b[0] - a[0], b[1] - a[1], b[2] - a[2] }, e2[3] = { c[0] - a[0], c[1] - a[1], c[2] - a[2] };
        double n[3] = { e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0] };
        double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        for (int v = 0; v < 3; v++) {
            const float *src = v == 0 ? a : v == 1 ? b : c;
            memcpy(f.positions + (t * 3 + v) * 3, src, 3 * sizeof(float));
            for (int k = 0; k < 3; k++) f.normals[(t * 3 + v) * 3 + k] = len > 0 ? (float)(n[k] / len) : 0.0f;
        }
    }
    return f;
}

static inline vkrt_mesh_desc flat_mesh_desc(const flat_mesh *f, const vkrt_material *material)
{
    return (vkrt_mesh_desc){ .positions = f->positions, .vertex_count = f->vertex_count, .normals = f->normals,
                             .material = material };
}

static inline void flat_mesh_free(flat_mesh *f)
{
    free(f->positions);
    free(f->normals);
    memset(f, 0, sizeof *f);
}

static inline void test_mesh_free(test_mesh *m)
{
    free(m->positions);
    free(m->indices);
    memset(m, 0, sizeof *m);
}

static inline vkrt_mesh_desc test_mesh_desc(const test_mesh *m, const vkrt_material *material)
{
    return (vkrt_mesh_desc){ .positions = m->positions, .vertex_count = m->vertex_count, .indices = m->indices,
                             .index_count = m->index_count, .material = material };
}

/* A scene of the given meshes in world coordinates (no normalisation). */
static inline vkrt_scene *test_scene(vkrt_context *ctx, const vkrt_mesh_desc *meshes, uint32_t count)
{
    vkrt_scene *s = NULL;
    vkrt_scene_desc d = { .meshes = meshes, .mesh_count = count, .keep_world_coordinates = true };
    vkrt_result r = vkrt_scene_create(ctx, &d, &s);
    CHECK_MSG(r == VKRT_OK, "scene: %s", vkrt_context_last_error(ctx));
    return s;
}

/* Renders d; *out_error (may be NULL) gets the per-pixel standard errors. NULL on failure. */
static inline float *test_render(vkrt_context *ctx, vkrt_scene *s, vkrt_render_desc d, float **out_error,
                                 vkrt_render_stats *out_stats)
{
    size_t n = vkrt_render_floats(d.width, d.height);
    float *rgba = malloc(n * sizeof *rgba);
    float *err = out_error ? malloc((size_t)d.width * d.height * sizeof *err) : NULL;
    d.out_error = err;
    vkrt_result r = rgba && (err || !out_error) ? vkrt_render(ctx, s, &d, rgba, n, out_stats) : VKRT_ERROR_OUT_OF_MEMORY;
    CHECK_MSG(r == VKRT_OK, "render: %s", vkrt_context_last_error(ctx));
    if (r != VKRT_OK) {
        free(rgba);
        free(err);
        return NULL;
    }
    if (out_error) *out_error = err;
    return rgba;
}

/* The white furnace seen from inside: a closed sphere whose every triangle emits Le = 1 and
 * reflects diffusely with albedo a. Every path gathers 1 + a + a^2 + ... = 1 / (1 - a), so
 * each pixel converges to that, through emission, next-event estimation of the triangles,
 * BSDF sampling weighed against it, and Russian roulette. */
#define FURNACE_ALBEDO 0.5f
static inline vkrt_scene *test_emissive_furnace(vkrt_context *ctx)
{
    test_mesh sphere = test_sphere(1.0f, 12, 24);
    flat_mesh flat = test_flatten(&sphere);
    static const vkrt_material glow = { .base_color = { FURNACE_ALBEDO, FURNACE_ALBEDO, FURNACE_ALBEDO, 1.0f },
                                        .roughness = 1.0f, .emissive = { 1.0f, 1.0f, 1.0f } };
    vkrt_mesh_desc m = flat_mesh_desc(&flat, &glow);
    vkrt_scene *s = test_scene(ctx, &m, 1);
    flat_mesh_free(&flat);
    test_mesh_free(&sphere);
    return s;
}

/* The mean of the red channel over n pixels and the standard error of that mean (from the
 * per-pixel standard errors of luminance, which equals red in a grey scene). */
static inline void test_mean_and_error(const float *img, const float *err, size_t n, double *out_mean, double *out_se)
{
    double sum = 0.0, var = 0.0;
    for (size_t i = 0; i < n; i++) {
        sum += img[i * 4];
        var += (double)err[i] * err[i];
    }
    *out_mean = sum / (double)n;
    *out_se = sqrt(var) / (double)n;
}

static inline vkrt_render_desc test_inside_view(vkrt_mode mode, uint32_t size)
{
    return (vkrt_render_desc){ .width = size, .height = size, .mode = mode,
                               .camera = { .eye = { 0.1f, 0.05f, 0.2f }, .target = { 0.0f, 0.0f, -1.0f }, .fov_y_degrees = 90 } };
}

#endif

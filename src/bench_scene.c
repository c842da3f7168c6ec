/* The procedural scene: a torus whose tube is rippled (so its BVH has real work: no two rows of
 * triangles alike, silhouettes against the background) and tilted towards the default camera,
 * tessellated into R x C quads of two triangles each, C = 3R as the tube is about a third of
 * the ring. No triangle is degenerate at any size, unlike a sphere's poles. */
#include "bench_scene.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define MAJOR_RADIUS 1.0
#define MINOR_RADIUS 0.35
#define RIPPLE 0.06        /* of the tube's radius: bumps a few triangles wide at any size */
#define TILT 1.0           /* radians about x: the ring seen at an angle, hole and all */

static void grid(uint32_t n, uint32_t *rows, uint32_t *cols)
{
    double r = sqrt((double)n / 6.0);
    *rows = r < 3.0 ? 3u : (uint32_t)lround(r);
    double c = (double)n / (2.0 * *rows);
    *cols = c < 3.0 ? 3u : (uint32_t)lround(c);
}

vkrt_result bench_scene_init(bench_scene *s, const bench_options *o, char *error, size_t error_size)
{
    *s = (bench_scene){ .o = o };
    if (!o->procedural) {
        if (!o->input) snprintf(s->label, sizeof s->label, "built-in");
        return VKRT_OK;
    }
    uint32_t rows, cols;
    grid(o->procedural, &rows, &cols);
    snprintf(s->label, sizeof s->label, "procedural-%llu", (unsigned long long)(2ull * rows * cols));
    /* The seam's vertices are shared: rows x cols vertices, indices wrap around. */
    size_t verts = (size_t)rows * cols, tris = 2 * verts;
    s->positions = malloc(verts * 3 * sizeof *s->positions);
    s->indices = malloc(tris * 3 * sizeof *s->indices);
    if (!s->positions || !s->indices) {
        snprintf(error, error_size, "out of memory for a procedural scene of %zu triangles", tris);
        bench_scene_free(s);
        return VKRT_ERROR_OUT_OF_MEMORY;
    }
    const double two_pi = 6.283185307179586, ct = cos(TILT), st = sin(TILT);
    for (uint32_t i = 0; i < rows; i++) {     /* around the tube */
        double v = two_pi * i / rows;
        for (uint32_t j = 0; j < cols; j++) { /* around the ring */
            double u = two_pi * j / cols;
            double r = MINOR_RADIUS * (1.0 + RIPPLE * sin(13.0 * u) * sin(7.0 * v));
            double x = (MAJOR_RADIUS + r * cos(v)) * cos(u), y = (MAJOR_RADIUS + r * cos(v)) * sin(u), z = r * sin(v);
            float *p = s->positions + ((size_t)i * cols + j) * 3;
            p[0] = (float)x;
            p[1] = (float)(y * ct - z * st);
            p[2] = (float)(y * st + z * ct);
        }
    }
    uint32_t *t = s->indices;
    for (uint32_t i = 0; i < rows; i++)
        for (uint32_t j = 0; j < cols; j++) {
            uint32_t a = i * cols + j, b = i * cols + (j + 1) % cols;
            uint32_t c = ((i + 1) % rows) * cols + j, d = ((i + 1) % rows) * cols + (j + 1) % cols;
            *t++ = a, *t++ = b, *t++ = d;
            *t++ = a, *t++ = d, *t++ = c;
        }
    s->mesh = (vkrt_mesh_desc){ .positions = s->positions, .vertex_count = (uint32_t)verts, .indices = s->indices,
                                .index_count = (uint32_t)(tris * 3) };
    return VKRT_OK;
}

vkrt_scene_desc bench_scene_desc(const bench_scene *s)
{
    vkrt_scene_desc d = { .keep_world_coordinates = s->o->keep_world_coordinates, .builder = s->o->builder };
    if (s->o->procedural) {
        d.meshes = &s->mesh;
        d.mesh_count = 1;
    } else {
        d.path = s->o->input;
    }
    return d;
}

const char *bench_scene_name(const bench_scene *s)
{
    return s->label[0] ? s->label : s->o->input;
}

vkrt_result bench_scene_create(vkrt_context *ctx, const char *gpu_rows, const vkrt_scene_desc *desc,
                               vkrt_scene **out_scene, char *skipped, size_t skipped_size, char *error,
                               size_t error_size)
{
    vkrt_result r = vkrt_scene_create(ctx, desc, out_scene);
    if ((r == VKRT_ERROR_LIMIT || r == VKRT_ERROR_OUT_OF_DEVICE_MEMORY) && gpu_rows) {
        snprintf(skipped, skipped_size, "%s not run: %s", gpu_rows, vkrt_context_last_error(ctx));
        return VKRT_OK;
    }
    if (r != VKRT_OK) snprintf(error, error_size, "%s", vkrt_context_last_error(ctx));
    return r;
}

void bench_scene_free(bench_scene *s)
{
    free(s->positions);
    free(s->indices);
    s->positions = NULL;
    s->indices = NULL;
}
